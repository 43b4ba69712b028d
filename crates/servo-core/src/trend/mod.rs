//! Trends of identified parameters over many logs (`servo trend`): per parameter a series of
//! estimates over time, a weighted linear trend with a 95 % interval on its slope
//! ([`linear`]), a test for a step change ([`step`]), the verdict (rising, falling, a step, or
//! steady) and the forecast of the date a limit is crossed with its interval ([`forecast`]).
//!
//! Pure arithmetic on small arrays (no I/O, no threads): the top layer of servo-core, above the
//! identification it takes its Student t quantiles from. Times are in days (any origin; the
//! CLI uses days since 1970-01-01 UTC), values in the parameter's SI unit.

pub mod forecast;
pub mod linear;
pub mod step;

pub use forecast::{forecast_crossing, Crossing};
pub use linear::{linear_trend, LinearTrend};
pub use step::{step_change, StepChange};

use alloc::vec::Vec;

/// One estimate of a parameter: when, what, and its standard error (`None` when the fit gives
/// none, e.g. a parameter sized by a search).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Point {
    /// Time of the log [days].
    pub t_day: f64,
    pub value: f64,
    pub std_err: Option<f64>,
}

/// What a parameter's series does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// A significant rise (the slope's 95 % interval above 0, the change material).
    Rising,
    /// A significant fall.
    Falling,
    /// A step between two levels explains the series better than a line.
    Step,
    /// No significant change.
    Steady,
    /// Too few points to judge (fewer than [`MIN_POINTS`]).
    Unknown,
}

impl Verdict {
    /// The verdict as a word (`rising`, `falling`, `step`, `steady`, `unknown`).
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Rising => "rising",
            Verdict::Falling => "falling",
            Verdict::Step => "step",
            Verdict::Steady => "steady",
            Verdict::Unknown => "unknown",
        }
    }
}

/// Fewest points a trend is judged on.
pub const MIN_POINTS: usize = 4;

/// Settings of [`analyse`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrendOptions {
    /// Smallest change over the span of the logs, as a fraction of the series' mean magnitude,
    /// that counts as a change (a statistically significant drift of 1 % is not wear).
    pub min_relative_change: f64,
    /// The magnitude a change is measured against is at least this (the parameter's limit,
    /// when it has one): a drift of 1e-4 rad of a gap that stays near 0 is no wear when its
    /// limit is 0.04 rad, however large it is relative to its own near-zero mean.
    pub scale_floor: f64,
}

impl Default for TrendOptions {
    fn default() -> Self {
        TrendOptions {
            min_relative_change: 0.10,
            scale_floor: 0.0,
        }
    }
}

/// The analysis of one parameter's series.
#[derive(Debug, Clone, PartialEq)]
pub struct Trend {
    pub verdict: Verdict,
    /// The weighted straight line (None with fewer than [`MIN_POINTS`] points).
    pub linear: Option<LinearTrend>,
    /// The best step change, when it beats the line (see [`step_change`]).
    pub step: Option<StepChange>,
    /// Relative change over the span: |slope| x span / mean |value| (line), or the step's jump
    /// over the mean |value| (step).
    pub relative_change: f64,
}

impl Trend {
    /// Is the change significant (rising, falling or a step)?
    pub fn significant(&self) -> bool {
        matches!(
            self.verdict,
            Verdict::Rising | Verdict::Falling | Verdict::Step
        )
    }
}

