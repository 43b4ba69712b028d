//! Stage 5 of a diagnosis: the electrical veto. The electrical balance holds no mechanical
//! effect: when it is itself far above its noise floor and no drive-side effect explains it, the
//! current or the speed measurement is inconsistent, and the torque balance (which uses both)
//! cannot be trusted to name a torque.

use super::judge::demote;
use super::kinds::on_simulation;
use super::structure::BalanceReport;
use super::thresholds::Thresholds;
use super::{checks, Candidate};
use crate::fit::model::Equation;

/// The electrical balance when it is broken ([`Thresholds::electrical_block_ratio`] times its
/// floor) and no candidate on it explains [`Thresholds::drive_explains_pct`] of it; every
/// significant torque candidate of `ranking` is then refused with the reason.
pub(super) fn electrical<'a>(
    balances: &'a [BalanceReport],
    ranking: &mut [Candidate],
    th: &Thresholds,
) -> Option<&'a BalanceReport> {
    let broken = balances.iter().find(|b| {
        b.equation == Equation::Electrical
            && b.above_noise
            && b.ratio_to_noise >= th.electrical_block_ratio
    });
    // A drive-side effect that explains most of the electrical residual (an input delay, a dead
    // zone) accounts for it: the measurements are then not suspect.
    let drive_explains = ranking.iter().any(|c| {
        c.equation == Equation::Electrical && c.error_reduction_pct >= th.drive_explains_pct
    });
    let broken = broken.filter(|_| !drive_explains);
    for c in ranking.iter_mut() {
        if let (true, true, Some(e)) = (
            c.significant,
            c.effect.is_mechanical() && !on_simulation(c.effect),
            broken,
        ) {
            c.checks.push(checks::Check {
                name: "electrical balance consistent",
                passed: false,
                detail: alloc::format!(
                    "the electrical balance, which holds no mechanical effect, is itself {:.1} times its noise floor and no drive-side effect explains it: the current or speed measurement is inconsistent, so no torque can be named from the torque balance",
                    e.ratio_to_noise
                ),
            });
            demote(c);
        }
    }
    broken
}
