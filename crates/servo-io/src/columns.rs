//! The column map of a CSV log: which column holds which signal, in which unit.
//!
//! Written by users as `--columns time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A` (signal =
//! column header, optional `:unit`, SI when omitted), recognised for servo's own CSV, or guessed
//! from common header suffixes (`_deg`, `_rad`, `_rpm`, `_deg_per_s`, `_A`, `_V`, ...).

use super::units::{Signal, Unit};
use crate::error::{self as anyhow, anyhow, bail};
use std::fmt;

/// One entry: the column `column` holds `signal` in `unit`.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnSpec {
    pub signal: Signal,
    pub column: String,
    pub unit: Unit,
}

/// Which columns hold which signals.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ColumnMap {
    pub entries: Vec<ColumnSpec>,
}

impl fmt::Display for ColumnMap {
    /// The `--columns` form of the map.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.entries.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            let name = match (e.signal, e.unit.is_linear()) {
                (Signal::ThetaL, true) => "x",
                (Signal::OmegaL, true) => "v_x",
                (s, _) => s.name(),
            };
            write!(f, "{name}={}", e.column)?;
            if e.unit != e.signal.si_unit() {
                write!(f, ":{}", e.unit)?;
            }
        }
        Ok(())
    }
}

/// An example `--columns` value for error messages.
pub const EXAMPLE: &str = "time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A";

impl ColumnMap {
    /// Parses a `--columns` value.
    pub fn parse(text: &str) -> anyhow::Result<ColumnMap> {
        let mut entries: Vec<ColumnSpec> = Vec::new();
        for item in split_top(text, ',')
            .into_iter()
            .map(str::trim)
            .filter(|s| !s.is_empty())
        {
            let (sig, rest) = item.split_once('=').ok_or_else(|| {
                anyhow!("--columns: `{item}` is not `signal=column[:unit]` (example: --columns {EXAMPLE})")
            })?;
            let sig = sig.trim();
            let signal = Signal::from_name(sig).ok_or_else(|| {
                anyhow!(
                    "--columns: unknown signal `{sig}`; signals are {}",
                    Signal::name_list()
                )
            })?;
            // A MATLAB path may hold `:` and `,` inside brackets (`values(:,1)`).
            let (column, unit_text) = match split_top(rest, ':').as_slice() {
                [c] => (c.trim(), None),
                [c, ..] => (c.trim(), Some(rest[c.len() + 1..].trim())),
                [] => ("", None),
            };
            if column.is_empty() {
                bail!("--columns: `{item}` names no column (example: --columns {EXAMPLE})");
            }
            let unit = match unit_text {
                Some(u) => Unit::parse(u)
                    .and_then(|x| x.check_for(signal, u))
                    .map_err(|e| anyhow!("--columns: `{item}`: {e}"))?,
                None => signal.si_unit(),
            };
            if entries.iter().any(|e| e.signal == signal) {
                bail!("--columns: signal `{sig}` is given twice");
            }
            entries.push(ColumnSpec {
                signal,
                column: column.to_string(),
                unit,
            });
        }
        if !entries.iter().any(|e| e.signal == Signal::Time) {
            bail!("--columns: `time=<column>` is required (example: --columns {EXAMPLE})");
        }
        if entries.len() < 2 {
            bail!(
                "--columns: give at least one signal besides time (example: --columns {EXAMPLE})"
            );
        }
        Ok(ColumnMap { entries })
    }

    /// The map of servo's own CSV if every header column is one of servo's column names
    /// (`time_s,u_V,theta_l_rad,i_a_A[,ref_rad,...]`, case-insensitive) and `time_s` is present.
    pub fn servo_own(header: &[&str]) -> Option<ColumnMap> {
        let mut entries = Vec::new();
        for h in header {
            let (signal, unit) = Signal::ALL.into_iter().find_map(|s| {
                if s.csv_column().eq_ignore_ascii_case(h.trim()) {
                    Some((s, s.si_unit()))
                } else {
                    s.csv_column_linear()
                        .filter(|c| c.eq_ignore_ascii_case(h.trim()))
                        .and_then(|_| s.linear_unit().map(|u| (s, u)))
                }
            })?;
            if entries.iter().any(|e: &ColumnSpec| e.signal == signal) {
                return None;
            }
            entries.push(ColumnSpec {
                signal,
                column: h.to_string(),
                unit,
            });
        }
        entries
            .iter()
            .any(|e| e.signal == Signal::Time)
            .then_some(ColumnMap { entries })
    }