/// The trend of `points` (in any order; sorted by time here): the line, the step test and the
/// verdict. A line is a change when its slope's 95 % interval excludes 0 and the change over
/// the span reaches `opts.min_relative_change` of the series' mean magnitude (or of
/// `opts.scale_floor` when larger); a step when [`step_change`] finds one that the
/// line does not explain as well.
pub fn analyse(points: &[Point], opts: &TrendOptions) -> Trend {
    let mut pts: Vec<Point> = points
        .iter()
        .copied()
        .filter(|p| p.t_day.is_finite() && p.value.is_finite())
        .collect();
    pts.sort_by(|a, b| a.t_day.total_cmp(&b.t_day));
    let unknown = Trend {
        verdict: Verdict::Unknown,
        linear: None,
        step: None,
        relative_change: f64::NAN,
    };
    if pts.len() < MIN_POINTS {
        return unknown;
    }
    let Some(lin) = linear_trend(&pts) else {
        return unknown;
    };
    let scale = pts.iter().map(|p| p.value.abs()).sum::<f64>() / pts.len() as f64;
    let scale = scale.max(opts.scale_floor.abs());
    let scale = if scale > 0.0 {
        scale
    } else {
        f64::MIN_POSITIVE
    };
    let rel_line = (lin.slope_per_day * lin.span_days()).abs() / scale;
    let line_sig = lin.excludes_zero() && rel_line >= opts.min_relative_change;
    let step = step_change(&pts, &lin);
    if let Some(s) = step.filter(|s| (s.after - s.before).abs() / scale >= opts.min_relative_change)
    {
        return Trend {
            verdict: Verdict::Step,
            linear: Some(lin),
            step: Some(s),
            relative_change: (s.after - s.before).abs() / scale,
        };
    }
    let verdict = match (line_sig, lin.slope_per_day > 0.0) {
        (true, true) => Verdict::Rising,
        (true, false) => Verdict::Falling,
        _ => Verdict::Steady,
    };
    Trend {
        verdict,
        linear: Some(lin),
        step: None,
        relative_change: rel_line,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(f: impl Fn(f64) -> f64, n: usize, noise: f64) -> Vec<Point> {
        // Deterministic scatter: a fixed pseudo-random sequence in [-1, 1].
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        (0..n)
            .map(|k| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let e = (s % 2001) as f64 / 1000.0 - 1.0;
                let t = 7.0 * k as f64;
                Point {
                    t_day: t,
                    value: f(t) + noise * e,
                    std_err: Some(noise),
                }
            })
            .collect()
    }

    #[test]
    fn a_rising_line_is_rising_with_its_slope() {
        let pts = series(|t| 0.01 + 2e-4 * t, 20, 5e-4);
        let tr = analyse(&pts, &TrendOptions::default());
        assert_eq!(tr.verdict, Verdict::Rising);
        let lin = tr.linear.unwrap();
        assert!((lin.slope_per_day / 2e-4 - 1.0).abs() < 0.05, "{lin:?}");
        assert!(
            lin.slope_ci95.0 < 2e-4 && 2e-4 < lin.slope_ci95.1,
            "{lin:?}"
        );
    }

    #[test]
    fn noise_alone_is_steady_and_a_step_is_a_step() {
        let flat = series(|_| 0.02, 20, 1e-3);
        assert_eq!(
            analyse(&flat, &TrendOptions::default()).verdict,
            Verdict::Steady
        );
        let jump = series(|t| if t < 70.0 { 0.02 } else { 0.03 }, 20, 5e-4);
        let tr = analyse(&jump, &TrendOptions::default());
        assert_eq!(tr.verdict, Verdict::Step, "{tr:?}");
        let s = tr.step.unwrap();
        assert!((s.t_day - 70.0).abs() <= 7.0, "{s:?}");
        assert!((s.after - s.before - 0.01).abs() < 1e-3, "{s:?}");
        // A significant drift near 0 is a change on its own scale, not against a far limit.
        let near_zero = series(|t| 1e-5 + 1e-6 * t, 20, 1e-6);
        assert_eq!(
            analyse(&near_zero, &TrendOptions::default()).verdict,
            Verdict::Rising
        );
        let against_limit = TrendOptions {
            scale_floor: 0.04,
            ..TrendOptions::default()
        };
        assert_eq!(analyse(&near_zero, &against_limit).verdict, Verdict::Steady);
        let few = series(|t| t, 3, 0.0);
        assert_eq!(
            analyse(&few, &TrendOptions::default()).verdict,
            Verdict::Unknown
        );
    }
}
