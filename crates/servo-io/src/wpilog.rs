//! WPILib DataLog files (`.wpilog`, the FRC robot logs): the decoder and the log reader.
//!
//! The format (WPILib's `datalog.adoc`): the header `WPILOG`, a u16 version 0x0100, a u32 length
//! and an extra header string; then records: one byte of field lengths (bits 0-1 the entry id's
//! length - 1, bits 2-3 the payload size's length - 1, bits 4-6 the timestamp's length - 1),
//! the entry id, the payload size and the timestamp [us] as little-endian integers of those
//! lengths, then the payload. Entry 0 carries the control records: start (an entry's id, name,
//! type and metadata), finish, set metadata. Data types decoded: `double`, `float`, `int64`,
//! `boolean`, `string` and the arrays `double[]`, `float[]`, `int64[]`, `boolean[]` (element k
//! named `NAME[k]` in `--columns`); other types (raw, struct, protobuf, `string[]`) are listed
//! by `servo inspect` and not read.
//!
//! A SysIdRoutine log (entries `voltage-M`, `position-M`, `velocity-M` and a
//! `sysid-test-state-...` string entry) is read without a column map: voltage in V, position in
//! rotations and velocity in rotations/s (or the unit the entry's metadata names), and the test
//! state as the enable column (on during a test): the tests are the log's parts.
//!
//! Every length is checked against the bytes left: a damaged file gives an error naming the
//! byte offset, never a panic or an allocation beyond the file's size.

use crate::error::{self as anyhow, anyhow, bail, Context};
use crate::series::{self, Series};
use crate::units::Signal;
use servo_core::record::Record;
use std::collections::HashMap;
use std::path::Path;

/// An example `--columns` value for a `.wpilog`.
pub const EXAMPLE: &str = "u=voltage-arm:V,theta_l=position-arm:rot,omega_l=velocity-arm:rot/s";

/// The test-state entry's prefix in a SysIdRoutine log.
pub const SYSID_STATE: &str = "sysid-test-state";

/// One entry of a DataLog (entries started again under the same name are one entry).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Entry {
    pub name: String,
    /// The WPILib type (`double`, `string`, `double[]`, ...).
    pub type_name: String,
    /// The entry's metadata (the last set).
    pub metadata: String,
    /// The records' timestamps [us].
    pub times_us: Vec<u64>,
    /// Numeric values per record (arrays: every element; `string`: empty).
    pub values: Vec<Vec<f64>>,
    /// `string` values per record.
    pub strings: Vec<String>,
}

/// A decoded DataLog.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DataLog {
    /// The extra header string.
    pub extra_header: String,
    pub entries: Vec<Entry>,
    /// Data records of unknown (not started) entries, skipped.
    pub orphans: usize,
}

fn le(b: &[u8]) -> u64 {
    b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x))
}

/// A cursor over a payload with checked reads.
struct Cur<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Cur<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if n > self.b.len() - self.at {
            return Err(format!(
                "{what} declares {n} bytes but only {} remain",
                self.b.len() - self.at
            ));
        }
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(le(self.take(4, what)?) as u32)
    }
    fn string(&mut self, what: &str) -> Result<String, String> {
        let n = self.u32(what)? as usize;
        let s = self.take(n, what)?;
        String::from_utf8(s.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }
}

