//! Gearmotor parameters (handout Table 2) and the quantities derived from them.

use crate::math;

/// Why a parameter set was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// A parameter is not a finite number.
    #[error("parameter `{key}` must be a finite number, got {value}")]
    NotFinite { key: &'static str, value: f64 },
    /// A parameter that must be positive (resistance, inductance, inertia, constants, ratio) is not.
    #[error("parameter `{key}` must be > 0 ({unit}), got {}", math::Num(*.value))]
    NotPositive {
        key: &'static str,
        unit: &'static str,
        value: f64,
    },
    /// A parameter that must be non-negative (friction) is negative.
    #[error("parameter `{key}` must be >= 0 ({unit}), got {}", math::Num(*.value))]
    Negative {
        key: &'static str,
        unit: &'static str,
        value: f64,
    },
    /// A parameter lies outside any physically sensible range for a DC gearmotor (e.g. a
    /// torque constant of 1e308 N m/A, a typo or a unit slip); computations on it would overflow
    /// or never converge.
    #[error("parameter `{key}` = {} {unit} is outside the physically sensible range {min:e} .. {max:e} {unit} for a DC gearmotor (a typo or a unit slip?)", math::Num(*.value))]
    OutOfRange {
        key: &'static str,
        unit: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// Physically sensible ranges (generous: from micro motors to large industrial drives) of the
/// parameters, `(key, unit, min, max)`; a value outside is refused by [`PlantParams::validate`].
/// Zero is allowed where the key may be absent or zero (friction, optional inertias).
pub const SENSIBLE_RANGES: [(&str, &str, f64, f64); 16] = [
    ("r_a", "ohm", 1e-4, 1e4),
    ("l_a", "H", 1e-9, 10.0),
    ("k_e", "V s/rad", 1e-6, 100.0),
    ("k_t", "N m/A", 1e-6, 100.0),
    ("j_m", "kg m^2", 1e-13, 100.0),
    ("n", "-", 1e-2, 1e5),
    ("k_drv", "V/V", 1e-3, 1e3),
    ("f_c_drv", "Hz", 1e-2, 1e9),
    ("j_eq", "kg m^2", 1e-13, 1e4),
    ("j_72", "kg m^2", 0.0, 1e4),
    ("j_d", "kg m^2", 0.0, 1e4),
    ("b_m", "N m s/rad", 0.0, 1e3),
    ("b_l", "N m s/rad", 0.0, 1e5),
    ("r_s", "ohm", 0.0, 1e4),
    ("b_eq", "N m s/rad", 0.0, 1e3),
    ("tau_sf", "N m", 0.0, 1e5),
];

/// DC gearmotor parameters, named after the handout's Table 2. SI units throughout.
///
/// The derived quantities (R_eq, J_l, J_eq, B_eq, k_m, T_m) are methods, so they cannot go stale.
/// `j_eq`, `b_eq` and `tau_sf` are optional *identified overrides*: when set they replace the value
/// derived from the datasheet (J_eq, B_eq) or the default (tau_sf = 0).
///
/// Model files name the fields by these short keys; readers also accept the keys of servo's JSON
/// outputs, with the SI unit as a suffix (`b_eq_n_m_s_rad`, `r_a_ohm`; docs/schemas/README.md).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct PlantParams {
    /// Armature resistance R_a [ohm].
    #[cfg_attr(feature = "serde", serde(alias = "r_a_ohm"))]
    pub r_a: f64,
    /// Armature inductance L_a [H].
    #[cfg_attr(feature = "serde", serde(alias = "l_a_h"))]
    pub l_a: f64,
    /// Electric (BEMF) constant k_e [V s/rad].
    #[cfg_attr(feature = "serde", serde(alias = "k_e_v_s_rad"))]
    pub k_e: f64,
    /// Torque constant k_t [N m/A].
    #[cfg_attr(feature = "serde", serde(alias = "k_t_n_m_a"))]
    pub k_t: f64,
    /// Rotor moment of inertia J_m [kg m^2].
    #[cfg_attr(feature = "serde", serde(alias = "j_m_kg_m2"))]
    pub j_m: f64,
    /// Rotor viscous friction coefficient B_m [N m s/rad] (not in the datasheet; default 0).
    #[cfg_attr(feature = "serde", serde(alias = "b_m_n_m_s_rad"))]
    pub b_m: f64,
    /// Gearbox reduction ratio N [-] (omega_l = omega_m / N).
    pub n: f64,
    /// Moment of inertia of one external 72-tooth gear J_72 [kg m^2] (three are fitted).
    #[cfg_attr(feature = "serde", serde(alias = "j_72_kg_m2"))]
    pub j_72: f64,
    /// Moment of inertia of the extra disc J_d [kg m^2].
    #[cfg_attr(feature = "serde", serde(alias = "j_d_kg_m2"))]
    pub j_d: f64,
    /// Load viscous friction coefficient B_l [N m s/rad] (to be estimated; default 0).
    #[cfg_attr(feature = "serde", serde(alias = "b_l_n_m_s_rad"))]
    pub b_l: f64,
    /// Voltage driver static gain k_drv [V/V].
    pub k_drv: f64,
    /// Voltage driver cut-off frequency f_c,drv [Hz]; T_drv = 1 / (2 pi f_c,drv).
    #[cfg_attr(feature = "serde", serde(alias = "f_c_drv_hz"))]
    pub f_c_drv: f64,
    /// Shunt resistance R_s [ohm].
    #[cfg_attr(feature = "serde", serde(alias = "r_s_ohm"))]
    pub r_s: f64,
    /// Identified total inertia at motor side J_eq [kg m^2]; overrides eq. 10 when set.
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "Option::is_none", alias = "j_eq_kg_m2")
    )]
    pub j_eq: Option<f64>,
    /// Identified total viscous friction at motor side B_eq [N m s/rad]; overrides eq. 10 when set.
    #[cfg_attr(
        feature = "serde",
        serde(
            default,
            skip_serializing_if = "Option::is_none",
            alias = "b_eq_n_m_s_rad"
        )
    )]
    pub b_eq: Option<f64>,
    /// Identified Coulomb friction at load side tau_sf [N m] (eq. 8); 0 when not set.
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "Option::is_none", alias = "tau_sf_n_m")
    )]
    pub tau_sf: Option<f64>,
}

