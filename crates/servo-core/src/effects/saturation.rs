//! `saturation`: the driver input u is clipped to +/- limit (symmetric), u -> u_in.

use super::{
    spec, ActsOn, EffectModel, NoEffectAt, ParamSpec, Regime, Sample, Search, SimRole,
};

/// The `saturation` effect.
#[derive(Debug, Clone, Copy)]
pub struct Saturation;

const PARAMS: [ParamSpec; 1] = [spec(
    "limit",
    "V",
    "symmetric limit on the driver input u",
    None,
    1e-9,
    true,
)];

/// Saturation of the driver input [V]: u clipped to [-limit, limit].
#[inline]
pub fn input_v(limit: f64, u_v: f64) -> f64 {
    if u_v > limit {
        limit
    } else if u_v < -limit {
        -limit
    } else {
        u_v
    }
}

impl EffectModel for Saturation {
    fn name(&self) -> &str {
        "saturation"
    }
    fn description(&self) -> &str {
        "the driver input u is clipped to +/- limit"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::Input
    }
    fn sim_role(&self) -> SimRole {
        // After any dead band, so that |u_in| <= limit always.
        SimRole::InputMap { order: 20 }
    }
    fn input_v(&self, v: &[f64], u_v: f64) -> f64 {
        input_v(v[0], u_v)
    }
    fn compensation(&self) -> super::Compensation {
        super::Compensation::Limit
    }
    fn search(&self, _key: &str) -> Search {
        Search {
            no_effect_at: NoEffectAt::Last,
            ..Search::LINEAR
        }
    }
    #[cfg(feature = "alloc")]
    fn search_grid(&self, _key: &str, ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        let umax = ctx.u_max_v;
        Some(crate::math::linspace(0.2 * umax, umax * 1.001, 33))
    }
    fn experiment(&self) -> &str {
        "apply steps large enough to drive the command to its limit"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::VoltageLimit]
    }
    fn suspect_phrase(&self) -> &str {
        "saturation of the driver"
    }
    fn compared(&self) -> &[&'static str] {
        &["limit"]
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, v: &[f64], _j: usize, x: &Sample) -> f64 {
        x.u_v - input_v(v[0], x.u_v)
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from("the command beyond the limit")
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
impl super::FitHooks for Saturation {
    fn constraints(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        _cand: &crate::plant::Plant,
        _base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        use crate::verdict::{get, Check};
        let l = get(params, "limit").unwrap_or(f64::NAN);
        let umax = ds.u_max_v;
        let beyond = ds
            .recs
            .iter()
            .filter(|r| r.has_u)
            .flat_map(|r| r.u_v.iter())
            .filter(|u| u.abs() > l)
            .count();
        let total: usize = ds
            .recs
            .iter()
            .filter(|r| r.has_u)
            .map(|r| r.u_v.len())
            .sum();
        alloc::vec![Check {
            name: "limit inside the |u| reached",
            passed: l < 0.97 * umax && beyond as f64 >= 0.002 * total as f64,
            detail: alloc::format!(
                "limit {l:.3} V against the largest commanded |u| {umax:.3} V with {:.2} % of the samples beyond it (needs the limit at least 3 % below the largest |u|, beyond the controller's own clip, and 0.2 % of the samples beyond it)",
                100.0 * beyond as f64 / total.max(1) as f64
            ),
        }]
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn compensated_by_narrowing_the_limit() {
        let (c, _) = crate::control::compensation::test_compensator("saturation:limit=6");
        assert_eq!(c.limit_v(), 6.0);
    }
}
