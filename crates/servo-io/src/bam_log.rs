//! Rhoban BAM's JSON logs of a smart servo (github.com/Rhoban/bam, `bam/*/record.py`): one
//! object with the bench (`mass`, `length` [kg, m], `kp` the firmware gain, `vin` [V], `motor`,
//! `trajectory`) and `entries`, one per host poll: `timestamp` [s], `position` [rad], `speed`
//! [rad/s], `goal_position` [rad], `torque_enable` (bool), and, when logged, `load` (the
//! Dynamixel XL330's present PWM as a duty in [-1, 1]), `input_volts` [V] and `temp` [deg C].
//!
//! The host polls with jitter: the entries are resampled onto a uniform grid at their median
//! period by linear interpolation (the torque enable held from the entry before), as BAM itself
//! does before fitting. The record holds the angle (`theta_l`), the speed, the goal as the
//! reference, the duty, the supply (never as u) and the enable.

use crate::error::{Error, Result};
use crate::log_reader::LogReader;
use crate::units::Signal;
use crate::LogMeta;
use servo_core::record::Record;
use std::path::Path;

/// The most entries a BAM log may have (an hour at 1 kHz).
pub const MAX_ENTRIES: usize = 4_000_000;

/// The reader of BAM's JSON logs.
pub struct BamReader;

/// A BAM log read: the record on its uniform grid and the bench's values.
#[derive(Debug, Clone, PartialEq)]
pub struct BamLog {
    pub record: Record,
    /// The firmware gain `kp` in the vendor's units, when given.
    pub kp_fw: Option<f64>,
    /// The load's mass [kg] and length [m], when given.
    pub mass_kg: Option<f64>,
    pub length_m: Option<f64>,
    /// The supply `vin` [V], when given.
    pub vin_v: Option<f64>,
    /// Entries read (before resampling).
    pub entries: usize,
}

fn bad(name: &str, why: String) -> Error {
    Error::Invalid(format!("{name}: {why}"))
}

