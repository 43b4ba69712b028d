//! The physics of every catalogue effect, in one place: torques versus speed and angle, and the
//! input nonlinearity u -> u_in.
//!
//! The simulator ([`crate::sim::PlantSim`]) evaluates exactly these functions, and the model fit
//! and the diagnosis use them as regressors, so truth and model cannot drift apart.
//!
//! Sign convention: every torque here is a *resisting* (load) torque, subtracted from the motor
//! torque k_t i_a in the torque balance, like tau_d in eq. 9:
//!
//! ```text
//! J_eq dw_m/dt = k_t i_a - B_eq w_m - tau_cog(theta_m) - (tau_fric(w_l) + tau_imb(theta_l)) / N
//! ```
//!
//! "Motor side" torques (`_m`) act on the rotor; "load side" torques (`_l`) act on the output
//! shaft and are seen at the motor as tau_l / N. Speeds and angles follow the same suffixes
//! (omega_l = omega_m / N without backlash).

use crate::effects::{EffectKind, Effects};
use crate::math;

/// Viscous friction torque B_eq omega_m [N m], motor side (`viscous`, eq. 9).
///
/// `b_eq` [N m s/rad], `omega_m` [rad/s].
#[inline]
pub fn viscous_torque_m(b_eq: f64, omega_m: f64) -> f64 {
    b_eq * omega_m
}

/// Coulomb friction tau_sf sign(omega_l) [N m], load side (`coulomb`, eq. 8); sign(0) = 0.
///
/// While the shaft is stuck the friction is whatever holds it (up to the breakaway level); see
/// [`Friction::breakaway_l`].
#[inline]
pub fn coulomb_torque_l(tau_sf: f64, omega_l: f64) -> f64 {
    tau_sf * math::sign(omega_l)
}

/// Stribeck shape exp(-(omega_l / omega_s)^2) [-]: 1 at rest, 0 well above the Stribeck speed.
///
/// `omega_l`, `omega_s` [rad/s], load side. The `stribeck` regressor for the excess
/// (tau_s - tau_sf) is `sign(omega_l) * stribeck_shape(omega_l, omega_s)`. Exactly 0 beyond
/// 6 omega_s (where the exponential is below 2.4e-16).
#[inline]
pub fn stribeck_shape(omega_l: f64, omega_s: f64) -> f64 {
    let r = omega_l / omega_s;
    let r2 = r * r;
    if r2 > 36.0 {
        0.0
    } else {
        math::exp(-r2)
    }
}

/// Kinetic friction level of Coulomb + Stribeck [N m] (magnitude, load side) at speed `omega_l`:
/// tau_c + (tau_s - tau_c) exp(-(omega_l / omega_s)^2).
///
/// `tau_c` is the Coulomb level for the direction of motion (tau_sf, or tau_sf_pos/tau_sf_neg
/// with `asymmetry`), `tau_s` the breakaway torque [N m], `omega_s` [rad/s].
#[inline]
pub fn stribeck_level_l(tau_c: f64, tau_s: f64, omega_s: f64, omega_l: f64) -> f64 {
    tau_c + (tau_s - tau_c) * stribeck_shape(omega_l, omega_s)
}

/// Direction-dependent Coulomb friction [N m], load side (`asymmetry`): tau_sf_pos for
/// omega_l > 0, -tau_sf_neg for omega_l < 0, 0 at rest.
#[inline]
pub fn asymmetry_torque_l(tau_sf_pos: f64, tau_sf_neg: f64, omega_l: f64) -> f64 {
    if omega_l > 0.0 {
        tau_sf_pos
    } else if omega_l < 0.0 {
        -tau_sf_neg
    } else {
        0.0
    }
}

/// Cogging torque [N m], motor side (`cogging`): amplitude sin(harmonic theta_m + phase).
///
/// `amplitude` [N m], `harmonic` [cycles per motor revolution], `phase` [rad], `theta_m` [rad].
/// Regressors for a fit at known harmonic: sin(harmonic theta_m) and cos(harmonic theta_m).
#[inline]
pub fn cogging_torque_m(amplitude: f64, harmonic: f64, phase: f64, theta_m: f64) -> f64 {
    amplitude * math::sin(harmonic * theta_m + phase)
}

