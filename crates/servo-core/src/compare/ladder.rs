//! One model against several logs: the pooled figures of the error ladder, the replay mode chosen
//! for each log, and the controller of a closed-loop replay (servo's PID plus the feedforward the
//! run logged). `servo compare` and a Rust user build the ladder from these.

use super::figures::Figures;
use super::replay::{Controller, ReplayMode};
use super::report::{CompareReport, SignalKind};
use crate::control::pid::{Pid, PidConfig};
use crate::control::ControlError;
use crate::plant::Plant;
use alloc::string::String;
use alloc::vec::Vec;

/// The comparison of one model with every log.
#[derive(Debug, Clone)]
pub struct ModelComparison {
    pub plant: Plant,
    /// One report per log, in the order of the logs.
    pub reports: Vec<CompareReport>,
}

/// How the model is driven, and why.
#[derive(Debug, Clone)]
pub struct ModeChoice {
    pub mode: ReplayMode,
    pub reason: String,
}

/// The controller of a closed-loop replay and of the controller check: servo's PID configured as
/// it ran plus the feedforward the run logged, sample by sample (it depends on the reference
/// only, so the model gets what the motor got).
pub struct ReplayController<'a> {
    pid: Pid,
    feedforward_v: Option<&'a [f64]>,
    k: usize,
}

impl<'a> ReplayController<'a> {
    /// A controller at rest, at the start of the log; `feedforward_v` [V] is added to the PID's
    /// output at each sample (non-finite entries count as 0).
    pub fn new(config: &PidConfig, feedforward_v: Option<&'a [f64]>) -> Result<Self, ControlError> {
        Ok(ReplayController {
            pid: Pid::new(*config)?,
            feedforward_v,
            k: 0,
        })
    }
}

impl Controller for ReplayController<'_> {
    fn update(&mut self, reference_rad: f64, measured_rad: f64) -> f64 {
        let ff = self
            .feedforward_v
            .and_then(|f| f.get(self.k))
            .copied()
            .filter(|v| v.is_finite())
            .unwrap_or(0.0);
        self.k += 1;
        self.pid.update(reference_rad, measured_rad, ff).u_v
    }
}

/// Figures of every signal pooled over the logs (the measurement and model concatenated), in the
/// order of first appearance; the first is the headline of the first log.
pub fn pooled(c: &ModelComparison) -> Vec<(SignalKind, Figures)> {
    let mut kinds: Vec<SignalKind> = Vec::new();
    if let Some(r) = c.reports.first() {
        kinds.push(r.headline_signal().kind);
    }
    for r in &c.reports {
        for s in &r.signals {
            if !kinds.contains(&s.kind) {
                kinds.push(s.kind);
            }
        }
    }
    kinds
        .into_iter()
        .map(|k| {
            let (mut y, mut yh) = (Vec::new(), Vec::new());
            for r in &c.reports {
                if let Some(s) = r.signals.iter().find(|s| s.kind == k) {
                    y.extend_from_slice(&s.measured);
                    yh.extend_from_slice(&s.model);
                }
            }
            (k, Figures::of(&y, &yh))
        })
        .collect()
}
