//! Operating regimes and where the squared error sits among them.
//!
//! Every sample gets one regime from the *measured* motion, by priority: velocity reversal
//! (within `reversal_window_s` of a change of direction), standstill, voltage near its limit,
//! acceleration, constant speed. Missing physics leaves fingerprints in specific regimes:
//! friction and gear play at reversals and standstill, a driver limit at the voltage limit, an
//! inertia error during acceleration, a viscous error at constant speed (each effect declares its
//! regimes: [`crate::effects::EffectModel::regimes`]). The figure that matters is the
//! share of squared error of a regime against its share of time.

use crate::signal::ZeroPhase;
use alloc::string::String;
use alloc::vec::Vec;

pub use crate::effects::Regime;

impl Regime {
    pub const ALL: [Regime; 5] = [
        Regime::Reversal,
        Regime::Standstill,
        Regime::VoltageLimit,
        Regime::Acceleration,
        Regime::ConstantSpeed,
    ];

    /// Machine name (JSON).
    pub fn name(self) -> &'static str {
        match self {
            Regime::Reversal => "reversal",
            Regime::Standstill => "standstill",
            Regime::VoltageLimit => "voltage_limit",
            Regime::Acceleration => "acceleration",
            Regime::ConstantSpeed => "constant_speed",
        }
    }

    /// The parameters and the registered effects whose error shows up mostly in this regime
    /// (the effects from the registry: [`crate::effects::EffectModel::regimes`]).
    pub fn suspects(self) -> String {
        let mut parts: Vec<String> = Vec::new();
        let base = match self {
            Regime::Reversal | Regime::Standstill => None,
            Regime::VoltageLimit => {
                Some("the top speed at full voltage (k_drv, k_e, R_eq and the friction level)")
            }
            Regime::Acceleration => Some("the inertia J_eq"),
            Regime::ConstantSpeed => Some("k_e/k_drv/R_eq"),
        };
        parts.extend(base.map(String::from));
        for k in crate::effects::EffectKind::registered() {
            let m = k.model();
            if m.regimes().contains(&self) {
                parts.push(String::from(m.suspect_phrase()));
            }
        }
        parts.join(", ")
    }
}

/// Thresholds of the classification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegimeOptions {
    /// Half width of the window around a velocity reversal [s].
    pub reversal_window_s: f64,
    /// Longest stop between opposite motions still counted as one reversal [s].
    pub reversal_max_stop_s: f64,
    /// Standstill threshold as a fraction of the 99th percentile of |omega_l| (default 0.03).
    pub standstill_fraction: f64,
    /// Absolute standstill threshold [rad/s]; the larger of the two is used.
    pub standstill_min_rad_s: f64,
    /// Acceleration threshold as a fraction of the 99th percentile of |alpha_l| (default 0.15).
    pub acceleration_fraction: f64,
    /// |u| >= this fraction of the limit counts as "at the limit" (default 0.95).
    pub limit_fraction: f64,
    /// Cut-off of the zero-phase filter used to get the acceleration from the speed [Hz].
    pub filter_hz: f64,
}

impl Default for RegimeOptions {
    fn default() -> Self {
        RegimeOptions {
            reversal_window_s: 0.05,
            reversal_max_stop_s: 0.2,
            standstill_fraction: 0.03,
            standstill_min_rad_s: 1e-3,
            acceleration_fraction: 0.15,
            limit_fraction: 0.95,
            filter_hz: 30.0,
        }
    }
}

/// The classification of a record.
#[derive(Debug, Clone, PartialEq)]
pub struct Classification {
    /// One regime per sample.
    pub regime: Vec<Regime>,
    /// Standstill threshold used [rad/s] (load side).
    pub standstill_rad_s: f64,
    /// Acceleration threshold used [rad/s^2] (load side).
    pub acceleration_rad_s2: f64,
    /// Voltage limit used [V], if any.
    pub u_limit_v: Option<f64>,
    /// Sample indices of the velocity reversals.
    pub reversals: Vec<usize>,
    /// Load acceleration [rad/s^2] (filtered derivative of the measured speed).
    pub alpha_l_rad_s2: Vec<f64>,
}

