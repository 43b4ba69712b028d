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
//!
//! Also the load-side speed controller of the identification experiments ([`SpeedLoop`]).
//! Everything here is `no_std` and allocation-free.

use crate::params::{ParamError, PlantParams};

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

/// Crossover of the speed loop [rad/s] (the identification experiments' default).
pub const SPEED_LOOP_CROSSOVER_RAD_S: f64 = 50.0;

/// The speed controller of the speed parts of a run (the identification staircase and ramps,
/// [`super::program::Program::Speed`]): a PI on the load-speed estimate plus a back-EMF and
/// inertia feedforward from nominal parameters,
///
/// ```text
/// u = (k_e N omega_ref + R_eq J_eq N alpha_ref / k_t) / k_drv + K_P e + K_I int(e),  e = omega_ref - omega_hat
/// ```
///
/// all at the load. [`SpeedLoopConfig::from_params`] places the PI zero on the pole of the
/// reduced model omega_l / u = (k_m / N) / (T_m s + 1) (eqs. 29-30), so the open loop is
/// omega_c / s with crossover omega_c. A zero reference (speed and acceleration 0) is a rest:
/// 0 V and the integral cleared, so the motor coasts (braking from full speed against the
/// back-EMF would draw more than a board's over-current trip).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLoopConfig {
    /// Proportional gain [V s/rad] on the load-speed error.
    pub kp_v_s_rad: f64,
    /// Integral gain [V/rad] on the load-speed error.
    pub ki_v_rad: f64,
    /// Back-EMF feedforward k_e N / k_drv [V s/rad] on the load-speed reference.
    pub ff_speed_v_s_rad: f64,
    /// Inertia feedforward R_eq J_eq N / (k_t k_drv) [V s^2/rad] on the load-acceleration
    /// reference.
    pub ff_accel_v_s2_rad: f64,
}

impl SpeedLoopConfig {
    /// The speed loop for the nominal parameters `p` with crossover `omega_c_rad_s` [rad/s].
    pub fn from_params(
        p: &PlantParams,
        omega_c_rad_s: f64,
    ) -> Result<SpeedLoopConfig, SpeedLoopError> {
        p.validate().map_err(SpeedLoopError::Params)?;
        if !(omega_c_rad_s.is_finite() && omega_c_rad_s > 0.0) {
            return Err(SpeedLoopError::Crossover { omega_c_rad_s });
        }
        let (k_m_load, t_m) = (p.k_m() / p.n, p.t_m());
        let kp = omega_c_rad_s * t_m / k_m_load;
        Ok(SpeedLoopConfig {
            kp_v_s_rad: kp,
            ki_v_rad: kp / t_m,
            ff_speed_v_s_rad: p.k_e * p.n / p.k_drv,
            ff_accel_v_s2_rad: p.r_eq() * p.j_eq() * p.n / (p.k_t * p.k_drv),
        })
    }
}

/// Why a speed loop could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SpeedLoopError {
    /// The nominal parameters are not a valid plant.
    #[error("speed loop: parameters")]
    Params(#[source] ParamError),
    /// The crossover is not a positive finite frequency.
    #[error("speed loop: crossover must be > 0 rad/s, got {omega_c_rad_s}")]
    Crossover { omega_c_rad_s: f64 },
}

/// One output of [`SpeedLoop::update`] [V].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLoopOutput {
    /// Driver input after the limit.
    pub u_v: f64,
    pub ff_v: f64,
    pub p_v: f64,
    pub i_v: f64,
    /// The output was clipped at the limit.
    pub saturated: bool,
}

/// The running speed controller of [`SpeedLoopConfig`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLoop {
    cfg: SpeedLoopConfig,
    ts_s: f64,
    integral_v: f64,
}

impl SpeedLoop {
    /// A controller at sample period `ts_s` [s], integral at 0.
    pub fn new(cfg: SpeedLoopConfig, ts_s: f64) -> SpeedLoop {
        SpeedLoop {
            cfg,
            ts_s,
            integral_v: 0.0,
        }
    }

    /// Clears the integral.
    pub fn reset(&mut self) {
        self.integral_v = 0.0;
    }

    /// One period: reference speed [rad/s] and acceleration [rad/s^2], speed estimate [rad/s],
    /// output limited to +-`u_limit_v`. Conditional integration (the integral does not grow
    /// while the output is clipped in the direction of the error).
    #[inline]
    pub fn update(
        &mut self,
        omega_ref_rad_s: f64,
        alpha_ref_rad_s2: f64,
        omega_rad_s: f64,
        u_limit_v: f64,
    ) -> SpeedLoopOutput {
        if omega_ref_rad_s == 0.0 && alpha_ref_rad_s2 == 0.0 {
            self.integral_v = 0.0;
            return SpeedLoopOutput {
                u_v: 0.0,
                ff_v: 0.0,
                p_v: 0.0,
                i_v: 0.0,
                saturated: false,
            };
        }
        let c = &self.cfg;
        let err = omega_ref_rad_s - omega_rad_s;
        let ff = c.ff_speed_v_s_rad * omega_ref_rad_s + c.ff_accel_v_s2_rad * alpha_ref_rad_s2;
        let p = c.kp_v_s_rad * err;
        let u_unsat = ff + p + self.integral_v;
        let u = if u_unsat.is_finite() {
            u_unsat.clamp(-u_limit_v, u_limit_v)
        } else {
            0.0
        };
        let saturated = u != u_unsat;
        if !saturated || err.signum() != u_unsat.signum() {
            self.integral_v += c.ki_v_rad * err * self.ts_s;
        }
        SpeedLoopOutput {
            u_v: u,
            ff_v: ff,
            p_v: p,
            i_v: self.integral_v,
            saturated,
        }
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

    #[test]
    fn speed_loop_tracks_a_first_order_motor() {
        // The reduced model omega_l' = ((k_m/N) u - omega_l) / T_m, Table 2, exact speed.
        let p = PlantParams::TABLE2;
        let cfg = SpeedLoopConfig::from_params(&p, 50.0).unwrap();
        let ts = 1e-3;
        let mut c = SpeedLoop::new(cfg, ts);
        let (km, tm) = (p.k_m() / p.n, p.t_m());
        let mut w = 0.0;
        for _ in 0..1000 {
            let o = c.update(20.0, 0.0, w, 10.0);
            w += ts * (km * o.u_v - w) / tm;
        }
        assert!((w - 20.0).abs() < 1e-3, "{w}");
        // The feedforward alone holds the nominal motor at speed: the integral stays near 0.
        assert!(c.update(20.0, 0.0, w, 10.0).i_v.abs() < 0.05);
        // Rest: 0 V and the integral cleared.
        let o = c.update(0.0, 0.0, w, 10.0);
        assert_eq!((o.u_v, o.i_v), (0.0, 0.0));
        // Clipped at the limit, the integral does not wind up.
        let o = c.update(1e4, 0.0, 0.0, 10.0);
        assert!(o.saturated && o.u_v == 10.0 && o.i_v == 0.0);
    }
}
