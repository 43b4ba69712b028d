//! The user's own effects in a diagnosis (`servo diagnose --effects FILE [--discover]`): each
//! user-defined effect the model lacks is fitted to the logs and judged by the same gates as the
//! catalogue (BIC gain, drop of the equation error, drop of the simulation error on held-out
//! data); with discovery on, a new effect is searched among signal terms when neither the
//! catalogue nor a user effect explains what is left.

use crate::custom::CustomActive;
use crate::diagnose::{DiagnoseOptions, Diagnosis, Status};
use crate::fit::discover::{self, Discovery, Gates, Judged};
use crate::fit::{Dataset, FitError};
use crate::plant::Plant;
use crate::record::Record;
use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

/// What the user effects and the discovery gave.
#[derive(Debug, Clone, Default)]
pub struct UserFindings {
    /// The user effects judged, significant ones first, then by the drop of the equation error.
    pub candidates: Vec<Judged>,
    /// Why the discovery did not run (it was asked for).
    pub discovery_skipped: Option<String>,
    pub discovery: Option<Discovery>,
}

/// Why the user effects could not be judged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum UserEffectsError {
    #[error("preparing the logs")]
    Prepare(#[source] FitError),
    #[error("fitting the model")]
    Base(#[source] FitError),
    #[error("fitting user effect `{effect}`")]
    Judge {
        effect: &'static str,
        #[source]
        source: FitError,
    },
    #[error("discovery failed")]
    Discover(#[source] FitError),
}

/// Judges each effect of `todo` (user effects with the parameters to fit NaN) on `model` against
/// `records`, and, with `discover` = Some(name), searches a new effect called `name` when the
/// last diagnosis `last` left a residual nothing explains. Gates and fit settings come from
/// `opts`.
pub fn judge_user_effects(
    records: &[Record],
    model: &Plant,
    opts: &DiagnoseOptions,
    todo: &[CustomActive],
    last: &Diagnosis,
    discover: Option<&str>,
) -> Result<UserFindings, UserEffectsError> {
    let mut out = UserFindings::default();
    if todo.is_empty() && discover.is_none() {
        return Ok(out);
    }
    let gates = Gates {
        min_bic_gain: opts.thresholds.min_bic_gain,
        min_eq_drop: super::thresholds::frac(opts.thresholds.min_eq_drop_pct),
        min_oe_drop: super::thresholds::frac(opts.thresholds.min_oe_drop_pct),
        ..Gates::default()
    };
    let ds = Dataset::new(records, &model.params, &opts.fit).map_err(UserEffectsError::Prepare)?;
    let base = ds.fit_config(model, &[]).map_err(UserEffectsError::Base)?;
    let base_oe = discover::reference_oe(&ds, &base);
    for a in todo {
        let j = discover::judge(&ds, model, &base, base_oe, *a, &gates).map_err(|source| {
            UserEffectsError::Judge {
                effect: a.name(),
                source,
            }
        })?;
        out.candidates.push(j);
    }
    out.candidates.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(b.eq_drop.total_cmp(&a.eq_drop))
    });
    if let Some(name) = discover {
        let explained_by_user = out.candidates.iter().find(|c| c.significant);
        if let Some(w) = last.winner() {
            out.discovery_skipped = Some(format!(
                "the catalogue effect `{}` explains the residual: add it first (`--auto`, or compare --add {})",
                w.effect.name(),
                w.effect.name()
            ));
        } else if let Some(u) = explained_by_user {
            out.discovery_skipped = Some(format!(
                "the user effect `{}` explains the residual: add it first (compare --effects FILE --add {})",
                u.name, u.name
            ));
        } else if last.status == Status::Complete {
            out.discovery_skipped = Some(String::from(
                "nothing is left above the noise in any balance: there is nothing to discover",
            ));
        } else {
            out.discovery = Some(
                discover::discover(&ds, model, &base, base_oe, name, &gates)
                    .map_err(UserEffectsError::Discover)?,
            );
        }
    }
    Ok(out)
}
