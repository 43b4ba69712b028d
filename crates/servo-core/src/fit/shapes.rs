//! The shapes of the catalogue effects as regressors: thin wrappers, per unit of their linear
//! parameters, over the one definition in [`crate::effects::torque`] that the simulator uses.

use crate::effects::torque;

/// Coulomb direction: sign of the speed (sign(0) = 0).
#[inline]
pub fn coulomb_dir(omega: f64) -> f64 {
    torque::coulomb_torque_l(1.0, omega)
}

/// Stribeck decay of the breakaway excess: exp(-(omega_l / omega_s)^2), load-side speeds.
#[inline]
pub fn stribeck_decay(omega_l: f64, omega_s: f64) -> f64 {
    torque::stribeck_shape(omega_l, omega_s)
}

/// Symmetric saturation of the driver input to +/- `limit` [V].
#[inline]
pub fn saturation(u: f64, limit: f64) -> f64 {
    torque::saturation_v(limit, u)
}

/// Dead band of half width `width` [V] on the driver input.
#[inline]
pub fn deadzone(u: f64, width: f64) -> f64 {
    torque::deadzone_v(width, u)
}

/// Cogging torque at the motor [N m] per unit amplitude: the (sin, cos) pair of harmonic * theta_m
/// (amplitude sin(h theta + phase) = A cos(phase) sin(h theta) + A sin(phase) cos(h theta)).
#[inline]
pub fn cogging_pair(theta_m: f64, harmonic: f64) -> (f64, f64) {
    (
        torque::cogging_torque_m(1.0, harmonic, 0.0, theta_m),
        torque::cogging_torque_m(1.0, harmonic, core::f64::consts::FRAC_PI_2, theta_m),
    )
}

/// Imbalance torque at the load [N m] per unit amplitude: the (sin, cos) pair of theta_l.
#[inline]
pub fn imbalance_pair(theta_l: f64) -> (f64, f64) {
    (
        torque::imbalance_torque_l(1.0, 0.0, theta_l),
        torque::imbalance_torque_l(1.0, core::f64::consts::FRAC_PI_2, theta_l),
    )
}
