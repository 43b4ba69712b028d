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
//! * With a dry-friction curve selected (the dry-friction effects), the curve
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
    /// The effects' torques (position- and speed-dependent torques) after the ramp [V].
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

    /// Adds the compensation of the user-defined effects of `plant` whose name `keep` accepts
    /// ([`EffectCompensator::with_custom`]: torques on the reference state, input maps
    /// inverted), ramped in as the catalogue's.
    pub fn with_custom(mut self, plant: &Plant, keep: &dyn Fn(&str) -> bool) -> LoopCompensation {
        let sign = self.linear.config().sign;
        let base = self
            .effects
            .unwrap_or_else(|| EffectCompensator::new(plant, EffectSelect::None, sign));
        let c = base.with_custom(plant, keep);
        self.effects = c.is_active().then_some(c);
        self
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
