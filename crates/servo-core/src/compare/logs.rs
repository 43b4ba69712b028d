//! One model against several logs, and the error ladder (what `servo compare` computes): the
//! replay mode of each log ([`choose_mode`]), the u a log without one was driven with
//! ([`rebuild_u`]), the replay and comparison of every log ([`compare_logs`]), and the ladder
//! of effects added one at a time, each fitted to the logs and compared again ([`error_ladder`]).
//!
//! The logs come in as [`LogReplay`]: the measured signals and the controller that ran (servo's
//! PID configuration, its logged feedforward and output limit), however the caller found them
//! (a gains file, the log's metadata, a least-squares fit to the logged u).

use super::controller_check::{check_controller, ControllerCheck};
use super::figures::Figures;
use super::ladder::{pooled, ModeChoice, ModelComparison, ReplayController};
use super::quantum::encoder_quantum;
use super::replay::{replay, ClosedLoop, Controller, ReplayMode};
use super::report::{compare, CompareOptions, SignalKind};
use super::{CompareError, Measured};
use crate::control::pid::PidConfig;
use crate::control::ControlError;
use crate::custom::{CustomActive, CustomError};
use crate::fit::custom::CustomEstimate;
use crate::fit::{fit_model, EffectToFit, FitError, FitOptions, ParamEstimate};
use crate::plant::Plant;
use crate::record::Record;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;

/// One log made ready for the replay.
#[derive(Debug, Clone, Copy)]
pub struct LogReplay<'a> {
    /// A name for messages (the file name).
    pub name: &'a str,
    pub measured: &'a Measured,
    /// The controller that ran (`None`: unknown; only open-loop modes then).
    pub controller: Option<&'a PidConfig>,
    /// The feedforward part of the logged u [V] per sample, added to the controller's output.
    pub feedforward_v: Option<&'a [f64]>,
    /// The output limit of the controller and the board [V].
    pub u_limit_v: Option<f64>,
}

impl<'a> LogReplay<'a> {
    /// The replay controller of the log, at rest (`None` when its controller is unknown).
    pub fn controller(&self) -> Result<Option<ReplayController<'a>>, ControlError> {
        self.controller
            .map(|c| ReplayController::new(c, self.feedforward_v))
            .transpose()
    }

    /// Runs the log's controller (or, without one, only the least-squares PID) on the logged
    /// reference and position and compares it with the logged u. `None` without reference or
    /// position.
    pub fn check_controller(&self) -> Result<Option<ControllerCheck>, ControlError> {
        let m = self.measured;
        let (Some(r), Some(th)) = (&m.ref_rad, &m.theta_l_rad) else {
            return Ok(None);
        };
        let (ff, limit) = (self.feedforward_v, self.u_limit_v);
        Ok(Some(match self.controller()? {
            Some(mut c) => check_controller(&mut c, r, th, &m.u_v, ff, limit, m.dt_s),
            None => check_controller(&mut |_: f64, _: f64| 0.0, r, th, &m.u_v, ff, limit, m.dt_s),
        }))
    }
}

/// Why a forced replay mode cannot run on a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ModeRefusal {
    #[error("a closed-loop replay needs the controller that ran")]
    NoController,
    #[error("a closed-loop replay needs the position reference and the measured position")]
    NoReferenceOrPosition,
    #[error("this mode re-initialises from the measured position, which the log does not have")]
    NoPosition,
}

