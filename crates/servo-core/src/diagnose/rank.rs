//! Stage 7 of a diagnosis: the ranking. Significant first; then by the held-out simulation error
//! reduction, the one figure comparable across equations, plus
//! [`Thresholds::rank_equation_weight`] times the equation residual reduction: a near tie in
//! simulation (Coulomb friction and an input dead band both brake a voltage-driven log, 74.2 % vs
//! 74.4 % on the real jacopisky steps at 250 Hz) goes to the effect that also explains its
//! equation better (56.9 % vs 48.0 %).

use super::kinds::nonlinear_searched;
use super::thresholds::Thresholds;
use super::Candidate;

/// The ranking's score of `c` [%].
fn score(c: &Candidate, th: &Thresholds) -> f64 {
    c.oe_reduction_pct.unwrap_or(f64::NEG_INFINITY)
        + th.rank_equation_weight * c.error_reduction_pct
}

/// Sorts `ranking` best first (a stable sort: ties keep the catalogue order).
pub(super) fn sort(ranking: &mut [Candidate], th: &Thresholds) {
    ranking.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(score(b, th).total_cmp(&score(a, th)))
            .then(b.error_reduction_pct.total_cmp(&a.error_reduction_pct))
    });
    // The two best significant candidates explain the data alike (within
    // [`Thresholds::rank_tie_points`] of the score: at N = 1 a torque periodic once per motor
    // revolution is one periodic in the load angle): the one with fewer searched parameters is
    // named.
    if let [a, b, ..] = &*ranking {
        if a.significant
            && b.significant
            && (score(a, th) - score(b, th)).abs() < th.rank_tie_points
            && nonlinear_searched(b.effect) < nonlinear_searched(a.effect)
        {
            ranking.swap(0, 1);
        }
    }
}
