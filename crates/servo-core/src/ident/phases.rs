//! Detection of constant acceleration / deceleration phases (handout 4.2).
//!
//! The acceleration is the derivative of the zero-phase low-passed speed. A phase is a maximal run
//! in which the acceleration keeps its sign with magnitude above a threshold (by default 30 % of
//! the 95th percentile of |dw_m/dt|, so that the test's own acceleration sets the scale). Runs
//! shorter than `min_duration_s` (speed-step transients) are dropped; each phase is trimmed at both
//! ends and its acceleration is the slope of a straight line fitted to the raw speed.

use alloc::format;
use alloc::vec::Vec;

use super::{median_dt, IdentError};
use crate::signal::{derivative_at, lowpass_zero_phase};

/// Settings of the phase detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseConfig {
    /// Cut-off of the zero-phase low-pass before differentiation [Hz].
    pub cutoff_hz: f64,
    /// Threshold relative to the 95th percentile of |dw_m/dt| [-] (used when no absolute one).
    pub min_accel_frac: f64,
    /// Absolute threshold on |dw_m/dt| [rad/s^2]; overrides `min_accel_frac`.
    pub min_accel_rad_s2: Option<f64>,
    /// Shortest phase kept [s].
    pub min_duration_s: f64,
    /// Fraction trimmed at each end of a phase [-].
    pub trim_frac: f64,
    /// Part of each detected phase kept, as fractions of its length `(from, to)`, 0 <= from < to
    /// <= 1; overrides `trim_frac`. E.g. `(0.7, 0.9)` averages the last part of each phase, after
    /// the current transient, as the padova2021-savian group did.
    pub window_frac: Option<(f64, f64)>,
    /// How the current was sampled (voltage drive, zero-order hold): J_eq is corrected for the
    /// samples' place in each period; `None`: the current is taken as the period's mean.
    pub current_sampling: Option<super::CurrentSampling>,
}

impl Default for PhaseConfig {
    fn default() -> Self {
        PhaseConfig {
            cutoff_hz: 10.0,
            min_accel_frac: 0.3,
            min_accel_rad_s2: None,
            min_duration_s: 0.2,
            trim_frac: 0.1,
            window_frac: None,
            current_sampling: None,
        }
    }
}

/// A constant-acceleration phase: samples `start..end` (trimmed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelPhase {
    pub start: usize,
    pub end: usize,
    /// Acceleration: slope of the line fitted to the speed [rad/s^2].
    pub accel_rad_s2: f64,
}

/// The filtered acceleration dw/dt [rad/s^2] of `omega` (zero-phase low-pass, then central
/// differences).
pub fn filtered_accel(t: &[f64], omega: &[f64], cutoff_hz: f64) -> Result<Vec<f64>, IdentError> {
    let wf = lowpass_zero_phase(omega, median_dt(t), cutoff_hz)?;
    Ok(derivative_at(t, &wf))
}

/// The acceleration threshold [rad/s^2] used for `accel`.
pub fn accel_threshold(accel: &[f64], cfg: &PhaseConfig) -> f64 {
    if let Some(a) = cfg.min_accel_rad_s2 {
        return a;
    }
    let mut mags: Vec<f64> = accel.iter().map(|a| a.abs()).collect();
    if mags.is_empty() {
        return f64::INFINITY;
    }
    let k = ((mags.len() - 1) as f64 * 0.95) as usize;
    let (_, p95, _) = mags.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    cfg.min_accel_frac * *p95
}

/// Finds the constant acceleration/deceleration phases of `omega` sampled at `t`.
pub fn find_phases(
    t: &[f64],
    omega: &[f64],
    cfg: &PhaseConfig,
) -> Result<Vec<AccelPhase>, IdentError> {
    if !(cfg.min_duration_s > 0.0
        && (0.0..0.5).contains(&cfg.trim_frac)
        && cfg.min_accel_frac > 0.0
        && match cfg.window_frac {
            Some((a, b)) => (0.0..1.0).contains(&a) && a < b && b <= 1.0,
            None => true,
        })
    {
        return Err(IdentError::BadConfig(format!(
            "phase settings out of range: {cfg:?}"
        )));
    }
    if t.len() != omega.len() {
        return Err(IdentError::Internal("time and speed lengths differ"));
    }
    if t.len() < 10 {
        return Ok(Vec::new());
    }
    let a = filtered_accel(t, omega, cfg.cutoff_hz)?;
    let thr = accel_threshold(&a, cfg);
    if !(thr > 0.0) {
        return Ok(Vec::new());
    }
    let sgn = |x: f64| {
        if x > thr {
            1
        } else if x < -thr {
            -1
        } else {
            0
        }
    };
    let mut out = Vec::new();
    let mut i = 0;
    let n = a.len();
    while i < n {
        let s = sgn(a[i]);
        let mut j = i + 1;
        while j < n && sgn(a[j]) == s {
            j += 1;
        }
        if s != 0 && t[j - 1] - t[i] >= cfg.min_duration_s {
            let len = j - i;
            let (ps, pe) = match cfg.window_frac {
                Some((from, to)) => (
                    i + (from * len as f64) as usize,
                    i + (to * len as f64) as usize,
                ),
                None => {
                    let cut = (cfg.trim_frac * len as f64) as usize;
                    (i + cut, j - cut)
                }
            };
            if pe > ps + 2 {
                let slope = line_slope(&t[ps..pe], &omega[ps..pe]);
                out.push(AccelPhase {
                    start: ps,
                    end: pe,
                    accel_rad_s2: slope,
                });
            }
        }
        i = j;
    }
    Ok(out)
}

/// Slope of the least-squares line through (x, y).
pub fn line_slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let xm = x.iter().sum::<f64>() / n;
    let ym = y.iter().sum::<f64>() / n;
    let sxy: f64 = x.iter().zip(y).map(|(x, y)| (x - xm) * (y - ym)).sum();
    let sxx: f64 = x.iter().map(|x| (x - xm) * (x - xm)).sum();
    sxy / sxx
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_triangle_wave_phases() {
        // 0 -> 600 rad/s in 1 s, back in 1 s, three times.
        let t: Vec<f64> = (0..6000).map(|k| k as f64 * 1e-3).collect();
        let w: Vec<f64> = t
            .iter()
            .map(|t| {
                let p = t % 2.0;
                if p < 1.0 {
                    600.0 * p
                } else {
                    600.0 * (2.0 - p)
                }
            })
            .collect();
        let ph = find_phases(&t, &w, &PhaseConfig::default()).unwrap();
        assert_eq!(ph.len(), 6, "{ph:?}");
        for (k, p) in ph.iter().enumerate() {
            let want = if k % 2 == 0 { 600.0 } else { -600.0 };
            assert!((p.accel_rad_s2 - want).abs() < 1.0, "{p:?}");
        }
    }

    #[test]
    fn constant_speed_has_no_phases() {
        let t: Vec<f64> = (0..3000).map(|k| k as f64 * 1e-3).collect();
        let w = alloc::vec![100.0; 3000];
        assert!(find_phases(&t, &w, &PhaseConfig::default())
            .unwrap()
            .is_empty());
    }
}