/// The replay mode of `log`: `forced` if it can run, else closed loop when the controller and
/// the reference are known (the model runs in the logged loop, as the motor did), else the
/// open-loop speed simulation with the logged u (an integrating plant's position would drift).
/// `gains_source` says where the controller's gains came from, for the reason.
pub fn choose_mode(
    log: &LogReplay,
    forced: Option<ReplayMode>,
    gains_source: &str,
) -> Result<ModeChoice, ModeRefusal> {
    let m = log.measured;
    let has_ctrl = log.controller.is_some();
    let (has_ref, has_pos) = (m.ref_rad.is_some(), m.theta_l_rad.is_some());
    if let Some(mode) = forced {
        if mode == ReplayMode::ClosedLoop {
            if !has_ctrl {
                return Err(ModeRefusal::NoController);
            }
            if !has_ref || !has_pos {
                return Err(ModeRefusal::NoReferenceOrPosition);
            }
        }
        if matches!(mode, ReplayMode::KStep { .. } | ReplayMode::Segments { .. }) && !has_pos {
            return Err(ModeRefusal::NoPosition);
        }
        return Ok(ModeChoice {
            mode,
            reason: String::from("forced with --mode"),
        });
    }
    Ok(match (has_ctrl, has_ref && has_pos) {
        (true, true) => ModeChoice {
            mode: ReplayMode::ClosedLoop,
            reason: format!(
                "controller (gains {gains_source}) and reference are known: the model runs in the logged loop, as the motor did"
            ),
        },
        (true, false) => ModeChoice {
            mode: ReplayMode::Speed,
            reason: String::from("gains given but the log has no reference/position: open-loop speed simulation with the logged u"),
        },
        _ => ModeChoice {
            mode: ReplayMode::Speed,
            reason: String::from("no controller known (--gains): open-loop speed simulation with the logged u (position would drift)"),
        },
    })
}

/// For a log without u (a lab's closed-loop record of angle, reference and current): the u the
/// controller commanded, rebuilt from the logged reference and position (the controller ran on
/// exactly these), limited to +-`u_limit_v` [V]. `None` without reference, position or
/// controller.
pub fn rebuild_u(log: &LogReplay, u_limit_v: f64) -> Result<Option<Vec<f64>>, ControlError> {
    let m = log.measured;
    let (Some(r), Some(th)) = (&m.ref_rad, &m.theta_l_rad) else {
        return Ok(None);
    };
    let Some(mut c) = log.controller()? else {
        return Ok(None);
    };
    Ok(Some(
        r.iter()
            .zip(th)
            .map(|(&rk, &tk)| c.update(rk, tk).clamp(-u_limit_v, u_limit_v))
            .collect(),
    ))
}

/// Why a replay or a rung of the ladder failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LadderError {
    #[error("replaying {log} on the model")]
    Replay {
        log: String,
        #[source]
        source: alloc::boxed::Box<CompareError>,
    },
    #[error("{log}: closed-loop replay without a controller")]
    NoController { log: String },
    #[error("the controller of {log}")]
    Controller {
        log: String,
        #[source]
        source: ControlError,
    },
    /// A user effect could not be added to the model (`rung`: its index in the added effects).
    #[error("adding {effect}: {error}")]
    Custom {
        rung: usize,
        effect: String,
        // Not a #[source]: CustomError is an Error only with std.
        error: alloc::boxed::Box<CustomError>,
    },
    /// Fitting an added effect to the logs failed (`rung`: its index in the added effects).
    #[error("fitting {effect} to the logs failed")]
    Fit {
        rung: usize,
        effect: String,
        #[source]
        source: FitError,
    },
    #[error("{logs} logs but {modes} replay modes")]
    Modes { logs: usize, modes: usize },
}

