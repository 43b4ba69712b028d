//! The whole compensation of a position loop (issue #29): the handout's linear feedforward
//! ([`Feedforward`], eq. 54) plus the compensation of the model's identified effects
//! ([`EffectCompensator`]), ramped in and kept inside the drive's limit.
//!
//! Per control period, with the reference `r` read [`LoopCompensation::lead_s`] ahead (the
//! compensated delays) and the measured load angle theta_l:
//!
//! ```text
//! u_ff   = linear(r) + ramp(t) [effects_torque(r, theta_l) + dry_friction(r)]      [V]
//! v      = PID(e) + u_ff, clipped by the PID to +-pid_limit_v (its anti-windup sees it)
//! u      = v + ramp(t) [inverse(v) - v], clipped to +-min(u_limit, saturation bound)
//! ```
//!
//! * With a dry-friction curve selected (Coulomb, Stribeck, direction asymmetry), the curve
//!   replaces the linear feedforward's symmetric Coulomb term (never both).
//! * The PID's own limit is narrowed so that the inverted input map of its largest output stays
//!   inside the limit: the PID's anti-windup then acts on the bound the drive really has.
//! * ramp(t) = min(1, t / ramp_s) (1 at once with ramp_s = 0): a compensation can be ramped in
//!   on a machine where it has not run before.
//!
//! `no_std`, no heap, a fixed-size copy: the same value runs in the host's run loop and in the
//! board core ([`crate::board::BoardCore::set_compensation`]).

use super::compensation::{EffectCompensator, EffectSelect};
use super::feedforward::{Feedforward, FeedforwardConfig, FeedforwardParams};
use super::reference::RefSample;
use super::{check_non_negative, ControlError};
use crate::plant::Plant;

/// The parts of one compensation voltage [V].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompensationTerms {
    /// The linear feedforward (inertia, viscous, back-EMF, and Coulomb without a curve) [V].
    pub linear_v: f64,
    /// The effects' torques (imbalance, cogging, user torques) after the ramp [V].
    pub torque_v: f64,
    /// The dry-friction curve after the ramp [V] (0 without a curve).
    pub friction_v: f64,
    /// The sum added to the PID's output [V].
    pub total_v: f64,
}

/// The compensation a position loop adds: linear feedforward and effects.
#[derive(Debug, Clone, Copy)]
pub struct LoopCompensation {
    linear: Feedforward,
    effects: Option<EffectCompensator>,
    ramp_s: f64,
}

impl LoopCompensation {
    /// The linear feedforward alone (the `--ff inertia,friction,...` terms; no effect).
    pub fn linear(ff: Feedforward) -> LoopCompensation {
        LoopCompensation {
            linear: ff,
            effects: None,
            ramp_s: 0.0,
        }
    }

    /// The linear terms `linear` with the constants of `plant`, and the compensation of the
    /// effects of `plant` that `select` picks, ramped in over `ramp_s` [s] (>= 0; 0: at once).
    /// With a dry-friction curve among the selected effects, the linear Coulomb term is off.
    pub fn new(
        plant: &Plant,
        linear: FeedforwardConfig,
        select: EffectSelect,
        ramp_s: f64,
    ) -> Result<LoopCompensation, ControlError> {
        check_non_negative("ramp_s", "s", ramp_s)?;
        let effects = (!select.is_none())
            .then(|| EffectCompensator::new(plant, select, linear.sign))
            .filter(|c| c.is_active());
        let mut cfg = linear;
        if effects.is_some_and(|c| c.has_friction_curve()) {
            cfg.coulomb = false;
        }
        Ok(LoopCompensation {
            linear: Feedforward::new(FeedforwardParams::from_plant(plant), cfg)?,
            effects,
            ramp_s,
        })
    }

    /// The linear feedforward in use (its Coulomb term off under a friction curve).
    pub fn linear_part(&self) -> &Feedforward {
        &self.linear
    }

    /// The effects' compensator, if any effect is compensated.
    pub fn effects(&self) -> Option<&EffectCompensator> {
        self.effects.as_ref()
    }

    /// The ramp-in time [s] (0: at once).
    pub fn ramp_s(&self) -> f64 {
        self.ramp_s
    }