    /// Guesses the map from header names with unit suffixes, e.g. `t_s`, `thl_meas_deg`,
    /// `thl_ref_deg`, `u_V`, `ia_A`, `wm_rpm`, `wl_rad_per_s`. Returns the map and the columns it
    /// left out, or an error showing the header and an example `--columns`.
    pub fn guess(header: &[&str]) -> anyhow::Result<(ColumnMap, Vec<String>)> {
        let mut entries: Vec<ColumnSpec> = Vec::new();
        let mut ignored = Vec::new();
        // Columns that look like a signal already taken: guessing one would drop the other.
        let mut twice: Vec<(Signal, String)> = Vec::new();
        // A smart servo's log (a goal position and the firmware's duty): its voltages are the
        // duty times the supply, derived, and the duty is the measured command.
        let smart = header
            .iter()
            .any(|h| unitless_column(h.trim()) == Some((Signal::Duty, Unit::Fraction)))
            && header
                .iter()
                .any(|h| matches!(guess_column(h.trim()), Some((Signal::Ref, _))));
        for h in header {
            let guess = guess_column(h.trim()).or_else(|| unitless_column(h.trim()));
            match guess.filter(|(s, _)| !(smart && *s == Signal::U)) {
                Some((signal, unit)) if !entries.iter().any(|e| e.signal == signal) => entries
                    .push(ColumnSpec {
                        signal,
                        column: h.trim().to_string(),
                        unit,
                    }),
                Some((signal, _)) => twice.push((signal, h.trim().to_string())),
                None => ignored.push(h.trim().to_string()),
            }
        }
        if let Some((signal, col)) = twice.first() {
            let first = entries
                .iter()
                .find(|e| e.signal == *signal)
                .map_or(String::new(), |e| e.column.clone());
            bail!(
                "columns `{first}` and `{col}` both look like the signal `{signal}`; servo does not \
                 guess which one to use (the other would be dropped): give the column map, e.g. \
                 --columns {}",
                ColumnMap {
                    entries: entries.clone()
                }
            );
        }
        let has_time = entries.iter().any(|e| e.signal == Signal::Time);
        if !has_time || entries.len() < 2 {
            bail!(
                "cannot tell which column holds which signal from the header `{}`; give a column map, e.g. \
                 --columns {EXAMPLE} (signals: {}; units after a colon: s, ms, rad, deg, rev, counts:4096, rad/s, \
                 deg/s, rpm, V, A, mA)",
                crate::excerpt::join_excerpt(header, ",", crate::excerpt::HEADER_CHARS),
                Signal::name_list()
            );
        }
        Ok((ColumnMap { entries }, ignored))
    }

    /// The factor of every entry (in order) from its column's unit to the record's SI unit on
    /// `axis` ([`Unit::factor_on`]); an error naming the column when a column is in a length or
    /// linear speed and the axis is not linear.
    pub fn factors_on(&self, axis: &servo_core::Transmission) -> anyhow::Result<Vec<f64>> {
        self.entries
            .iter()
            .map(|e| {
                // A duty in counts: N counts are the full scale (a fraction of 1).
                if let (Signal::Duty, super::units::Unit::Counts(n)) = (e.signal, e.unit) {
                    return Ok(1.0 / n);
                }
                e.unit.factor_on(axis).ok_or_else(|| {
                    let (angle, units) = if e.signal.dimension() == super::units::Dimension::Angle {
                        ("an angle", "rad, deg or rev")
                    } else {
                        ("an angular speed", "rad/s, deg/s or rpm")
                    };
                    anyhow!(
                        "column `{}` holds {} in {}, a linear unit, but the model is a rotary gear, \
                         where {} is {angle}: if the column holds {angle}, say its unit ({units}: \
                         --columns ...,{}={}:deg, or rename the header, e.g. `{}_rad`); if the rig is a \
                         screw or a belt, give the model file of the linear axis (a [transmission] section \
                         with kind = \"screw\" and lead_m, or kind = \"belt\" and radius_m) with --params, \
                         --model or --plant",
                        e.column,
                        e.signal,
                        e.unit,
                        e.signal,
                        e.signal,
                        e.column,
                        e.signal.name(),
                    )
                })
            })
            .collect()
    }