/// Replays every log on `plant` in its mode (`modes[i]` for `logs[i]`) and compares.
pub fn compare_logs(
    plant: &Plant,
    logs: &[LogReplay],
    modes: &[ModeChoice],
    opts: &CompareOptions,
) -> Result<ModelComparison, LadderError> {
    if logs.len() != modes.len() {
        return Err(LadderError::Modes {
            logs: logs.len(),
            modes: modes.len(),
        });
    }
    let mut reports = Vec::new();
    for (log, mc) in logs.iter().zip(modes) {
        let m = log.measured;
        let failed = |source| LadderError::Replay {
            log: log.name.to_string(),
            source: alloc::boxed::Box::new(source),
        };
        let rp = if mc.mode == ReplayMode::ClosedLoop {
            let mut pid = log
                .controller()
                .map_err(|source| LadderError::Controller {
                    log: log.name.to_string(),
                    source,
                })?
                .ok_or_else(|| LadderError::NoController {
                    log: log.name.to_string(),
                })?;
            let q = m.theta_l_rad.as_deref().and_then(encoder_quantum);
            replay(
                plant,
                m,
                mc.mode,
                Some(ClosedLoop {
                    controller: &mut pid,
                    u_limit_v: log.u_limit_v,
                    encoder_quantum_rad: q,
                }),
            )
        } else {
            replay(plant, m, mc.mode, None)
        }
        .map_err(failed)?;
        reports.push(compare(m, &rp, plant.params.n, opts));
    }
    Ok(ModelComparison {
        plant: *plant,
        reports,
    })
}

/// An effect to add on the error ladder: from the catalogue, or user-defined with its unknown
/// parameters NaN (fitted).
#[derive(Debug, Clone, Copy)]
pub enum AddEffect {
    Catalogue(EffectToFit),
    Custom(CustomActive),
}

impl AddEffect {
    /// The effect's name.
    pub fn name(&self) -> &'static str {
        match self {
            AddEffect::Catalogue(e) => e.effect.kind.name(),
            AddEffect::Custom(c) => c.name(),
        }
    }
}

/// One rung of the error ladder.
#[derive(Debug, Clone)]
pub struct LadderStep {
    /// `model as given`, `+ coulomb`, ...
    pub label: String,
    /// The effect added at this rung (`None` for the model as given).
    pub effect: Option<&'static str>,
    /// Pooled figures of each signal over the logs.
    pub cmp_fit: Vec<(SignalKind, Figures)>,
    /// Base and catalogue parameters fitted at this rung.
    pub params: Vec<ParamEstimate>,
    /// Parameters of the user-defined effects fitted at this rung.
    pub custom: Vec<CustomEstimate>,
    /// Were the base parameters (J_eq, B_eq, tau_sf, R_eq, k_drv) refitted with the effect?
    /// Each rung is fitted twice, with the base refitted and with the base kept as given, and
    /// the fit whose replay predicts the logs better is kept: the base is refitted only when
    /// the data ask for it together with the effect.
    pub base_refitted: bool,
}

/// The error ladder: the rungs, the final model and its comparison with every log.
#[derive(Debug, Clone)]
pub struct ErrorLadder {
    pub steps: Vec<LadderStep>,
    /// The model after the last added effect.
    pub plant: Plant,
    /// The final model against every log.
    pub comparison: ModelComparison,
}