    /// How far ahead of the control time [s] the caller reads the reference for
    /// [`Self::feedforward`] (the compensated input delays; 0 without).
    pub fn lead_s(&self) -> f64 {
        self.effects.map_or(0.0, |c| c.lead_s())
    }

    #[inline]
    fn ramp(&self, t_s: f64) -> f64 {
        if self.ramp_s > 0.0 {
            (t_s / self.ramp_s).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// The compensation [V] at control time `t_s` [s] for the reference sample `r` (read
    /// [`Self::lead_s`] ahead), the measured load angle `theta_l_meas_rad` [rad] and speed
    /// `omega_l_meas_rad_s` [rad/s] (NaN when unknown: the reference's are used).
    #[inline]
    pub fn feedforward(
        &self,
        r: &RefSample,
        t_s: f64,
        theta_l_meas_rad: f64,
        omega_l_meas_rad_s: f64,
    ) -> CompensationTerms {
        let linear_v = self.linear.for_sample(r).total_v;
        let (mut torque_v, mut friction_v) = (0.0, 0.0);
        if let Some(c) = &self.effects {
            let k = self.ramp(t_s);
            torque_v = k * c.torque_v(r, t_s, theta_l_meas_rad);
            friction_v = k * c.friction_v(r.vel_rad_s, omega_l_meas_rad_s).unwrap_or(0.0);
        }
        CompensationTerms {
            linear_v,
            torque_v,
            friction_v,
            total_v: linear_v + torque_v + friction_v,
        }
    }

    /// The bound [V] of the command: `u_limit_v` narrowed by a compensated saturation.
    pub fn limit_v(&self, u_limit_v: f64) -> f64 {
        self.effects
            .map_or(u_limit_v, |c| u_limit_v.min(c.limit_v()))
    }

    /// The limit [V] the PID should clip to so that its output, through the inverted input
    /// maps, stays inside [`Self::limit_v`]: its anti-windup then acts on the drive's real
    /// bound. `u_limit_v` itself without an inverted map.
    pub fn pid_limit_v(&self, u_limit_v: f64) -> f64 {
        let bound = self.limit_v(u_limit_v);
        match &self.effects {
            Some(c) if c.inverts_input() && bound.is_finite() => {
                // The inverse is increasing and adds a bounded offset: the largest v with
                // inverse(v) <= bound, by bisection on [0, bound].
                let (mut lo, mut hi) = (0.0, bound);
                for _ in 0..48 {
                    let mid = 0.5 * (lo + hi);
                    if c.input_inverse_v(mid) <= bound {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                lo
            }
            _ => bound,
        }
    }

    /// The command [V] applied for the PID's (clipped) output `v_v` at time `t_s` [s]: the
    /// inverted input maps (ramped in) and the clip to +-[`Self::limit_v`].
    #[inline]
    pub fn command_v(&self, v_v: f64, t_s: f64, u_limit_v: f64) -> f64 {
        let bound = self.limit_v(u_limit_v);
        let u = match &self.effects {
            Some(c) if c.inverts_input() => v_v + self.ramp(t_s) * (c.input_inverse_v(v_v) - v_v),
            _ => v_v,
        };
        if u.is_finite() {
            u.clamp(-bound, bound)
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::SmoothSign;
    use crate::effects::Effect;
    use crate::params::PlantParams;

    fn plant(spec: &[&str]) -> Plant {
        let mut p = Plant::from_params(PlantParams {
            tau_sf: Some(0.01),
            ..PlantParams::TABLE2
        })
        .unwrap();
        for s in spec {
            p.effects.insert(Effect::parse(s).unwrap());
        }
        p
    }

    fn exact(cfg: FeedforwardConfig) -> FeedforwardConfig {
        FeedforwardConfig {
            sign: SmoothSign::Exact,
            ..cfg
        }
    }

    fn sample(pos: f64, vel: f64) -> RefSample {
        RefSample {
            pos_rad: pos,
            vel_rad_s: vel,
            acc_rad_s2: 0.0,
        }
    }

    #[test]
    fn without_effects_it_is_the_linear_feedforward() {
        let p = plant(&[]);
        let cfg = exact(FeedforwardConfig::FULL);
        let c = LoopCompensation::new(&p, cfg, EffectSelect::None, 0.0).unwrap();
        let ff = Feedforward::new(FeedforwardParams::from_plant(&p), cfg).unwrap();
        let r = sample(0.3, 2.0);
        assert_eq!(
            c.feedforward(&r, 0.0, 0.3, f64::NAN).total_v,
            ff.for_sample(&r).total_v
        );
        assert!(c.effects().is_none());
        assert_eq!(c.pid_limit_v(10.0), 10.0);
        assert_eq!(c.command_v(12.0, 0.0, 10.0), 10.0);
    }

    #[test]
    fn a_friction_curve_replaces_the_linear_coulomb_term() {
        // Stribeck: the curve's level at 0.5 rad/s is above tau_sf; the linear Coulomb is off.
        let p = plant(&["stribeck:tau_s=0.02,omega_s=0.5"]);
        let cfg = exact(FeedforwardConfig::FRICTION);
        let c = LoopCompensation::new(&p, cfg, EffectSelect::All, 0.0).unwrap();
        assert!(!c.linear_part().config().coulomb);
        let t = c.feedforward(&sample(0.0, 0.5), 1.0, 0.0, f64::NAN);
        let lin = LoopCompensation::new(&p, cfg, EffectSelect::None, 0.0).unwrap();
        let t0 = lin.feedforward(&sample(0.0, 0.5), 1.0, 0.0, f64::NAN);
        assert!(t.friction_v > 0.0 && t.friction_v > t0.total_v - t0.linear_v + 0.0);
        assert!(
            t.friction_v > t0.linear_v - t.linear_v,
            "curve {} V vs Coulomb {} V",
            t.friction_v,
            t0.linear_v - t.linear_v
        );
        // Odd in the speed.
        let m = c.feedforward(&sample(0.0, -0.5), 1.0, 0.0, f64::NAN);
        assert!((m.total_v + t.total_v).abs() < 1e-12);
    }

    #[test]
    fn the_ramp_scales_the_effects_not_the_linear_part() {
        let p = plant(&["imbalance:amplitude=0.02,phase=0"]);
        let cfg = exact(FeedforwardConfig::INERTIA);
        let c = LoopCompensation::new(&p, cfg, EffectSelect::All, 2.0).unwrap();
        let r = sample(1.0, 0.0);
        let full = c.feedforward(&r, 5.0, 1.0, 0.0);
        let half = c.feedforward(&r, 1.0, 1.0, 0.0);
        assert!(full.torque_v.abs() > 0.01, "{full:?}");
        assert!((half.torque_v - 0.5 * full.torque_v).abs() < 1e-12);
        assert_eq!(half.linear_v, full.linear_v);
        assert_eq!(c.feedforward(&r, 0.0, 1.0, 0.0).torque_v, 0.0);
        assert!(LoopCompensation::new(&p, cfg, EffectSelect::All, -1.0).is_err());
    }

    #[test]
    fn the_dead_band_inverse_stays_inside_the_limit() {
        let p = plant(&["deadzone:width=0.5"]);
        let c = LoopCompensation::new(&p, exact(FeedforwardConfig::OFF), EffectSelect::All, 0.0)
            .unwrap();
        let l = c.pid_limit_v(10.0);
        assert!((l - 9.5).abs() < 1e-6, "{l}");
        assert!(c.command_v(l, 1.0, 10.0) <= 10.0 + 1e-12);
        // Away from 0 the command adds the width.
        assert!((c.command_v(2.0, 1.0, 10.0) - 2.5).abs() < 1e-6);
        assert!((c.command_v(-2.0, 1.0, 10.0) + 2.5).abs() < 1e-6);
        assert_eq!(c.command_v(f64::NAN, 1.0, 10.0), 0.0);
    }

    #[test]
    fn a_compensated_saturation_narrows_the_limit() {
        let p = plant(&["saturation:limit=4.5"]);
        let c = LoopCompensation::new(&p, exact(FeedforwardConfig::OFF), EffectSelect::All, 0.0)
            .unwrap();
        assert!((c.limit_v(10.0) - 4.5).abs() < 1e-9, "{}", c.limit_v(10.0));
        assert!((c.command_v(8.0, 0.0, 10.0) - 4.5).abs() < 1e-9);
    }
}
