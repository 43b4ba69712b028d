//! Stage 6 of a diagnosis: physical consistency. The candidates that pass every other check must
//! agree with themselves across independent parts of the data ([`checks::consistency`]); those
//! that do get their effect's notes and conditional findings
//! ([`crate::effects::FitHooks::candidate_note`], [`crate::effects::FitHooks::conditional`]).

use super::judge::demote;
use super::thresholds::Thresholds;
use super::{checks, timing, Candidate};
use crate::fit::Dataset;
use crate::plant::Plant;

/// Checks every significant candidate of `ranking` (fitted on `ds` against `model`).
pub(super) fn check(ds: &Dataset, model: &Plant, ranking: &mut [Candidate], th: &Thresholds) {
    for c in ranking.iter_mut().filter(|c| c.significant) {
        let cons = timing::timed(
            || alloc::format!("consistency of {}", c.effect),
            || checks::consistency(ds, model, c, th),
        );
        let agrees = cons.iter().all(|k| k.passed);
        c.checks.extend(cons);
        if !agrees {
            demote(c);
            continue;
        }
        let note = c
            .effect
            .model()
            .fit_hooks()
            .and_then(|h| h.candidate_note(ds, model, c));
        if let Some(note) = note {
            c.evidence.push_str(&note);
        }
        let cond = c.effect.model().fit_hooks().and_then(|h| {
            timing::timed(
                || alloc::format!("conditional of {}", c.effect),
                || h.conditional(ds, model, c),
            )
        });
        if let Some((cond, note)) = cond {
            c.evidence.push_str(&note);
            c.conditional = Some(cond);
        }
    }
}
