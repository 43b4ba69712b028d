//! `deadzone`: the driver ignores |u| below a threshold (a dead band of half width `width`):
//! u -> u_in = 0 for |u| <= width, u - sign(u) width beyond.

use super::{
    spec, ActsOn, EffectModel, NoEffectAt, ParamSpec, Regime, Sample, Search, SimRole,
};

/// The `deadzone` effect.
#[derive(Debug, Clone, Copy)]
pub struct Deadzone;

const PARAMS: [ParamSpec; 1] = [spec(
    "width",
    "V",
    "dead band half width on the driver input u",
    None,
    0.0,
    true,
)];

/// Dead band on the driver input [V]: 0 for |u| <= width, u - sign(u) width beyond.
#[inline]
pub fn input_v(width: f64, u_v: f64) -> f64 {
    if u_v > width {
        u_v - width
    } else if u_v < -width {
        u_v + width
    } else {
        0.0
    }
}

/// Inverse of the dead band [V]: the command that makes the driver see `u_in_v`,
/// u_in + width tanh(u_in / smooth) (exact, u_in + sign(u_in) width, once |u_in| is a few
/// `smooth_v` away from 0; continuous through 0 so that a resting loop does not chatter).
#[inline]
pub fn inverse_v(width: f64, u_in_v: f64, smooth_v: f64) -> f64 {
    if width <= 0.0 {
        return u_in_v;
    }
    u_in_v + width * crate::math::tanh(u_in_v / smooth_v.max(1e-9))
}

impl EffectModel for Deadzone {
    fn name(&self) -> &str {
        "deadzone"
    }
    fn description(&self) -> &str {
        "the driver ignores |u| below a threshold (dead band)"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::Input
    }
    fn sim_role(&self) -> SimRole {
        // Before any saturation.
        SimRole::InputMap { order: 10 }
    }
    fn input_v(&self, v: &[f64], u_v: f64) -> f64 {
        input_v(v[0], u_v)
    }
    fn compensation(&self) -> super::Compensation {
        super::Compensation::InputInverse
    }
    fn inverse_input_v(&self, v: &[f64], u_in_v: f64, smooth_v: f64) -> f64 {
        inverse_v(v[0], u_in_v, smooth_v)
    }
    fn search(&self, _key: &str) -> Search {
        Search {
            no_effect_at: NoEffectAt::First,
            ..Search::LINEAR
        }
    }
    #[cfg(feature = "alloc")]
    fn search_grid(&self, _key: &str, ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        let umax = ctx.u_max_v;
        Some(crate::math::linspace(0.0, (0.4 * umax).min(3.0), 31))
    }
    fn experiment(&self) -> &str {
        "apply slow voltage ramps through zero and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Standstill]
    }
    fn suspect_phrase(&self) -> &str {
        "a dead band of the driver"
    }
    fn compared(&self) -> &[&'static str] {
        &["width"]
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, v: &[f64], _j: usize, x: &Sample) -> f64 {
        x.u_v - input_v(v[0], x.u_v)
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from("the command inside the dead band")
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
impl super::FitHooks for Deadzone {
    fn constraints(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        _cand: &crate::plant::Plant,
        _base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        use crate::verdict::{get, u_resolution, Check};
        let w = get(params, "width").unwrap_or(f64::NAN);
        let res = u_resolution(ds);
        let floor = (2.0 * res).max(0.005 * ds.u_max_v);
        alloc::vec![Check {
            name: "width above the u resolution",
            passed: w > floor,
            detail: alloc::format!(
                "half width {w:.4} V against the commanded-u resolution {res:.2e} V (needs more than {floor:.2e} V: twice the resolution and 0.5 % of the largest |u|)"
            ),
        }]
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn compensated_by_the_inverse_on_the_command() {
        let (c, _) = crate::control::compensation::test_compensator("deadzone:width=0.4");
        assert!(c.inverts_input());
        let u = c.input_inverse_v(2.0);
        assert!((super::input_v(0.4, u) - 2.0).abs() < 1e-9);
    }
    use crate::effects::torque::InputNonlinearity;
    use crate::effects::{Effect, EffectKind, Effects};

    #[test]
    fn inverse_undoes_the_dead_band_away_from_zero() {
        for u in [-5.0, -1.2, 0.8, 3.0] {
            let c = super::inverse_v(0.5, u, 0.01);
            assert!((super::input_v(0.5, c) - u).abs() < 1e-9, "{u} -> {c}");
        }
        assert_eq!(super::inverse_v(0.5, 0.0, 0.01), 0.0);
        assert_eq!(super::inverse_v(0.0, 0.3, 0.01), 0.3);
    }

    #[test]
    fn input_nonlinearity_by_hand() {
        let mut e = Effects::NONE;
        assert_eq!(InputNonlinearity::from_effects(&e).apply(3.0), 3.0);
        e.insert(Effect::new(EffectKind::Deadzone, &[0.5]).unwrap());
        e.insert(Effect::new(EffectKind::Saturation, &[2.0]).unwrap());
        let n = InputNonlinearity::from_effects(&e);
        assert_eq!(n.apply(0.4), 0.0);
        assert_eq!(n.apply(-0.5), 0.0);
        assert_eq!(n.apply(1.5), 1.0);
        assert_eq!(n.apply(-1.5), -1.0);
        assert_eq!(n.apply(9.0), 2.0);
        assert_eq!(n.apply(-9.0), -2.0);
    }
}
