//! Stage 8 of a diagnosis: the joint search. No single effect passes but a balance is still above
//! its noise floor: two or more missing effects may hide each other. The effects already named
//! and the best candidates are fitted jointly on the simulation and eliminated backward
//! ([`super::backward`]). Only when the elimination cannot run (fewer than two members, a joint
//! fit or a cost that cannot be computed) are the best candidates judged in pairs
//! ([`super::joint`]). An elimination that ran to its end and refused every set is the verdict:
//! its members include every candidate the pairs would pair ([`super::joint::seeds`]), each was
//! judged given all the others, and two that hide each other are judged given each other once
//! the rest are dropped, which is the pair test. No test of the suite needs the pairs after a
//! refusal (every one passes without them), and they took 16 % of an "unexplained" verdict on
//! the Padova friction ramps (1.1 of 7.0 s) and 18 % on the torque ripple outside the catalogue
//! (5.7 of 32 s). A set found together goes to the head of the ranking.

use super::base::Base;
use super::survey::Survey;
use super::{backward, joint, regimes, timing, Candidate, DiagnoseOptions};
use crate::fit::Dataset;
use crate::plant::Plant;
use alloc::vec::Vec;

/// Runs the search when it is asked for ([`DiagnoseOptions::joint_candidates`] of at least 2)
/// and needed (no significant candidate, a balance above its floor, and not `outside`: a
/// shape no catalogue effect makes carries the residual); `electrical_broken`: the
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
    // A shape no catalogue effect makes carries the residual (a friction curve's, a periodic
    // one's): what is missing is not a set of catalogue effects ([`super::outside`]).
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
    let found = match timing::timed(
        || "backward elimination".into(),
        || backward::search(&cx, &survey.fits, ranking),
    ) {
        backward::Outcome::Found(set) => Some(set),
        backward::Outcome::Refused => None,
        backward::Outcome::NotRun => timing::timed(
            || "pairs".into(),
            || joint::best_pair(&cx, &survey.fits, ranking).map(Vec::from),
        ),
    };
    if let Some(set) = found {
        ranking.retain(|c| !set.iter().any(|m| m.effect == c.effect));
        ranking.splice(0..0, set);
    }
}