/// Decodes the bytes of a `.wpilog`. Not a DataLog (no `WPILOG` magic): `Ok(None)`.
pub fn decode(bytes: &[u8]) -> Result<Option<DataLog>, String> {
    if bytes.len() < 6 || &bytes[..6] != b"WPILOG" {
        return Ok(None);
    }
    let mut c = Cur { b: bytes, at: 6 };
    let version = le(c.take(2, "the header's version")?);
    if version != 0x0100 {
        return Err(format!(
            "DataLog version 0x{version:04x}; servo reads version 0x0100 (1.0)"
        ));
    }
    let extra_header = c.string("the extra header")?;
    let mut log = DataLog {
        extra_header,
        ..DataLog::default()
    };
    // Active ids -> index into log.entries.
    let mut ids: HashMap<u32, usize> = HashMap::new();
    while c.at < bytes.len() {
        let at = c.at;
        let r = (|| -> Result<(), String> {
            let h = c.take(1, "a record's header")?[0];
            let id = le(c.take(usize::from(h & 3) + 1, "a record's entry id")?) as u32;
            let size = le(c.take(usize::from((h >> 2) & 3) + 1, "a record's size")?) as usize;
            let ts = le(c.take(usize::from((h >> 4) & 7) + 1, "a record's timestamp")?);
            let payload = c.take(size, "a record's payload")?;
            if id == 0 {
                control(&mut log, &mut ids, payload)
            } else if let Some(&k) = ids.get(&id) {
                data(&mut log.entries[k], ts, payload)
            } else {
                log.orphans += 1;
                Ok(())
            }
        })();
        r.map_err(|e| format!("record at byte {at}: {e}"))?;
    }
    Ok(Some(log))
}

fn control(log: &mut DataLog, ids: &mut HashMap<u32, usize>, p: &[u8]) -> Result<(), String> {
    let mut c = Cur { b: p, at: 0 };
    let kind = c.take(1, "a control record's type")?[0];
    let id = c.u32("a control record's entry id")?;
    match kind {
        0 => {
            let name = c.string("a start record's name")?;
            let type_name = c.string("a start record's type")?;
            let metadata = c.string("a start record's metadata")?;
            let k = match log
                .entries
                .iter()
                .position(|e| e.name == name && e.type_name == type_name)
            {
                Some(k) => k,
                None => {
                    log.entries.push(Entry {
                        name,
                        type_name,
                        metadata: metadata.clone(),
                        ..Entry::default()
                    });
                    log.entries.len() - 1
                }
            };
            log.entries[k].metadata = metadata;
            ids.insert(id, k);
        }
        1 => {
            ids.remove(&id);
        }
        2 => {
            let m = c.string("a set-metadata record's metadata")?;
            if let Some(&k) = ids.get(&id) {
                log.entries[k].metadata = m;
            }
        }
        other => return Err(format!("unknown control record type {other}")),
    }
    Ok(())
}

fn data(e: &mut Entry, ts: u64, p: &[u8]) -> Result<(), String> {
    let fixed = |n: usize| -> Result<(), String> {
        if !p.len().is_multiple_of(n) {
            Err(format!(
                "entry `{}` ({}): a payload of {} bytes is not a multiple of {n}",
                e.name,
                e.type_name,
                p.len()
            ))
        } else {
            Ok(())
        }
    };
    let vals: Vec<f64> = match e.type_name.as_str() {
        "double" | "double[]" | "int64" | "int64[]" => {
            fixed(8)?;
            let int = e.type_name.starts_with("int64");
            p.chunks_exact(8)
                .map(|b| {
                    let x = le(b);
                    if int {
                        x as i64 as f64
                    } else {
                        f64::from_bits(x)
                    }
                })
                .collect()
        }
        "float" | "float[]" => {
            fixed(4)?;
            p.chunks_exact(4)
                .map(|b| f64::from(f32::from_bits(le(b) as u32)))
                .collect()
        }
        "boolean" | "boolean[]" => p.iter().map(|&b| f64::from(u8::from(b != 0))).collect(),
        "string" => {
            let s = String::from_utf8_lossy(p).into_owned();
            e.strings.push(s);
            e.times_us.push(ts);
            return Ok(());
        }
        _ => {
            e.times_us.push(ts);
            return Ok(());
        }
    };
    if !e.type_name.ends_with("[]") && vals.len() != 1 {
        return Err(format!(
            "entry `{}` ({}): a payload of {} bytes holds {} values, not one",
            e.name,
            e.type_name,
            p.len(),
            vals.len()
        ));
    }
    e.times_us.push(ts);
    e.values.push(vals);
    Ok(())
}

/// The bytes of `path`, refused after the first 6 when they are not a DataLog.
fn read_bytes(path: &Path) -> anyhow::Result<DataLog> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    match decode(&bytes) {
        Ok(Some(log)) => Ok(log),
        Ok(None) => bail!(
            "{}: not a WPILib DataLog (the file does not start with `WPILOG`)",
            path.display()
        ),
        Err(e) => bail!("{}: damaged WPILib DataLog: {e}", path.display()),
    }
}

