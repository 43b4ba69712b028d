//! `delay`: transport delay of the driver input beyond the one-sample zero-order hold. The
//! simulator holds it in a fixed-size delay line; fractional delays are exact.

use super::{spec, ActsOn, EffectModel, NoEffectAt, ParamSpec, Regime, Sample, Search, SimRole};

/// The `delay` effect.
#[derive(Debug, Clone, Copy)]
pub struct Delay;

const PARAMS: [ParamSpec; 1] = [spec(
    "delay",
    "s",
    "input transport delay beyond the zero-order hold",
    None,
    0.0,
    true,
)];

impl EffectModel for Delay {
    fn name(&self) -> &str {
        "delay"
    }
    fn description(&self) -> &str {
        "transport delay of the input beyond the zero-order hold"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::Input
    }
    fn sim_role(&self) -> SimRole {
        SimRole::InputDelay
    }
    fn input_delay_s(&self, v: &[f64]) -> f64 {
        v.first().copied().unwrap_or(0.0)
    }
    fn search(&self, _key: &str) -> Search {
        Search {
            no_effect_at: NoEffectAt::First,
            ..Search::LINEAR
        }
    }
    #[cfg(feature = "alloc")]
    fn search_grid(&self, _key: &str, ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        let n = (libm::ceil(ctx.max_delay_s / (0.5 * ctx.dt_s)) as usize).clamp(2, 200);
        Some(crate::math::linspace(0.0, ctx.max_delay_s, n + 1))
    }
    fn schedule_rank(&self) -> u8 {
        5
    }
    fn experiment(&self) -> &str {
        "apply a fast voltage excitation (PRBS or chirp up to 100 Hz) and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Acceleration]
    }
    fn suspect_phrase(&self) -> &str {
        "delay"
    }
    fn compared(&self) -> &[&'static str] {
        &["delay"]
    }
    fn signature_len(&self) -> usize {
        1
    }
    fn signature(&self, _v: &[f64], _j: usize, x: &Sample) -> f64 {
        x.u_v - x.u_prev_v
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from("the rate of change of the command")
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
impl super::FitHooks for Delay {
    fn constraints(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        _cand: &crate::plant::Plant,
        _base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        use crate::verdict::{get, Check};
        let d = get(params, "delay").unwrap_or(f64::NAN);
        // The top of the search range is checked for every searched parameter by the
        // diagnosis (`diagnose::checks::search_bounds`).
        let max = ds.opts.max_delay_s;
        alloc::vec![Check {
            name: "delay > 0",
            passed: d > 0.0,
            detail: alloc::format!(
                "delay {:.2} ms, searched over 0-{:.1} ms (a best fit at zero is no delay)",
                1e3 * d,
                1e3 * max
            ),
        }]
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn compensated_by_a_lead_of_the_feedforward() {
        let (c, _) = crate::control::compensation::test_compensator("delay:delay=0.004");
        assert!((c.lead_s() - 0.004).abs() < 1e-15);
    }
}
