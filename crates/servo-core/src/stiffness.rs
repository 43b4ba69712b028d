//! The stiffness a model's angle-dependent torques add to the loop (issue #29: a design on the
//! identified model, verified with and without the compensation).
//!
//! A torque that depends on the angle alone (an unbalanced load's m g L sin(theta_l + phi), a
//! motor's detent torque) acts, linearised about an angle, like a spring: d tau / d theta. Referred to
//! the rotor it enters the mechanics of eqs. 9-10 as J_eq s^2 theta_m + B s theta_m +
//! k theta_m, so the reduced model of eq. 29 becomes k_m / (N (T_m s^2 + s + k T_m / J_eq)) and
//! the loop's crossover and phase margin move with the angle. A compensation that cancels the
//! torque at the measured angle takes the spring out of the loop; one that acts on the reference
//! (feedforward) leaves it in.
//!
//! This module finds the range of that stiffness over one load revolution; the margins of the
//! loop with a given stiffness are [`crate::design::verify::loop_with_stiffness`].

use crate::effects::{ActsOn, EffectKind, Signals, SimRole};
use crate::plant::Plant;

/// Angles sampled over one load revolution: enough for a motor-side ripple of up to 200
/// periods per load revolution (a 12-period detent ripple behind a 14:1 gear is 168) at 40 samples each.
pub const ANGLES_PER_REV: usize = 8192;

/// The range of the rotor-side stiffness of a model's angle-dependent torques over one load
/// revolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessRange {
    /// Smallest d tau / d theta_m at the rotor [N m/rad] (negative: a torque that pushes away
    /// from the angle, an unbalanced load above its pivot).
    pub min_nm_per_rad: f64,
    /// Load angle where the smallest is found [rad].
    pub min_at_load_rad: f64,
    /// Largest d tau / d theta_m at the rotor [N m/rad].
    pub max_nm_per_rad: f64,
    /// Load angle where the largest is found [rad].
    pub max_at_load_rad: f64,
}

impl StiffnessRange {
    /// No angle-dependent torque.
    pub const NONE: StiffnessRange = StiffnessRange {
        min_nm_per_rad: 0.0,
        min_at_load_rad: 0.0,
        max_nm_per_rad: 0.0,
        max_at_load_rad: 0.0,
    };
}

/// True when `kind` is a smooth torque set by its side's angle alone (what this module
/// linearises).
pub fn angle_torque(kind: EffectKind) -> bool {
    let m = kind.model();
    kind.sim_role() == SimRole::Smooth
        && m.depends_on_angle_only()
        && matches!(kind.acts_on(), ActsOn::LoadTorque | ActsOn::MotorTorque)
}

/// The range over one load revolution of the rotor-side stiffness of the angle-dependent torques
/// of `plant` for which `keep` is true (the others, e.g. those a compensation cancels, are left
/// out). `NONE` when no such torque is kept. User-defined effects are not included (their
/// expressions may depend on any signal).
pub fn stiffness_range(plant: &Plant, keep: &dyn Fn(EffectKind) -> bool) -> StiffnessRange {
    let n = plant.params.n;
    let kept = || {
        plant
            .effects
            .iter()
            .filter(|e| angle_torque(e.kind) && keep(e.kind))
    };
    if kept().next().is_none() || !(n.is_finite() && n > 0.0) {
        return StiffnessRange::NONE;
    }
    // The total resisting torque at the rotor as a function of the load angle:
    // g(theta_l) = tau_m(N theta_l) + tau_l(theta_l) / N; d tau / d theta_m = g'(theta_l) / N.
    let g = |theta_l: f64| -> f64 {
        let s = Signals {
            t_s: 0.0,
            theta_l_rad: theta_l,
            theta_m_rad: n * theta_l,
            omega_l_rad_s: 0.0,
            omega_m_rad_s: 0.0,
            i_a_a: 0.0,
            u_v: 0.0,
        };
        kept()
            .map(|e| {
                let t = e.kind.model().torque_nm(e.values(), &s);
                match e.kind.acts_on() {
                    ActsOn::LoadTorque => t / n,
                    _ => t,
                }
            })
            .sum()
    };
    let step_rad = core::f64::consts::TAU / ANGLES_PER_REV as f64;
    // Central differences on a fifth of the grid step (the ripple's period is >= 40 steps).
    let h = 0.2 * step_rad;
    let mut out = StiffnessRange {
        min_nm_per_rad: f64::INFINITY,
        min_at_load_rad: 0.0,
        max_nm_per_rad: f64::NEG_INFINITY,
        max_at_load_rad: 0.0,
    };
    for i in 0..ANGLES_PER_REV {
        let th = i as f64 * step_rad;
        let k = (g(th + h) - g(th - h)) / (2.0 * h) / n;
        if !k.is_finite() {
            continue;
        }
        if k < out.min_nm_per_rad {
            out.min_nm_per_rad = k;
            out.min_at_load_rad = th;
        }
        if k > out.max_nm_per_rad {
            out.max_nm_per_rad = k;
            out.max_at_load_rad = th;
        }
    }
    if out.min_nm_per_rad.is_finite() {
        out
    } else {
        StiffnessRange::NONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effect;

    #[test]
    fn an_unbalanced_load_is_a_spring_of_plus_minus_its_amplitude_over_n_squared() {
        // the catalogue's load-side angle torque: amplitude sin(theta_l + phase)
        let kind = EffectKind::registered()
            .find(|k| angle_torque(*k) && k.acts_on() == ActsOn::LoadTorque)
            .unwrap();
        let mut plant = Plant::lab();
        plant
            .effects
            .insert(Effect::new(kind, &[0.02, 0.3]).unwrap());
        let n = plant.params.n;
        let r = stiffness_range(&plant, &|_| true);
        let want = 0.02 / (n * n);
        assert!((r.max_nm_per_rad / want - 1.0).abs() < 1e-3, "{r:?}");
        assert!((r.min_nm_per_rad / -want - 1.0).abs() < 1e-3, "{r:?}");
        // the largest where cos(theta_l + phi) = 1: theta_l = -0.3 (mod 2 pi)
        let at = (r.max_at_load_rad + 0.3).rem_euclid(core::f64::consts::TAU);
        assert!(
            !(1e-3..=core::f64::consts::TAU - 1e-3).contains(&at),
            "{r:?}"
        );
        // left out (a compensation cancels it): nothing
        assert_eq!(
            stiffness_range(&plant, &|k| k != kind),
            StiffnessRange::NONE
        );
        // friction is no angle torque
        assert_eq!(
            stiffness_range(&Plant::lab(), &|_| true),
            StiffnessRange::NONE
        );
    }
}
