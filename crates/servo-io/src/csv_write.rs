//! Writing a [`Record`] as servo's CSV: `time_s,u_V,theta_l_rad,i_a_A[,ref_rad,theta_m_rad,
//! omega_l_rad_s,omega_m_rad_s]` (only the signals present), SI units, shortest round-trip
//! number format.

use super::units::Signal;
use crate::error::{self as anyhow, bail};
use servo_core::record::Record;
use servo_core::Transmission;
use std::io::Write;
use std::path::Path;

/// Column order of servo's CSV.
pub const ORDER: [Signal; 11] = [
    Signal::Time,
    Signal::U,
    Signal::ThetaL,
    Signal::IA,
    Signal::Ref,
    Signal::ThetaM,
    Signal::OmegaL,
    Signal::OmegaM,
    Signal::IRef,
    Signal::Duty,
    Signal::VSupply,
];

/// The samples of `signal` in `rec`, if present.
pub fn signal_of(rec: &Record, signal: Signal) -> Option<&[f64]> {
    match signal {
        Signal::Time => Some(&rec.time_s),
        Signal::U => rec.u_v.as_deref(),
        Signal::ThetaL => rec.theta_l_rad.as_deref(),
        Signal::ThetaM => rec.theta_m_rad.as_deref(),
        Signal::OmegaL => rec.omega_l_rad_s.as_deref(),
        Signal::OmegaM => rec.omega_m_rad_s.as_deref(),
        Signal::IA => rec.i_a_a.as_deref(),
        Signal::Ref => rec.ref_rad.as_deref(),
        Signal::Enable => rec.enable.as_deref(),
        Signal::IRef => rec.i_ref_a.as_deref(),
        Signal::Duty => rec.duty.as_deref(),
        Signal::VSupply => rec.v_supply_v.as_deref(),
    }
}

/// Writes `rec` to `out` as servo's CSV.
pub fn write_csv_to(out: &mut dyn Write, rec: &Record) -> anyhow::Result<()> {
    write_csv_to_on(out, rec, &Transmission::GEAR)
}

/// Writes `rec` to `out` as servo's CSV of the axis `axis`: on a linear axis (a screw, a belt)
/// the load position, its speed and the reference in metres (`x_m`, `v_x_m_s`, `ref_m`: the
/// record's equivalent rotation times the travel per radian), which every servo command reads
/// back on that axis without `--columns`; the motor angle stays in rad.
pub fn write_csv_to_on(
    out: &mut dyn Write,
    rec: &Record,
    axis: &Transmission,
) -> anyhow::Result<()> {
    let metres = axis.metres_per_rad();
    let cols: Vec<(Signal, &str, f64, &[f64])> = ORDER
        .iter()
        .filter_map(|&s| {
            let v = signal_of(rec, s)?;
            Some(match (metres, s.csv_column_linear()) {
                (Some(m), Some(name)) => (s, name, m, v),
                _ => (s, s.csv_column(), 1.0, v),
            })
        })
        .collect();
    for (s, _, _, v) in &cols {
        if v.len() != rec.time_s.len() {
            bail!(
                "signal `{s}` has {} samples but time_s has {}",
                v.len(),
                rec.time_s.len()
            );
        }
    }
    let header: Vec<&str> = cols.iter().map(|(_, name, _, _)| *name).collect();
    let mut line = String::with_capacity(128);
    line.push_str(&header.join(","));
    line.push('\n');
    out.write_all(line.as_bytes())?;
    for k in 0..rec.time_s.len() {
        line.clear();
        for (j, (_, _, f, v)) in cols.iter().enumerate() {
            if j > 0 {
                line.push(',');
            }
            use std::fmt::Write as _;
            if *f == 1.0 {
                let _ = write!(line, "{}", v[k]);
            } else {
                let _ = write!(line, "{}", v[k] * f);
            }
        }
        line.push('\n');
        out.write_all(line.as_bytes())?;
    }
    Ok(())
}

