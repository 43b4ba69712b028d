//! `coulomb`: Coulomb friction tau_sf sign(omega_l) at the load side (eq. 8).
//!
//! Dry friction with stiction at tau_sf (see [`super::torque::Friction`]). The fit estimates
//! tau_sf with the base parameters (its regressor is the Coulomb direction, the same for every
//! model, precomputed by the fit's dataset).

use super::torque::Friction;
use super::{spec, ActsOn, EffectModel, ParamSpec, Regime, Sample, SimRole};
use crate::math;

/// The `coulomb` effect.
#[derive(Debug, Clone, Copy)]
pub struct Coulomb;

const PARAMS: [ParamSpec; 1] = [spec(
    "tau_sf",
    "N m",
    "Coulomb friction torque, load side",
    None,
    0.0,
    false,
)];

/// Coulomb friction tau_sf sign(omega_l) [N m], load side (eq. 8); sign(0) = 0.
///
/// While the shaft is stuck the friction is whatever holds it (up to the breakaway level); see
/// [`Friction::breakaway_l`].
#[inline]
pub fn torque_l(tau_sf: f64, omega_l: f64) -> f64 {
    tau_sf * math::sign(omega_l)
}

/// Coulomb direction: sign of the speed (sign(0) = 0), the regressor of tau_sf.
#[inline]
pub fn direction(omega: f64) -> f64 {
    torque_l(1.0, omega)
}

impl EffectModel for Coulomb {
    fn name(&self) -> &str {
        "coulomb"
    }
    fn description(&self) -> &str {
        "Coulomb friction tau_sf sign(omega_l) at load side (eq. 8)"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::LoadTorque
    }
    fn sim_role(&self) -> SimRole {
        SimRole::DryFriction
    }
    fn dry_friction(&self, v: &[f64], f: &mut Friction) {
        let c = v.first().copied().unwrap_or(0.0);
        f.tau_c_pos = c;
        f.tau_c_neg = c;
    }
    fn experiment(&self) -> &str {
        "run a friction staircase (constant speeds in both directions) and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Reversal, Regime::Standstill, Regime::ConstantSpeed]
    }
    fn suspect_phrase(&self) -> &str {
        "Coulomb friction"
    }
    fn compared(&self) -> &[&'static str] {
        &["tau_sf"]
    }
    fn speed_independent(&self) -> bool {
        true
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, _v: &[f64], _j: usize, x: &Sample) -> f64 {
        direction(x.omega_m_rad_s)
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from("sign(omega)")
    }
}
