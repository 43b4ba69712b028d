//! A controller run with and without the compensation of a model's effects (issue #29), as
//! `servo run` runs it: the simulator backend on the plant given, the run loop of
//! [`super::run_loop`], the PID as run builds it, the feedforward and effect compensation of
//! [`LoopCompensation`] built from the model.
//!
//! [`tracking_ladder`] runs one reference with nothing, with the linear feedforward terms, and
//! adding the model's compensated effects one at a time: the tracking error at each rung says
//! what each compensation is worth. `servo design --model M --ff ...` reports it on the model
//! itself; `servo compare` on two runs (without, with) prints it beside the measured errors.

use super::{run_loop, RunConfig, RunError};
use crate::sim::SimBackend;
use servo_core::control::{EffectSelect, FeedforwardConfig, LoopCompensation, PidConfig, Program};
use servo_core::effects::EffectKind;
use servo_core::sim::SensorConfig;
use servo_core::Plant;

/// The run every rung repeats.
#[derive(Debug, Clone)]
pub struct TrackingRun<'a> {
    /// The plant simulated (the motor: a model file's full plant, effects included).
    pub truth: &'a Plant,
    pub sensors: SensorConfig,
    /// The model the compensation is built from (often `truth` itself).
    pub model: &'a Plant,
    /// The PID as `servo run` builds it (limits, anti-windup, discretisation, T_s).
    pub pid: PidConfig,
    /// Driver input limit [V].
    pub u_limit_v: f64,
    /// The reference.
    pub program: Program,
    /// Run length [s].
    pub duration_s: f64,
    /// Ramp-in of the effects' compensation [s].
    pub ramp_s: f64,
    /// The drive between the loop and the plant ([`RunConfig::drive`]), as `servo run --plant`
    /// runs it.
    pub drive: servo_core::drive::Drive,
}

/// One rung of the ladder.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingRung {
    /// The linear feedforward terms of the rung.
    pub linear: FeedforwardConfig,
    /// The effects compensated at this rung (each rung adds one to the one before).
    pub effects: Vec<EffectKind>,
    /// The user-defined effects compensated at this rung (added after the catalogue's).
    pub custom: Vec<&'static str>,
    /// RMS tracking error ref - theta_l [rad].
    pub err_rms_rad: f64,
    /// Largest |ref - theta_l| [rad].
    pub err_max_rad: f64,
    /// Time with the command at the voltage limit [s].
    pub saturation_time_s: f64,
}

impl TrackingRung {
    /// The effect this rung added (`None`: the rung of no compensation or of the linear terms).
    pub fn added(&self) -> Option<EffectKind> {
        self.effects.last().copied()
    }

    /// The rung in words: `no compensation`, the linear terms in `--ff` form, or `+ <effect>`.
    pub fn label(&self) -> String {
        if let Some(name) = self.custom.last() {
            return format!("+ {name} (user-defined)");
        }
        let lin = servo_io::controller::ff_name(&self.linear);
        match (self.added(), lin.as_str()) {
            (Some(k), _) => format!("+ {}", k.name()),
            (None, "none") => "no compensation".into(),
            (None, l) => l.to_string(),
        }
    }
}

/// Runs `run` once with `linear`, the effects `effects` and the user-defined effects `custom`
/// of `run.model` compensated, and returns its tracking figures.
pub fn tracking_rung(
    run: &TrackingRun,
    linear: FeedforwardConfig,
    effects: &[EffectKind],
    custom: &[&'static str],
) -> Result<TrackingRung, RunError> {
    let select = effects.iter().fold(EffectSelect::None, |s, &k| s.with(k));
    let mut comp = LoopCompensation::new(run.model, linear, select, run.ramp_s)
        .map_err(|e| RunError::Config(format!("compensation: {e}")))?;
    if !custom.is_empty() {
        comp = comp.with_custom(run.model, &|n| custom.contains(&n));
    }
    let mut backend = SimBackend::new(run.truth, run.sensors, run.pid.ts_s)
        .and_then(|b| b.behind(&run.drive))
        .map_err(|e| RunError::Config(format!("simulator: {e}")))?;
    let cfg = RunConfig {
        u_limit_v: run.u_limit_v,
        keep_record: false,
        feedforward: Some(comp),
        drive: run.drive,
        ..RunConfig::closed_loop(run.program.clone(), run.pid, run.duration_s)
    };
    let out = run_loop(&mut backend, &cfg, None)?;
    let s = &out.summary;
    let (Some(err_rms_rad), Some(err_max_rad)) = (s.err_rms_rad, s.err_max_rad) else {
        return Err(RunError::Config(
            "the tracking run has no position reference (a closed-loop program is needed)".into(),
        ));
    };
    Ok(TrackingRung {
        linear,
        effects: effects.to_vec(),
        custom: custom.to_vec(),
        err_rms_rad,
        err_max_rad,
        saturation_time_s: s.saturation_time_s,
    })
}

/// The ladder: no compensation, then the `linear` terms (when any), then each of `effects`
/// added in turn (in the order given; the model's Coulomb friction is skipped when the linear
/// terms compensate it already: its curve is the same level), then each of the user-defined
/// `custom`.
pub fn tracking_ladder(
    run: &TrackingRun,
    linear: FeedforwardConfig,
    effects: &[EffectKind],
    custom: &[&'static str],
) -> Result<Vec<TrackingRung>, RunError> {
    let mut out = vec![tracking_rung(run, FeedforwardConfig::OFF, &[], &[])?];
    let any_linear = linear.inertia || linear.viscous || linear.coulomb || linear.back_emf;
    if any_linear {
        out.push(tracking_rung(run, linear, &[], &[])?);
    }
    let effects: Vec<EffectKind> = effects
        .iter()
        .copied()
        .filter(|k| !(linear.coulomb && *k == EffectKind::Coulomb))
        .collect();
    for i in 0..effects.len() {
        out.push(tracking_rung(run, linear, &effects[..=i], &[])?);
    }
    for i in 0..custom.len() {
        out.push(tracking_rung(run, linear, &effects, &custom[..=i])?);
    }
    Ok(out)
}
