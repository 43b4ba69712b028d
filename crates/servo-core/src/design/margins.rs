//! Gain and phase margins of a loop L(jw) by a logarithmic frequency sweep with bisection
//! refinement (like MATLAB's `margin`: the smallest phase margin over all gain crossovers and the
//! gain margin of the phase crossover closest to 0 dB). No heap: the sweep is streamed.

use super::{c_abs, c_arg, deg, Complex};
use crate::math;

/// Margins and crossovers of a loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// Gain crossover frequency w_gc [rad/s] (|L| = 1); NaN when |L| never crosses 1.
    pub omega_gc: f64,
    /// Phase margin 180 + angle L(j w_gc) [deg], wrapped into (-180, 180]; NaN without crossover.
    pub phase_margin_deg: f64,
    /// Phase crossover frequency w_pc [rad/s] (angle L = -180 mod 360); infinite when none.
    pub omega_pc: f64,
    /// Gain margin -20 log10 |L(j w_pc)| [dB]; +infinity when the phase never crosses -180.
    pub gain_margin_db: f64,
    /// Number of gain crossovers found.
    pub gain_crossovers: usize,
}

/// Sweep settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    /// Lowest frequency [rad/s].
    pub omega_lo: f64,
    /// Highest frequency [rad/s] (below pi/T_s for a discrete loop).
    pub omega_hi: f64,
    /// Number of log-spaced grid points.
    pub points: usize,
    /// Number of integrators in the loop (type); fixes the branch of the low-frequency phase
    /// (-90 deg per integrator).
    pub loop_type: i32,
}

fn unwrap_near(principal_deg: f64, reference_deg: f64) -> f64 {
    principal_deg - 360.0 * math::round((principal_deg - reference_deg) / 360.0)
}

/// Margins of `l` over the sweep.
pub fn margins<F: Fn(f64) -> Complex<f64>>(l: F, sweep: &Sweep) -> Margins {
    let n = sweep.points.max(16);
    let (lw0, lw1) = (math::ln(sweep.omega_lo), math::ln(sweep.omega_hi));
    let w_at = |i: usize| math::exp(lw0 + (lw1 - lw0) * i as f64 / (n - 1) as f64);
    let eval = |w: f64, ref_deg: f64| {
        let v = l(w);
        (math::ln(c_abs(v)), unwrap_near(deg(c_arg(v)), ref_deg))
    };
    let mut out = Margins {
        omega_gc: f64::NAN,
        phase_margin_deg: f64::NAN,
        omega_pc: f64::INFINITY,
        gain_margin_db: f64::INFINITY,
        gain_crossovers: 0,
    };
    let mut w_prev = w_at(0);
    let (mut lm_prev, mut ph_prev) = eval(w_prev, -90.0 * sweep.loop_type as f64);
    for i in 1..n {
        let w = w_at(i);
        let (lm, ph) = eval(w, ph_prev);
        // gain crossover
        if lm_prev.is_finite() && lm.is_finite() && (lm_prev > 0.0) != (lm > 0.0) {
            let (mut a, mut b) = (math::ln(w_prev), math::ln(w));
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                let (lmm, _) = eval(math::exp(m), ph_prev);
                if (lmm > 0.0) == (lm_prev > 0.0) {
                    a = m;
                } else {
                    b = m;
                }
            }
            let wc = math::exp(0.5 * (a + b));
            let (_, phc) = eval(wc, ph_prev);
            let pm = wrap180(180.0 + phc);
            out.gain_crossovers += 1;
            if out.phase_margin_deg.is_nan() || pm < out.phase_margin_deg {
                out.phase_margin_deg = pm;
                out.omega_gc = wc;
            }
        }
        // phase crossovers at -180 + 360 k
        let (lo, hi) = if ph_prev < ph {
            (ph_prev, ph)
        } else {
            (ph, ph_prev)
        };
        let k_lo = math::floor((lo + 180.0) / 360.0) + 1.0;
        let k_hi = math::floor((hi + 180.0) / 360.0);
        let mut k = k_lo;
        while k <= k_hi {
            let target = -180.0 + 360.0 * k;
            let (mut a, mut b) = (math::ln(w_prev), math::ln(w));
            let above = ph_prev > target;
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                let (_, phm) = eval(math::exp(m), ph_prev);
                if (phm > target) == above {
                    a = m;
                } else {
                    b = m;
                }
            }
            let wp = math::exp(0.5 * (a + b));
            let (lmp, _) = eval(wp, ph_prev);
            let gm = -20.0 * lmp / math::ln(10.0);
            if gm.abs() < out.gain_margin_db.abs() {
                out.gain_margin_db = gm;
                out.omega_pc = wp;
            }
            k += 1.0;
        }
        // the exact -180 + 360 k at a grid point is caught by the next interval unless last
        w_prev = w;
        lm_prev = lm;
        ph_prev = ph;
    }
    out
}

fn wrap180(x: f64) -> f64 {
    let r = math::rem_euclid(x + 180.0, 360.0) - 180.0;
    if r <= -180.0 {
        r + 360.0
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrator_with_lag() {
        // L = K / (s (s + 1)^2): phase crossover at w = 1 (two lags of 45 deg), |L(j1)| = K/2
        let k = 0.5;
        let l = |w: f64| {
            let s = Complex::new(0.0, w);
            Complex::new(k, 0.0) / (s * (s + 1.0) * (s + 1.0))
        };
        let m = margins(
            l,
            &Sweep {
                omega_lo: 1e-3,
                omega_hi: 1e3,
                points: 800,
                loop_type: 1,
            },
        );
        assert!((m.omega_pc - 1.0).abs() < 1e-9, "{m:?}");
        assert!((m.gain_margin_db - 20.0 * (2.0f64 / k).log10()).abs() < 1e-8);
        // w_gc solves w sqrt(1 + w^2)^2 = K -> w (1 + w^2) = 0.5
        let wc = m.omega_gc;
        assert!((wc * (1.0 + wc * wc) - 0.5).abs() < 1e-9);
        let pm = 180.0 - 90.0 - 2.0 * wc.atan().to_degrees();
        assert!((m.phase_margin_deg - pm).abs() < 1e-7);
    }

    #[test]
    fn double_integrator_with_lead_has_infinite_gain_margin() {
        // L = (1 + s/0.5)/(s^2 (1 + s/50)): phase stays above -180
        let l = |w: f64| {
            let s = Complex::new(0.0, w);
            (s * 2.0 + 1.0) / (s * s * (s * 0.02 + 1.0))
        };
        let m = margins(
            l,
            &Sweep {
                omega_lo: 1e-3,
                omega_hi: 1e4,
                points: 800,
                loop_type: 2,
            },
        );
        assert!(m.gain_margin_db.is_infinite());
        assert!(m.phase_margin_deg > 0.0 && m.gain_crossovers == 1);
    }
}
