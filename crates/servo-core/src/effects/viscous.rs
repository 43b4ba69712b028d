//! `viscous`: viscous friction B_eq omega_m at the motor side (eq. 9).
//!
//! Part of the linear dynamics: the simulator discretises it exactly with the rest of eq. 20,
//! and the fit estimates B_eq with the base parameters. Its value lives in the plant's
//! parameters (`b_eq`) and in this effect alike.

use super::{spec, ActsOn, EffectModel, ParamSpec, Regime, SimRole};

/// The `viscous` effect.
#[derive(Debug, Clone, Copy)]
pub struct Viscous;

const PARAMS: [ParamSpec; 1] = [spec(
    "b_eq",
    "N m s/rad",
    "viscous friction coefficient, motor side",
    None,
    0.0,
    false,
)];

/// Viscous friction torque B_eq omega_m [N m], motor side (eq. 9).
///
/// `b_eq` [N m s/rad], `omega_m` [rad/s].
#[inline]
pub fn torque_m(b_eq: f64, omega_m: f64) -> f64 {
    b_eq * omega_m
}

impl EffectModel for Viscous {
    fn name(&self) -> &str {
        "viscous"
    }
    fn description(&self) -> &str {
        "viscous friction B_eq omega_m at motor side (eq. 9)"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::MotorTorque
    }
    fn sim_role(&self) -> SimRole {
        SimRole::Linear
    }
    fn experiment(&self) -> &str {
        "run a friction staircase (constant speeds in both directions) and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::ConstantSpeed]
    }
    fn suspect_phrase(&self) -> &str {
        "viscous friction B_eq"
    }
}