/// Statistics of the residual in one regime.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegimeStats {
    pub regime: Regime,
    /// Samples in the regime.
    pub samples: usize,
    /// Share of the time [%].
    pub time_share_pct: f64,
    /// Share of the total squared error [%].
    pub error_share_pct: f64,
    /// RMS residual in the regime (unit of the signal).
    pub rms: f64,
    /// Mean residual (measurement minus model) in the regime.
    pub mean: f64,
    /// error share / time share: > 1 means the error concentrates here.
    pub concentration: f64,
}

/// Percentile `p` (0..1) of |x| (0 for empty input).
pub fn abs_percentile(x: &[f64], p: f64) -> f64 {
    let mut a: Vec<f64> = x
        .iter()
        .map(|v| libm::fabs(*v))
        .filter(|v| v.is_finite())
        .collect();
    if a.is_empty() {
        return 0.0;
    }
    a.sort_by(|x, y| x.total_cmp(y));
    let i = ((a.len() - 1) as f64 * p.clamp(0.0, 1.0)) as usize;
    a[i]
}

/// The output limit of a logged u [V]: the largest |u| when it recurs as a flat plateau (at least
/// 5 samples within 1e-6 relative), as a board's DAC or a controller's clamp leaves it.
pub fn detect_u_limit(u: &[f64]) -> Option<f64> {
    let umax = u.iter().fold(0.0f64, |m, v| m.max(libm::fabs(*v)));
    if !(umax > 0.0) {
        return None;
    }
    let at = u
        .iter()
        .filter(|v| libm::fabs(**v) >= umax * (1.0 - 1e-6))
        .count();
    (at >= 5).then_some(umax)
}

/// Classifies every sample from the measured load speed `omega_l` [rad/s], the input `u` [V] and
/// the voltage limit `u_limit_v` (none: the voltage-limit regime is empty).
pub fn classify(
    omega_l: &[f64],
    u: &[f64],
    u_limit_v: Option<f64>,
    dt_s: f64,
    opts: &RegimeOptions,
) -> Classification {
    let n = omega_l.len();
    let w_scale = abs_percentile(omega_l, 0.99);
    let w_still = (opts.standstill_fraction * w_scale).max(opts.standstill_min_rad_s);
    let alpha = ZeroPhase::clamped(opts.filter_hz, dt_s).derivative(omega_l);
    let a_thr = opts.acceleration_fraction * abs_percentile(&alpha, 0.99);
    // Reversals: opposite signs of consecutive moving samples, with a short stop in between.
    let max_gap = (opts.reversal_max_stop_s / dt_s) as usize + 1;
    let mut reversals = Vec::new();
    let mut last: Option<(usize, f64)> = None;
    for (k, &w) in omega_l.iter().enumerate() {
        if libm::fabs(w) <= w_still {
            continue;
        }
        let s = if w > 0.0 { 1.0 } else { -1.0 };
        if let Some((kl, sl)) = last {
            if sl != s && k - kl <= max_gap {
                reversals.push((kl + k) / 2);
            }
        }
        last = Some((k, s));
    }
    let half = (opts.reversal_window_s / dt_s) as usize;
    let mut near_rev = alloc::vec![false; n];
    for &r in &reversals {
        for f in near_rev
            .iter_mut()
            .take((r + half + 1).min(n))
            .skip(r.saturating_sub(half))
        {
            *f = true;
        }
    }
    let regime = (0..n)
        .map(|k| {
            if near_rev[k] {
                Regime::Reversal
            } else if libm::fabs(omega_l[k]) <= w_still {
                Regime::Standstill
            } else if u_limit_v.is_some_and(|l| libm::fabs(u[k]) >= opts.limit_fraction * l) {
                Regime::VoltageLimit
            } else if a_thr > 0.0 && libm::fabs(alpha[k]) > a_thr {
                Regime::Acceleration
            } else {
                Regime::ConstantSpeed
            }
        })
        .collect();
    Classification {
        regime,
        standstill_rad_s: w_still,
        acceleration_rad_s2: a_thr,
        u_limit_v,
        reversals,
        alpha_l_rad_s2: alpha,
    }
}

