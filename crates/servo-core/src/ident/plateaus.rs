//! Detection of constant-speed segments (plateaus) in a speed record, for the friction test
//! (handout 4.1: "torque at different constant speed levels").
//!
//! The speed is smoothed with a centred moving average; a plateau is a maximal run in which the
//! smoothed speed stays within a tolerance band around the run's mean. Runs shorter than
//! `min_duration_s` (transients, ramps) are discarded, and the start of each plateau (the settling
//! after the step) and its very end are trimmed, like the published "mean over 1..4.9 s of each
//! 5 s step".

use alloc::vec::Vec;

use super::{median_dt, IdentError};
use crate::signal::moving_average;

/// Settings of the plateau detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateauConfig {
    /// Length of the centred moving average on the speed [s].
    pub smooth_s: f64,
    /// Band half-width relative to the plateau speed [-].
    pub rel_tol: f64,
    /// Band half-width floor, relative to the record's largest |speed| [-].
    pub abs_tol_frac: f64,
    /// Shortest plateau kept [s].
    pub min_duration_s: f64,
    /// Fraction of each plateau dropped at its start (settling) [-].
    pub trim_start_frac: f64,
    /// Fraction of each plateau dropped at its end [-].
    pub trim_end_frac: f64,
}

impl Default for PlateauConfig {
    fn default() -> Self {
        PlateauConfig {
            smooth_s: 0.1,
            rel_tol: 0.05,
            abs_tol_frac: 0.01,
            min_duration_s: 0.5,
            trim_start_frac: 0.2,
            trim_end_frac: 0.02,
        }
    }
}

/// A plateau: samples `start..end` (trimmed) of a record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plateau {
    /// First sample (inclusive).
    pub start: usize,
    /// Last sample (exclusive).
    pub end: usize,
    /// Mean speed over the trimmed plateau [rad/s].
    pub omega_mean: f64,
}

/// Finds the constant-speed plateaus of `omega` sampled at times `t`.
pub fn find_plateaus(
    t: &[f64],
    omega: &[f64],
    cfg: &PlateauConfig,
) -> Result<Vec<Plateau>, IdentError> {
    let n = omega.len();
    if t.len() != n {
        return Err(IdentError::Internal("time and speed lengths differ"));
    }
    if !(cfg.smooth_s >= 0.0
        && cfg.rel_tol > 0.0
        && cfg.abs_tol_frac >= 0.0
        && cfg.min_duration_s > 0.0
        && (0.0..0.5).contains(&cfg.trim_start_frac)
        && (0.0..0.5).contains(&cfg.trim_end_frac))
    {
        return Err(IdentError::BadConfig(alloc::format!(
            "plateau settings out of range: {cfg:?}"
        )));
    }
    if n < 3 {
        return Ok(Vec::new());
    }
    let dt = median_dt(t);
    let half = ((cfg.smooth_s / dt) / 2.0) as usize;
    let ws = moving_average(omega, half);
    let wmax = ws.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
    let abs_tol = (cfg.abs_tol_frac * wmax).max(1e-9);
    let mut out = Vec::new();
    let mut i = 0;
    while i < n {
        let mut sum = 0.0;
        let mut cnt = 0.0;
        let mut level = ws[i];
        let mut j = i;
        while j < n {
            let tol = (cfg.rel_tol * level.abs()).max(abs_tol);
            if (ws[j] - level).abs() > tol {
                break;
            }
            sum += ws[j];
            cnt += 1.0;
            level = sum / cnt;
            j += 1;
        }
        if t[j - 1] - t[i] >= cfg.min_duration_s {
            let len = j - i;
            let s = i + (cfg.trim_start_frac * len as f64) as usize;
            let e = j - (cfg.trim_end_frac * len as f64) as usize;
            if e > s + 1 {
                let omega_mean = super::mean(&omega[s..e]);
                out.push(Plateau {
                    start: s,
                    end: e,
                    omega_mean,
                });
            }
        }
        i = j.max(i + 1);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::sensors::SplitMix64;

    #[test]
    fn finds_the_steps_of_a_noisy_staircase() {
        let dt = 1e-3;
        let mut rng = SplitMix64(5);
        let levels = [0.0, 100.0, 200.0, 300.0, -150.0];
        let mut t = Vec::new();
        let mut w = Vec::new();
        let mut wf = 0.0;
        for (k, lv) in levels.iter().enumerate() {
            for j in 0..3000 {
                // First-order response with 30 ms time constant plus noise.
                wf += (lv - wf) * dt / 0.03;
                t.push((k * 3000 + j) as f64 * dt);
                w.push(wf + 2.0 * rng.normal());
            }
        }
        let p = find_plateaus(&t, &w, &PlateauConfig::default()).unwrap();
        let got: Vec<f64> = p.iter().map(|p| p.omega_mean).collect();
        assert_eq!(got.len(), 5, "{got:?}");
        for (g, l) in got.iter().zip(levels) {
            assert!((g - l).abs() < 0.5, "{g} vs {l}");
        }
        // Trimmed: starts at least 20 % into the 3 s step.
        assert!(p[1].start >= 3000 + 550, "{}", p[1].start);
    }

    #[test]
    fn a_ramp_has_no_plateaus() {
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 1e-3).collect();
        let w: Vec<f64> = t.iter().map(|t| 600.0 * t).collect();
        assert!(find_plateaus(&t, &w, &PlateauConfig::default())
            .unwrap()
            .is_empty());
    }
}
