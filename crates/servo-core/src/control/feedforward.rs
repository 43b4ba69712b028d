//! Feedforward inertia and friction compensation (handout sec. 1 and 4, eqs. 9, 54; Lab 1).
//!
//! From the reference's load speed omega_l [rad/s] and acceleration a_l [rad/s^2], the motor
//! torque that the nominal model needs (eq. 54 with omega_m = N omega_l) is
//!
//! ```text
//! tau_m = J_eq N a_l + B_eq N omega_l + (tau_sf / N) sgn_s(omega_l)        [N m, motor side]
//! ```
//!
//! and the driver input that produces it at steady electrical state (eqs. 1, 5, 22; L_a and the
//! driver pole neglected) is
//!
//! ```text
//! u_ff = (R_eq tau_m / k_t + k_e N omega_l) / k_drv                         [V]
//! ```
//!
//! Each of the four parts can be switched on or off ([`FeedforwardConfig`]):
//! inertia (J_eq), viscous (B_eq), Coulomb (tau_sf, through a smoothed sign) and back-EMF (k_e).
//! The sign is smoothed near zero speed ([`SmoothSign`]) so that the compensation does not
//! chatter when the reference stops.

use super::reference::RefSample;
use super::{check_non_negative, check_positive, ControlError};
use crate::math;
use crate::params::PlantParams;
use crate::plant::Plant;

/// Constants of the compensator, named as in the handout (motor side unless stated).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FeedforwardParams {
    /// Total inertia at motor side J_eq [kg m^2].
    pub j_eq: f64,
    /// Total viscous friction at motor side B_eq [N m s/rad].
    pub b_eq: f64,
    /// Coulomb friction at load side tau_sf [N m].
    pub tau_sf: f64,
    /// Armature-circuit resistance R_eq = R_a + R_s [ohm].
    pub r_eq: f64,
    /// Torque constant k_t [N m/A].
    pub k_t: f64,
    /// BEMF constant k_e [V s/rad].
    pub k_e: f64,
    /// Driver gain k_drv [V/V].
    pub k_drv: f64,
    /// Gearbox ratio N [-].
    pub n: f64,
}

impl FeedforwardParams {
    /// From parameters: J_eq, B_eq, tau_sf as [`PlantParams`] derives them (identified values
    /// when set).
    pub fn from_params(p: &PlantParams) -> FeedforwardParams {
        FeedforwardParams {
            j_eq: p.j_eq(),
            b_eq: p.b_eq(),
            tau_sf: p.tau_sf(),
            r_eq: p.r_eq(),
            k_t: p.k_t,
            k_e: p.k_e,
            k_drv: p.k_drv,
            n: p.n,
        }
    }

    /// From a plant model: B_eq and tau_sf from its `viscous` and `coulomb` effects.
    pub fn from_plant(plant: &Plant) -> FeedforwardParams {
        Self::from_params(&plant.linear_params())
    }

    /// Checks signs and finiteness.
    pub fn validate(&self) -> Result<(), ControlError> {
        check_non_negative("j_eq", "kg m^2", self.j_eq)?;
        check_non_negative("b_eq", "N m s/rad", self.b_eq)?;
        check_non_negative("tau_sf", "N m", self.tau_sf)?;
        check_positive("r_eq", "ohm", self.r_eq)?;
        check_positive("k_t", "N m/A", self.k_t)?;
        check_non_negative("k_e", "V s/rad", self.k_e)?;
        check_positive("k_drv", "V/V", self.k_drv)?;
        check_positive("n", "-", self.n)?;
        Ok(())
    }
}

/// Smoothed sign of the load speed used for the Coulomb term.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum SmoothSign {
    /// The handout's sign (0 at 0): jumps by 2 when the reference reverses.
    Exact,
    /// tanh(omega_l / omega_eps): smooth, 0.76 at omega_eps.
    Tanh {
        /// Smoothing speed omega_eps at load side [rad/s] (> 0).
        omega_eps_rad_s: f64,
    },
    /// omega_l / omega_eps clipped to [-1, 1]: exact outside the band.
    Linear {
        /// Half width of the linear band at load side [rad/s] (> 0).
        omega_eps_rad_s: f64,
    },
}

