//! `imbalance`: gravity torque of an eccentric load, periodic in the load angle:
//! amplitude sin(theta_l + phase), load side.
//!
//! Linear in (amplitude cos(phase), amplitude sin(phase)): the fit estimates the pair by least
//! squares (no search).

use super::periodic::{amplitude_phase, amplitude_std_err, phase_std_err, periodic_regressor};
use super::{spec, ActsOn, CoefSign, EffectModel, ParamSpec, Sample, Signals, SimRole, Span};
use crate::math;

/// The `imbalance` effect.
#[derive(Debug, Clone, Copy)]
pub struct Imbalance;

const PARAMS: [ParamSpec; 2] = [
    spec(
        "amplitude",
        "N m",
        "imbalance torque amplitude at the load",
        None,
        0.0,
        false,
    ),
    spec(
        "phase",
        "rad",
        "phase in load angle",
        Some(0.0),
        f64::NEG_INFINITY,
        false,
    ),
];

/// Imbalance (eccentric mass) torque [N m], load side: amplitude sin(theta_l + phase).
/// `amplitude` [N m], `phase` [rad], `theta_l` [rad].
#[inline]
pub fn torque_l(amplitude: f64, phase: f64, theta_l: f64) -> f64 {
    amplitude * math::sin(theta_l + phase)
}

impl EffectModel for Imbalance {
    fn name(&self) -> &str {
        "imbalance"
    }
    fn description(&self) -> &str {
        "gravity torque of an eccentric load, periodic in load angle"
    }
    fn params(&self) -> &[ParamSpec] {
        &PARAMS
    }
    fn acts_on(&self) -> ActsOn {
        ActsOn::LoadTorque
    }
    fn sim_role(&self) -> SimRole {
        SimRole::Smooth
    }
    fn torque_nm(&self, v: &[f64], s: &Signals) -> f64 {
        torque_l(v[0], v[1], s.theta_l_rad)
    }
    fn depends_on_angle_only(&self) -> bool {
        true
    }
    #[cfg(feature = "alloc")]
    fn angle_orders(&self, _ctx: &super::GridContext) -> Option<alloc::vec::Vec<f64>> {
        // m g L sin(theta_l + phi): once per load revolution.
        Some(alloc::vec![1.0])
    }
    fn dominant_load_candidate(&self) -> bool {
        true
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
    fn regressor(&self, _v: &[f64], j: usize, x: &Sample) -> f64 {
        let n = x.n;
        periodic_regressor(
            x.theta_m_rad / n,
            x.omega_m_rad_s / n,
            1.0,
            1.0 / n,
            x.filter_hz,
            j,
        )
    }
    fn coef_from_values(&self, v: &[f64], j: usize, _tau_sf: f64) -> f64 {
        if j == 0 {
            v[0] * math::cos(v[1])
        } else {
            v[0] * math::sin(v[1])
        }
    }
    fn values_from_coefs(&self, c: &[f64], v: &mut [f64], _tau_sf: f64) {
        (v[0], v[1]) = amplitude_phase(c);
    }
    fn std_err(&self, key: &str, se: &[f64], coefs: &[f64]) -> Option<f64> {
        match key {
            "amplitude" => Some(amplitude_std_err(se)),
            "phase" => phase_std_err(coefs, se),
            _ => None,
        }
    }
    fn schedule_rank(&self) -> u8 {
        4
    }
    fn experiment(&self) -> &str {
        "turn the load slowly over full revolutions in both directions and log the current"
    }
    fn compared(&self) -> &[&'static str] {
        &["amplitude"]
    }
    fn speed_independent(&self) -> bool {
        true
    }
    fn signature_len(&self) -> usize {
        2
    }
    fn signature(&self, _v: &[f64], j: usize, x: &Sample) -> f64 {
        let theta_l = x.theta_m_rad / x.n;
        let p = (
            torque_l(1.0, 0.0, theta_l),
            torque_l(1.0, core::f64::consts::FRAC_PI_2, theta_l),
        );
        if j == 0 {
            p.0
        } else {
            p.1
        }
    }
    #[cfg(feature = "alloc")]
    fn signature_name(&self, _v: &[f64]) -> alloc::string::String {
        alloc::string::String::from("sin/cos of the load angle")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The compensator cancels it at the measured angle, in volts through the motor.
    #[test]
    fn compensated_at_the_measured_angle() {
        use crate::control::{EffectCompensator, EffectSelect, RefSample, SmoothSign};
        let mut p = crate::plant::Plant::from_params(crate::params::PlantParams::TABLE2).unwrap();
        p.effects
            .insert(crate::effects::Effect::parse("imbalance:amplitude=0.05,phase=0.3").unwrap());
        let c = EffectCompensator::new(&p, EffectSelect::All, SmoothSign::default());
        let lp = p.linear_params();
        let vpn = lp.r_eq() / (lp.k_t * lp.k_drv);
        let r = RefSample {
            pos_rad: 0.0,
            vel_rad_s: 1.0,
            acc_rad_s2: 0.0,
        };
        let want = vpn * 0.05 * (1.2f64 + 0.3).sin() / lp.n;
        assert!((c.torque_v(&r, 0.0, 1.2) - want).abs() < 1e-12);
        let none = EffectCompensator::new(&p, EffectSelect::None, SmoothSign::default());
        assert_eq!(none.torque_v(&r, 0.0, 1.2), 0.0);
    }

    #[test]
    fn periodic_torque_by_hand() {
        assert!((torque_l(0.02, 0.5, 1.0) - 0.02 * 1.5f64.sin()).abs() < 1e-15);
    }
}