/// Writes `rec` to the file `path` as servo's CSV.
pub fn write_csv(path: &Path, rec: &Record) -> anyhow::Result<()> {
    write_csv_on(path, rec, &Transmission::GEAR)
}

/// Writes `rec` to the file `path` as servo's CSV of the axis `axis` ([`write_csv_to_on`]).
pub fn write_csv_on(path: &Path, rec: &Record, axis: &Transmission) -> anyhow::Result<()> {
    let mut w = crate::output::AtomicFile::create(path, "CSV")?;
    if let Err(e) = write_csv_to_on(&mut w, rec, axis) {
        return Err(w.error(e));
    }
    w.commit()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_exact() {
        let rec = Record {
            source: "mem".into(),
            time_s: vec![0.0, 0.001, 0.002],
            u_v: Some(vec![1.0 / 3.0, -2.5, 1e-17]),
            theta_l_rad: Some(vec![0.1, 0.2, std::f64::consts::PI]),
            i_a_a: Some(vec![0.0, 0.5, -0.123456789012345]),
            ref_rad: Some(vec![1.5; 3]),
            omega_l_rad_s: Some(vec![0.0, 100.0, f64::NAN]),
            ..Record::default()
        };
        let mut buf = Vec::new();
        write_csv_to(&mut buf, &rec).unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert!(
            text.starts_with("time_s,u_V,theta_l_rad,i_a_A,ref_rad,omega_l_rad_s\n"),
            "{text}"
        );
        let back = super::super::csv_read::parse_csv(&text, "mem", None).unwrap();
        assert!(
            back.notes.iter().all(|n| n.contains("non-finite")),
            "{:?}",
            back.notes
        );
        let b = back.record;
        assert_eq!(b.time_s, rec.time_s);
        assert_eq!(b.u_v, rec.u_v);
        assert_eq!(b.theta_l_rad, rec.theta_l_rad);
        assert_eq!(b.i_a_a, rec.i_a_a);
        assert_eq!(b.ref_rad, rec.ref_rad);
        assert!(b.omega_l_rad_s.unwrap()[2].is_nan());
    }

    #[test]
    fn a_linear_axis_writes_metres_that_read_back() {
        use servo_core::transmission::{EncoderSide, TransmissionKind};
        let axis = Transmission {
            kind: TransmissionKind::Screw { lead_m: 0.004 },
            encoder: EncoderSide::Load,
        };
        let s = 0.004 / std::f64::consts::TAU;
        let rec = Record {
            source: "mem".into(),
            time_s: vec![0.0, 0.001, 0.002],
            u_v: Some(vec![0.0, 1.0, 2.0]),
            theta_l_rad: Some(vec![0.0, 1.0, 2.0]),
            theta_m_rad: Some(vec![0.0, 3.0, 6.0]),
            ref_rad: Some(vec![5.0; 3]),
            omega_l_rad_s: Some(vec![0.0, 10.0, 20.0]),
            ..Record::default()
        };
        let mut buf = Vec::new();
        write_csv_to_on(&mut buf, &rec, &axis).unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert!(
            text.starts_with("time_s,u_V,x_m,ref_m,theta_m_rad,v_x_m_s\n"),
            "{text}"
        );
        let row: Vec<f64> = text
            .lines()
            .nth(2)
            .unwrap()
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect();
        assert!((row[2] - s).abs() < 1e-15 && (row[3] - 5.0 * s).abs() < 1e-15);
        assert_eq!(row[4], 3.0);
        let back = super::super::csv_read::parse_csv_on(&text, "mem", None, None, &axis)
            .unwrap()
            .record;
        for (a, b) in back
            .theta_l_rad
            .unwrap()
            .iter()
            .zip(rec.theta_l_rad.unwrap())
        {
            assert!((a - b).abs() < 1e-12, "{a} {b}");
        }
        assert_eq!(back.theta_m_rad, rec.theta_m_rad);
        for (a, b) in back
            .omega_l_rad_s
            .unwrap()
            .iter()
            .zip(rec.omega_l_rad_s.unwrap())
        {
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
    }
}
