//! Compensation of the identified effects (issue #29): what `diagnose` found and `--add` fitted,
//! cancelled in the loop from the same model file.
//!
//! Each effect declares how it is compensated ([`EffectModel::compensation`], one method behind
//! the registry); this module only combines the declarations, so it names no effect:
//!
//! * a torque (an unbalanced load, a periodic motor torque, a user's torque expression) is evaluated on the
//!   reference state, at the measured angle when it depends on the angle only, and added to the
//!   motor torque demand: u = R_eq tau_m / (k_t k_drv) (eqs. 1, 5, 22, as the inertia and
//!   friction feedforward);
//! * dry friction (Coulomb, a breakaway and its decay, direction asymmetry) is the plant's friction curve at the
//!   reference speed with a smoothed sign, in place of the symmetric tau_sf term;
//! * an input map with an inverse (the dead band) is inverted on the whole command;
//! * a bound of the input (saturation) narrows the controller's limit ([`EffectCompensator::limit_v`]);
//! * a delay makes the feedforward read the reference ahead ([`EffectCompensator::lead_s`]);
//! * anything else (gear play) is not compensated, with the effect's reason
//!   ([`EffectCompensator::plan`]).
//!
//! `no_std`, no heap: the compensator is a fixed-size copy of the effects it needs, so the same
//! code can run in the board core.

use super::feedforward::SmoothSign;
use super::reference::RefSample;
use crate::custom::{ActsOn as CustomPlace, CustomSlots};
use crate::effects::torque::Friction;
use crate::effects::{ActsOn, AngleFrom, Compensation, Effect, EffectKind, Signals};
use crate::plant::Plant;

/// Most torque effects one compensator carries.
pub const MAX_COMPENSATED: usize = 8;
/// Most inverted input maps.
pub const MAX_INVERSES: usize = 4;

/// Which of a model's effects to compensate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum EffectSelect {
    /// None (the linear feedforward only).
    #[default]
    None,
    /// Every effect of the model that declares a compensation.
    All,
    /// The effects whose registry slots are set in the mask (bit k: slot k).
    Mask(u32),
}

impl EffectSelect {
    /// True when `kind` is selected.
    pub fn selects(&self, kind: EffectKind) -> bool {
        match *self {
            EffectSelect::None => false,
            EffectSelect::All => true,
            EffectSelect::Mask(m) => kind.slot() < 32 && m & (1u32 << kind.slot()) != 0,
        }
    }
    /// This selection with `kind` added.
    pub fn with(self, kind: EffectKind) -> EffectSelect {
        let bit = if kind.slot() < 32 {
            1u32 << kind.slot()
        } else {
            0
        };
        match self {
            EffectSelect::None => EffectSelect::Mask(bit),
            EffectSelect::All => EffectSelect::All,
            EffectSelect::Mask(m) => EffectSelect::Mask(m | bit),
        }
    }
    /// True when nothing is selected.
    pub fn is_none(&self) -> bool {
        matches!(self, EffectSelect::None | EffectSelect::Mask(0))
    }
}

/// The compensation of a model's selected effects, with its constants precomputed.
#[derive(Debug, Clone, Copy)]
pub struct EffectCompensator {
    torques: [Option<(Effect, AngleFrom)>; MAX_COMPENSATED],
    friction: Option<Friction>,
    inverses: [Option<Effect>; MAX_INVERSES],
    limit_v: f64,
    lead_s: f64,
    /// R_eq / (k_t k_drv) [V/(N m)], motor side.
    volts_per_nm: f64,
    /// Gear ratio N.
    n: f64,
    sign: SmoothSign,
    /// Smoothing of the inverse maps' sign [V].
    smooth_v: f64,
    /// The user-defined effects compensated: torques on the reference state, input maps
    /// inverted numerically ([`Self::with_custom`]).
    custom: CustomSlots,
}

