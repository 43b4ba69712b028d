//! The transmission between the motor and the load: a rotary gear (the handout), a lead screw or
//! a belt/rack, and where the encoder sits.
//!
//! The core keeps the handout's rotary equations throughout. A linear axis is described by an
//! *equivalent rotation* of its load shaft (the screw, the pulley or pinion), theta_l [rad], with
//! the gear ratio N between motor and that shaft (theta_m = N theta_l, handout eq. 1) and a
//! travel per radian s [m/rad]:
//!
//! * screw: x = theta_l lead / (2 pi), s = lead / (2 pi);
//! * belt or rack: x = r theta_l, s = r.
//!
//! A carriage mass m [kg] is then an inertia J = m s^2 at the load shaft, J = m s^2 / N^2 at the
//! motor (the handout's J_eq is motor side, eq. 10); a viscous coefficient b [N s/m] is
//! B = b s^2 / N^2 at the motor; a force F [N] is a torque F s at the load shaft (tau_sf is load
//! side, eq. 8). A screw's efficiency below one is a load-dependent friction and is not modelled
//! here: the Coulomb and viscous forces identified are what the motor sees.
//!
//! Conversions happen at the boundaries (log columns, model files, reports); [`Transmission`]
//! holds the factors.

use crate::effects::ActsOn;

/// The kind of transmission between the motor (after its gearbox N) and the load.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TransmissionKind {
    /// A rotary gear: the load turns, theta_l = theta_m / N (the handout).
    #[default]
    Gear,
    /// A lead screw: x = theta_l lead / (2 pi), `lead_m` the travel per screw revolution [m].
    Screw { lead_m: f64 },
    /// A belt pulley or a rack pinion: x = r theta_l, `radius_m` the pulley/pinion radius [m].
    Belt { radius_m: f64 },
}

/// Where the position encoder sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EncoderSide {
    /// At the load (the handout's SRV-02): the log holds theta_l (or x on a linear axis).
    #[default]
    Load,
    /// On the motor shaft: the log holds theta_m; the load position is inferred, theta_m / N
    /// (a play between them is invisible to this encoder).
    Motor,
    /// Both: the log holds theta_m and theta_l (or x).
    Both,
}

impl EncoderSide {
    /// The name in model files (`load`, `motor`, `both`).
    pub const fn name(self) -> &'static str {
        match self {
            EncoderSide::Load => "load",
            EncoderSide::Motor => "motor",
            EncoderSide::Both => "both",
        }
    }
}

/// Why a transmission was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TransmissionError {
    /// The lead or radius is missing, not finite or not positive.
    #[error("`{key}` must be a positive length in metres (got {value})")]
    BadLength { key: &'static str, value: f64 },
    /// The lead or radius is outside any sensible range (a unit slip, mm for m?).
    #[error("`{key}` = {value} m is outside the sensible range {min:e} .. {max:e} m (a length in mm given as m?)")]
    OutOfRange {
        key: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// The transmission of a rig: its kind and the encoder's place.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Transmission {
    pub kind: TransmissionKind,
    pub encoder: EncoderSide,
}

/// A value converted for display on a linear axis: the value and its unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linear {
    pub value: f64,
    pub unit: &'static str,
}

impl Transmission {
    /// The handout's rotary gear with a load-side encoder.
    pub const GEAR: Transmission = Transmission {
        kind: TransmissionKind::Gear,
        encoder: EncoderSide::Load,
    };

