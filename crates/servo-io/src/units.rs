//! Signals of a log and the units their columns may be written in.
//!
//! Signal names are the ones users type in `--columns`: `time`, `u`, `theta_l`, `theta_m`,
//! `omega_l`, `omega_m`, `i_a`, `ref`. Units (after a colon in `--columns`; SI when omitted):
//! time `s`, `ms`, `us`; angle `rad`, `deg`, `rev`, `counts:N` (N counts per revolution); angular
//! speed `rad/s`, `deg/s`, `rpm`, `rev/s`; voltage `V`, `mV`; current `A`, `mA`. The `enable`
//! signal (drive on / torque on: nonzero = on, 0 = off) has no unit (`flag`).

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
}

impl Dimension {
    /// The units accepted for this dimension, for error messages.
    pub fn unit_list(self) -> &'static str {
        match self {
            Dimension::Time => "s, ms, us",
            Dimension::Angle => "rad, deg, rev, counts:N (N counts per revolution)",
            Dimension::AngularSpeed => "rad/s, deg/s, rpm, rev/s",
            Dimension::Voltage => "V, mV",
            Dimension::Current => "A, mA",
            Dimension::Flag => "flag (no unit: nonzero = on, 0 = off)",
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
        }
    }
}

impl Signal {
    /// Every signal, in the order of servo's CSV columns.
    pub const ALL: [Signal; 9] = [
        Signal::Time,
        Signal::U,
        Signal::ThetaL,
        Signal::ThetaM,
        Signal::OmegaL,
        Signal::OmegaM,
        Signal::IA,
        Signal::Ref,
        Signal::Enable,
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
        }
    }

    /// Looks a signal up by the name users type.
    pub fn from_name(name: &str) -> Option<Signal> {
        Signal::ALL.into_iter().find(|s| s.name() == name)
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
        }
    }

    /// What the signal measures.
    pub const fn dimension(self) -> Dimension {
        match self {
            Signal::Time => Dimension::Time,
            Signal::U => Dimension::Voltage,
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
}

/// Why a unit string could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitError {
    #[error("unknown unit `{0}`; known units: s, ms, us, rad, deg, rev, counts:N, rad/s, deg/s, rpm, rev/s, V, mV, A, mA, flag")]
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
            "rev" => Unit::Rev,
            "rad/s" | "rad_per_s" | "rad_s" => Unit::RadPerS,
            "deg/s" | "deg_per_s" | "deg_s" => Unit::DegPerS,
            "rpm" => Unit::Rpm,
            "rev/s" | "rps" => Unit::RevPerS,
            "v" => Unit::Volt,
            "mv" => Unit::Millivolt,
            "a" => Unit::Ampere,
            "ma" => Unit::Milliampere,
            "flag" | "1" => Unit::Flag,
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
        }
    }

    /// Checks that the unit fits `signal`.
    pub fn check_for(self, signal: Signal, text: &str) -> Result<Unit, UnitError> {
        if self.dimension() == signal.dimension() {
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
            Unit::Millisecond | Unit::Millivolt | Unit::Milliampere => 1e-3,
            Unit::Microsecond => 1e-6,
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
    }
}