impl EffectCompensator {
    /// The compensation of the effects of `plant` that `select` picks, the friction sign
    /// smoothed by `sign`. Effects that declare no compensation are skipped (see [`Self::plan`]);
    /// beyond [`MAX_COMPENSATED`] torques or [`MAX_INVERSES`] maps the rest are skipped too.
    pub fn new(plant: &Plant, select: EffectSelect, sign: SmoothSign) -> EffectCompensator {
        let p = plant.linear_params();
        let mut c = EffectCompensator {
            torques: [None; MAX_COMPENSATED],
            friction: None,
            inverses: [None; MAX_INVERSES],
            limit_v: f64::INFINITY,
            lead_s: 0.0,
            volts_per_nm: p.r_eq() / (p.k_t * p.k_drv),
            n: p.n,
            sign,
            smooth_v: 0.02,
            custom: CustomSlots::NONE,
        };
        let (mut nt, mut ni) = (0, 0);
        let mut dry = false;
        for e in plant.effects.iter().filter(|e| select.selects(e.kind)) {
            let model = e.kind.model();
            match model.compensation() {
                Compensation::Torque { angle } if nt < MAX_COMPENSATED => {
                    c.torques[nt] = Some((*e, angle));
                    nt += 1;
                }
                Compensation::DryFriction => dry = true,
                Compensation::InputInverse if ni < MAX_INVERSES => {
                    c.inverses[ni] = Some(*e);
                    ni += 1;
                }
                Compensation::Limit => {
                    // The bound the map puts on u: where a large command ends up.
                    let big = model.input_v(e.values(), 1e9);
                    if big.is_finite() && big > 0.0 {
                        c.limit_v = c.limit_v.min(big);
                    }
                }
                Compensation::Lead => c.lead_s += model.input_delay_s(e.values()).max(0.0),
                _ => {}
            }
        }
        if dry {
            // The whole curve: the selected shape on the model's Coulomb level.
            c.friction = Some(Friction::from_effects(&plant.effects));
        }
        c
    }

    /// Adds the user-defined effects of `plant` for which `keep` is true (by name) and that a
    /// compensation can cancel: a torque (load or motor side) is evaluated on the reference
    /// state (theta_l = r, omega_l = dr/dt, i_a = u = 0) and added to the torque demand; an input
    /// map is inverted numerically (as a function of u alone, assumed non-decreasing, the
    /// inverse smoothed over +-0.02 V around zero as the catalogue's dead band). A sensor map
    /// changes what is measured, not the motion: never compensated.
    pub fn with_custom(mut self, plant: &Plant, keep: &dyn Fn(&str) -> bool) -> EffectCompensator {
        for e in plant.custom.iter().filter(|e| keep(e.name())) {
            if matches!(
                e.def.acts_on(),
                CustomPlace::LoadTorque | CustomPlace::MotorTorque | CustomPlace::Input
            ) {
                // (at most MAX_CUSTOM: the plant's own bound)
                let _ = self.custom.insert(*e);
            }
        }
        self
    }

    /// True when a user-defined effect is compensated.
    pub fn has_custom(&self) -> bool {
        !self.custom.is_empty()
    }