    /// The name in model files (`gear`, `screw`, `belt`).
    pub const fn kind_name(&self) -> &'static str {
        match self.kind {
            TransmissionKind::Gear => "gear",
            TransmissionKind::Screw { .. } => "screw",
            TransmissionKind::Belt { .. } => "belt",
        }
    }

    /// Checks the lead or radius (1 um .. 10 m).
    pub fn validate(&self) -> Result<(), TransmissionError> {
        let (key, value) = match self.kind {
            TransmissionKind::Gear => return Ok(()),
            TransmissionKind::Screw { lead_m } => ("lead_m", lead_m),
            TransmissionKind::Belt { radius_m } => ("radius_m", radius_m),
        };
        if !(value > 0.0 && value.is_finite()) {
            return Err(TransmissionError::BadLength { key, value });
        }
        let (min, max) = (1e-6, 10.0);
        if !(min..=max).contains(&value) {
            return Err(TransmissionError::OutOfRange {
                key,
                value,
                min,
                max,
            });
        }
        Ok(())
    }

    /// True for a screw or a belt/rack: the load moves in metres.
    pub const fn is_linear(&self) -> bool {
        !matches!(self.kind, TransmissionKind::Gear)
    }

    /// Load travel per radian of the load shaft s [m/rad] (lead / 2 pi or r); `None` for a gear.
    pub fn metres_per_rad(&self) -> Option<f64> {
        match self.kind {
            TransmissionKind::Gear => None,
            TransmissionKind::Screw { lead_m } => Some(lead_m / crate::math::TAU),
            TransmissionKind::Belt { radius_m } => Some(radius_m),
        }
    }

    /// The carriage mass [kg] of a motor-side inertia J_eq [kg m^2] with gear ratio `n`:
    /// m = J_eq N^2 / s^2 (`None` for a gear).
    pub fn mass_kg(&self, j_eq_kg_m2: f64, n: f64) -> Option<f64> {
        self.metres_per_rad().map(|s| j_eq_kg_m2 * n * n / (s * s))
    }

    /// The motor-side inertia J_eq = m s^2 / N^2 [kg m^2] of a mass `m_kg`.
    pub fn j_eq_of_mass(&self, m_kg: f64, n: f64) -> Option<f64> {
        self.metres_per_rad().map(|s| m_kg * s * s / (n * n))
    }

    /// The linear viscous coefficient b = B_eq N^2 / s^2 [N s/m] of a motor-side B_eq
    /// [N m s/rad].
    pub fn viscous_n_s_m(&self, b_eq_n_m_s_rad: f64, n: f64) -> Option<f64> {
        self.mass_kg(b_eq_n_m_s_rad, n)
    }

    /// The motor-side B_eq = b s^2 / N^2 [N m s/rad] of a linear viscous coefficient [N s/m].
    pub fn b_eq_of_viscous(&self, b_n_s_m: f64, n: f64) -> Option<f64> {
        self.j_eq_of_mass(b_n_s_m, n)
    }

    /// The force F = tau / s [N] of a load-side torque [N m].
    pub fn force_n(&self, tau_l_n_m: f64) -> Option<f64> {
        self.metres_per_rad().map(|s| tau_l_n_m / s)
    }

    /// The load-side torque tau = F s [N m] of a force [N].
    pub fn torque_of_force(&self, f_n: f64) -> Option<f64> {
        self.metres_per_rad().map(|s| f_n * s)
    }

    /// The load position x = s theta_l [m] of a load angle [rad].
    pub fn position_m(&self, theta_l_rad: f64) -> Option<f64> {
        self.metres_per_rad().map(|s| theta_l_rad * s)
    }

    /// An effect's parameter (`unit` as in the registry, acting where `acts_on` says) in linear
    /// units on a linear axis: a load-side torque as a force [N], a load-side stiffness
    /// [N m/rad] as [N/m], a load-side damping [N m s/rad] as [N s/m], a load angle or speed as
    /// [m] or [m/s]. `None` when the value stays as it is (a gear, a motor-side or input
    /// parameter, a phase, a ratio). A phase [rad] keeps its unit: it is an angle of the
    /// position's period, whatever the period's length.
    pub fn linear_param(
        &self,
        acts_on: ActsOn,
        key: &str,
        unit: &str,
        value: f64,
    ) -> Option<Linear> {
        let s = self.metres_per_rad()?;
        if acts_on != ActsOn::LoadTorque || key.contains("phase") {
            return None;
        }
        let (value, unit) = match unit {
            "N m" => (value / s, "N"),
            "N m/rad" => (value / (s * s), "N/m"),
            "N m s/rad" => (value / (s * s), "N s/m"),
            "rad" => (value * s, "m"),
            "rad/s" => (value * s, "m/s"),
            _ => return None,
        };
        Some(Linear { value, unit })
    }

    /// The linear key of an effect's parameter for JSON reports: the registry key with its
    /// linear unit as a suffix (`tau_sf_pos` -> `tau_sf_pos_n`, `omega_s` -> `omega_s_m_s`).
    pub fn linear_key(key: &str, unit: &str) -> alloc_free::Key {
        alloc_free::Key::new(key, unit)
    }
}

