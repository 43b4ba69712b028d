//! The reference steps a time-domain design promises, run exactly as `servo run` runs them: the
//! simulator backend on the named plant (its effects, friction included, and its sensors), the
//! run loop of [`super::run_loop`] with the PID as `servo run` builds it from the gains file,
//! and the step metrics of the run summary (5 % band).
//!
//! Cases, for each step size A:
//! * `step:A`: the step at t = 0, the first sample of the run (the PID starts on it: no
//!   derivative kick, as any first move after power-up);
//! * `step:A@t0`: from rest, later in the run (the PID has run at r = 0: the error's derivative
//!   kicks);
//! * after a previous move: A, back to 0, and A again (each held long enough to settle), the
//!   worse figures of the return and the second A step.

use super::{run_loop, RunConfig, RunError};
use crate::sim::SimBackend;
use servo_core::control::{
    LoopCompensation, PidConfig, PlacedSegment, Program, Reference, Segment,
};
use servo_core::drive::Drive;
use servo_core::sim::SensorConfig;
use servo_core::Plant;

/// Time of the later step from rest [s].
pub const LATER_STEP_S: f64 = 0.1;

/// How a step starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepStart {
    /// At t = 0, the run's first sample.
    AtStart,
    /// From rest at [`LATER_STEP_S`].
    Later,
    /// After a move to A and back to 0.
    AfterMove,
}

impl StepStart {
    /// Every case, in the order they are reported.
    pub const ALL: [StepStart; 3] = [StepStart::AtStart, StepStart::Later, StepStart::AfterMove];

    /// The case in words, with the `servo run --ref` that gives it.
    pub fn words(self, step_rad: f64) -> String {
        // the step size to the micro-radian, without float noise (0.3, not 0.30000000000000004)
        let step_rad = (step_rad * 1e6).round() / 1e6;
        match self {
            StepStart::AtStart => format!("step:{step_rad} (at t = 0)"),
            StepStart::Later => format!("step:{step_rad}@{LATER_STEP_S} (from rest, later)"),
            StepStart::AfterMove => {
                format!("after a move to {step_rad} rad and back (steps.toml-like sequence)")
            }
        }
    }
}

/// One case's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseOutcome {
    pub step_rad: f64,
    pub start: StepStart,
    /// Overshoot [% of the step].
    pub overshoot_pct: f64,
    /// 5 % settling time [s]; `None`: not settled within the hold.
    pub settling_time_s: Option<f64>,
}

impl CaseOutcome {
    /// True when the overshoot is at most `overshoot_max_pct` and the settling time at most
    /// `settling_max_s` (`None`: not specified).
    pub fn meets(&self, overshoot_max_pct: f64, settling_max_s: Option<f64>) -> bool {
        self.overshoot_pct <= overshoot_max_pct
            && match settling_max_s {
                Some(s) => self.settling_time_s.is_some_and(|t| t <= s),
                None => true,
            }
    }
}

/// The simulated rig the cases run on, as `servo run --plant` simulates it: the plant (the
/// drive's equivalent chain), its sensors, and the drive the controller's output goes through
/// ([`RunConfig::drive`]: a current clipped at its limit, a duty at its own, the dead time).
#[derive(Debug, Clone, Copy)]
pub struct CaseRig<'a> {
    pub plant: &'a Plant,
    pub sensors: SensorConfig,
    pub drive: Drive,
}

/// Runs every case of every step size on `rig` with `pid` (as `servo run` builds it: limits,
/// anti-windup, discretisation), holding each step `hold_s` [s].
pub fn run_step_cases(
    rig: &CaseRig,
    pid: &PidConfig,
    u_limit_v: f64,
    steps_rad: &[f64],
    hold_s: f64,
) -> Result<Vec<CaseOutcome>, RunError> {
    run_step_cases_compensated(rig, pid, u_limit_v, steps_rad, hold_s, None)
}

/// [`run_step_cases`] with `feedforward` (a model's compensation, `servo run --ff`) added to the
/// PID as `servo run` adds it.
pub fn run_step_cases_compensated(
    rig: &CaseRig,
    pid: &PidConfig,
    u_limit_v: f64,
    steps_rad: &[f64],
    hold_s: f64,
    feedforward: Option<&LoopCompensation>,
) -> Result<Vec<CaseOutcome>, RunError> {
    let mut out = Vec::new();
    for &a in steps_rad {
        for start in StepStart::ALL {
            // (program, run length, earliest time of the step checked)
            let (program, duration_s, from_s) = match start {
                StepStart::AtStart => (Program::Position(Reference::step(a, 0.0)), hold_s, 0.0),
                StepStart::Later => (
                    Program::Position(Reference::step(a, LATER_STEP_S)),
                    LATER_STEP_S + hold_s,
                    0.5 * LATER_STEP_S,
                ),
                StepStart::AfterMove => {
                    let mut placed: Vec<PlacedSegment> = Vec::new();
                    for v in [a, 0.0, a] {
                        let s = Segment::position(Reference::step(v, 0.0), hold_s);
                        let p = PlacedSegment::after(&placed, s)
                            .map_err(|e| RunError::Config(format!("step sequence: {e}")))?;
                        placed.push(p);
                    }
                    (Program::Segments(placed), 3.0 * hold_s, 0.5 * hold_s)
                }
            };
            let mut backend = SimBackend::new(rig.plant, rig.sensors, pid.ts_s)
                .and_then(|b| b.behind(&rig.drive))
                .map_err(|e| RunError::Config(format!("simulator: {e}")))?;
            let cfg = RunConfig {
                u_limit_v,
                keep_record: false,
                feedforward: feedforward.copied(),
                drive: rig.drive,
                ..RunConfig::closed_loop(program, *pid, duration_s)
            };
            let run = run_loop(&mut backend, &cfg, None)?;
            // The steps checked: the one of the case; after a move, the return and the second
            // step (both moves after a previous one), the worse of each figure.
            let steps: Vec<_> = run
                .summary
                .steps
                .iter()
                .filter(|s| s.time_s >= from_s && (s.to_rad - s.from_rad).abs() > 0.5 * a.abs())
                .collect();
            if steps.is_empty() {
                return Err(RunError::Config(format!(
                    "the run of {} shows none of the steps checked",
                    start.words(a)
                )));
            }
            let overshoot_pct = steps.iter().map(|s| s.overshoot_pct).fold(0.0, f64::max);
            let settling_time_s = steps
                .iter()
                .map(|s| s.settling_time_s)
                .try_fold(0.0f64, |w, t| t.map(|t| w.max(t)));
            out.push(CaseOutcome {
                step_rad: a,
                start,
                overshoot_pct,
                settling_time_s,
            });
        }
    }
    Ok(out)
}