/// Imbalance (eccentric mass) torque [N m], load side (`imbalance`): amplitude sin(theta_l +
/// phase). `amplitude` [N m], `phase` [rad], `theta_l` [rad].
#[inline]
pub fn imbalance_torque_l(amplitude: f64, phase: f64, theta_l: f64) -> f64 {
    amplitude * math::sin(theta_l + phase)
}

/// Backlash penetration [rad], load side: how far the motor side, reflected to the load
/// (theta_m / N), is past the edge of the play relative to the load angle. `delta_l = theta_m / N
/// - theta_l`; positive result: contact on the driving (+) flank, negative: on the (-) flank,
/// 0 inside the gap. `gap` [rad] is the total play.
#[inline]
pub fn backlash_penetration_l(gap: f64, delta_l: f64) -> f64 {
    let half = 0.5 * gap;
    if delta_l > half {
        delta_l - half
    } else if delta_l < -half {
        delta_l + half
    } else {
        0.0
    }
}

/// Backlash contact torque [N m] transmitted to the load (and -1/N of it to the motor): a
/// spring-damper that acts only in contact and never pulls the flanks together.
///
/// `gap` [rad], `stiffness` [N m/rad], `damping` [N m s/rad], `delta_l` = theta_m / N - theta_l
/// [rad], `delta_dot_l` its rate [rad/s].
#[inline]
pub fn backlash_torque_l(
    gap: f64,
    stiffness: f64,
    damping: f64,
    delta_l: f64,
    delta_dot_l: f64,
) -> f64 {
    let p = backlash_penetration_l(gap, delta_l);
    if p > 0.0 {
        (stiffness * p + damping * delta_dot_l).max(0.0)
    } else if p < 0.0 {
        (stiffness * p + damping * delta_dot_l).min(0.0)
    } else {
        0.0
    }
}

/// Dead zone on the driver input [V] (`deadzone`): 0 for |u| <= width, u - sign(u) width beyond.
#[inline]
pub fn deadzone_v(width: f64, u_v: f64) -> f64 {
    if u_v > width {
        u_v - width
    } else if u_v < -width {
        u_v + width
    } else {
        0.0
    }
}

/// Saturation of the driver input [V] (`saturation`): u clipped to [-limit, limit].
#[inline]
pub fn saturation_v(limit: f64, u_v: f64) -> f64 {
    if u_v > limit {
        limit
    } else if u_v < -limit {
        -limit
    } else {
        u_v
    }
}

/// The memoryless input nonlinearity of a plant: dead zone first, then saturation (so that
/// |u_in| <= limit always). Identity when neither effect is active. The `delay` is a memory
/// effect and lives in the simulator's delay line.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InputNonlinearity {
    /// Dead band half width [V], if `deadzone` is active.
    pub deadzone_width_v: Option<f64>,
    /// Symmetric limit [V], if `saturation` is active.
    pub saturation_limit_v: Option<f64>,
}

impl InputNonlinearity {
    /// From the active effects.
    pub fn from_effects(effects: &Effects) -> InputNonlinearity {
        InputNonlinearity {
            deadzone_width_v: effects.value(EffectKind::Deadzone, "width"),
            saturation_limit_v: effects.value(EffectKind::Saturation, "limit"),
        }
    }
    /// u -> u_in [V].
    #[inline]
    pub fn apply(&self, u_v: f64) -> f64 {
        let mut u = u_v;
        if let Some(w) = self.deadzone_width_v {
            u = deadzone_v(w, u);
        }
        if let Some(l) = self.saturation_limit_v {
            u = saturation_v(l, u);
        }
        u
    }
}

/// The dry (Coulomb + Stribeck + asymmetry) friction of a plant, load side.
///
/// * Coulomb level tau_c(dir): `asymmetry` (tau_sf_pos / tau_sf_neg) when active — it replaces
///   `coulomb` — else `coulomb` tau_sf, else 0.
/// * With `stribeck`: level tau_c + (tau_s - tau_c) exp(-(omega_l/omega_s)^2), breakaway tau_s.
///   Without: level and breakaway tau_c (Coulomb alone also has stiction at tau_sf).
///
/// Viscous friction is linear and separate ([`viscous_torque_m`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Friction {
    /// Coulomb level for omega_l > 0 [N m].
    pub tau_c_pos: f64,
    /// Coulomb level (magnitude) for omega_l < 0 [N m].
    pub tau_c_neg: f64,
    /// Stribeck breakaway torque tau_s [N m] and speed omega_s [rad/s], if active.
    pub stribeck: Option<(f64, f64)>,
}

