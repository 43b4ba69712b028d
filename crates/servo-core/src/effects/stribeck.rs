//! `stribeck`: stiction and Stribeck friction, load side: the shaft stays stuck until the
//! breakaway torque tau_s, and the friction level decays from tau_s to the Coulomb level above
//! the Stribeck speed omega_s:
//!
//! ```text
//! tau_fric(omega_l) = sign(omega_l) (tau_c + (tau_s - tau_c) exp(-(omega_l / omega_s)^2))
//! ```
//!
//! Needs `coulomb` (or `asymmetry`) in the model: tau_c is its level. The fit estimates the
//! excess tau_s - tau_sf by least squares at each omega_s of a logarithmic grid.

use super::torque::{Breakaway, Friction};
use super::{
    spec, ActsOn, CoefSign, EffectModel, ParamSpec, Regime, Sample, Search, SearchScale, SimRole,
    Span,
};

/// The `stribeck` effect.
#[derive(Debug, Clone, Copy)]
pub struct Stribeck;

const PARAMS: [ParamSpec; 2] = [
    spec(
        "tau_s",
        "N m",
        "breakaway (static) friction torque, load side, > tau_sf",
        None,
        0.0,
        false,
    ),
    spec(
        "omega_s",
        "rad/s",
        "Stribeck speed, load side",
        Some(0.5),
        1e-6,
        true,
    ),
];

/// Stribeck shape exp(-(omega_l / omega_s)^2) [-]: 1 at rest, 0 well above the Stribeck speed.
///
/// `omega_l`, `omega_s` [rad/s], load side. The regressor of the excess (tau_s - tau_sf) is
/// `sign(omega_l) * shape(omega_l, omega_s)`. Exactly 0 beyond 6 omega_s (where the exponential
/// is below 2.4e-16).
#[inline]
pub fn shape(omega_l: f64, omega_s: f64) -> f64 {
    let r = omega_l / omega_s;
    let r2 = r * r;
    if r2 > 36.0 {
        0.0
    } else {
        crate::math::exp(-r2)
    }
}

/// Kinetic friction level of Coulomb + Stribeck [N m] (magnitude, load side) at speed `omega_l`:
/// tau_c + (tau_s - tau_c) exp(-(omega_l / omega_s)^2).
#[inline]
pub fn level_l(tau_c: f64, tau_s: f64, omega_s: f64, omega_l: f64) -> f64 {
    tau_c + (tau_s - tau_c) * shape(omega_l, omega_s)
}

/// The low-speed excess regressor at motor speed `omega_m` [rad/s]: sign(omega) times the
/// decay at omega_m / n.
#[inline]
fn excess(omega_m: f64, n: f64, omega_s: f64) -> f64 {
    super::coulomb::direction(omega_m) * shape(omega_m / n, omega_s)
}

