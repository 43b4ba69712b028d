//! Which compensated effect a log contradicts (issue #29).
//!
//! A run that compensated effects of a model (`servo run --ff all`) logs which ones. When the
//! tracking error rose, the first question is which compensation is wrong. The replay answers
//! it without a new experiment: the compensation the motor got is in the log (`ff_v`), so the
//! model is replayed on the log as given and once without each compensated effect. If the
//! model *without* an effect predicts the log clearly better than the model with it
//! ([`SUSPECT_MIN_DROP`]), the motor does not have that effect as the model says (a wrong sign,
//! a wrong size or phase): it is the suspect. A right compensation leaves the effect in the
//! plant (the replay without it predicts worse).

use super::ladder::{ModeChoice, ModelComparison};
use super::logs::{compare_logs, LadderError, LogReplay};
use super::report::CompareOptions;
use crate::effects::EffectKind;
use crate::plant::Plant;
use alloc::vec::Vec;

/// How much smaller the headline RMSE of the replay without a compensated effect must be than
/// with it for the effect to be the suspect [fraction]: 10 %, above the few-percent spread of a
/// replay's error between seeds of the sensor noise, well below what a wrong sign gives (the
/// error roughly doubles).
pub const SUSPECT_MIN_DROP: f64 = 0.10;

/// One compensated effect checked against one log.
#[derive(Debug, Clone, PartialEq)]
pub struct CompensationCheck {
    /// The log's index.
    pub log: usize,
    pub effect: EffectKind,
    /// Headline RMSE of the model as given (with the effect), in `unit`.
    pub rmse_with: f64,
    /// Headline RMSE of the model without the effect.
    pub rmse_without: f64,
    pub unit: &'static str,
    /// True when the model without the effect predicts the log better by
    /// [`SUSPECT_MIN_DROP`] or more.
    pub suspect: bool,
}

impl CompensationCheck {
    /// The relative change of the error without the effect (negative: it falls).
    pub fn change(&self) -> f64 {
        if self.rmse_with > 0.0 {
            self.rmse_without / self.rmse_with - 1.0
        } else {
            0.0
        }
    }
}

/// Checks each effect of `compensated[i]` (those the run of log i compensated, as its metadata
/// says) against log i: `given` is the comparison of `plant` with the logs (as `compare_logs`
/// made it); each effect the plant has is taken out and the log replayed again.
pub fn check_compensated(
    plant: &Plant,
    given: &ModelComparison,
    logs: &[LogReplay],
    modes: &[ModeChoice],
    compensated: &[Vec<EffectKind>],
    opts: &CompareOptions,
) -> Result<Vec<CompensationCheck>, LadderError> {
    let mut out = Vec::new();
    for (i, kinds) in compensated.iter().enumerate() {
        let (Some(log), Some(mode), Some(report)) =
            (logs.get(i), modes.get(i), given.reports.get(i))
        else {
            continue;
        };
        let with = report.headline_signal();
        for &kind in kinds {
            if !plant.effects.contains(kind) {
                continue;
            }
            let mut without = *plant;
            without.effects.remove(kind);
            let c = compare_logs(
                &without,
                core::slice::from_ref(log),
                core::slice::from_ref(mode),
                opts,
            )?;
            let Some(r) = c.reports.first() else { continue };
            let rmse_without = r.headline_signal().figures.rmse;
            let rmse_with = with.figures.rmse;
            out.push(CompensationCheck {
                log: i,
                effect: kind,
                rmse_with,
                rmse_without,
                unit: with.kind.unit(),
                suspect: rmse_with.is_finite()
                    && rmse_without.is_finite()
                    && rmse_without < (1.0 - SUSPECT_MIN_DROP) * rmse_with,
            });
        }
    }
    Ok(out)
}
