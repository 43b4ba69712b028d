//! Signals of a log and the units their columns may be written in.
//!
//! Signal names are the ones users type in `--columns`: `time`, `u`, `theta_l`, `theta_m`,
//! `omega_l`, `omega_m`, `i_a`, `ref`. Units (after a colon in `--columns`; SI when omitted):
//! time `s`, `ms`, `us`; angle `rad`, `deg`, `rev` (also `rot`, WPILib's rotations), `counts:N` (N
//! counts per revolution); angular speed `rad/s`, `deg/s`, `rpm`, `rev/s` (also `rot/s`); voltage `V`, `mV`; current `A`, `mA`. The `enable`
//! signal (drive on / torque on: nonzero = on, 0 = off) has no unit (`flag`).
//!
//! On a linear axis (a screw or a belt, [`servo_core::transmission`]) the load position may be
//! written in `m`, `mm`, `um` (signal `theta_l`, also named `x`) and the load speed in `m/s`,
//! `mm/s` (signal `omega_l`, also named `v_x`); the reference in `m`, `mm`, `um`. Such a column is
//! converted to the load shaft's equivalent rotation with the axis' travel per radian when the log
//! is read ([`Unit::factor_on`]); without a linear axis it is refused.

use std::f64::consts::PI;
use std::fmt;

/// A signal of [`servo_core::record::Record`], by the name users type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Signal {
    Time,
    U,
    ThetaL,
    ThetaM,
    OmegaL,
    OmegaM,
    IA,
    Ref,
    /// Drive enable / torque-on flag: nonzero = the drive is on, 0 = off (the motor coasts).
    Enable,
    /// Current reference of a current (torque) drive [A] ([`servo_core::drive`]).
    IRef,
    /// Duty cycle of a PWM H-bridge or smart servo (a fraction in [-1, 1]; `%`, or `counts:N`
    /// with N the full scale).
    Duty,
    /// Supply voltage of a duty drive [V].
    VSupply,
}

impl Signal {
    /// Stores `col` (SI units) as this signal's column of `rec`; the time column replaces
    /// `rec.time_s`. The one place that maps a signal to its record field, for every log reader.
    pub fn store(self, rec: &mut servo_core::record::Record, col: Vec<f64>) {
        match self {
            Signal::Time => rec.time_s = col,
            Signal::U => rec.u_v = Some(col),
            Signal::ThetaL => rec.theta_l_rad = Some(col),
            Signal::ThetaM => rec.theta_m_rad = Some(col),
            Signal::OmegaL => rec.omega_l_rad_s = Some(col),
            Signal::OmegaM => rec.omega_m_rad_s = Some(col),
            Signal::IA => rec.i_a_a = Some(col),
            Signal::Ref => rec.ref_rad = Some(col),
            Signal::Enable => rec.enable = Some(col),
            Signal::IRef => rec.i_ref_a = Some(col),
            Signal::Duty => rec.duty = Some(col),
            Signal::VSupply => rec.v_supply_v = Some(col),
        }
    }
}

/// What a signal measures; decides which units it accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dimension {
    Time,
    Angle,
    AngularSpeed,
    Voltage,
    Current,
    /// A flag without unit (nonzero = on).
    Flag,
    /// A length on a linear axis [m].
    Length,
    /// A speed on a linear axis [m/s].
    LinearSpeed,
    /// A force [N] (no log signal is a force yet).
    Force,
    /// A fraction (a duty cycle: 1 = full scale).
    Fraction,
}

impl Dimension {
    /// The units accepted for this dimension, for error messages.
    pub fn unit_list(self) -> &'static str {
        match self {
            Dimension::Time => "s, ms, us",
            Dimension::Angle => "rad, deg, rev (or rot), counts:N (N counts per revolution)",
            Dimension::AngularSpeed => "rad/s, deg/s, rpm, rev/s (or rot/s)",
            Dimension::Voltage => "V, mV",
            Dimension::Current => "A, mA",
            Dimension::Flag => "flag (no unit: nonzero = on, 0 = off)",
            Dimension::Length => "m, mm, um",
            Dimension::LinearSpeed => "m/s, mm/s",
            Dimension::Force => "N",
            Dimension::Fraction => "fraction (1 = full scale), %, counts:N (N counts full scale)",
        }
    }
    fn name(self) -> &'static str {
        match self {
            Dimension::Time => "a time",
            Dimension::Angle => "an angle",
            Dimension::AngularSpeed => "an angular speed",
            Dimension::Voltage => "a voltage",
            Dimension::Current => "a current",
            Dimension::Flag => "an on/off flag",
            Dimension::Length => "a length",
            Dimension::LinearSpeed => "a linear speed",
            Dimension::Force => "a force",
            Dimension::Fraction => "a fraction",
        }
    }
}