impl Default for SmoothSign {
    /// tanh with omega_eps = 0.05 rad/s at the load (about 0.5 rpm).
    fn default() -> Self {
        SmoothSign::Tanh {
            omega_eps_rad_s: 0.05,
        }
    }
}

impl SmoothSign {
    /// The smoothed sign of `omega_rad_s`, in [-1, 1].
    #[inline]
    pub fn eval(&self, omega_rad_s: f64) -> f64 {
        match *self {
            SmoothSign::Exact => math::sign(omega_rad_s),
            SmoothSign::Tanh { omega_eps_rad_s } => math::tanh(omega_rad_s / omega_eps_rad_s),
            SmoothSign::Linear { omega_eps_rad_s } => {
                (omega_rad_s / omega_eps_rad_s).clamp(-1.0, 1.0)
            }
        }
    }
}

/// Which parts of the compensation are active.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FeedforwardConfig {
    /// Inertia term R_eq J_eq N a_l / (k_t k_drv).
    pub inertia: bool,
    /// Viscous friction term R_eq B_eq N omega_l / (k_t k_drv).
    pub viscous: bool,
    /// Coulomb friction term R_eq tau_sf sgn_s(omega_l) / (N k_t k_drv).
    pub coulomb: bool,
    /// Back-EMF term k_e N omega_l / k_drv (the voltage that sustains the speed).
    pub back_emf: bool,
    /// Smoothed sign for the Coulomb term.
    pub sign: SmoothSign,
}

impl Default for FeedforwardConfig {
    /// Everything on ([`FeedforwardConfig::FULL`]).
    fn default() -> Self {
        Self::FULL
    }
}

impl FeedforwardConfig {
    /// Inertia and friction compensation: the full inverse of the nominal model (all four terms).
    pub const FULL: FeedforwardConfig = FeedforwardConfig {
        inertia: true,
        viscous: true,
        coulomb: true,
        back_emf: true,
        sign: SmoothSign::Tanh {
            omega_eps_rad_s: 0.05,
        },
    };
    /// Inertia compensation only: the inverse of the frictionless linear model (inertia and
    /// back-EMF terms; eq. 30's T_m s + 1 with B_eq = 0).
    pub const INERTIA: FeedforwardConfig = FeedforwardConfig {
        inertia: true,
        viscous: false,
        coulomb: false,
        back_emf: true,
        sign: SmoothSign::Tanh {
            omega_eps_rad_s: 0.05,
        },
    };
    /// Friction compensation only (viscous and Coulomb torques).
    pub const FRICTION: FeedforwardConfig = FeedforwardConfig {
        inertia: false,
        viscous: true,
        coulomb: true,
        back_emf: false,
        sign: SmoothSign::Tanh {
            omega_eps_rad_s: 0.05,
        },
    };
    /// Nothing (u_ff = 0).
    pub const OFF: FeedforwardConfig = FeedforwardConfig {
        inertia: false,
        viscous: false,
        coulomb: false,
        back_emf: false,
        sign: SmoothSign::Exact,
    };
}

/// The parts of one feedforward voltage [V].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FeedforwardTerms {
    /// Inertia term [V].
    pub inertia_v: f64,
    /// Viscous friction term [V].
    pub viscous_v: f64,
    /// Coulomb friction term [V].
    pub coulomb_v: f64,
    /// Back-EMF term [V].
    pub back_emf_v: f64,
    /// Sum of the active terms [V].
    pub total_v: f64,
}

/// The compensator, with its gains precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feedforward {
    params: FeedforwardParams,
    cfg: FeedforwardConfig,
    /// [V/(rad/s^2)] on a_l.
    g_inertia: f64,
    /// [V/(rad/s)] on omega_l.
    g_viscous: f64,
    /// [V] times sgn_s(omega_l).
    g_coulomb: f64,
    /// [V/(rad/s)] on omega_l.
    g_back_emf: f64,
}