/// A suffixed key built without a heap (the crate's no-alloc build has this module too).
pub mod alloc_free {
    /// A parameter key with a unit suffix, at most 48 bytes.
    #[derive(Debug, Clone, Copy)]
    pub struct Key {
        buf: [u8; 48],
        len: usize,
    }

    impl Key {
        /// `key` + `_` + the unit's suffix (`N` -> `n`, `N/m` -> `n_m`, `N s/m` -> `n_s_m`,
        /// `m` -> `m`, `m/s` -> `m_s`); truncated at 48 bytes.
        pub fn new(key: &str, unit: &str) -> Key {
            let suffix = match unit {
                "N" => "n",
                "N/m" => "n_m",
                "N s/m" => "n_s_m",
                "m" => "m",
                "m/s" => "m_s",
                _ => "",
            };
            let mut k = Key {
                buf: [0; 48],
                len: 0,
            };
            for part in [key, if suffix.is_empty() { "" } else { "_" }, suffix] {
                for &b in part.as_bytes() {
                    if k.len < k.buf.len() {
                        k.buf[k.len] = b;
                        k.len += 1;
                    }
                }
            }
            k
        }
        /// The key.
        pub fn as_str(&self) -> &str {
            core::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn screw() -> Transmission {
        Transmission {
            kind: TransmissionKind::Screw { lead_m: 0.01 },
            encoder: EncoderSide::Motor,
        }
    }

    #[test]
    fn conversions_round_trip_and_follow_the_lead() {
        let t = screw();
        let s = 0.01 / crate::math::TAU;
        assert!((t.metres_per_rad().unwrap() - s).abs() < 1e-18);
        // 5 kg on a 10 mm lead screw behind a 2:1 belt: J = 5 s^2 / 4 at the motor.
        let j = t.j_eq_of_mass(5.0, 2.0).unwrap();
        assert!((j - 5.0 * s * s / 4.0).abs() < 1e-18);
        assert!((t.mass_kg(j, 2.0).unwrap() - 5.0).abs() < 1e-12);
        let b = t.b_eq_of_viscous(40.0, 1.0).unwrap();
        assert!((t.viscous_n_s_m(b, 1.0).unwrap() - 40.0).abs() < 1e-12);
        // 12 N of Coulomb friction is 12 s N m at the screw.
        assert!((t.torque_of_force(12.0).unwrap() - 12.0 * s).abs() < 1e-15);
        assert!((t.force_n(12.0 * s).unwrap() - 12.0).abs() < 1e-12);
        // One screw revolution is one lead.
        assert!((t.position_m(crate::math::TAU).unwrap() - 0.01).abs() < 1e-15);
        let belt = Transmission {
            kind: TransmissionKind::Belt { radius_m: 0.02 },
            ..Transmission::GEAR
        };
        assert!((belt.position_m(1.0).unwrap() - 0.02).abs() < 1e-15);
        assert_eq!(Transmission::GEAR.mass_kg(1.0, 1.0), None);
    }

    #[test]
    fn effect_parameters_in_linear_units() {
        let t = screw();
        let s = t.metres_per_rad().unwrap();
        let f = t
            .linear_param(ActsOn::LoadTorque, "tau_sf_pos", "N m", 3.0 * s)
            .unwrap();
        assert!((f.value - 3.0).abs() < 1e-12 && f.unit == "N");
        assert!(t
            .linear_param(ActsOn::LoadTorque, "phase", "rad", 1.0)
            .is_none());
        assert!(t
            .linear_param(ActsOn::MotorTorque, "amplitude", "N m", 1.0)
            .is_none());
        assert!(Transmission::GEAR
            .linear_param(ActsOn::LoadTorque, "tau_sf", "N m", 1.0)
            .is_none());
        assert_eq!(
            Transmission::linear_key("tau_sf_pos", "N").as_str(),
            "tau_sf_pos_n"
        );
        assert_eq!(
            Transmission::linear_key("omega_s", "m/s").as_str(),
            "omega_s_m_s"
        );
    }

    #[test]
    fn refuses_bad_lengths() {
        for lead_m in [0.0, -0.01, f64::NAN, 20.0, 1e-9] {
            let t = Transmission {
                kind: TransmissionKind::Screw { lead_m },
                ..Transmission::GEAR
            };
            assert!(t.validate().is_err(), "{lead_m}");
        }
        assert!(screw().validate().is_ok());
    }
}