impl Signal {
    /// Every signal, in the order of servo's CSV columns.
    pub const ALL: [Signal; 12] = [
        Signal::Time,
        Signal::U,
        Signal::ThetaL,
        Signal::ThetaM,
        Signal::OmegaL,
        Signal::OmegaM,
        Signal::IA,
        Signal::Ref,
        Signal::Enable,
        Signal::IRef,
        Signal::Duty,
        Signal::VSupply,
    ];

    /// The name users type.
    pub const fn name(self) -> &'static str {
        match self {
            Signal::Time => "time",
            Signal::U => "u",
            Signal::ThetaL => "theta_l",
            Signal::ThetaM => "theta_m",
            Signal::OmegaL => "omega_l",
            Signal::OmegaM => "omega_m",
            Signal::IA => "i_a",
            Signal::Ref => "ref",
            Signal::Enable => "enable",
            Signal::IRef => "i_ref",
            Signal::Duty => "duty",
            Signal::VSupply => "v_supply",
        }
    }

    /// Looks a signal up by the name users type; `x` is the load position and `v_x` the load
    /// speed of a linear axis (the signals `theta_l` and `omega_l` in a length or linear speed
    /// unit).
    pub fn from_name(name: &str) -> Option<Signal> {
        match name {
            "x" => Some(Signal::ThetaL),
            "v_x" => Some(Signal::OmegaL),
            _ => Signal::ALL.into_iter().find(|s| s.name() == name),
        }
    }

    /// The column name in servo's own CSV of a linear axis (`x_m`, `v_x_m_s`, `ref_m`), for the
    /// signals a linear axis writes in metres.
    pub const fn csv_column_linear(self) -> Option<&'static str> {
        match self {
            Signal::ThetaL => Some("x_m"),
            Signal::OmegaL => Some("v_x_m_s"),
            Signal::Ref => Some("ref_m"),
            _ => None,
        }
    }

    /// The signal's SI unit on a linear axis (`m`, `m/s`) where it differs from
    /// [`Signal::si_unit`].
    pub const fn linear_unit(self) -> Option<Unit> {
        match self {
            Signal::ThetaL | Signal::Ref => Some(Unit::Metre),
            Signal::OmegaL => Some(Unit::MetrePerS),
            _ => None,
        }
    }

    /// True when `dim` is the linear form of this signal's dimension (a load position or
    /// reference in a length, the load speed in a linear speed).
    pub fn accepts_linear(self, dim: Dimension) -> bool {
        matches!(
            (self, dim),
            (Signal::ThetaL | Signal::Ref, Dimension::Length)
                | (Signal::OmegaL, Dimension::LinearSpeed)
        )
    }

    /// The column name in servo's own CSV (SI unit in the name).
    pub const fn csv_column(self) -> &'static str {
        match self {
            Signal::Time => "time_s",
            Signal::U => "u_V",
            Signal::ThetaL => "theta_l_rad",
            Signal::ThetaM => "theta_m_rad",
            Signal::OmegaL => "omega_l_rad_s",
            Signal::OmegaM => "omega_m_rad_s",
            Signal::IA => "i_a_A",
            Signal::Ref => "ref_rad",
            Signal::Enable => "enable",
            Signal::IRef => "i_ref_A",
            Signal::Duty => "duty",
            Signal::VSupply => "v_supply_V",
        }
    }

    /// What the signal measures.
    pub const fn dimension(self) -> Dimension {
        match self {
            Signal::Time => Dimension::Time,
            Signal::U | Signal::VSupply => Dimension::Voltage,
            Signal::IRef => Dimension::Current,
            Signal::Duty => Dimension::Fraction,
            Signal::ThetaL | Signal::ThetaM | Signal::Ref => Dimension::Angle,
            Signal::OmegaL | Signal::OmegaM => Dimension::AngularSpeed,
            Signal::IA => Dimension::Current,
            Signal::Enable => Dimension::Flag,
        }
    }

    /// The SI unit of the signal.
    pub const fn si_unit(self) -> Unit {
        match self.dimension() {
            Dimension::Time => Unit::Second,
            Dimension::Angle => Unit::Rad,
            Dimension::AngularSpeed => Unit::RadPerS,
            Dimension::Voltage => Unit::Volt,
            Dimension::Current => Unit::Ampere,
            Dimension::Flag => Unit::Flag,
            Dimension::Length => Unit::Metre,
            Dimension::LinearSpeed => Unit::MetrePerS,
            Dimension::Force => Unit::Newton,
            Dimension::Fraction => Unit::Fraction,
        }
    }

    /// Comma-separated list of all signal names, for error messages.
    pub fn name_list() -> String {
        Signal::ALL.map(|s| s.name()).join(", ")
    }
}