/// Reads a BAM JSON log (see the module).
pub fn read_bam(path: &Path) -> Result<BamLog> {
    let name = path.display().to_string();
    let text = crate::text_file::read_text(path).map_err(|e| bad(&name, e.to_string()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| bad(&name, format!("not JSON ({e}); expected a BAM log")))?;
    let Some(entries) = v.get("entries").and_then(|e| e.as_array()) else {
        return Err(bad(
            &name,
            "no \"entries\" array: expected a BAM log (an object with \"entries\" of timestamp, position, goal_position, ...)".into(),
        ));
    };
    if entries.len() > MAX_ENTRIES {
        return Err(bad(
            &name,
            format!(
                "{} entries, more than {MAX_ENTRIES}: cut the log",
                entries.len()
            ),
        ));
    }
    if entries.len() < 3 {
        return Err(bad(
            &name,
            format!("{} entries: a log needs at least 3", entries.len()),
        ));
    }
    let top = |k: &str| v.get(k).and_then(|x| x.as_f64()).filter(|x| x.is_finite());
    let col = |key: &str, need: bool| -> Result<Option<Vec<f64>>> {
        let mut out = Vec::with_capacity(entries.len());
        for (i, e) in entries.iter().enumerate() {
            let x = match e.get(key) {
                Some(serde_json::Value::Bool(b)) => Some(if *b { 1.0 } else { 0.0 }),
                Some(x) => x.as_f64().filter(|x| x.is_finite()),
                None => None,
            };
            match (x, need, i) {
                (Some(x), _, _) => out.push(x),
                (None, false, 0) => return Ok(None),
                (None, _, _) => {
                    return Err(bad(
                        &name,
                        format!("entries[{i}]: \"{key}\" is missing or not a finite number"),
                    ))
                }
            }
        }
        Ok(Some(out))
    };
    let t = col("timestamp", true)?.unwrap_or_default();
    let theta = col("position", true)?.unwrap_or_default();
    let goal = col("goal_position", true)?.unwrap_or_default();
    let speed = col("speed", false)?;
    let duty = col("load", false)?;
    let vin = col("input_volts", false)?;
    let enable = col("torque_enable", false)?;
    if let Some(k) = t.windows(2).position(|w| w[1] <= w[0]) {
        return Err(bad(
            &name,
            format!("entries[{}]: the timestamp does not increase", k + 1),
        ));
    }
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    let dt = match top("dt") {
        Some(dt) if dt > 0.0 => dt,
        _ => d[d.len() / 2],
    };
    let n = ((t[t.len() - 1] - t[0]) / dt).floor() as usize + 1;
    let grid: Vec<f64> = (0..n).map(|k| t[0] + k as f64 * dt).collect();
    // Linear interpolation (and the entry at or before, for the enable) on the grid.
    let mut at = Vec::with_capacity(n);
    let mut j = 0usize;
    for &g in &grid {
        while j + 2 < t.len() && t[j + 1] <= g {
            j += 1;
        }
        let f = ((g - t[j]) / (t[j + 1] - t[j])).clamp(0.0, 1.0);
        at.push((j, f));
    }
    let lin = |x: &[f64]| -> Vec<f64> {
        at.iter()
            .map(|&(j, f)| x[j] + f * (x[j + 1] - x[j]))
            .collect()
    };
    let held = |x: &[f64]| -> Vec<f64> {
        at.iter()
            .map(|&(j, f)| if f >= 1.0 { x[j + 1] } else { x[j] })
            .collect()
    };
    let record = Record {
        source: name,
        time_s: grid.iter().map(|g| g - t[0]).collect(),
        theta_l_rad: Some(lin(&theta)),
        omega_l_rad_s: speed.as_deref().map(lin),
        ref_rad: Some(lin(&goal)),
        duty: duty.as_deref().map(lin),
        v_supply_v: vin.as_deref().map(lin),
        enable: enable.as_deref().map(held),
        ..Record::default()
    };
    Ok(BamLog {
        record,
        kp_fw: top("kp"),
        mass_kg: top("mass"),
        length_m: top("length"),
        vin_v: top("vin"),
        entries: entries.len(),
    })
}

impl LogReader for BamReader {
    fn name(&self) -> &'static str {
        "BAM JSON"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["json"]
    }
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        _want: Option<&[Signal]>,
        _axis: &servo_core::Transmission,
    ) -> Result<(Record, LogMeta)> {
        if columns.is_some() {
            return Err(Error::Invalid(format!(
                "{}: a BAM JSON log names its own signals: drop --columns",
                path.display()
            )));
        }
        let b = read_bam(path)?;
        let meta = LogMeta {
            notes: vec![format!(
                "{}: {} BAM entries resampled onto a uniform {} ms grid (linear interpolation)",
                path.display(),
                b.entries,
                servo_core::math::sig(1e3 * b.record.time_s.get(1).copied().unwrap_or(0.0), 3)
            )],
            ..LogMeta::default()
        };
        Ok((b.record, meta))
    }
    fn inspect(&self, path: &Path) -> Result<Vec<String>> {
        let b = read_bam(path)?;
        let r = &b.record;
        let mut out = vec![format!(
            "{}: BAM JSON log of a smart servo, {} entries, {} rows on a uniform grid",
            path.display(),
            b.entries,
            r.len()
        )];
        for (what, present) in [
            ("position -> theta_l [rad]", r.theta_l_rad.is_some()),
            (
                "goal_position -> ref [rad] (the goal the host wrote)",
                r.ref_rad.is_some(),
            ),
            (
                "speed -> omega_l [rad/s] (the servo's estimate)",
                r.omega_l_rad_s.is_some(),
            ),
            (
                "load -> duty [-1, 1] (the firmware's PWM)",
                r.duty.is_some(),
            ),
            (
                "input_volts -> v_supply [V] (the supply, not u)",
                r.v_supply_v.is_some(),
            ),
            ("torque_enable -> enable", r.enable.is_some()),
        ] {
            if present {
                out.push(format!("  {what}"));
            }
        }
        if let Some(kp) = b.kp_fw {
            out.push(format!("  firmware gain kp = {kp} (vendor units)"));
        }
        if let (Some(m), Some(l)) = (b.mass_kg, b.length_m) {
            out.push(format!(
                "  load: {m} kg at {l} m (m g L = {} N m)",
                servo_core::math::sig(m * 9.80665 * l, 4)
            ));
        }
        Ok(out)
    }
}
