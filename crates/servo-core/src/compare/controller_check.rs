//! Does the controller we were told about reproduce the logged u?
//!
//! A closed-loop replay is only as good as its controller: when the gains in a gains file or in
//! a log's metadata are not the ones that ran, the replay diverges from the measurement for reasons
//! that have nothing to do with the plant. The check runs the controller, configured as for the
//! replay (discretisation, derivative input, anti-windup, limit, feedforward), on the *measured*
//! reference and position (no plant involved) and compares its output with the logged u on the
//! samples where the logged u is inside the output limit. The least-squares gains of a PID
//! (u - u_ff = K_P e + K_I sum(e) T_s + K_D (e_k - e_{k-1}) / T_s, backward Euler, ideal
//! derivative, integral running free as without anti-windup, u_ff the logged feedforward if any)
//! are estimated from the same samples.

use super::figures::fit_percent;
use super::replay::Controller;
use alloc::vec::Vec;
use nalgebra::{DMatrix, DVector};

/// Outcome of the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerCheck {
    /// Fit [%] of the controller's output to the logged u (unsaturated samples).
    pub fit_percent: f64,
    /// RMS difference [V].
    pub rms_v: f64,
    /// Samples used.
    pub samples: usize,
    /// Least-squares PID gains that best reproduce the logged u: K_P [V/rad], K_I [V/(rad s)],
    /// K_D [V s/rad]; `None` when the problem is singular.
    pub ls_gains: Option<[f64; 3]>,
    /// Fit [%] of the least-squares PID to the logged u.
    pub ls_fit_percent: f64,
}

/// Runs `controller` on the measured `reference` and `theta` [rad], compares with `u` [V] on the
/// samples where |u| < 0.999 `u_limit_v` (all samples without a limit). `feedforward_v` [V] is the
/// feedforward part of the logged u, if any: `controller` adds it itself; the least-squares PID is
/// fitted to u minus it.
pub fn check_controller(
    controller: &mut dyn Controller,
    reference: &[f64],
    theta: &[f64],
    u: &[f64],
    feedforward_v: Option<&[f64]>,
    u_limit_v: Option<f64>,
    dt_s: f64,
) -> ControllerCheck {
    let n = reference.len().min(theta.len()).min(u.len());
    let inside = |k: usize| u_limit_v.is_none_or(|l| libm::fabs(u[k]) < 0.999 * l);
    let mut y = Vec::new();
    let mut yh = Vec::new();
    for k in 0..n {
        let v = controller.update(reference[k], theta[k]);
        if inside(k) {
            y.push(u[k]);
            yh.push(v);
        }
    }
    let samples = y.len();
    let rms_v = if samples > 0 {
        crate::math::sqrt(
            y.iter()
                .zip(&yh)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                / samples as f64,
        )
    } else {
        f64::NAN
    };
    // Least squares on [e, sum e T_s, de/T_s].
    let mut rows: Vec<[f64; 3]> = Vec::with_capacity(samples);
    let mut s = 0.0;
    let mut e_prev = None;
    for k in 0..n {
        let e = reference[k] - theta[k];
        s += e * dt_s;
        let de = e_prev.map_or(0.0, |p| (e - p) / dt_s);
        e_prev = Some(e);
        if inside(k) {
            rows.push([e, s, de]);
        }
    }
    let (mut ls_gains, mut ls_fit_percent) = (None, f64::NAN);
    if rows.len() >= 10 {
        let a = DMatrix::from_fn(rows.len(), 3, |i, j| rows[i][j]);
        let ff = |k: usize| {
            feedforward_v
                .and_then(|f| f.get(k))
                .copied()
                .filter(|v| v.is_finite())
                .unwrap_or(0.0)
        };
        let b =
            DVector::from_iterator(y.len(), (0..n).filter(|k| inside(*k)).map(|k| u[k] - ff(k)));
        // nalgebra's SVD panics on non-finite input ("singular value was NaN"): absurd or
        // overflowing samples leave the LS gains unknown instead.
        let finite = a.iter().chain(b.iter()).all(|v| v.is_finite());
        let solved = if finite {
            a.clone().svd(true, true).solve(&b, 1e-12).ok()
        } else {
            None
        };
        if let Some(x) = solved {
            let g = [x[0], x[1], x[2]];
            if g.iter().all(|v| v.is_finite()) {
                let pred: Vec<f64> = (&a * &x)
                    .iter()
                    .zip((0..n).filter(|k| inside(*k)))
                    .map(|(p, k)| p + ff(k))
                    .collect();
                ls_fit_percent = fit_percent(&y, &pred);
                ls_gains = Some(g);
            }
        }
    }
    ControllerCheck {
        fit_percent: fit_percent(&y, &yh),
        rms_v,
        samples,
        ls_gains,
        ls_fit_percent,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{Pid, PidConfig, PidGains};

    #[test]
    fn recovers_the_gains_that_ran() {
        let dt = 1e-3;
        let gains = PidGains {
            kp: 17.0,
            ki: 140.0,
            kd: 0.5,
            tl_s: 0.0,
        };
        let mut real = Pid::new(PidConfig::new(gains, dt)).unwrap();
        let n = 3000;
        let r: Vec<f64> = (0..n).map(|k| if k < 1500 { 0.5 } else { 0.0 }).collect();
        let th: Vec<f64> = (0..n)
            .map(|k| 0.4 * (1.0 - (-(k as f64) * dt / 0.05).exp()) + 0.01 * (k as f64 * 0.1).sin())
            .collect();
        let u: Vec<f64> = (0..n)
            .map(|k| Controller::update(&mut real, r[k], th[k]))
            .collect();
        let mut same = Pid::new(PidConfig::new(gains, dt)).unwrap();
        let c = check_controller(&mut same, &r, &th, &u, None, None, dt);
        assert!(c.fit_percent > 99.999, "{c:?}");
        let g = c.ls_gains.unwrap();
        assert!(
            (g[0] - 17.0).abs() < 1e-6 && (g[1] - 140.0).abs() < 1e-4 && (g[2] - 0.5).abs() < 1e-8,
            "{g:?}"
        );
        let mut wrong = Pid::new(PidConfig::new(
            PidGains {
                kp: 7.5,
                ki: 94.0,
                kd: 0.15,
                tl_s: 0.0,
            },
            dt,
        ))
        .unwrap();
        let c = check_controller(&mut wrong, &r, &th, &u, None, None, dt);
        assert!(c.fit_percent < 80.0, "{c:?}");
        // With a feedforward in the logged u: the least squares fits the PID part.
        let ff: Vec<f64> = (0..n).map(|k| 2.0 * (k as f64 * 0.01).sin()).collect();
        let u_ff: Vec<f64> = u.iter().zip(&ff).map(|(a, b)| a + b).collect();
        let mut pid = Pid::new(PidConfig::new(gains, dt)).unwrap();
        let mut k = 0;
        let mut with_ff = |r: f64, y: f64| {
            k += 1;
            Pid::update(&mut pid, r, y, ff[k - 1]).u_v
        };
        let c = check_controller(&mut with_ff, &r, &th, &u_ff, Some(&ff), None, dt);
        assert!(c.fit_percent > 99.999, "{c:?}");
        let g = c.ls_gains.unwrap();
        assert!(
            (g[0] - 17.0).abs() < 1e-6 && c.ls_fit_percent > 99.999,
            "{c:?}"
        );
    }
}