impl EffectModel for Stribeck {
    fn name(&self) -> &str {
        "stribeck"
    }
    fn description(&self) -> &str {
        "stiction and Stribeck friction: stuck until the breakaway torque tau_s, decaying to tau_sf above omega_s"
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
        if let (Some(&tau_s), Some(&omega_s)) = (v.first(), v.get(1)) {
            f.breakaway = Some(Breakaway {
                tau_s,
                omega_s,
                level: level_l,
            });
        }
    }
    fn search(&self, _key: &str) -> Search {
        Search {
            scale: SearchScale::Log,
            ..Search::LINEAR
        }
    }
    #[cfg(feature = "alloc")]
    fn search_grid(&self, _key: &str, ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        let wl = ctx.omega_l_max_rad_s.max(1e-3);
        Some(crate::math::logspace(wl * 2e-3, wl * 0.5, 24))
    }
    fn polish(&self) -> &[(&'static str, Span)] {
        &[("tau_s", Span::Scale(1.2)), ("omega_s", Span::Scale(1.5))]
    }
    fn linear_coefs(&self) -> usize {
        1
    }
    fn coef_sign(&self, _j: usize) -> CoefSign {
        CoefSign::NonNegative
    }
    fn regressor(&self, v: &[f64], _j: usize, x: &Sample) -> f64 {
        excess(x.omega_m_rad_s, x.n, v[1]) / x.n
    }
    fn coef_from_values(&self, v: &[f64], _j: usize, tau_sf: f64) -> f64 {
        v[0] - tau_sf
    }
    fn values_from_coefs(&self, c: &[f64], v: &mut [f64], tau_sf: f64) {
        v[0] = tau_sf + c.first().copied().unwrap_or(0.0).max(0.0);
    }
    fn std_err(&self, key: &str, se: &[f64], _coefs: &[f64]) -> Option<f64> {
        (key == "tau_s").then(|| se.first().copied()).flatten()
    }
    fn schedule_rank(&self) -> u8 {
        2
    }
    fn experiment(&self) -> &str {
        "run slow speed ramps through zero (below 1 rad/s at the load) and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Reversal, Regime::Standstill]
    }
    fn suspect_phrase(&self) -> &str {
        "stiction (Stribeck friction)"
    }
    fn compared(&self) -> &[&'static str] {
        &["tau_s"]
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, v: &[f64], _j: usize, x: &Sample) -> f64 {
        excess(x.omega_m_rad_s, x.n, v[1])
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from(
            "the low-speed friction excess sign(omega) exp(-(omega_l/omega_s)^2)",
        )
    }
    fn applicable(&self, has: &dyn Fn(&str) -> bool) -> bool {
        // Stribeck decays to the Coulomb level: it needs Coulomb friction in the model.
        has("coulomb")
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
impl super::FitHooks for Stribeck {
    fn constraints(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        cand: &crate::plant::Plant,
        base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        use crate::verdict::{get, Check};
        let mut out = alloc::vec::Vec::new();
        let (ts, tf) = (get(params, "tau_s").unwrap_or(f64::NAN), cand.tau_sf());
        out.push(Check {
            name: "tau_s > tau_sf",
            passed: ts > 1.05 * tf,
            detail: alloc::format!(
                "breakaway torque tau_s = {ts:.4} N m against the Coulomb level tau_sf = {tf:.4} N m: Stribeck friction decays from a breakaway above the Coulomb level (needs tau_s > 1.05 tau_sf); a best fit below it is a friction rising with speed, not Stribeck"
            ),
        });
        out.push(Check {
            name: "tau_sf off its bound",
            passed: tf > 0.1 * base.tau_sf().max(1e-12),
            detail: alloc::format!(
                "with it the Coulomb level falls to {tf:.4} N m from {:.4} N m without it (needs more than 10 % of it: a friction level pinned at zero is a curve of another shape, not Stribeck on top of Coulomb)",
                base.tau_sf()
            ),
        });
        let ws = get(params, "omega_s").unwrap_or(f64::NAN);
        let wl = ds
            .recs
            .iter()
            .flat_map(|r| r.omega_f.iter())
            .fold(0.0f64, |m, w| m.max(w.abs()))
            / ds.gear_ratio;
        out.push(Check {
            name: "omega_s inside the speeds reached",
            passed: ws < 0.45 * wl,
            detail: alloc::format!(
                "Stribeck speed omega_s = {ws:.3} rad/s against the largest load speed {wl:.2} rad/s (needs omega_s < 45 % of it: a decay over the whole speed range is a friction curve of another shape)"
            ),
        });
        out
    }
}

#[cfg(test)]
mod tests {

    /// The compensator uses the whole curve: the breakaway at low speed, the Coulomb level far
    /// above omega_s, odd in speed.
    #[test]
    fn compensated_by_the_friction_curve() {
        let (c, _) = crate::control::compensation::test_compensator("stribeck:tau_s=0.02,omega_s=0.5");
        assert!(c.has_friction_curve());
        let slow = c.friction_v(0.01, f64::NAN).unwrap();
        let fast = c.friction_v(50.0, f64::NAN).unwrap();
        assert!(slow > fast && fast > 0.0, "{slow} {fast}");
        assert!((c.friction_v(-50.0, f64::NAN).unwrap() + fast).abs() < 1e-12);
        // The level at the measured speed: a stuck shaft (0 rad/s) gets the breakaway while
        // the reference moves fast; a shaft moving against the reference gets the reference's.
        let stuck = c.friction_v(50.0, 0.0).unwrap();
        assert!(stuck > fast && stuck == c.friction_v(1e-9, 0.0).unwrap());
        assert_eq!(c.friction_v(50.0, -3.0).unwrap(), fast);
    }
    use crate::effects::torque::Friction;
    use crate::effects::{Effect, EffectKind, Effects};

    #[test]
    fn friction_levels_by_hand() {
        let mut e = Effects::NONE;
        e.insert(Effect::new(EffectKind::Coulomb, &[0.01]).unwrap());
        let f = Friction::from_effects(&e);
        assert_eq!(f.torque_l(2.0, 0.0), 0.01);
        assert_eq!(f.torque_l(-2.0, 0.0), -0.01);
        assert_eq!(f.torque_l(0.0, -1.0), -0.01);
        assert_eq!(f.breakaway_l(1.0), 0.01);
        e.insert(Effect::new(EffectKind::Stribeck, &[0.03, 0.5]).unwrap());
        let f = Friction::from_effects(&e);
        assert_eq!(f.breakaway_l(-1.0), 0.03);
        // At omega_s: 0.01 + 0.02 / e.
        assert!((f.torque_l(0.5, 0.0) - (0.01 + 0.02 * (-1.0f64).exp())).abs() < 1e-15);
        assert!((f.torque_l(-10.0, 0.0) + 0.01).abs() < 1e-12);
        e.insert(Effect::new(EffectKind::Asymmetry, &[0.01, 0.02]).unwrap());
        e.remove(EffectKind::Stribeck);
        let f = Friction::from_effects(&e);
        assert_eq!(f.torque_l(1.0, 0.0), 0.01);
        assert_eq!(f.torque_l(-1.0, 0.0), -0.02);
        assert_eq!(f.breakaway_l(-1.0), 0.02);
    }
}