    /// How each effect of `plant` is (or is not) compensated, in registry order.
    pub fn plan(plant: &Plant) -> impl Iterator<Item = (EffectKind, Compensation)> + '_ {
        plant
            .effects
            .iter()
            .map(|e| (e.kind, e.kind.model().compensation()))
    }

    /// True when anything is compensated (a torque, a friction curve, an inverted map, a
    /// limit or a lead).
    pub fn is_active(&self) -> bool {
        self.has_custom()
            || self.torques.iter().any(Option::is_some)
            || self.friction.is_some()
            || self.inverts_input()
            || self.limit_v.is_finite()
            || self.lead_s > 0.0
    }

    /// True when the dry-friction curve replaces the symmetric Coulomb term.
    pub fn has_friction_curve(&self) -> bool {
        self.friction.is_some()
    }

    /// The compensated torques [V] at reference `r`, time `t_s` [s] and measured load angle
    /// `theta_l_meas_rad` [rad] (used by the effects compensated at the measured angle).
    #[inline]
    pub fn torque_v(&self, r: &RefSample, t_s: f64, theta_l_meas_rad: f64) -> f64 {
        let mut tau_m = 0.0;
        for (e, angle) in self.torques.iter().flatten() {
            let theta_l = match angle {
                AngleFrom::Reference => r.pos_rad,
                AngleFrom::Measured if theta_l_meas_rad.is_finite() => theta_l_meas_rad,
                AngleFrom::Measured => r.pos_rad,
            };
            let s = Signals {
                t_s,
                theta_l_rad: theta_l,
                theta_m_rad: self.n * theta_l,
                omega_l_rad_s: r.vel_rad_s,
                omega_m_rad_s: self.n * r.vel_rad_s,
                i_a_a: 0.0,
                u_v: 0.0,
            };
            let tau = e.kind.model().torque_nm(e.values(), &s);
            tau_m += match e.kind.acts_on() {
                ActsOn::LoadTorque => tau / self.n,
                ActsOn::MotorTorque => tau,
                _ => 0.0,
            };
        }
        if self.custom.has(CustomPlace::LoadTorque) || self.custom.has(CustomPlace::MotorTorque) {
            // [theta_l, theta_m, omega_l, omega_m, i_a, u, t] on the reference
            let sig = [
                r.pos_rad,
                self.n * r.pos_rad,
                r.vel_rad_s,
                self.n * r.vel_rad_s,
                0.0,
                0.0,
                t_s,
            ];
            tau_m += self.custom.torque(CustomPlace::LoadTorque, &sig) / self.n
                + self.custom.torque(CustomPlace::MotorTorque, &sig);
        }
        if tau_m.is_finite() {
            self.volts_per_nm * tau_m
        } else {
            0.0
        }
    }

    /// The dry friction [V] for the reference load speed `omega_l_rad_s` and the measured one
    /// `omega_l_meas_rad_s` (NaN when unknown): the curve's level in the reference's direction
    /// times the smoothed sign of the reference speed. The level is read at the measured speed
    /// while the shaft is still or moves in the reference's direction (a stuck shaft needs the
    /// breakaway torque; a curve that falls with the speed, read at the reference speed would leave the
    /// plant's negative damping in the loop, a stick-slip cycle), at the reference speed
    /// otherwise. None without a friction curve.
    #[inline]
    pub fn friction_v(&self, omega_l_rad_s: f64, omega_l_meas_rad_s: f64) -> Option<f64> {
        let f = self.friction.as_ref()?;
        let dir = if omega_l_rad_s < 0.0 { -1.0 } else { 1.0 };
        let w = if omega_l_meas_rad_s.is_finite() && omega_l_meas_rad_s * dir >= 0.0 {
            omega_l_meas_rad_s
        } else {
            omega_l_rad_s
        };
        let level = f.torque_l(w, dir).abs();
        Some(self.volts_per_nm * level / self.n * self.sign.eval(omega_l_rad_s))
    }

    /// The command [V] that makes the plant's inverted input maps give `u_v` (identity without
    /// any).
    #[inline]
    pub fn input_inverse_v(&self, u_v: f64) -> f64 {
        // The plant applies the catalogue's maps, then the user's: invert the user's first.
        let mut u = if self.custom.has(CustomPlace::Input) {
            let s = self.smooth_v;
            if u_v.abs() >= s {
                self.custom_inverse_v(u_v)
            } else {
                // across zero, where a dead band's inverse jumps: the line between +-s
                let (a, b) = (self.custom_inverse_v(-s), self.custom_inverse_v(s));
                a + (b - a) * (u_v + s) / (2.0 * s)
            }
        } else {
            u_v
        };
        for e in self.inverses.iter().flatten() {
            u = e.kind.model().inverse_input_v(e.values(), u, self.smooth_v);
        }
        u
    }

    /// The user's input maps applied to `u_v` [V] (other signals at zero).
    fn custom_input_v(&self, u_v: f64) -> f64 {
        self.custom.input(&[0.0, 0.0, 0.0, 0.0, 0.0, u_v, 0.0])
    }

    /// The v with custom_input(v) = `y_v` [V], by bracketing and bisection (the map assumed
    /// non-decreasing); `y_v` itself when no bracket is found within +-1e6 V.
    fn custom_inverse_v(&self, y_v: f64) -> f64 {
        let f = |v: f64| self.custom_input_v(v);
        // the first of y_v + side {1, 2, 4, ...} V where `ok` holds (a NaN never does)
        let bracket = |side: f64, ok: &dyn Fn(f64) -> bool| -> Option<f64> {
            let mut width = 1.0;
            while width <= 1e6 {
                let v = y_v + side * width;
                if ok(f(v)) {
                    return Some(v);
                }
                width *= 2.0;
            }
            None
        };
        let (Some(mut lo), Some(mut hi)) =
            (bracket(-1.0, &|x| x <= y_v), bracket(1.0, &|x| x >= y_v))
        else {
            return y_v;
        };
        for _ in 0..52 {
            let mid = 0.5 * (lo + hi);
            if f(mid) < y_v {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// True when some input map is inverted.
    pub fn inverts_input(&self) -> bool {
        self.inverses.iter().any(Option::is_some) || self.custom.has(CustomPlace::Input)
    }

    /// The bound of the input a compensated saturation puts on the command [V] (infinite
    /// without one): the controller's limit should not exceed it.
    pub fn limit_v(&self) -> f64 {
        self.limit_v
    }

    /// How far ahead [s] the feedforward reads the reference (the compensated delays).
    pub fn lead_s(&self) -> f64 {
        self.lead_s
    }
}

/// The compensator of the default plant with a Coulomb level and the effect `spec`
/// (`name:key=value,...`), everything selected, exact sign: the effects' own tests use it.
#[cfg(test)]
pub(crate) fn test_compensator(spec: &str) -> (EffectCompensator, Plant) {
    let mut p = Plant::from_params(crate::params::PlantParams::TABLE2).unwrap();
    p.effects
        .insert(Effect::parse("coulomb:tau_sf=0.01").unwrap());
    p.effects.insert(Effect::parse(spec).unwrap());
    (
        EffectCompensator::new(&p, EffectSelect::All, SmoothSign::Exact),
        p,
    )
}
