//! Stage 8 of a diagnosis: the joint search. No single effect passes but a balance is still above
//! its noise floor: two or more missing effects may hide each other. The effects already named
//! and the best candidates are fitted jointly on the simulation and eliminated backward
//! ([`super::backward`]); failing that, the best candidates are judged in pairs
//! ([`super::joint`]). A set found together goes to the head of the ranking.

use super::base::Base;
use super::survey::Survey;
use super::{backward, joint, regimes, timing, Candidate, DiagnoseOptions};
use crate::fit::Dataset;
use crate::plant::Plant;
use alloc::vec::Vec;

/// Runs the search when it is asked for ([`DiagnoseOptions::joint_candidates`] of at least 2)
/// and needed (no significant candidate, a balance above its floor, and not `outside`: a
/// friction shape outside the catalogue carries the residual); `electrical_broken`: the
/// electrical veto of stage 5 holds (no torque may be named).
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    ds: &Dataset,
    model: &Plant,
    base: &Base,
    survey: &Survey,
    labels: &regimes::Labels,
    electrical_broken: bool,
    ranking: &mut Vec<Candidate>,
    opts: &DiagnoseOptions,
    outside: bool,
) {
    let needed = !ranking.first().is_some_and(|c| c.significant)
        && survey.balances.iter().any(|b| b.above_noise);
    // A friction shape outside the catalogue carries the residual: what is missing is not a set
    // of catalogue effects ([`super::friction_curve::outside_catalogue`]).
    if opts.joint_candidates < 2 || !needed || outside {
        return;
    }
    let cx = joint::Context {
        ds,
        model,
        noise_a: base.noise_a,
        floors: &base.floors,
        electrical_broken,
        reference: &survey.reference,
        labels,
        opts,
    };
    let found = timing::timed(
        || "backward elimination".into(),
        || backward::search(&cx, &survey.fits, ranking),
    )
    .or_else(|| {
        timing::timed(
            || "pairs".into(),
            || joint::best_pair(&cx, &survey.fits, ranking).map(Vec::from),
        )
    });
    if let Some(set) = found {
        ranking.retain(|c| !set.iter().any(|m| m.effect == c.effect));
        ranking.splice(0..0, set);
    }
}
