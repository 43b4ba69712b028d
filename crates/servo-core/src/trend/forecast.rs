//! When a trend reaches a limit: the time the line crosses it, with the interval that the
//! slope's 95 % interval gives (the line anchored at its weighted mean time, where its value and
//! slope are uncorrelated). A limit is passed only when the line's 95 % interval at the last log
//! is past it; a line past it whose interval still holds it is only at the limit.

use super::LinearTrend;
use crate::ident::student_t::t95;
use crate::math;

/// The line's crossing of a limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Crossing {
    /// The line reaches the limit at `t_day` (after the last log), between `earliest_day` and
    /// `latest_day` (`f64::INFINITY` when the slope's interval includes 0: it may never).
    Ahead {
        t_day: f64,
        earliest_day: f64,
        latest_day: f64,
    },
    /// The line was already past the limit at the last log, its 95 % interval there too.
    Passed,
    /// At the last log the line's 95 % interval (`lo`, `hi`) holds the limit: it may have
    /// reached it or not, these logs cannot tell.
    AtLimit { lo: f64, hi: f64 },
    /// The line moves away from the limit (or is flat).
    Never,
}

/// Where `line` crosses `limit` (same unit as its values).
pub fn forecast_crossing(line: &LinearTrend, limit: f64) -> Crossing {
    let last = line.at(line.t_last_day);
    let gap = limit - line.value_at_ref;
    let slope = line.slope_per_day;
    let before = limit - line.at(line.t_first_day);
    // The line's 95 % interval at the last log (value and slope uncorrelated at t_ref).
    let dt = line.t_last_day - line.t_ref_day;
    let se_last = math::sqrt(
        line.value_at_ref_std_err * line.value_at_ref_std_err
            + dt * dt * line.slope_std_err * line.slope_std_err,
    );
    let half = t95((line.n.max(3) - 2) as f64) * se_last;
    let (lo, hi) = (last - half, last + half);
    // Past it at the last log, having moved towards it: passed when the interval is past too.
    let past = |x: f64| (limit - x) * before <= 0.0;
    if past(last) && before != 0.0 {
        return if past(lo) && past(hi) {
            Crossing::Passed
        } else {
            Crossing::AtLimit { lo, hi }
        };
    }
    if slope == 0.0 || gap * slope <= 0.0 {
        return Crossing::Never;
    }
    let at = |s: f64| {
        if s * slope > 0.0 {
            line.t_ref_day + gap / s
        } else {
            f64::INFINITY
        }
    };
    let (lo, hi) = line.slope_ci95;
    let (a, b) = (at(lo), at(hi));
    Crossing::Ahead {
        t_day: line.t_ref_day + gap / slope,
        earliest_day: a.min(b),
        latest_day: a.max(b),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{linear_trend, Point};
    use super::*;

    #[test]
    fn a_line_towards_a_limit_crosses_it_on_time() {
        let pts: alloc::vec::Vec<Point> = (0..20)
            .map(|k| Point {
                t_day: 7.0 * k as f64,
                value: 0.01 + 1e-4 * 7.0 * k as f64 + if k % 2 == 0 { 2e-4 } else { -2e-4 },
                std_err: Some(3e-4),
            })
            .collect();
        let l = linear_trend(&pts).unwrap();
        match forecast_crossing(&l, 0.03) {
            Crossing::Ahead {
                t_day,
                earliest_day,
                latest_day,
            } => {
                assert!((t_day - 200.0).abs() < 5.0, "{t_day}");
                assert!(earliest_day <= t_day && t_day <= latest_day);
            }
            c => panic!("{c:?}"),
        }
        assert_eq!(forecast_crossing(&l, 0.0), Crossing::Never);
        assert_eq!(forecast_crossing(&l, 0.015), Crossing::Passed);
    }
}
