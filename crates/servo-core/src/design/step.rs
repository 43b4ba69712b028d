//! Closed-loop unit-step response (r = 1 rad) of a [`ClosedLoop`] and its metrics: overshoot,
//! 10-90 % rise time, 5 % and 1 % settling times. Continuous loops are simulated exactly (ZOH of
//! a constant input is exact) on a fine grid; discrete loops at their own T_s.

use super::closed_loop::ClosedLoop;
use super::ss::StateSpace;
use alloc::vec::Vec;
use nalgebra::DVector;

/// Step response samples.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// Time [s].
    pub time_s: Vec<f64>,
    /// Output theta_l [rad] for a 1 rad reference step.
    pub y_rad: Vec<f64>,
}

/// Metrics of a unit-step response (final value 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMetrics {
    /// Overshoot (max y - 1) / 1 [%], 0 when y never exceeds 1.
    pub overshoot_pct: f64,
    /// 10 % to 90 % rise time [s]; None if 90 % is never reached.
    pub rise_time_s: Option<f64>,
    /// Time after which |y - 1| <= 5 % [s]; None if not settled within the simulated horizon.
    pub settling_time_5pct_s: Option<f64>,
    /// Time after which |y - 1| <= 1 % [s]; None if not settled within the simulated horizon.
    pub settling_time_1pct_s: Option<f64>,
}

/// Simulates the unit step for `horizon_s` seconds with `steps` steps (continuous loops) or at
/// T_s (discrete loops, `steps` ignored).
pub fn step_response(cl: &ClosedLoop, horizon_s: f64, steps: usize) -> StepResponse {
    let (phi, gamma, dt) = match cl.ts_s {
        Some(ts) => (cl.a.clone(), cl.b.clone(), ts),
        None => {
            let dt = horizon_s / steps.max(1) as f64;
            let d = StateSpace {
                a: cl.a.clone(),
                b: cl.b.clone(),
                c: cl.c.clone(),
                d: 0.0,
            }
            .discretize_zoh(dt);
            (d.phi, d.gamma, dt)
        }
    };
    let n = crate::math::floor(horizon_s / dt) as usize + 1;
    let mut x = DVector::<f64>::zeros(cl.a.nrows());
    let mut time_s = Vec::with_capacity(n + 1);
    let mut y_rad = Vec::with_capacity(n + 1);
    for k in 0..=n {
        time_s.push(k as f64 * dt);
        y_rad.push(cl.c.dot(&x));
        x = &phi * &x + &gamma;
    }
    StepResponse { time_s, y_rad }
}

/// Metrics of a unit-step response (final value 1), with linear interpolation between samples.
pub fn metrics(r: &StepResponse) -> StepMetrics {
    let (t, y) = (&r.time_s, &r.y_rad);
    let max = y.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let cross = |level: f64| -> Option<f64> {
        for k in 1..y.len() {
            if y[k] >= level && y[k - 1] < level {
                return Some(t[k - 1] + (level - y[k - 1]) / (y[k] - y[k - 1]) * (t[k] - t[k - 1]));
            }
        }
        None
    };
    let rise_time_s = match (cross(0.1), cross(0.9)) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    let settle = |band: f64| -> Option<f64> {
        let last_out = y.iter().rposition(|v| (v - 1.0).abs() > band);
        match last_out {
            None => Some(0.0),
            Some(k) if k + 1 >= y.len() => None,
            Some(k) => {
                // the response must stay settled for at least the last 10 % of the horizon
                if t[k] > 0.9 * t[t.len() - 1] {
                    return None;
                }
                let target = if y[k] > 1.0 { 1.0 + band } else { 1.0 - band };
                let (y0, y1) = (y[k], y[k + 1]);
                let f = if y1 != y0 {
                    ((target - y0) / (y1 - y0)).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                Some(t[k] + f * (t[k + 1] - t[k]))
            }
        }
    };
    StepMetrics {
        overshoot_pct: ((max - 1.0) * 100.0).max(0.0),
        rise_time_s,
        settling_time_5pct_s: settle(0.05),
        settling_time_1pct_s: settle(0.01),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::spec::overshoot_from_damping;
    use nalgebra::{DMatrix, DVector};

    /// Second-order loop w_n^2/(s^2 + 2 delta w_n s + w_n^2) against its analytic step response
    /// y(t) = 1 - e^{-delta w_n t} sin(w_d t + acos delta) / sqrt(1 - delta^2).
    #[test]
    fn second_order_metrics() {
        let (wn, d) = (10.0f64, 0.5f64);
        let cl = ClosedLoop {
            a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -wn * wn, -2.0 * d * wn]),
            b: DVector::from_column_slice(&[0.0, wn * wn]),
            c: DVector::from_column_slice(&[1.0, 0.0]),
            ts_s: None,
        };
        let r = step_response(&cl, 3.0, 30_000);
        let m = metrics(&r);
        assert!(
            (m.overshoot_pct - 100.0 * overshoot_from_damping(d)).abs() < 1e-3,
            "{m:?}"
        );
        let wd = wn * (1.0 - d * d).sqrt();
        let y =
            |t: f64| 1.0 - (-d * wn * t).exp() * (wd * t + d.acos()).sin() / (1.0 - d * d).sqrt();
        let first = |level: f64| {
            let (mut a, mut b) = (0.0, std::f64::consts::PI / wd);
            for _ in 0..100 {
                let m = 0.5 * (a + b);
                if y(m) < level {
                    a = m
                } else {
                    b = m
                }
            }
            a
        };
        assert!(
            (m.rise_time_s.unwrap() - (first(0.9) - first(0.1))).abs() < 1e-6,
            "{m:?}"
        );
        // settling: last time |y - 1| = band, found on a dense analytic grid
        let last_out = |band: f64| {
            (0..3_000_000)
                .rev()
                .map(|k| k as f64 * 1e-6)
                .find(|&t| (y(t) - 1.0).abs() > band)
                .unwrap()
        };
        let ts5 = m.settling_time_5pct_s.unwrap();
        assert!((ts5 - last_out(0.05)).abs() < 2e-5, "{ts5}");
        let ts1 = m.settling_time_1pct_s.unwrap();
        assert!((ts1 - last_out(0.01)).abs() < 2e-5, "{ts1}");
    }
}