    /// The entry for `signal`, if mapped.
    pub fn get(&self, signal: Signal) -> Option<&ColumnSpec> {
        self.entries.iter().find(|e| e.signal == signal)
    }
}

/// Splits `text` at `sep` outside `(...)` and `{...}`.
fn split_top(text: &str, sep: char) -> Vec<&str> {
    let (mut depth, mut start, mut out) = (0i32, 0, Vec::new());
    for (i, c) in text.char_indices() {
        match c {
            '(' | '{' => depth += 1,
            ')' | '}' => depth -= 1,
            _ if c == sep && depth <= 0 => {
                out.push(&text[start..i]);
                start = i + c.len_utf8();
            }
            _ => {}
        }
    }
    out.push(&text[start..]);
    out
}

/// Unit suffixes recognised at the end of a header name (case-sensitive for V/A to avoid
/// matching words; longest first). `None`: a derivative we do not import (acceleration).
const SUFFIXES: [(&str, Option<&str>); 34] = [
    ("_mm_per_s", Some("mm/s")),
    ("_m_per_s", Some("m/s")),
    ("_mm_s", Some("mm/s")),
    ("_m_s", Some("m/s")),
    ("_deg_per_s2", None),
    ("_rad_per_s2", None),
    ("_rpm_per_s", None),
    ("_deg_per_s", Some("deg/s")),
    ("_rad_per_s", Some("rad/s")),
    ("_rev_per_s", Some("rev/s")),
    ("_deg_s", Some("deg/s")),
    ("_rad_s", Some("rad/s")),
    ("_rpm", Some("rpm")),
    ("_rps", Some("rev/s")),
    ("_deg", Some("deg")),
    ("_rad", Some("rad")),
    ("_rev", Some("rev")),
    ("_counts", None),
    ("_ms", Some("ms")),
    ("_us", Some("us")),
    ("_s", Some("s")),
    ("_sec", Some("s")),
    ("_mV", Some("mV")),
    ("_V", Some("V")),
    ("_v", Some("V")),
    ("_mA", Some("mA")),
    ("_mm", Some("mm")),
    ("_um", Some("um")),
    ("_m", Some("m")),
    ("_A", Some("A")),
    ("_a", Some("A")),
    ("_Nm", None),
    ("_N_m", None),
    ("_N", None),
];

/// Base-name words that identify a signal (after splitting on `_`).
fn signal_from_word(word: &str) -> Option<Signal> {
    Some(match word {
        "t" | "time" => Signal::Time,
        "u" | "v" | "volt" | "voltage" | "uin" => Signal::U,
        "thl" | "thetal" | "theta" | "pos" | "position" | "angle" | "ql" | "x" => Signal::ThetaL,
        "vx" | "xdot" | "vel" | "velocity" | "omega" | "speed" => Signal::OmegaL,
        "goal" => Signal::ThetaL,
        "thm" | "thetam" => Signal::ThetaM,
        "wl" | "omegal" => Signal::OmegaL,
        "wm" | "omegam" => Signal::OmegaM,
        "ia" | "i" | "current" | "cur" | "curr" => Signal::IA,
        _ => return None,
    })
}

/// A column named without a unit suffix that still says what it holds: a duty (`duty`, `pwm`,
/// `present_pwm`, never a commanded or computed one: `duty_cmd`) as a fraction, a torque
/// enable (`torque_enable`, `enable`) as a flag.
fn unitless_column(name: &str) -> Option<(Signal, Unit)> {
    match name.to_ascii_lowercase().as_str() {
        "duty" | "pwm" | "present_pwm" | "duty_cycle" => Some((Signal::Duty, Unit::Fraction)),
        "torque_enable" | "enable" | "enabled" | "torque_on" => Some((Signal::Enable, Unit::Flag)),
        _ => None,
    }
}

