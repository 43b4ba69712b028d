//! A step change in a parameter's series (a part replaced, a re-greased gear, a load changed):
//! the split into two constant levels that best explains the points, kept when it explains them
//! better than the straight line by a margin of the Bayesian information criterion and its jump
//! exceeds three standard errors of the difference of the two means.

use super::linear::{weights, LinearTrend};
use super::Point;
use crate::math;

/// Each side of a step holds at least this many points.
pub const MIN_SIDE: usize = 3;

/// BIC advantage [-] the step must have over the line (both with 2 parameters of level, plus
/// the split for the step): 6, "strong" evidence.
pub const BIC_MARGIN: f64 = 6.0;

/// A step between two levels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepChange {
    /// Index in the time-sorted points of the first point after the step.
    pub index: usize,
    /// Time of the first point after the step [days].
    pub t_day: f64,
    /// Mean levels before and after.
    pub before: f64,
    pub after: f64,
    /// Standard error of after - before.
    pub jump_std_err: f64,
}

/// The best step of `points` (sorted by time), when it beats `line` (the line through the same
/// points); `None` otherwise.
pub fn step_change(points: &[Point], line: &LinearTrend) -> Option<StepChange> {
    let n = points.len();
    if n < 2 * MIN_SIDE {
        return None;
    }
    let (w, _) = weights(points);
    let mean = |r: core::ops::Range<usize>| {
        let sw: f64 = w[r.clone()].iter().sum();
        let m = points[r.clone()]
            .iter()
            .zip(&w[r])
            .map(|(p, w)| w * p.value)
            .sum::<f64>()
            / sw;
        (m, sw)
    };
    let mut best: Option<(f64, usize, f64, f64, f64, f64)> = None;
    for k in MIN_SIDE..=n - MIN_SIDE {
        let ((a, wa), (b, wb)) = (mean(0..k), mean(k..n));
        let rss: f64 = points
            .iter()
            .zip(&w)
            .enumerate()
            .map(|(i, (p, w))| {
                let r = p.value - if i < k { a } else { b };
                w * r * r
            })
            .sum();
        if best.is_none_or(|b| rss < b.0) {
            best = Some((rss, k, a, b, wa, wb));
        }
    }
    let (rss, k, a, b, wa, wb) = best?;
    let nf = n as f64;
    // Gaussian BIC with the noise level estimated: n ln(RSS/n) + p ln n (line p = 2, step 3).
    let bic = |rss: f64, p: f64| nf * math::ln(rss.max(1e-300) / nf) + p * math::ln(nf);
    let gain = bic(line.weighted_rss, 2.0) - bic(rss, 3.0);
    let sigma2 = (rss / (nf - 2.0)).max(if line.weighted { 1.0 } else { 0.0 });
    let se = math::sqrt(sigma2 * (1.0 / wa + 1.0 / wb));
    if gain >= BIC_MARGIN && (b - a).abs() > 3.0 * se {
        Some(StepChange {
            index: k,
            t_day: points[k].t_day,
            before: a,
            after: b,
            jump_std_err: se,
        })
    } else {
        None
    }
}