/// The error ladder (`servo compare --add`): `plant` as given against the logs, then each effect
/// of `adds` in order, fitted together with the base parameters to `records` (the logs'
/// records, u rebuilt where a log had none) and compared again.
///
/// ```
/// # use servo_core::{record::Record, sim::{PlantSim, SensorConfig, Sensors}, Plant, PlantParams};
/// use servo_core::compare::logs::{choose_mode, error_ladder, AddEffect, LogReplay};
/// use servo_core::compare::{CompareOptions, Measured};
/// use servo_core::effects::{Effect, EffectKind};
/// use servo_core::fit::EffectToFit;
/// // A driver that saturates at 4.5 V, driven open loop by voltage steps; the model lacks it.
/// let mut truth = Plant::from_params(PlantParams::TABLE2)?;
/// truth.effects.insert(Effect::new(EffectKind::Saturation, &[4.5])?);
/// let (mut sim, mut sensors) = (PlantSim::new(&truth, 1e-3)?, Sensors::new(SensorConfig::default()));
/// let mut rec = Record::default();
/// let (mut th, mut ia, mut uv) = (Vec::new(), Vec::new(), Vec::new());
/// for k in 0..8000 {
///     let u = [3.0, -5.0, 2.0, -2.5, 6.0, -4.0, 2.5][(k / 400) % 7];
///     let m = sensors.measure(sim.state());
///     rec.time_s.push(k as f64 * 1e-3);
///     th.push(m.theta_l_rad); ia.push(m.i_a_a); uv.push(u);
///     sim.step(u);
/// }
/// (rec.theta_l_rad, rec.i_a_a, rec.u_v) = (Some(th), Some(ia), Some(uv));
/// let opts = CompareOptions::default();
/// let measured = Measured::from_record(&rec, PlantParams::TABLE2.n, opts.speed_filter_hz)?;
/// let log = LogReplay { name: "sim", measured: &measured, controller: None, feedforward_v: None, u_limit_v: None };
/// let modes = [choose_mode(&log, None, "")?]; // no controller: open-loop speed replay
/// let model = Plant::from_params(PlantParams::TABLE2)?;
/// let saturation = AddEffect::Catalogue(EffectToFit::parse("saturation")?);
/// let ladder = error_ladder(&model, &[log], &modes, &[rec], &[saturation], &opts)?;
/// let fit = |i: usize| ladder.steps[i].cmp_fit[0].1.fit_percent;
/// assert!(fit(1) > fit(0), "fit {} % -> {} %", fit(0), fit(1));
/// assert!(ladder.steps[1].params.iter().any(|p| p.effect == Some(EffectKind::Saturation)));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn error_ladder(
    plant: &Plant,
    logs: &[LogReplay],
    modes: &[ModeChoice],
    records: &[Record],
    adds: &[AddEffect],
    opts: &CompareOptions,
) -> Result<ErrorLadder, LadderError> {
    let mut plant = *plant;
    let first = compare_logs(&plant, logs, modes, opts)?;
    let mut steps = alloc::vec![LadderStep {
        label: String::from("model as given"),
        effect: None,
        cmp_fit: pooled(&first),
        params: Vec::new(),
        custom: Vec::new(),
        base_refitted: false,
    }];
    let mut current = first;
    for (rung, eff) in adds.iter().enumerate() {
        let mut start = plant;
        let catalogue: Vec<EffectToFit> = match eff {
            AddEffect::Catalogue(e) => alloc::vec![*e],
            AddEffect::Custom(c) => {
                start
                    .custom
                    .insert(*c)
                    .map_err(|error| LadderError::Custom {
                        rung,
                        effect: eff.name().to_string(),
                        error: alloc::boxed::Box::new(error),
                    })?;
                Vec::new()
            }
        };
        let fitted = |refit_base: bool| {
            let fo = FitOptions {
                refit_base,
                ..FitOptions::default()
            };
            fit_model(records, &start, &catalogue, &fo).map_err(|source| LadderError::Fit {
                rung,
                effect: eff.name().to_string(),
                source,
            })
        };
        let fit = fitted(true)?;
        let cmp = compare_logs(&fit.plant, logs, modes, opts)?;
        // The same effect with the base kept as given: kept when its replay predicts better.
        let kept = fitted(false).ok().and_then(|f| {
            let c = compare_logs(&f.plant, logs, modes, opts).ok()?;
            Some((f, c))
        });
        let rmse = |c: &ModelComparison| pooled(c).first().map_or(f64::INFINITY, |p| p.1.rmse);
        let (fit, cmp, base_refitted) = match kept {
            Some((f, c)) if rmse(&c) < rmse(&cmp) => (f, c, false),
            _ => (fit, cmp, true),
        };
        plant = fit.plant;
        steps.push(LadderStep {
            label: format!("+ {}", eff.name()),
            effect: Some(eff.name()),
            cmp_fit: pooled(&cmp),
            params: fit.params,
            custom: fit.custom,
            base_refitted,
        });
        current = cmp;
    }
    Ok(ErrorLadder {
        steps,
        plant,
        comparison: current,
    })
}