/// Residual statistics per regime (every regime listed, empty ones with zero samples).
pub fn regime_stats(residual: &[f64], c: &Classification) -> Vec<RegimeStats> {
    let n = residual.len().min(c.regime.len());
    let total: f64 = residual[..n].iter().map(|e| e * e).sum();
    Regime::ALL
        .iter()
        .map(|&r| {
            let (mut cnt, mut se, mut s) = (0usize, 0.0, 0.0);
            for (e, _) in residual[..n]
                .iter()
                .zip(&c.regime[..n])
                .filter(|(_, g)| **g == r)
            {
                cnt += 1;
                se += e * e;
                s += e;
            }
            let time_share_pct = 100.0 * cnt as f64 / n.max(1) as f64;
            let error_share_pct = if total > 0.0 { 100.0 * se / total } else { 0.0 };
            RegimeStats {
                regime: r,
                samples: cnt,
                time_share_pct,
                error_share_pct,
                rms: if cnt > 0 {
                    crate::math::sqrt(se / cnt as f64)
                } else {
                    0.0
                },
                mean: if cnt > 0 { s / cnt as f64 } else { 0.0 },
                concentration: if time_share_pct > 0.0 {
                    error_share_pct / time_share_pct
                } else {
                    0.0
                },
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classifies_a_synthetic_motion() {
        // 0-1 s standstill, 1-2 s accelerate to 10 rad/s, 2-4 s constant, 4-5 s ramp down through
        // zero to -10 rad/s (reversal at 4.5 s), 5-6 s constant at -10 rad/s, u saturating in 1-1.2 s.
        let dt = 1e-3;
        let w: Vec<f64> = (0..6000)
            .map(|k| {
                let t = k as f64 * dt;
                if t < 1.0 {
                    0.0
                } else if t < 2.0 {
                    10.0 * (t - 1.0)
                } else if t < 4.0 {
                    10.0
                } else if t < 5.0 {
                    10.0 - 20.0 * (t - 4.0)
                } else {
                    -10.0
                }
            })
            .collect();
        let u: Vec<f64> = (0..6000)
            .map(|k| if (1000..1200).contains(&k) { 10.0 } else { 3.0 })
            .collect();
        let c = classify(&w, &u, detect_u_limit(&u), dt, &RegimeOptions::default());
        assert_eq!(c.reversals.len(), 1);
        assert!(
            (c.reversals[0] as i64 - 4500).abs() <= 2,
            "{:?}",
            c.reversals
        );
        assert_eq!(c.regime[500], Regime::Standstill);
        assert_eq!(c.regime[1100], Regime::VoltageLimit);
        assert_eq!(c.regime[1500], Regime::Acceleration);
        assert_eq!(c.regime[3000], Regime::ConstantSpeed);
        assert_eq!(c.regime[4470], Regime::Reversal);
        assert_eq!(c.regime[4530], Regime::Reversal);
        assert_eq!(c.regime[4300], Regime::Acceleration);
        assert_eq!(c.regime[5500], Regime::ConstantSpeed);
        // An error only near the reversal: all of it there, in 101 ms of 6 s.
        let e: Vec<f64> = (0..6000)
            .map(|k| if (4480..4520).contains(&k) { 1.0 } else { 0.0 })
            .collect();
        let st = regime_stats(&e, &c);
        let rev = st.iter().find(|s| s.regime == Regime::Reversal).unwrap();
        assert!((rev.error_share_pct - 100.0).abs() < 1e-9);
        assert!(
            (rev.time_share_pct - 100.0 * 101.0 / 6000.0).abs() < 0.05,
            "{}",
            rev.time_share_pct
        );
        assert!(rev.concentration > 50.0);
    }

    #[test]
    fn stop_and_restart_is_not_a_reversal() {
        let dt = 1e-3;
        let w: Vec<f64> = (0..3000)
            .map(|k| {
                if k < 1000 {
                    5.0
                } else if k < 2000 {
                    0.0
                } else {
                    -5.0
                }
            })
            .collect();
        let c = classify(&w, &[0.0; 3000], None, dt, &RegimeOptions::default());
        assert!(c.reversals.is_empty());
        assert_eq!(detect_u_limit(&[1.0, 2.0, 3.0]), None);
    }
}
