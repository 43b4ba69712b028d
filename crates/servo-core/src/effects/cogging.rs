//! `cogging`: magnetic cogging torque of the motor, periodic in the motor angle:
//! amplitude sin(harmonic theta_m + phase), motor side.
//!
//! Linear in (amplitude cos(phase), amplitude sin(phase)) at a known harmonic: the fit searches
//! the harmonic over the integers 1..=max and estimates the pair by least squares.

use super::{
    spec, ActsOn, CoefSign, EffectModel, ParamSpec, Regime, Sample, Search, SearchScale, Signals,
    SimRole, Span,
};
use super::periodic::{
    amplitude_phase, amplitude_std_err, phase_std_err, pair, periodic_regressor, phasor_pow, taper,
};
use crate::math;

/// The `cogging` effect.
#[derive(Debug, Clone, Copy)]
pub struct Cogging;

const PARAMS: [ParamSpec; 3] = [
    spec(
        "amplitude",
        "N m",
        "cogging torque amplitude at the motor",
        None,
        0.0,
        false,
    ),
    spec(
        "harmonic",
        "1/rev",
        "cycles per motor revolution",
        None,
        1.0,
        true,
    ),
    spec(
        "phase",
        "rad",
        "phase in motor angle",
        Some(0.0),
        f64::NEG_INFINITY,
        false,
    ),
];

/// Cogging torque [N m], motor side: amplitude sin(harmonic theta_m + phase).
///
/// `amplitude` [N m], `harmonic` [cycles per motor revolution], `phase` [rad], `theta_m` [rad].
#[inline]
pub fn torque_m(amplitude: f64, harmonic: f64, phase: f64, theta_m: f64) -> f64 {
    amplitude * math::sin(harmonic * theta_m + phase)
}

impl EffectModel for Cogging {
    fn name(&self) -> &str {
        "cogging"
    }
    fn description(&self) -> &str {
        "magnetic cogging torque periodic in motor angle"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::MotorTorque
    }
    fn sim_role(&self) -> SimRole {
        SimRole::Smooth
    }
    fn torque_nm(&self, v: &[f64], s: &Signals) -> f64 {
        torque_m(v[0], v[1], v[2], s.theta_m_rad)
    }
    fn depends_on_angle_only(&self) -> bool {
        true
    }
    #[cfg(feature = "alloc")]
    fn angle_orders(&self, ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        self.search_grid("harmonic", ctx)
    }
    fn schedule_rank(&self) -> u8 {
        // Its harmonic's search over every order is the longest fit on real logs (1.3 s of a
        // 2 x 30 s diagnosis, the others 0.1-0.5 s): started first, it ends with the rest.
        0
    }
    fn search(&self, _key: &str) -> Search {
        Search {
            scale: SearchScale::Integer,
            ..Search::LINEAR
        }
    }
    #[cfg(feature = "alloc")]
    fn search_grid(&self, _key: &str, ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        Some((1..=ctx.max_harmonic.max(1)).map(f64::from).collect())
    }
    fn polish(&self) -> &[(&'static str, Span)] {
        &[("phase", Span::Add(0.5))]
    }
    fn linear_coefs(&self) -> usize {
        2
    }
    fn coef_sign(&self, _j: usize) -> CoefSign {
        CoefSign::Free
    }
    fn regressor(&self, v: &[f64], j: usize, x: &Sample) -> f64 {
        periodic_regressor(x.theta_m_rad, x.omega_m_rad_s, v[1], 1.0, x.filter_hz, j)
    }
    fn regressors(&self, v: &[f64], x: &Sample, out: &mut [f64]) {
        // An integer harmonic from the motor phasor by complex powers (the harmonic scan
        // evaluates every harmonic up to 40), else [`periodic_regressor`].
        let h = v[1];
        let integer = (1.0..=64.0).contains(&h) && h == math::floor(h);
        if !integer {
            for (j, o) in out.iter_mut().enumerate() {
                *o = self.regressor(v, j, x);
            }
            return;
        }
        let taper = taper(x.omega_m_rad_s, h, x.filter_hz);
        let (sv, cv) = if taper == 0.0 {
            (0.0, 0.0)
        } else {
            let [c1, s1] = x.motor_phasor;
            let (sv, cv) = phasor_pow(c1, s1, h as u32);
            (sv * taper, cv * taper)
        };
        if let [a, b, ..] = out {
            (*a, *b) = (sv, cv);
        }
    }
    fn coef_from_values(&self, v: &[f64], j: usize, _tau_sf: f64) -> f64 {
        if j == 0 {
            v[0] * math::cos(v[2])
        } else {
            v[0] * math::sin(v[2])
        }
    }
    fn values_from_coefs(&self, c: &[f64], v: &mut [f64], _tau_sf: f64) {
        (v[0], v[2]) = amplitude_phase(c);
    }
    fn std_err(&self, key: &str, se: &[f64], coefs: &[f64]) -> Option<f64> {
        match key {
            "amplitude" => Some(amplitude_std_err(se)),
            "phase" => phase_std_err(coefs, se),
            _ => None,
        }
    }
    fn experiment(&self) -> &str {
        "turn the motor slowly at constant speed over several revolutions and log the current"
    }
    fn regimes(&self) -> &[Regime] {
        &[Regime::Standstill]
    }
    fn compared(&self) -> &[&'static str] {
        &["amplitude"]
    }
    fn signature_len(&self) -> usize {
        2
    }
    fn signature(&self, v: &[f64], j: usize, x: &Sample) -> f64 {
        let p = pair(x.theta_m_rad, v[1]);
        if j == 0 {
            p.0
        } else {
            p.1
        }
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, v: &[f64]) -> alloc::string::String {
        alloc::format!("sin/cos of {:.0} x motor angle", v[1])
    }
    #[cfg(feature = "alloc")]
    fn fit_hooks(&self) -> Option<&dyn super::FitHooks> {
        Some(self)
    }
}

#[cfg(feature = "alloc")]
impl super::FitHooks for Cogging {
    fn constraints(
        &self,
        ds: &crate::fit::Dataset,
        params: &[crate::fit::ParamEstimate],
        _cand: &crate::plant::Plant,
        _base: &crate::plant::Plant,
    ) -> alloc::vec::Vec<crate::verdict::Check> {
        use crate::verdict::{get, Check};
        let h = get(params, "harmonic").unwrap_or(f64::NAN);
        let max = f64::from(ds.opts.max_harmonic);
        alloc::vec![Check {
            name: "harmonic inside the search range",
            passed: h < max,
            detail: alloc::format!(
                "harmonic {h:.0} against the searched 1-{max:.0} cycles per motor revolution"
            ),
        }]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_torque_by_hand() {
        assert!((torque_m(1e-3, 12.0, 0.0, core::f64::consts::PI / 24.0) - 1e-3).abs() < 1e-15);
    }
}