impl Default for PlantParams {
    /// Table 2 of the handout.
    fn default() -> Self {
        Self::TABLE2
    }
}

impl PlantParams {
    /// The nominal parameters of the handout's Table 2 (B_m = B_l = 0, no overrides).
    pub const TABLE2: PlantParams = PlantParams {
        r_a: 2.6,
        l_a: 180e-6,
        k_e: 7.68e-3,
        k_t: 7.682e-3,
        j_m: 3.90e-7,
        b_m: 0.0,
        n: 14.0,
        j_72: 1.4e-6,
        j_d: 3.0e-5,
        b_l: 0.0,
        k_drv: 0.6,
        f_c_drv: 1200.0,
        r_s: 0.5,
        j_eq: None,
        b_eq: None,
        tau_sf: None,
    };

    /// A realistic SRV-02 as the Padova lab groups measured it (`/work/shared/realdata/*/SOURCE.txt`
    /// of the development machine): Table 2 with the identified J_eq = 7.0e-7 kg m^2 (published
    /// 7.35e-7, 8.0e-7, 5.6e-7), B_eq = 1.0e-6 N m s/rad (7.2e-7, 1.07e-6, 1.27e-6) and load-side
    /// Coulomb friction tau_sf = 9.0e-3 N m (9.7e-3, 7.1e-3, 10.6e-3). The default plant of the
    /// simulator, `servo params` and the QEMU board.
    pub const LAB: PlantParams = PlantParams {
        j_eq: Some(7.0e-7),
        b_eq: Some(1.0e-6),
        tau_sf: Some(9.0e-3),
        ..PlantParams::TABLE2
    };

    /// Equivalent armature-circuit resistance R_eq = R_a + R_s [ohm] (eq. 22).
    pub fn r_eq(&self) -> f64 {
        self.r_a + self.r_s
    }
    /// Load inertia J_l = J_d + 3 J_72 [kg m^2].
    pub fn j_l(&self) -> f64 {
        self.j_d + 3.0 * self.j_72
    }
    /// Total inertia at motor side J_eq [kg m^2]: the identified value if set, else eq. 10.
    pub fn j_eq(&self) -> f64 {
        self.j_eq
            .unwrap_or(self.j_m + self.j_l() / (self.n * self.n))
    }
    /// Total viscous friction at motor side B_eq [N m s/rad]: identified if set, else eq. 10.
    pub fn b_eq(&self) -> f64 {
        self.b_eq.unwrap_or(self.b_m + self.b_l / (self.n * self.n))
    }
    /// Coulomb friction at load side tau_sf [N m] (identified; 0 when not set).
    pub fn tau_sf(&self) -> f64 {
        self.tau_sf.unwrap_or(0.0)
    }
    /// Driver time constant T_drv = 1 / (2 pi f_c,drv) [s].
    pub fn t_drv(&self) -> f64 {
        1.0 / (math::TAU * self.f_c_drv)
    }
    /// Armature electrical time constant L_a / R_eq [s].
    pub fn t_a(&self) -> f64 {
        self.l_a / self.r_eq()
    }
    /// Reduced-model static gain k_m [rad/(V s)] at motor side (eq. 30).
    pub fn k_m(&self) -> f64 {
        self.k_drv * self.k_t / (self.r_eq() * self.b_eq() + self.k_t * self.k_e)
    }
    /// Reduced-model mechanical time constant T_m [s] (eq. 30).
    pub fn t_m(&self) -> f64 {
        self.r_eq() * self.j_eq() / (self.r_eq() * self.b_eq() + self.k_t * self.k_e)
    }

