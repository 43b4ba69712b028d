//! `asymmetry`: direction-dependent Coulomb friction, load side: tau_sf_pos while omega_l > 0,
//! tau_sf_neg (magnitude) while omega_l < 0. It replaces `coulomb` in the model (the fit
//! estimates both levels in place of tau_sf, and sets tau_sf to their mean).

use super::torque::Friction;
use super::{spec, ActsOn, EffectModel, ParamSpec, Sample, SimRole};

/// The `asymmetry` effect.
#[derive(Debug, Clone, Copy)]
pub struct Asymmetry;

const PARAMS: [ParamSpec; 2] = [
    spec(
        "tau_sf_pos",
        "N m",
        "Coulomb friction for omega_l > 0, load side",
        None,
        0.0,
        false,
    ),
    spec(
        "tau_sf_neg",
        "N m",
        "Coulomb friction for omega_l < 0, load side (magnitude)",
        None,
        0.0,
        false,
    ),
];

/// Direction-dependent Coulomb friction [N m], load side: tau_sf_pos for omega_l > 0,
/// -tau_sf_neg for omega_l < 0, 0 at rest.
#[inline]
pub fn torque_l(tau_sf_pos: f64, tau_sf_neg: f64, omega_l: f64) -> f64 {
    if omega_l > 0.0 {
        tau_sf_pos
    } else if omega_l < 0.0 {
        -tau_sf_neg
    } else {
        0.0
    }
}

impl EffectModel for Asymmetry {
    fn name(&self) -> &str {
        "asymmetry"
    }
    fn description(&self) -> &str {
        "direction-dependent Coulomb friction (tau_sf_pos, tau_sf_neg)"
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
        // Replaces the Coulomb level (applied after `coulomb` in registry order).
        f.tau_c_pos = v.first().copied().unwrap_or(0.0);
        f.tau_c_neg = v.get(1).copied().unwrap_or(0.0);
    }
    fn experiment(&self) -> &str {
        "run the same constant-speed staircase in both directions and log the current"
    }
    fn compared(&self) -> &[&'static str] {
        &["tau_sf_pos", "tau_sf_neg"]
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, _v: &[f64], _j: usize, x: &Sample) -> f64 {
        if x.omega_m_rad_s > 0.0 {
            1.0
        } else {
            0.0
        }
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from("the direction of motion (omega > 0)")
    }
    fn applicable(&self, has: &dyn Fn(&str) -> bool) -> bool {
        // Asymmetry replaces Coulomb friction, which must be found first.
        has("coulomb")
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
impl super::FitHooks for Asymmetry {
    fn constraints(
        &self,
        _ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        _cand: &crate::plant::Plant,
        _base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        use crate::verdict::{get, Check};
        let (p, n) = (
            get(params, "tau_sf_pos").unwrap_or(f64::NAN),
            get(params, "tau_sf_neg").unwrap_or(f64::NAN),
        );
        alloc::vec![Check {
            name: "both Coulomb levels > 0",
            passed: p > 0.0 && n > 0.0,
            detail: alloc::format!("tau_sf_pos = {p:.4} N m, tau_sf_neg = {n:.4} N m"),
        }]
    }
}