/// Guesses (signal, unit) of one header name, or `None`.
pub(crate) fn guess_column(name: &str) -> Option<(Signal, Unit)> {
    let (base, unit) = SUFFIXES.iter().find_map(|(suf, unit)| {
        let base = name.strip_suffix(suf)?;
        (!base.is_empty()).then_some((base, *unit))
    })?;
    let unit = Unit::parse(unit?).ok()?;
    let lower = base.to_ascii_lowercase();
    // Joined forms first (`theta_l`, `omega_m`, `i_a`), then single words.
    let joined = lower.replace('_', "");
    let words: Vec<&str> = lower.split('_').filter(|w| !w.is_empty()).collect();
    // a date stamp (`unix_time_s`, `epoch_s`) says when, not the log's time axis
    if words
        .iter()
        .any(|w| matches!(*w, "unix" | "epoch" | "posix" | "utc"))
    {
        return None;
    }
    if words.iter().any(|w| matches!(*w, "err" | "error" | "e")) {
        return None;
    }
    let is_ref = words.iter().any(|w| {
        matches!(
            *w,
            "ref" | "reference" | "setpoint" | "sp" | "target" | "des" | "desired" | "goal"
        )
    });
    // A supply voltage is never the command u: `v_supply_V`, `vin_meas_V`, `vbus_V`,
    // `input_voltage_V`, `battery_V`.
    let supply = words.iter().any(|w| {
        matches!(
            *w,
            "supply"
                | "sup"
                | "vin"
                | "vbus"
                | "bus"
                | "vcc"
                | "vdd"
                | "vbat"
                | "bat"
                | "battery"
                | "input"
                | "vsupply"
        )
    }) || matches!(joined.as_str(), "vsupply" | "vin" | "vbus" | "vcc" | "vdd");
    let mut signal = if supply {
        Signal::VSupply
    } else {
        signal_from_word(&joined).or_else(|| words.iter().find_map(|w| signal_from_word(w)))?
    };
    // A length suffix (`_m`) is read as one only on a position or speed named as linear (`x_m`,
    // `pos_mm`, `v_x_m_s`): `theta_m` is the motor angle, not a load position in metres.
    // A load position in mm or um (`theta_l_mm`) is read as a length: on a rotary rig it is
    // then refused with what to write instead, never dropped.
    let small_length = matches!(
        unit,
        Unit::Millimetre | Unit::Micrometre | Unit::MillimetrePerS
    ) && signal.accepts_linear(unit.dimension());
    if unit.is_linear()
        && !small_length
        && !words.iter().any(|w| {
            matches!(
                *w,
                "x" | "pos" | "position" | "vx" | "xdot" | "vel" | "velocity" | "carriage"
            )
        })
        && !matches!(joined.as_str(), "vx" | "xdot")
    {
        return None;
    }
    if is_ref {
        if signal != Signal::ThetaL {
            return None;
        }
        signal = Signal::Ref;
    }
    // The unit decides between look-alikes: `v` with an angle unit is not a voltage.
    (unit.dimension() == signal.dimension() || signal.accepts_linear(unit.dimension()))
        .then_some((signal, unit))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_smart_servos_columns_are_guessed_and_its_supply_is_never_u() {
        let header = [
            "t_s",
            "theta_rad",
            "omega_rad_s",
            "goal_rad",
            "duty",
            "duty_cmd",
            "u_V",
            "u_cmd_V",
            "vin_meas_V",
            "torque_enable",
            "temp_C",
        ];
        let (m, ignored) = ColumnMap::guess(&header).unwrap();
        let col = |s: Signal| m.get(s).map(|e| e.column.as_str());
        assert_eq!(col(Signal::ThetaL), Some("theta_rad"));
        assert_eq!(col(Signal::OmegaL), Some("omega_rad_s"));
        assert_eq!(col(Signal::Ref), Some("goal_rad"));
        assert_eq!(col(Signal::Duty), Some("duty"));
        assert_eq!(col(Signal::VSupply), Some("vin_meas_V"));
        assert_eq!(col(Signal::Enable), Some("torque_enable"));
        assert_eq!(col(Signal::U), None);
        assert!(ignored.contains(&"temp_C".to_string()), "{ignored:?}");
        // Dynamixel-style names.
        let (m, _) = ColumnMap::guess(&[
            "time_s",
            "present_position_rad",
            "goal_position_rad",
            "present_pwm",
            "input_voltage_V",
        ])
        .unwrap();
        assert_eq!(
            m.get(Signal::Ref).map(|e| e.column.as_str()),
            Some("goal_position_rad")
        );
        assert_eq!(
            m.get(Signal::ThetaL).map(|e| e.column.as_str()),
            Some("present_position_rad")
        );
        assert_eq!(
            m.get(Signal::VSupply).map(|e| e.column.as_str()),
            Some("input_voltage_V")
        );
        assert!(m.get(Signal::U).is_none());
    }

    #[test]
    fn parse_and_display() {
        let m = ColumnMap::parse(
            "time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A:mA,theta_m=enc:counts:4096",
        )
        .unwrap();
        assert_eq!(m.entries.len(), 5);
        assert_eq!(m.get(Signal::ThetaL).unwrap().unit, Unit::Deg);
        assert_eq!(m.get(Signal::ThetaM).unwrap().unit, Unit::Counts(4096.0));
        assert_eq!(m.get(Signal::U).unwrap().unit, Unit::Volt);
        assert_eq!(
            m.to_string(),
            "time=t_s,theta_l=thl_meas_deg:deg,u=u_V,i_a=ia_A:mA,theta_m=enc:counts:4096"
        );
        assert_eq!(ColumnMap::parse(&m.to_string()).unwrap(), m);
    }

    #[test]
    fn matlab_paths_keep_their_brackets() {
        let t = "time=s.time,theta_l=s.signals(1).values(:,1):deg,theta_m=s.signals(2).values(:,end):counts:2000,u=c{2}";
        let m = ColumnMap::parse(t).unwrap();
        assert_eq!(
            m.get(Signal::ThetaL).unwrap().column,
            "s.signals(1).values(:,1)"
        );
        assert_eq!(m.get(Signal::ThetaL).unwrap().unit, Unit::Deg);
        assert_eq!(m.get(Signal::ThetaM).unwrap().unit, Unit::Counts(2000.0));
        assert_eq!(m.get(Signal::U).unwrap().column, "c{2}");
        assert_eq!(m.to_string(), t);
    }

    #[test]
    fn parse_errors() {
        for (bad, needle) in [
            ("time=t,speed=w", "unknown signal `speed`"),
            ("time=t,theta_l=x:rpm", "not an angle unit"),
            ("theta_l=x", "time=<column>"),
            ("time=t,u=a,u=b", "twice"),
            ("time=t,u", "signal=column"),
            ("time=t,u=x:parsec", "unknown unit"),
        ] {
            let e = format!("{:#}", ColumnMap::parse(bad).unwrap_err());
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }

    #[test]
    fn own_header() {
        let m =
            ColumnMap::servo_own(&["time_s", "u_V", "theta_l_rad", "i_a_A", "ref_rad"]).unwrap();
        assert_eq!(m.entries.len(), 5);
        assert!(ColumnMap::servo_own(&["time_s", "u_V", "other"]).is_none());
        assert!(ColumnMap::servo_own(&["u_V", "theta_l_rad"]).is_none());
    }

    #[test]
    fn guesses_lab_headers() {
        let (m, ign) = ColumnMap::guess(&[
            "t_s",
            "thl_meas_deg",
            "thl_ref_deg",
            "u_V",
            "ia_A",
            "wm_deg_per_s",
            "err_deg",
        ])
        .unwrap();
        assert_eq!(m.to_string(), "time=t_s,theta_l=thl_meas_deg:deg,ref=thl_ref_deg:deg,u=u_V,i_a=ia_A,omega_m=wm_deg_per_s:deg/s");
        assert_eq!(ign, ["err_deg"]);
        let (m, ign) =
            ColumnMap::guess(&["t_s", "wm_rpm", "am_rpm_per_s", "ia_A", "ia2_A"]).unwrap();
        assert_eq!(m.to_string(), "time=t_s,omega_m=wm_rpm:rpm,i_a=ia_A");
        assert_eq!(ign, ["am_rpm_per_s", "ia2_A"]);
        let (m, _) = ColumnMap::guess(&["t_s", "ia_A", "wl_rad_per_s", "al_rad_per_s2"]).unwrap();
        assert_eq!(m.to_string(), "time=t_s,i_a=ia_A,omega_l=wl_rad_per_s");
        let (m, _) =
            ColumnMap::guess(&["t_s", "thl_meas_deg", "thl_ref_deg", "ch2_probably_ia_A"]).unwrap();
        assert_eq!(m.get(Signal::IA).unwrap().column, "ch2_probably_ia_A");
        let (m, _) = ColumnMap::guess(&["time_ms", "theta_l_rad", "i_a_mA"]).unwrap();
        assert_eq!(
            m.to_string(),
            "time=time_ms:ms,theta_l=theta_l_rad,i_a=i_a_mA:mA"
        );
    }

    #[test]
    fn linear_columns() {
        let m = ColumnMap::parse("time=t:s,x=q:mm,u=u_V:V,i_a=ia:A,v_x=v:m/s,ref=r:um").unwrap();
        assert_eq!(m.get(Signal::ThetaL).unwrap().unit, Unit::Millimetre);
        assert_eq!(m.get(Signal::OmegaL).unwrap().unit, Unit::MetrePerS);
        assert_eq!(
            m.to_string(),
            "time=t,x=q:mm,u=u_V,i_a=ia,v_x=v:m/s,ref=r:um"
        );
        assert_eq!(ColumnMap::parse(&m.to_string()).unwrap(), m);
        assert!(ColumnMap::parse("time=t,theta_l=q:m").is_ok());
        let e = format!("{:#}", ColumnMap::parse("time=t,theta_m=q:m").unwrap_err());
        assert!(e.contains("not an angle unit"), "{e}");
        let e = format!(
            "{:#}",
            m.factors_on(&servo_core::Transmission::GEAR).unwrap_err()
        );
        assert!(e.contains("`q`") && e.contains("[transmission]"), "{e}");
        let own = ColumnMap::servo_own(&["time_s", "u_V", "x_m", "i_a_A", "ref_m"]).unwrap();
        assert_eq!(
            own.to_string(),
            "time=time_s,u=u_V,x=x_m:m,i_a=i_a_A,ref=ref_m:m"
        );
        let (g, ign) =
            ColumnMap::guess(&["t_s", "x_mm", "theta_m", "pos_ref_mm", "u_V", "v_x_mm_s"]).unwrap();
        assert_eq!(
            g.to_string(),
            "time=t_s,x=x_mm:mm,ref=pos_ref_mm:mm,u=u_V,v_x=v_x_mm_s:mm/s"
        );
        assert_eq!(ign, ["theta_m"]);
    }

    #[test]
    fn guess_fails_with_header_and_example() {
        let e = format!("{:#}", ColumnMap::guess(&["a", "b", "c"]).unwrap_err());
        assert!(
            e.contains("`a,b,c`") && e.contains("--columns time="),
            "{e}"
        );
    }
}

#[cfg(test)]
mod honest_tests {
    use super::*;

    #[test]
    fn a_supply_voltage_is_never_u() {
        for h in [
            "v_supply_V",
            "vin_meas_V",
            "vbus_V",
            "input_voltage_V",
            "battery_V",
        ] {
            let (m, _) = ColumnMap::guess(&["t_s", "theta_l_rad", h]).unwrap();
            assert!(m.get(Signal::U).is_none(), "{h}: {m}");
            assert_eq!(m.get(Signal::VSupply).unwrap().column, h);
        }
        let (m, _) = ColumnMap::guess(&["t_s", "theta_l_rad", "u_V", "v_supply_V"]).unwrap();
        assert_eq!(m.get(Signal::U).unwrap().column, "u_V");
    }

    #[test]
    fn two_columns_of_one_signal_are_not_guessed() {
        let e = format!(
            "{:#}",
            ColumnMap::guess(&["t_s", "u_V", "u_cmd_V", "theta_l_rad"]).unwrap_err()
        );
        assert!(
            e.contains("`u_V` and `u_cmd_V`") && e.contains("--columns time=t_s,u=u_V"),
            "{e}"
        );
    }

    #[test]
    fn a_length_on_a_rotary_rig_is_refused_with_the_fix() {
        let (m, ign) = ColumnMap::guess(&["t_s", "theta_l_mm", "u_V"]).unwrap();
        assert!(ign.is_empty());
        assert_eq!(m.get(Signal::ThetaL).unwrap().unit, Unit::Millimetre);
        let e = format!(
            "{:#}",
            m.factors_on(&servo_core::Transmission::GEAR).unwrap_err()
        );
        assert!(
            e.contains("theta_l=theta_l_mm:deg") && e.contains("theta_l_rad"),
            "{e}"
        );
    }
}