    /// Checks every value: finite, positive where physics demands it, friction non-negative.
    pub fn validate(&self) -> Result<(), ParamError> {
        let positive: [(&'static str, &'static str, f64); 11] = [
            ("r_a", "ohm", self.r_a),
            ("l_a", "H", self.l_a),
            ("k_e", "V s/rad", self.k_e),
            ("k_t", "N m/A", self.k_t),
            ("j_m", "kg m^2", self.j_m),
            ("n", "-", self.n),
            ("k_drv", "V/V", self.k_drv),
            ("f_c_drv", "Hz", self.f_c_drv),
            ("j_eq", "kg m^2", self.j_eq.unwrap_or(1.0)),
            (
                "j_72",
                "kg m^2",
                if self.j_72 == 0.0 { 1.0 } else { self.j_72 },
            ),
            (
                "j_d",
                "kg m^2",
                if self.j_d == 0.0 { 1.0 } else { self.j_d },
            ),
        ];
        let non_negative: [(&'static str, &'static str, f64); 5] = [
            ("b_m", "N m s/rad", self.b_m),
            ("b_l", "N m s/rad", self.b_l),
            ("r_s", "ohm", self.r_s),
            ("b_eq", "N m s/rad", self.b_eq.unwrap_or(0.0)),
            ("tau_sf", "N m", self.tau_sf.unwrap_or(0.0)),
        ];
        for (key, unit, value) in positive.iter().chain(non_negative.iter()) {
            if !value.is_finite() {
                return Err(ParamError::NotFinite { key, value: *value });
            }
            let _ = unit;
        }
        for (key, unit, value) in positive {
            if value <= 0.0 {
                return Err(ParamError::NotPositive { key, unit, value });
            }
        }
        for (key, unit, value) in non_negative {
            if value < 0.0 {
                return Err(ParamError::Negative { key, unit, value });
            }
        }
        let values = [
            self.r_a,
            self.l_a,
            self.k_e,
            self.k_t,
            self.j_m,
            self.n,
            self.k_drv,
            self.f_c_drv,
            self.j_eq.unwrap_or(1e-6),
            self.j_72,
            self.j_d,
            self.b_m,
            self.b_l,
            self.r_s,
            self.b_eq.unwrap_or(0.0),
            self.tau_sf.unwrap_or(0.0),
        ];
        for ((key, unit, min, max), value) in SENSIBLE_RANGES.into_iter().zip(values) {
            if !(value >= min && value <= max) {
                return Err(ParamError::OutOfRange {
                    key,
                    unit,
                    value,
                    min,
                    max,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table2_derived_values_by_hand() {
        let p = PlantParams::TABLE2;
        assert!((p.r_eq() - 3.1).abs() < 1e-12);
        // J_l = 3e-5 + 3 * 1.4e-6 = 3.42e-5; J_eq = 3.9e-7 + 3.42e-5 / 196 = 5.644898e-7
        assert!((p.j_l() - 3.42e-5).abs() < 1e-15);
        assert!((p.j_eq() - 5.644_897_959e-7).abs() < 1e-15);
        // k_m = 0.6 * 7.682e-3 / (7.682e-3 * 7.68e-3) = 0.6 / 7.68e-3 = 78.125
        assert!((p.k_m() - 78.125).abs() < 1e-9);
        // T_m = 3.1 * 5.644898e-7 / (7.682e-3 * 7.68e-3)
        let t_m = 3.1 * 5.644_897_959_183_673e-7 / (7.682e-3 * 7.68e-3);
        assert!((p.t_m() - t_m).abs() < 1e-12);
        p.validate().unwrap();
    }

    #[test]
    fn rejects_negative_inertia_and_friction() {
        let p = PlantParams {
            j_m: -1.0,
            ..PlantParams::TABLE2
        };
        assert!(matches!(
            p.validate(),
            Err(ParamError::NotPositive { key: "j_m", .. })
        ));
        let p = PlantParams {
            b_eq: Some(-1e-6),
            ..PlantParams::TABLE2
        };
        assert!(matches!(
            p.validate(),
            Err(ParamError::Negative { key: "b_eq", .. })
        ));
        let p = PlantParams {
            r_a: f64::NAN,
            ..PlantParams::TABLE2
        };
        assert!(matches!(
            p.validate(),
            Err(ParamError::NotFinite { key: "r_a", .. })
        ));
    }

    #[test]
    fn rejects_absurd_constants() {
        for key in ["k_t", "k_e", "f_c_drv"] {
            let mut p = PlantParams::TABLE2;
            match key {
                "k_t" => p.k_t = 1e308,
                "k_e" => p.k_e = 1e308,
                _ => p.f_c_drv = 1e308,
            }
            let e = p.validate().unwrap_err();
            assert!(
                matches!(e, ParamError::OutOfRange { key: k, .. } if k == key),
                "{e}"
            );
            // Readable: `1e308`, not a 309-digit integer.
            let msg = std::format!("{e}");
            assert!(msg.contains("= 1e308 ") && msg.len() < 300, "{msg}");
        }
    }
}