impl DataLog {
    /// The numeric series of the log: each scalar entry by its name, each element k of an array
    /// entry as `NAME[k]`, a `sysid-test-state` string entry as 1 during a test and 0 at `none`.
    /// Times [s] from the records' timestamps.
    pub fn series(&self) -> Vec<Series> {
        let mut out = Vec::new();
        for e in &self.entries {
            let t: Vec<f64> = e.times_us.iter().map(|&t| t as f64 * 1e-6).collect();
            if e.type_name == "string" && e.name.starts_with(SYSID_STATE) {
                out.push(Series {
                    name: e.name.clone(),
                    t_s: t,
                    v: e.strings
                        .iter()
                        .map(|s| f64::from(u8::from(!s.is_empty() && s != "none")))
                        .collect(),
                });
            } else if e.type_name.ends_with("[]") {
                let width = e.values.iter().map(Vec::len).max().unwrap_or(0).min(64);
                for k in 0..width {
                    out.push(Series {
                        name: format!("{}[{k}]", e.name),
                        t_s: t.clone(),
                        v: e.values
                            .iter()
                            .map(|v| v.get(k).copied().unwrap_or(f64::NAN))
                            .collect(),
                    });
                }
            } else if !e.values.is_empty() {
                out.push(Series {
                    name: e.name.clone(),
                    t_s: t,
                    v: e.values.iter().map(|v| v[0]).collect(),
                });
            }
        }
        out
    }

    /// The SysIdRoutine map (`u=voltage-M:V,theta_l=position-M:rot,omega_l=velocity-M:rot/s,
    /// enable=sysid-test-state-...`), units from the entries' metadata where it names one;
    /// `None` when the log is not one motor's SysIdRoutine log.
    pub fn sysid_map(&self) -> Option<String> {
        let state = self
            .entries
            .iter()
            .find(|e| e.name.starts_with(SYSID_STATE) && e.type_name == "string")?;
        let has = |n: &str| {
            self.entries
                .iter()
                .find(|e| e.name == n && !e.values.is_empty())
        };
        let motors: Vec<&str> = self
            .entries
            .iter()
            .filter_map(|e| e.name.strip_prefix("voltage-"))
            .filter(|m| has(&format!("position-{m}")).is_some())
            .collect();
        let [m] = motors.as_slice() else {
            return None;
        };
        let unit = |n: &str, default: &str| {
            has(n)
                .and_then(|e| metadata_unit(&e.metadata))
                .unwrap_or(default)
                .to_string()
        };
        let mut map = format!(
            "u=voltage-{m}:V,theta_l=position-{m}:{}",
            unit(&format!("position-{m}"), "rot")
        );
        if has(&format!("velocity-{m}")).is_some() {
            map.push_str(&format!(
                ",omega_l=velocity-{m}:{}",
                unit(&format!("velocity-{m}"), "rot/s")
            ));
        }
        map.push_str(&format!(",enable={}", state.name));
        Some(map)
    }

    /// The SysId tests in order: (state, first and last time [s] from the log's start).
    pub fn sysid_tests(&self, t0_s: f64) -> Vec<(String, f64, f64)> {
        let mut out: Vec<(String, f64, f64)> = Vec::new();
        for e in self
            .entries
            .iter()
            .filter(|e| e.name.starts_with(SYSID_STATE) && e.type_name == "string")
        {
            for (s, &t) in e.strings.iter().zip(&e.times_us) {
                let t = t as f64 * 1e-6 - t0_s;
                match out.last_mut() {
                    Some(last) if last.0 == *s => last.2 = t,
                    _ => out.push((s.clone(), t, t)),
                }
            }
        }
        out.retain(|(s, _, _)| !s.is_empty() && s != "none");
        out
    }

    /// The earliest data timestamp [s].
    pub fn start_s(&self) -> f64 {
        self.entries
            .iter()
            .filter_map(|e| e.times_us.first())
            .min()
            .map_or(0.0, |&t| t as f64 * 1e-6)
    }
}