impl Friction {
    /// From the active effects.
    pub fn from_effects(effects: &Effects) -> Friction {
        let (tau_c_pos, tau_c_neg) = match effects.get(EffectKind::Asymmetry) {
            Some(a) => (
                a.get("tau_sf_pos").unwrap_or(0.0),
                a.get("tau_sf_neg").unwrap_or(0.0),
            ),
            None => {
                let c = effects.value(EffectKind::Coulomb, "tau_sf").unwrap_or(0.0);
                (c, c)
            }
        };
        let stribeck = effects
            .get(EffectKind::Stribeck)
            .and_then(|s| Some((s.get("tau_s")?, s.get("omega_s")?)));
        Friction {
            tau_c_pos,
            tau_c_neg,
            stribeck,
        }
    }

    /// True when there is any dry friction (then the shaft can stick).
    pub fn is_active(&self) -> bool {
        self.tau_c_pos > 0.0 || self.tau_c_neg > 0.0 || self.stribeck.is_some_and(|(s, _)| s > 0.0)
    }

    /// Breakaway torque [N m], load side, for starting in direction `dir` (> 0 or < 0): the
    /// largest driving torque the stuck shaft withstands.
    #[inline]
    pub fn breakaway_l(&self, dir: f64) -> f64 {
        match self.stribeck {
            Some((tau_s, _)) => tau_s,
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
        let level = match self.stribeck {
            Some((tau_s, omega_s)) => stribeck_level_l(tau_c, tau_s, omega_s, omega_l),
            None => tau_c,
        };
        s * level
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effect;

    #[test]
    fn friction_levels_by_hand() {
        let mut e = Effects::NONE;
        e.insert(Effect::new(EffectKind::Coulomb, &[0.01]).unwrap());
        let f = Friction::from_effects(&e);
        assert_eq!(f.torque_l(2.0, 0.0), 0.01);
        assert_eq!(f.torque_l(-2.0, 0.0), -0.01);
        assert_eq!(f.torque_l(0.0, -1.0), -0.01);
        assert_eq!(f.breakaway_l(1.0), 0.01);
        e.insert(Effect::new(EffectKind::Stribeck, &[0.03, 0.5]).unwrap());
        let f = Friction::from_effects(&e);
        assert_eq!(f.breakaway_l(-1.0), 0.03);
        // At omega_s: 0.01 + 0.02 / e.
        assert!((f.torque_l(0.5, 0.0) - (0.01 + 0.02 * (-1.0f64).exp())).abs() < 1e-15);
        assert!((f.torque_l(-10.0, 0.0) + 0.01).abs() < 1e-12);
        e.insert(Effect::new(EffectKind::Asymmetry, &[0.01, 0.02]).unwrap());
        e.remove(EffectKind::Stribeck);
        let f = Friction::from_effects(&e);
        assert_eq!(f.torque_l(1.0, 0.0), 0.01);
        assert_eq!(f.torque_l(-1.0, 0.0), -0.02);
        assert_eq!(f.breakaway_l(-1.0), 0.02);
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

    #[test]
    fn periodic_and_contact_torques() {
        assert!(
            (cogging_torque_m(1e-3, 12.0, 0.0, core::f64::consts::PI / 24.0) - 1e-3).abs() < 1e-15
        );
        assert!((imbalance_torque_l(0.02, 0.5, 1.0) - 0.02 * 1.5f64.sin()).abs() < 1e-15);
        assert_eq!(backlash_penetration_l(0.04, 0.01), 0.0);
        assert!((backlash_penetration_l(0.04, 0.03) - 0.01).abs() < 1e-15);
        assert!((backlash_penetration_l(0.04, -0.03) + 0.01).abs() < 1e-15);
        assert!((backlash_torque_l(0.04, 20.0, 0.0, 0.03, 0.0) - 0.2).abs() < 1e-12);
        // Separating fast: the damper would pull, the contact does not.
        assert_eq!(backlash_torque_l(0.04, 20.0, 0.02, 0.021, -100.0), 0.0);
        assert_eq!(backlash_torque_l(0.04, 20.0, 0.02, 0.0, 5.0), 0.0);
    }
}
