//! The user's own effects in a diagnosis (`servo diagnose --effects FILE [--discover]`): each
//! user-defined effect the model lacks is fitted to the logs and judged by the same gates as the
//! catalogue (BIC gain, drop of the equation error, drop of the simulation error on held-out
//! data); with discovery on, a new effect is searched among signal terms when neither the
//! catalogue nor a user effect explains what is left.

use crate::custom::CustomActive;
use crate::diagnose::{evidence, structure, DiagnoseOptions, Diagnosis, Status, Thresholds};
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
    // The measured friction curve of the base model's sliding rows, which every user friction
    // must match as the catalogue's frictions do (a breakaway its hump, a drag its rise). It is
    // measured again on this fit (a few milliseconds): the diagnosis's curve may come from its
    // sliding rows alone, and its bins index that data set's rows.
    let labels = super::regimes::Labels::new(&ds);
    let curve = super::friction_curve::measure(
        &ds,
        &base.mech,
        &base.plant,
        labels.of(base.mech.equation),
        &opts.thresholds,
    );
    for a in todo {
        let mut j = discover::judge(&ds, model, &base, base_oe, *a, &gates).map_err(|source| {
            UserEffectsError::Judge {
                effect: a.name(),
                source,
            }
        })?;
        if let Some(c) = curve.as_ref().filter(|_| a.def.is_friction()) {
            against_curve(&ds, &base, &mut j, c, &opts.thresholds).map_err(|source| {
                UserEffectsError::Judge {
                    effect: a.name(),
                    source,
                }
            })?;
        }
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

/// Judges the user friction `j` against the measured friction curve `curve` of the base model
/// `base` ([`super::friction_curve::check`], the check of the catalogue's frictions): it must
/// take away most of what the curve shows beyond the base model. A user friction that passes
/// the statistical guards while the curve's shape stays (a drag bent into a breakaway) is not
/// significant.
fn against_curve(
    ds: &Dataset,
    base: &crate::fit::Solved,
    j: &mut Judged,
    curve: &super::friction_curve::FrictionCurve,
    th: &Thresholds,
) -> Result<(), FitError> {
    let cand = ds.fit_config(&j.plant, &[])?;
    let (Some(b), Some(c)) = (base.equation(curve.equation), cand.equation(curve.equation)) else {
        return Ok(());
    };
    let k = super::friction_curve::check(curve, b, c, &base.plant, &cand.plant, th);
    j.significant &= k.passed;
    j.checks.push((k.name, k.passed, k.detail));
    Ok(())
}

/// What a significant user effect or discovered term removes, in words: its equation's held-out
/// residual drop, the held-out simulation drop and its fitted parameters.
fn figures(j: &Judged) -> String {
    let mut s = format!(
        "adding it removes {:.1} % of the held-out {} residual",
        100.0 * j.eq_drop,
        j.equation.name()
    );
    if let Some(d) = j.oe_drop {
        s.push_str(&format!(
            " and {:.1} % of the held-out simulation error",
            100.0 * d
        ));
    }
    s.push_str(&format!(" (BIC gain {:.1})", j.bic_gain));
    if !j.params.is_empty() {
        let p: Vec<String> = j
            .params
            .iter()
            .map(|(k, u, v)| format!("{k} = {v:.4e} {u}"))
            .collect();
        s.push_str(&format!("; fitted {}", p.join(", ")));
    }
    s
}

/// The diagnosis `d` once the user effects and the discovery of `found` are judged: when no
/// catalogue effect was named and a user effect (the first significant one) or the discovered
/// term passes every guard, the model is missing that effect: the status becomes missing and
/// the verdict names it, with its figures and how to add it, before what the catalogue alone
/// leaves (`th`: the thresholds the diagnosis used). Returns whether `d` changed.
pub fn conclude(d: &mut Diagnosis, found: &UserFindings, th: &Thresholds) -> bool {
    if d.winner().is_some() {
        return false;
    }
    let lead = if let Some(u) = found.candidates.iter().find(|c| c.significant) {
        format!(
            "The model is missing the user-defined effect `{}` (status: missing; from the effects file, outside the catalogue): {}. Add it with `servo compare LOG --effects FILE --add {}`.",
            u.name,
            figures(u),
            u.name
        )
    } else if let Some((disc, name, j)) = found.discovery.as_ref().and_then(|disc| {
        disc.proposal
            .as_ref()
            .filter(|(_, j)| j.significant)
            .map(|(a, j)| (disc, a.name(), j))
    }) {
        format!(
            "The model is missing a term outside the catalogue, found by --discover as the effect `{name}`: {} (status: missing): {}. Write it with --save-effect FILE and add it with `servo compare LOG --effects FILE --add {name}`.",
            disc.words(),
            figures(j)
        )
    } else {
        return false;
    };
    let mut v = lead;
    if !d.unexplained.is_empty() {
        v.push_str(" Without it, the catalogue leaves: ");
        for (i, b) in d.unexplained.iter().enumerate() {
            if i > 0 {
                v.push_str(" Also, ");
            }
            v.push_str(&structure::describe(b));
        }
    }
    v.push(' ');
    v.push_str(&evidence::thresholds_text(th));
    d.status = Status::Missing;
    d.verdict = v;
    true
}
