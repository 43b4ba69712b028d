//! The composite physics the simulator builds from several effects: the dry friction (Coulomb
//! level, breakaway and its decay, per direction) and the memoryless input map u -> u_in. Each
//! effect's own physics lives in its file (`effects/<name>.rs`); this module only combines them
//! through the [`EffectModel`] hooks, so it names no effect.
//!
//! Sign convention: every torque is a *resisting* (load) torque, subtracted from the motor
//! torque k_t i_a in the torque balance, like tau_d in eq. 9:
//!
//! ```text
//! J_eq dw_m/dt = k_t i_a - B_eq w_m - tau_motor_side(theta_m, ...) - tau_load_side(...) / N
//! ```
//!
//! "Motor side" torques (`_m`) act on the rotor; "load side" torques (`_l`) act on the output
//! shaft and are seen at the motor as tau_l / N. Speeds and angles follow the same suffixes
//! (omega_l = omega_m / N without play).

use crate::effects::{Effect, EffectModel, Effects, SimRole};
use crate::math;

/// Most memoryless input maps of one plant.
pub const MAX_INPUT_MAPS: usize = 8;

/// The memoryless input nonlinearity of a plant: every active effect of role
/// [`SimRole::InputMap`], in increasing order (the catalogue's dead band before its saturation,
/// so that |u_in| <= limit always). Identity when none is active. A delay is a memory effect and
/// lives in the simulator's delay line.
#[derive(Clone, Copy, Default)]
pub struct InputNonlinearity {
    maps: [Option<InputMap>; MAX_INPUT_MAPS],
}

/// One input map: the effect with its model and parameter count looked up once (the simulator
/// applies the maps every control period).
#[derive(Clone, Copy)]
struct InputMap {
    effect: Effect,
    model: &'static dyn EffectModel,
    len: usize,
}

impl core::fmt::Debug for InputNonlinearity {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list()
            .entries(self.maps.iter().flatten().map(|m| &m.effect))
            .finish()
    }
}

impl InputNonlinearity {
    /// From the active effects.
    pub fn from_effects(effects: &Effects) -> InputNonlinearity {
        let mut maps = [None; MAX_INPUT_MAPS];
        let mut n = 0;
        let order = |e: &Effect| match e.kind.sim_role() {
            SimRole::InputMap { order } => Some(order),
            _ => None,
        };
        for e in effects.iter().filter(|e| order(e).is_some()) {
            if n < MAX_INPUT_MAPS {
                maps[n] = Some(*e);
                n += 1;
            }
        }
        // Stable insertion sort by order (no heap).
        for i in 1..n {
            let mut j = i;
            while j > 0 && maps[j - 1].as_ref().and_then(order) > maps[j].as_ref().and_then(order) {
                maps.swap(j - 1, j);
                j -= 1;
            }
        }
        InputNonlinearity {
            maps: maps.map(|m| {
                m.map(|effect| InputMap {
                    effect,
                    model: effect.kind.model(),
                    len: effect.kind.params().len(),
                })
            }),
        }
    }
    /// True when no input map is active.
    pub fn is_identity(&self) -> bool {
        self.maps.iter().all(Option::is_none)
    }
    /// u -> u_in [V].
    #[inline]
    pub fn apply(&self, u_v: f64) -> f64 {
        let mut u = u_v;
        for m in self.maps.iter().flatten() {
            u = m.model.input_v(&m.effect.values[..m.len], u);
        }
        u
    }
}

/// A breakaway level and its decay with speed (stiction), load side.
#[derive(Debug, Clone, Copy)]
pub struct Breakaway {
    /// Breakaway torque tau_s [N m].
    pub tau_s: f64,
    /// Speed scale of the decay [rad/s].
    pub omega_s: f64,
    /// Kinetic level (magnitude) [N m] from (tau_c, tau_s, omega_s, omega_l): tau_s at rest,
    /// tau_c far above omega_s.
    pub level: fn(f64, f64, f64, f64) -> f64,
}

/// The dry friction of a plant, load side, from every active effect of role
/// [`SimRole::DryFriction`] ([`crate::effects::EffectModel::dry_friction`], in registry order).
///
/// * Coulomb level tau_c(dir): set by the Coulomb-type effects (a direction-dependent one
///   replaces the symmetric one), else 0.
/// * With a [`Breakaway`]: level from its decay, breakaway tau_s. Without: level and breakaway
///   tau_c (Coulomb alone also has stiction at tau_sf).
///
/// Viscous friction is linear and separate.
#[derive(Debug, Clone, Copy, Default)]
pub struct Friction {
    /// Coulomb level for omega_l > 0 [N m].
    pub tau_c_pos: f64,
    /// Coulomb level (magnitude) for omega_l < 0 [N m].
    pub tau_c_neg: f64,
    /// Breakaway torque and its decay, if active.
    pub breakaway: Option<Breakaway>,
}

impl Friction {
    /// From the active effects.
    pub fn from_effects(effects: &Effects) -> Friction {
        let mut f = Friction::default();
        for e in effects
            .iter()
            .filter(|e| e.kind.sim_role() == SimRole::DryFriction)
        {
            e.kind.model().dry_friction(e.values(), &mut f);
        }
        f
    }

    /// True when there is any dry friction (then the shaft can stick).
    pub fn is_active(&self) -> bool {
        self.tau_c_pos > 0.0
            || self.tau_c_neg > 0.0
            || self.breakaway.is_some_and(|b| b.tau_s > 0.0)
    }

    /// Breakaway torque [N m], load side, for starting in direction `dir` (> 0 or < 0): the
    /// largest driving torque the stuck shaft withstands.
    #[inline]
    pub fn breakaway_l(&self, dir: f64) -> f64 {
        match self.breakaway {
            Some(b) => b.tau_s,
            None => {
                if dir >= 0.0 {
                    self.tau_c_pos
                } else {
                    self.tau_c_neg
                }
            }
        }
    }

    /// Kinetic friction torque [N m], load side, signed (resisting): direction `dir` (+1/-1) is
    /// used when `omega_l` is exactly 0 (the shaft has just broken away in that direction).
    #[inline]
    pub fn torque_l(&self, omega_l: f64, dir: f64) -> f64 {
        let s = if omega_l > 0.0 {
            1.0
        } else if omega_l < 0.0 {
            -1.0
        } else {
            math::sign(dir)
        };
        let tau_c = if s >= 0.0 {
            self.tau_c_pos
        } else {
            self.tau_c_neg
        };
        let level = match self.breakaway {
            Some(b) => (b.level)(tau_c, b.tau_s, b.omega_s, omega_l),
            None => tau_c,
        };
        s * level
    }
}