impl Feedforward {
    /// A compensator; fails if a constant or the smoothing speed is out of range.
    pub fn new(
        params: FeedforwardParams,
        cfg: FeedforwardConfig,
    ) -> Result<Feedforward, ControlError> {
        params.validate()?;
        match cfg.sign {
            SmoothSign::Exact => {}
            SmoothSign::Tanh { omega_eps_rad_s } | SmoothSign::Linear { omega_eps_rad_s } => {
                check_positive("omega_eps_rad_s", "rad/s", omega_eps_rad_s)?;
            }
        }
        let p = &params;
        let volts_per_nm = p.r_eq / (p.k_t * p.k_drv);
        let on = |b: bool| if b { 1.0 } else { 0.0 };
        Ok(Feedforward {
            params,
            cfg,
            g_inertia: on(cfg.inertia) * volts_per_nm * p.j_eq * p.n,
            g_viscous: on(cfg.viscous) * volts_per_nm * p.b_eq * p.n,
            g_coulomb: on(cfg.coulomb) * volts_per_nm * p.tau_sf / p.n,
            g_back_emf: on(cfg.back_emf) * p.k_e * p.n / p.k_drv,
        })
    }

    /// The constants in use.
    pub fn params(&self) -> &FeedforwardParams {
        &self.params
    }
    /// The active terms.
    pub fn config(&self) -> &FeedforwardConfig {
        &self.cfg
    }

    /// The feedforward voltage [V] and its parts for load speed `omega_l_rad_s` and acceleration
    /// `a_l_rad_s2` of the reference.
    #[inline]
    pub fn terms(&self, omega_l_rad_s: f64, a_l_rad_s2: f64) -> FeedforwardTerms {
        let inertia_v = self.g_inertia * a_l_rad_s2;
        let viscous_v = self.g_viscous * omega_l_rad_s;
        let coulomb_v = if self.g_coulomb != 0.0 {
            self.g_coulomb * self.cfg.sign.eval(omega_l_rad_s)
        } else {
            0.0
        };
        let back_emf_v = self.g_back_emf * omega_l_rad_s;
        FeedforwardTerms {
            inertia_v,
            viscous_v,
            coulomb_v,
            back_emf_v,
            total_v: inertia_v + viscous_v + coulomb_v + back_emf_v,
        }
    }

    /// The feedforward voltage [V] (sum of the active terms).
    #[inline]
    pub fn voltage(&self, omega_l_rad_s: f64, a_l_rad_s2: f64) -> f64 {
        self.terms(omega_l_rad_s, a_l_rad_s2).total_v
    }