impl fmt::Display for Signal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A unit a column may be written in; [`Unit::to_si`] converts its values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unit {
    Second,
    Millisecond,
    Microsecond,
    Nanosecond,
    Rad,
    Deg,
    Rev,
    /// Encoder counts with the given counts per revolution.
    Counts(f64),
    RadPerS,
    DegPerS,
    Rpm,
    RevPerS,
    Volt,
    Millivolt,
    Ampere,
    Milliampere,
    /// No unit: an on/off flag (nonzero = on).
    Flag,
    Metre,
    Millimetre,
    Micrometre,
    MetrePerS,
    MillimetrePerS,
    Newton,
    /// A fraction (1 = full scale).
    Fraction,
    /// Percent of full scale.
    Percent,
}

/// Why a unit string could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitError {
    #[error("unknown unit `{0}`; known units: s, ms, us, rad, deg, rev (rot), counts:N, rad/s, deg/s, rpm, rev/s (rot/s), V, mV, A, mA, m, mm, um, m/s, mm/s, N, flag, fraction, %")]
    Unknown(String),
    #[error("`counts:N` needs N, the counts per revolution (> 0), got `{0}`")]
    BadCounts(String),
    #[error("unit `{unit}` is not {dim} unit, but `{signal}` is {dim}: use one of {list}", dim = signal.dimension().name(), list = signal.dimension().unit_list())]
    Mismatch { unit: String, signal: Signal },
}

impl Unit {
    /// Parses a unit as written after the colon in `--columns` (case-insensitive except `mA`/`MA`
    /// ambiguity, which does not arise: there is no mega-ampere).
    pub fn parse(text: &str) -> Result<Unit, UnitError> {
        let t = text.trim();
        let lower = t.to_ascii_lowercase();
        if let Some(n) = lower
            .strip_prefix("counts:")
            .or_else(|| lower.strip_prefix("counts/"))
        {
            return match n.trim().parse::<f64>() {
                Ok(n) if n > 0.0 && n.is_finite() => Ok(Unit::Counts(n)),
                _ => Err(UnitError::BadCounts(n.to_string())),
            };
        }
        Ok(match lower.as_str() {
            "s" | "sec" => Unit::Second,
            "ms" => Unit::Millisecond,
            "us" | "µs" => Unit::Microsecond,
            "ns" => Unit::Nanosecond,
            "rad" => Unit::Rad,
            "deg" => Unit::Deg,
            "rev" | "rot" | "rotation" | "rotations" => Unit::Rev,
            "rad/s" | "rad_per_s" | "rad_s" => Unit::RadPerS,
            "deg/s" | "deg_per_s" | "deg_s" => Unit::DegPerS,
            "rpm" => Unit::Rpm,
            "rev/s" | "rps" | "rot/s" | "rotations/s" => Unit::RevPerS,
            "v" => Unit::Volt,
            "mv" => Unit::Millivolt,
            "a" => Unit::Ampere,
            "ma" => Unit::Milliampere,
            "flag" | "1" => Unit::Flag,
            "m" => Unit::Metre,
            "mm" => Unit::Millimetre,
            "um" | "µm" => Unit::Micrometre,
            "m/s" | "m_per_s" | "m_s" => Unit::MetrePerS,
            "mm/s" | "mm_per_s" | "mm_s" => Unit::MillimetrePerS,
            "n" => Unit::Newton,
            "fraction" | "frac" => Unit::Fraction,
            "%" | "pct" | "percent" => Unit::Percent,
            "counts" => return Err(UnitError::BadCounts(String::new())),
            _ => return Err(UnitError::Unknown(t.to_string())),
        })
    }

