//! Weighted straight line through a parameter's estimates over time, with the 95 % interval of
//! its slope (Student t on n - 2 degrees of freedom).
//!
//! Weights are 1/se^2 when every point has a positive standard error, else equal. The slope's
//! variance is scaled by the scatter about the line (the reduced chi-square, at least 1 with
//! weights): estimates whose spread exceeds their own intervals (a fit that moves with the
//! excitation) widen the interval rather than fake a trend.

use super::Point;
use crate::ident::student_t::t95;
use crate::math;

/// A fitted line value(t) = intercept + slope (t - t_ref).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearTrend {
    /// Slope [unit/day].
    pub slope_per_day: f64,
    /// 95 % interval of the slope [unit/day].
    pub slope_ci95: (f64, f64),
    /// Standard error of the slope [unit/day].
    pub slope_std_err: f64,
    /// Weighted mean time [days], where the line's value and its slope are uncorrelated.
    pub t_ref_day: f64,
    /// The line's value at `t_ref_day`.
    pub value_at_ref: f64,
    /// Standard error of `value_at_ref`.
    pub value_at_ref_std_err: f64,
    /// First and last times [days].
    pub t_first_day: f64,
    pub t_last_day: f64,
    /// Points used.
    pub n: usize,
    /// Root-mean-square residual about the line [unit].
    pub rms_residual: f64,
    /// Weighted residual sum of squares (the line's cost, for the step test).
    pub weighted_rss: f64,
    /// Were the points weighted by their standard errors?
    pub weighted: bool,
}

impl LinearTrend {
    /// The line's value at `t_day`.
    pub fn at(&self, t_day: f64) -> f64 {
        self.value_at_ref + self.slope_per_day * (t_day - self.t_ref_day)
    }
    /// Days from the first to the last point.
    pub fn span_days(&self) -> f64 {
        self.t_last_day - self.t_first_day
    }
    /// Does the slope's 95 % interval exclude 0?
    pub fn excludes_zero(&self) -> bool {
        self.slope_ci95.0 > 0.0 || self.slope_ci95.1 < 0.0
    }
}

/// The weights of `points`: 1/se^2 when every point has a positive finite se, else 1.
pub(crate) fn weights(points: &[Point]) -> (alloc::vec::Vec<f64>, bool) {
    let all = points
        .iter()
        .all(|p| p.std_err.is_some_and(|s| s.is_finite() && s > 0.0));
    let w = points
        .iter()
        .map(|p| match (all, p.std_err) {
            (true, Some(s)) => 1.0 / (s * s),
            _ => 1.0,
        })
        .collect();
    (w, all)
}

/// The line through `points` (at least 3 with two distinct times), or `None`.
pub fn linear_trend(points: &[Point]) -> Option<LinearTrend> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let (w, weighted) = weights(points);
    let sw: f64 = w.iter().sum();
    let t_ref = points.iter().zip(&w).map(|(p, w)| w * p.t_day).sum::<f64>() / sw;
    let y_ref = points.iter().zip(&w).map(|(p, w)| w * p.value).sum::<f64>() / sw;
    let stt: f64 = points
        .iter()
        .zip(&w)
        .map(|(p, w)| w * (p.t_day - t_ref) * (p.t_day - t_ref))
        .sum();
    // also refuses a NaN sum
    if stt.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
        return None;
    }
    let sty: f64 = points
        .iter()
        .zip(&w)
        .map(|(p, w)| w * (p.t_day - t_ref) * (p.value - y_ref))
        .sum();
    let slope = sty / stt;
    let (mut wrss, mut rss) = (0.0, 0.0);
    for (p, w) in points.iter().zip(&w) {
        let r = p.value - (y_ref + slope * (p.t_day - t_ref));
        wrss += w * r * r;
        rss += r * r;
    }
    let dof = (n - 2) as f64;
    let chi2 = wrss / dof;
    // With weights, the scatter only widens (estimates noisier than their own intervals);
    // without, it is the only measure of the noise.
    let scale = if weighted { chi2.max(1.0) } else { chi2 };
    let se_slope = math::sqrt(scale / stt);
    let se_ref = math::sqrt(scale / sw);
    let t = t95(dof);
    let (t_first, t_last) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.t_day), b.max(p.t_day))
        });
    Some(LinearTrend {
        slope_per_day: slope,
        slope_ci95: (slope - t * se_slope, slope + t * se_slope),
        slope_std_err: se_slope,
        t_ref_day: t_ref,
        value_at_ref: y_ref,
        value_at_ref_std_err: se_ref,
        t_first_day: t_first,
        t_last_day: t_last,
        n,
        rms_residual: math::sqrt(rss / n as f64),
        weighted_rss: wrss,
        weighted,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_line_comes_back_with_a_tight_interval() {
        let pts: alloc::vec::Vec<Point> = (0..10)
            .map(|k| Point {
                t_day: k as f64,
                value: 1.0 + 0.5 * k as f64 + if k % 2 == 0 { 1e-3 } else { -1e-3 },
                std_err: None,
            })
            .collect();
        let l = linear_trend(&pts).unwrap();
        assert!((l.slope_per_day - 0.5).abs() < 1e-3, "{l:?}");
        assert!(l.slope_ci95.1 - l.slope_ci95.0 < 1e-2, "{l:?}");
        assert!((l.at(0.0) - 1.0).abs() < 1e-2);
        assert!(!l.weighted && l.excludes_zero());
        assert!(linear_trend(&pts[..2]).is_none());
    }
}
