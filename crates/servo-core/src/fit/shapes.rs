//! The shapes of the catalogue effects as functions of the measured signals, per unit of their
//! linear parameters: the regressors of the equation-error fit.
//!
//! These mirror the effect definitions of the simulator (`crate::sim`) so that a model fitted here
//! and simulated there is the same model.

use crate::math;

/// Coulomb direction: sign of the speed (sign(0) = 0).
#[inline]
pub fn coulomb_dir(omega: f64) -> f64 {
    math::sign(omega)
}

/// Stribeck decay of the breakaway excess: exp(-(|omega_l| / omega_s)^2), load-side speeds.
#[inline]
pub fn stribeck_decay(omega_l: f64, omega_s: f64) -> f64 {
    let x = omega_l / omega_s;
    math::exp(-x * x)
}

/// Symmetric saturation of the driver input to +/- `limit` [V].
#[inline]
pub fn saturation(u: f64, limit: f64) -> f64 {
    u.clamp(-limit, limit)
}

/// Dead band of half width `width` [V] on the driver input.
#[inline]
pub fn deadzone(u: f64, width: f64) -> f64 {
    if u > width {
        u - width
    } else if u < -width {
        u + width
    } else {
        0.0
    }
}

/// Cogging torque at the motor [N m] per unit amplitude: the (sin, cos) pair of harmonic * theta_m.
#[inline]
pub fn cogging_pair(theta_m: f64, harmonic: f64) -> (f64, f64) {
    let x = harmonic * theta_m;
    (math::sin(x), math::cos(x))
}

/// Imbalance torque at the load [N m] per unit amplitude: the (sin, cos) pair of theta_l.
#[inline]
pub fn imbalance_pair(theta_l: f64) -> (f64, f64) {
    (math::sin(theta_l), math::cos(theta_l))
}
