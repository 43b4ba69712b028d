//! Speed estimate from the encoder angle: a second-order tracking loop (PLL), as in ODrive's
//! encoder estimator. With bandwidth w_b [rad/s]:
//!
//! ```text
//! theta_hat += T_s omega_hat
//! e          = theta_meas - theta_hat
//! theta_hat += T_s 2 w_b e
//! omega_hat += T_s w_b^2 e
//! ```
//!
//! i.e. a critically damped filter of the derivative with both poles at -w_b (continuous time).
//! Unlike a finite difference it does not jump by one count per sample at low speed.

/// Tracking-loop speed estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedEstimator {
    ts_s: f64,
    kp: f64,
    ki: f64,
    theta_hat_rad: f64,
    omega_hat_rad_s: f64,
    primed: bool,
}

impl SpeedEstimator {
    /// Estimator with bandwidth `bandwidth_rad_s` [rad/s] at sample period `ts_s` [s]. The
    /// bandwidth is capped at 0.5/T_s so that the discrete loop stays well damped.
    pub fn new(bandwidth_rad_s: f64, ts_s: f64) -> SpeedEstimator {
        let wb = bandwidth_rad_s.clamp(1e-3, 0.5 / ts_s);
        SpeedEstimator {
            ts_s,
            kp: 2.0 * wb,
            ki: wb * wb,
            theta_hat_rad: 0.0,
            omega_hat_rad_s: 0.0,
            primed: false,
        }
    }

    /// Feeds one angle measurement [rad]; returns the speed estimate [rad/s].
    #[inline]
    pub fn update(&mut self, theta_rad: f64) -> f64 {
        if !theta_rad.is_finite() {
            return self.omega_hat_rad_s;
        }
        if !self.primed {
            self.theta_hat_rad = theta_rad;
            self.primed = true;
            return 0.0;
        }
        self.theta_hat_rad += self.ts_s * self.omega_hat_rad_s;
        let e = theta_rad - self.theta_hat_rad;
        self.theta_hat_rad += self.ts_s * self.kp * e;
        self.omega_hat_rad_s += self.ts_s * self.ki * e;
        self.omega_hat_rad_s
    }

    /// The last speed estimate [rad/s].
    pub fn omega_rad_s(&self) -> f64 {
        self.omega_hat_rad_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracks_a_quantised_ramp() {
        let ts = 1e-3;
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        let mut est = SpeedEstimator::new(2.0 * std::f64::consts::PI * 50.0, ts);
        let speed = 3.0; // rad/s: about 2 counts per sample
        let mut w = 0.0;
        let mut max_dev: f64 = 0.0;
        for k in 0..2000 {
            let theta = ((speed * k as f64 * ts) / q).floor() * q;
            w = est.update(theta);
            if k > 500 {
                max_dev = max_dev.max((w - speed).abs());
            }
        }
        assert!((w - speed).abs() < 0.2, "{w}");
        // Much smoother than a finite difference (which jumps by q/ts = 1.53 rad/s).
        assert!(max_dev < 0.5, "{max_dev}");
        // Standstill: exactly zero.
        let mut est = SpeedEstimator::new(300.0, ts);
        for _ in 0..100 {
            assert_eq!(est.update(1.0), 0.0);
        }
    }
}