    /// What the unit measures.
    pub fn dimension(self) -> Dimension {
        match self {
            Unit::Second | Unit::Millisecond | Unit::Microsecond | Unit::Nanosecond => {
                Dimension::Time
            }
            Unit::Rad | Unit::Deg | Unit::Rev | Unit::Counts(_) => Dimension::Angle,
            Unit::RadPerS | Unit::DegPerS | Unit::Rpm | Unit::RevPerS => Dimension::AngularSpeed,
            Unit::Volt | Unit::Millivolt => Dimension::Voltage,
            Unit::Ampere | Unit::Milliampere => Dimension::Current,
            Unit::Flag => Dimension::Flag,
            Unit::Metre | Unit::Millimetre | Unit::Micrometre => Dimension::Length,
            Unit::MetrePerS | Unit::MillimetrePerS => Dimension::LinearSpeed,
            Unit::Newton => Dimension::Force,
            Unit::Fraction | Unit::Percent => Dimension::Fraction,
        }
    }

    /// True for a length or a linear speed: a column in this unit needs a linear axis.
    pub fn is_linear(self) -> bool {
        matches!(
            self.dimension(),
            Dimension::Length | Dimension::LinearSpeed | Dimension::Force
        )
    }

    /// Factor from this unit to the record's SI unit on `axis` (value_record = value * factor):
    /// [`Unit::factor_to_si`] for a rotary unit; for a length or a linear speed the metres (per
    /// second) divided by the axis' travel per radian, i.e. the load shaft's equivalent rotation
    /// [rad] ([`servo_core::transmission`]). `None` when the unit is linear and the axis is not.
    pub fn factor_on(self, axis: &servo_core::Transmission) -> Option<f64> {
        if self.is_linear() {
            axis.metres_per_rad().map(|s| self.factor_to_si() / s)
        } else {
            Some(self.factor_to_si())
        }
    }

    /// Checks that the unit fits `signal` (a load position, reference or speed also in its
    /// linear form: [`Signal::accepts_linear`]).
    pub fn check_for(self, signal: Signal, text: &str) -> Result<Unit, UnitError> {
        let duty_counts = signal == Signal::Duty && matches!(self, Unit::Counts(_));
        if self.dimension() == signal.dimension()
            || signal.accepts_linear(self.dimension())
            || duty_counts
        {
            Ok(self)
        } else {
            Err(UnitError::Mismatch {
                unit: text.to_string(),
                signal,
            })
        }
    }

    /// Factor from this unit to SI (value_si = value * factor).
    pub fn factor_to_si(self) -> f64 {
        match self {
            Unit::Second | Unit::Rad | Unit::RadPerS | Unit::Volt | Unit::Ampere | Unit::Flag => {
                1.0
            }
            Unit::Metre | Unit::MetrePerS | Unit::Newton | Unit::Fraction => 1.0,
            Unit::Percent => 1e-2,
            Unit::Millisecond | Unit::Millivolt | Unit::Milliampere => 1e-3,
            Unit::Millimetre | Unit::MillimetrePerS => 1e-3,
            Unit::Microsecond | Unit::Micrometre => 1e-6,
            Unit::Nanosecond => 1e-9,
            Unit::Deg => PI / 180.0,
            Unit::Rev => 2.0 * PI,
            Unit::Counts(n) => 2.0 * PI / n,
            Unit::DegPerS => PI / 180.0,
            Unit::Rpm => 2.0 * PI / 60.0,
            Unit::RevPerS => 2.0 * PI,
        }
    }