/// The servo unit a SysId entry's metadata names (WPILib's unit names, e.g. `Rotation`,
/// `Rotation per Second`, `Volt`; a plain `rot`, `deg`, ... is taken as is).
pub fn metadata_unit(meta: &str) -> Option<&'static str> {
    let m = meta.trim().to_ascii_lowercase();
    let m = m.trim_end_matches('s');
    Some(match m {
        "volt" | "v" => "V",
        "rotation" | "rot" | "rev" => "rot",
        "rotation per second" | "rotations per second" | "rot/" | "rp" => "rot/s",
        "radian" | "rad" => "rad",
        "radian per second" | "radians per second" | "rad/" => "rad/s",
        "degree" | "deg" => "deg",
        "degree per second" | "degrees per second" | "deg/" => "deg/s",
        "meter" | "metre" | "m" => "m",
        "meter per second" | "meters per second" | "m/" => "m/s",
        "rpm" => "rpm",
        _ => return None,
    })
}

/// servo's reader of WPILib DataLogs (`.wpilog`).
pub struct WpilogReader;

impl crate::log_reader::LogReader for WpilogReader {
    fn name(&self) -> &'static str {
        "WPILib DataLog"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["wpilog"]
    }
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        want: Option<&[Signal]>,
        axis: &servo_core::Transmission,
    ) -> anyhow::Result<(Record, crate::LogMeta)> {
        let source = path.display().to_string();
        let log = read_bytes(path)?;
        let mut notes = Vec::new();
        let t0 = log.start_s();
        let text = match columns {
            Some(c) => c.to_string(),
            None => {
                let m = log.sysid_map().ok_or_else(|| {
                    anyhow!(
                        "{source}: not one motor's SysIdRoutine log (entries voltage-M, position-M, \
                         velocity-M and sysid-test-state-...): name the entries with --columns, e.g. \
                         --columns {EXAMPLE} (`servo inspect {source}` lists them)"
                    )
                })?;
                notes.push(format!(
                    "{source}: a SysIdRoutine log: read with --columns {m}"
                ));
                m
            }
        };
        let map = series::parse_map(&text, "WPILib DataLog", EXAMPLE)?;
        if map
            .get(Signal::Enable)
            .is_some_and(|e| e.column.starts_with(SYSID_STATE))
        {
            let tests = log.sysid_tests(t0);
            if !tests.is_empty() {
                let list: Vec<String> = tests
                    .iter()
                    .map(|(s, a, b)| format!("{s} {a:.3} .. {b:.3} s"))
                    .collect();
                notes.push(format!(
                    "{source}: SysId tests (the log's parts, by the test state): {}; a command \
                     uses the first (--window START..END picks another)",
                    list.join(", ")
                ));
            }
        }
        let (rec, n) = series::build(&log.series(), &map, want, axis, t0, &source)?;
        notes.extend(n);
        let meta = crate::LogMeta {
            columns: Some(map.to_string()),
            notes,
            ..crate::LogMeta::default()
        };
        Ok((rec, meta))
    }
    fn inspect(&self, path: &Path) -> anyhow::Result<Vec<String>> {
        let source = path.display().to_string();
        let log = read_bytes(path)?;
        let mut out = vec![format!(
            "{source}: WPILib DataLog, {} entries{}",
            log.entries.len(),
            if log.extra_header.is_empty() {
                String::new()
            } else {
                format!(", header `{}`", log.extra_header)
            }
        )];
        for e in &log.entries {
            let t: Vec<f64> = e.times_us.iter().map(|&t| t as f64 * 1e-6).collect();
            out.push(format!(
                "  entry {}: {}, {} records, {}{}",
                e.name,
                e.type_name,
                e.times_us.len(),
                series::rate_text(&t),
                if e.metadata.is_empty() {
                    String::new()
                } else {
                    format!(", metadata `{}`", e.metadata)
                }
            ));
        }
        for (s, a, b) in log.sysid_tests(log.start_s()) {
            out.push(format!("  SysId test {s}: {a:.3} .. {b:.3} s"));
        }
        out.push(match log.sysid_map() {
            Some(m) => format!("SysIdRoutine log: read as --columns {m}"),
            None => format!("no guessed map: name the entries, e.g. --columns {EXAMPLE}"),
        });
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record with 1-byte id and size and a 4-byte timestamp.
    fn rec(id: u8, ts: u32, payload: &[u8]) -> Vec<u8> {
        let mut v = vec![0x30, id, payload.len() as u8];
        v.extend_from_slice(&ts.to_le_bytes());
        v.extend_from_slice(payload);
        v
    }

    fn start(id: u32, name: &str, ty: &str, meta: &str) -> Vec<u8> {
        let mut p = vec![0u8];
        p.extend_from_slice(&id.to_le_bytes());
        for s in [name, ty, meta] {
            p.extend_from_slice(&(s.len() as u32).to_le_bytes());
            p.extend_from_slice(s.as_bytes());
        }
        rec(0, 0, &p)
    }

    fn sample_log() -> Vec<u8> {
        let mut b = b"WPILOG".to_vec();
        b.extend_from_slice(&0x0100u16.to_le_bytes());
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(b"hi");
        b.extend(start(1, "voltage-arm", "double", "Volt"));
        b.extend(start(2, "position-arm", "float", "Rotation"));
        b.extend(start(3, "sysid-test-state-arm", "string", ""));
        b.extend(start(4, "flags", "int64[]", ""));
        for k in 0..4u32 {
            b.extend(rec(1, 1000 * k, &(k as f64).to_le_bytes()));
            b.extend(rec(2, 1000 * k, &(0.5f32 * k as f32).to_le_bytes()));
            let s = if k < 2 { "quasistatic-forward" } else { "none" };
            b.extend(rec(3, 1000 * k, s.as_bytes()));
            let mut a = (k as i64).to_le_bytes().to_vec();
            a.extend_from_slice(&(-(k as i64)).to_le_bytes());
            b.extend(rec(4, 1000 * k, &a));
        }
        b
    }

    #[test]
    fn decodes_entries_and_sysid() {
        let log = decode(&sample_log()).unwrap().unwrap();
        assert_eq!(log.extra_header, "hi");
        assert_eq!(log.entries.len(), 4);
        let s = log.series();
        let pos = s.iter().find(|s| s.name == "position-arm").unwrap();
        assert_eq!(pos.v, vec![0.0, 0.5, 1.0, 1.5]);
        assert_eq!(pos.t_s[3], 0.003);
        let f1 = s.iter().find(|s| s.name == "flags[1]").unwrap();
        assert_eq!(f1.v[3], -3.0);
        let state = s.iter().find(|s| s.name == "sysid-test-state-arm").unwrap();
        assert_eq!(state.v, vec![1.0, 1.0, 0.0, 0.0]);
        assert_eq!(
            log.sysid_map().unwrap(),
            "u=voltage-arm:V,theta_l=position-arm:rot,enable=sysid-test-state-arm"
        );
        assert_eq!(
            log.sysid_tests(0.0),
            vec![("quasistatic-forward".into(), 0.0, 0.001)]
        );
    }

    #[test]
    fn truncated_and_hostile_input_is_an_error() {
        let b = sample_log();
        for cut in 0..b.len() {
            // Every prefix: an error or a log, never a panic.
            let _ = decode(&b[..cut]);
        }
        // A size field claiming more than the file holds.
        let mut bad = b[..20].to_vec();
        bad.extend_from_slice(&[0x3c, 1, 0xff, 0xff, 0xff, 0x7f, 0, 0, 0, 0]);
        let e = decode(&bad).unwrap_err();
        assert!(e.contains("declares"), "{e}");
        // A double with 5 bytes.
        let mut odd = b.clone();
        odd.extend(rec(1, 9, &[1, 2, 3, 4, 5]));
        assert!(decode(&odd).unwrap_err().contains("multiple of 8"));
        let mut v = b.clone();
        v[6] = 2;
        assert!(decode(&v).unwrap_err().contains("version"));
        assert_eq!(decode(b"PK\x03\x04").unwrap(), None);
    }
}