    /// The feedforward terms for a reference sample (uses its speed and acceleration).
    #[inline]
    pub fn for_sample(&self, r: &RefSample) -> FeedforwardTerms {
        self.terms(r.vel_rad_s, r.acc_rad_s2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Table 2 with identified J_eq = 7e-7 kg m^2, B_eq = 1e-6 N m s/rad, tau_sf = 0.01 N m.
    fn params() -> PlantParams {
        PlantParams {
            j_eq: Some(7e-7),
            b_eq: Some(1e-6),
            tau_sf: Some(0.01),
            ..PlantParams::TABLE2
        }
    }

    #[test]
    fn terms_by_hand() {
        // R_eq/(k_t k_drv) = 3.1/(7.682e-3 * 0.6) = 672.5679 V/(N m). At omega_l = 2 rad/s,
        // a_l = 10 rad/s^2:
        //   inertia  672.5679 * 7e-7 * 14 * 10 = 0.0659117 V
        //   viscous  672.5679 * 1e-6 * 14 * 2  = 0.0188319 V
        //   Coulomb  672.5679 * 0.01 / 14      = 0.4804056 V (exact sign)
        //   back-EMF 7.68e-3 * 14 * 2 / 0.6   = 0.3584 V
        let cfg = FeedforwardConfig {
            sign: SmoothSign::Exact,
            ..FeedforwardConfig::FULL
        };
        let ff = Feedforward::new(FeedforwardParams::from_params(&params()), cfg).unwrap();
        let t = ff.terms(2.0, 10.0);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        assert!(close(t.inertia_v, 0.0659117), "{t:?}");
        assert!(close(t.viscous_v, 0.0188319), "{t:?}");
        assert!(close(t.coulomb_v, 0.4804056), "{t:?}");
        assert!(close(t.back_emf_v, 0.3584), "{t:?}");
        assert!(close(t.total_v, 0.0659117 + 0.0188319 + 0.4804056 + 0.3584));
        // Reversal: odd in speed and acceleration.
        let m = ff.terms(-2.0, -10.0);
        assert!(close(m.total_v, -t.total_v));
        // At rest with the exact sign: nothing.
        assert_eq!(ff.voltage(0.0, 0.0), 0.0);
        // Presets switch the terms.
        let p = FeedforwardParams::from_params(&params());
        let i = Feedforward::new(p, FeedforwardConfig::INERTIA)
            .unwrap()
            .terms(2.0, 10.0);
        assert!(close(i.total_v, 0.0659117 + 0.3584) && i.coulomb_v == 0.0 && i.viscous_v == 0.0);
        let f = Feedforward::new(
            p,
            FeedforwardConfig {
                sign: SmoothSign::Exact,
                ..FeedforwardConfig::FRICTION
            },
        )
        .unwrap()
        .terms(2.0, 10.0);
        assert!(
            close(f.total_v, 0.0188319 + 0.4804056) && f.inertia_v == 0.0 && f.back_emf_v == 0.0
        );
        assert_eq!(
            Feedforward::new(p, FeedforwardConfig::OFF)
                .unwrap()
                .voltage(2.0, 10.0),
            0.0
        );
    }

    #[test]
    fn smoothed_sign() {
        let tanh = SmoothSign::Tanh {
            omega_eps_rad_s: 0.05,
        };
        assert!((tanh.eval(0.025) - 0.46211715726000974).abs() < 1e-12); // tanh(0.5)
        assert_eq!(tanh.eval(0.0), 0.0);
        assert!((tanh.eval(1.0) - 1.0).abs() < 1e-12);
        let lin = SmoothSign::Linear {
            omega_eps_rad_s: 0.1,
        };
        assert!(
            (lin.eval(0.05) - 0.5).abs() < 1e-15 && lin.eval(0.3) == 1.0 && lin.eval(-0.3) == -1.0
        );
        assert_eq!(SmoothSign::Exact.eval(-1e-9), -1.0);
        // Coulomb part with tanh at omega_eps/2: 0.4804056 * tanh(0.5) = 0.2220037 V.
        let cfg = FeedforwardConfig {
            inertia: false,
            viscous: false,
            back_emf: false,
            ..FeedforwardConfig::FULL
        };
        let ff = Feedforward::new(FeedforwardParams::from_params(&params()), cfg).unwrap();
        assert!((ff.voltage(0.025, 0.0) - 0.2220037).abs() < 1e-6);
    }

    #[test]
    fn from_plant_reads_the_friction_effects_and_validates() {
        let plant = Plant::from_params(params()).unwrap();
        assert_eq!(
            FeedforwardParams::from_plant(&plant),
            FeedforwardParams::from_params(&params())
        );
        let bad = FeedforwardParams {
            k_t: 0.0,
            ..FeedforwardParams::from_params(&params())
        };
        assert!(matches!(
            Feedforward::new(bad, FeedforwardConfig::FULL),
            Err(ControlError::NotPositive { key: "k_t", .. })
        ));
        let p = FeedforwardParams::from_params(&params());
        let cfg = FeedforwardConfig {
            sign: SmoothSign::Tanh {
                omega_eps_rad_s: 0.0,
            },
            ..FeedforwardConfig::FULL
        };
        assert!(matches!(
            Feedforward::new(p, cfg),
            Err(ControlError::NotPositive {
                key: "omega_eps_rad_s",
                ..
            })
        ));
    }

    /// Open loop, feedforward only, on the simulator with the same friction: the steady load
    /// speed equals the reference speed (the compensation is the exact steady-state inverse).
    #[test]
    fn open_loop_feedforward_reaches_the_reference_speed_on_the_simulator() {
        let plant = Plant::from_params(params()).unwrap();
        let ff = Feedforward::new(
            FeedforwardParams::from_plant(&plant),
            FeedforwardConfig::FULL,
        )
        .unwrap();
        let mut sim = crate::sim::PlantSim::new(&plant, 1e-3).unwrap();
        let omega_ref = 2.0;
        let u = ff.voltage(omega_ref, 0.0);
        for _ in 0..1500 {
            sim.step(u);
        }
        let w = sim.state().omega_l_rad_s;
        assert!(
            (w - omega_ref).abs() < 0.01 * omega_ref,
            "steady load speed {w} rad/s for {omega_ref}"
        );
    }
}