    /// Converts one value to SI.
    pub fn to_si(self, v: f64) -> f64 {
        if self.factor_to_si() == 1.0 {
            v
        } else {
            v * self.factor_to_si()
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Unit::Second => f.write_str("s"),
            Unit::Millisecond => f.write_str("ms"),
            Unit::Microsecond => f.write_str("us"),
            Unit::Nanosecond => f.write_str("ns"),
            Unit::Rad => f.write_str("rad"),
            Unit::Deg => f.write_str("deg"),
            Unit::Rev => f.write_str("rev"),
            Unit::Counts(n) => write!(f, "counts:{n}"),
            Unit::RadPerS => f.write_str("rad/s"),
            Unit::DegPerS => f.write_str("deg/s"),
            Unit::Rpm => f.write_str("rpm"),
            Unit::RevPerS => f.write_str("rev/s"),
            Unit::Volt => f.write_str("V"),
            Unit::Millivolt => f.write_str("mV"),
            Unit::Ampere => f.write_str("A"),
            Unit::Milliampere => f.write_str("mA"),
            Unit::Flag => f.write_str("flag"),
            Unit::Metre => f.write_str("m"),
            Unit::Millimetre => f.write_str("mm"),
            Unit::Micrometre => f.write_str("um"),
            Unit::MetrePerS => f.write_str("m/s"),
            Unit::MillimetrePerS => f.write_str("mm/s"),
            Unit::Newton => f.write_str("N"),
            Unit::Fraction => f.write_str("fraction"),
            Unit::Percent => f.write_str("%"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions() {
        assert!((Unit::parse("deg").unwrap().to_si(180.0) - PI).abs() < 1e-15);
        assert!((Unit::parse("rpm").unwrap().to_si(60.0) - 2.0 * PI).abs() < 1e-15);
        assert!((Unit::parse("counts:4096").unwrap().to_si(1024.0) - PI / 2.0).abs() < 1e-15);
        assert!((Unit::parse("mA").unwrap().to_si(250.0) - 0.25).abs() < 1e-15);
        assert!((Unit::parse("ms").unwrap().to_si(5.0) - 0.005).abs() < 1e-15);
        assert_eq!(Unit::parse("V").unwrap().to_si(3.5), 3.5);
        assert_eq!(Unit::parse("deg/s").unwrap(), Unit::DegPerS);
        assert_eq!(Unit::parse("rot").unwrap(), Unit::Rev);
        assert_eq!(Unit::parse("rot/s").unwrap(), Unit::RevPerS);
        assert_eq!(
            Unit::parse("counts:4096").unwrap().to_string(),
            "counts:4096"
        );
    }

    #[test]
    fn rejects() {
        assert!(matches!(Unit::parse("furlong"), Err(UnitError::Unknown(_))));
        assert!(matches!(
            Unit::parse("counts:0"),
            Err(UnitError::BadCounts(_))
        ));
        assert!(matches!(
            Unit::parse("counts"),
            Err(UnitError::BadCounts(_))
        ));
        let e = Unit::parse("rpm")
            .unwrap()
            .check_for(Signal::ThetaL, "rpm")
            .unwrap_err()
            .to_string();
        assert!(e.contains("theta_l") && e.contains("rad, deg"), "{e}");
        assert!(Unit::parse("deg")
            .unwrap()
            .check_for(Signal::Ref, "deg")
            .is_ok());
        // A length is a load position or reference, never a motor angle or a current.
        assert!(Unit::parse("mm")
            .unwrap()
            .check_for(Signal::ThetaL, "mm")
            .is_ok());
        assert!(Unit::parse("m")
            .unwrap()
            .check_for(Signal::ThetaM, "m")
            .is_err());
        assert!(Unit::parse("N")
            .unwrap()
            .check_for(Signal::IA, "N")
            .is_err());
    }

    #[test]
    fn linear_units_need_a_linear_axis() {
        use servo_core::transmission::{Transmission, TransmissionKind};
        let screw = Transmission {
            kind: TransmissionKind::Screw { lead_m: 0.01 },
            ..Transmission::GEAR
        };
        // 10 mm of travel is one screw revolution.
        let f = Unit::parse("mm").unwrap().factor_on(&screw).unwrap();
        assert!((10.0 * f - 2.0 * PI).abs() < 1e-12);
        let f = Unit::parse("m/s").unwrap().factor_on(&screw).unwrap();
        assert!((0.01 * f - 2.0 * PI).abs() < 1e-12);
        assert_eq!(
            Unit::parse("um").unwrap().factor_on(&Transmission::GEAR),
            None
        );
        assert_eq!(
            Unit::parse("deg").unwrap().factor_on(&screw),
            Some(PI / 180.0)
        );
        assert_eq!(Signal::from_name("x"), Some(Signal::ThetaL));
        assert_eq!(Signal::from_name("v_x"), Some(Signal::OmegaL));
    }
}
