//! A MAT-file as a log: the `--columns` map with MATLAB paths, a guessed map from Simulink Scope
//! labels, signals on their own Scope time resampled onto the log's time, and the listing
//! `servo inspect` prints.

use super::columns::{ColumnMap, ColumnSpec};
use super::mat_path::{resolve, MatPath, Series};
use super::mat_read::{dims_text, numel, read_mat_file, MatFile, MatValue};
use super::units::Signal;
use crate::error::{self as anyhow, anyhow, bail, Context};
use servo_core::record::Record;
use std::path::Path;

/// An example `--columns` value for MAT-files.
pub const EXAMPLE: &str = "time=scope.time,theta_l=scope.signals(1).values:deg,u=scope.signals(2).values,i_a=ia_scope.signals.values";

/// A MAT-file read into a record, with the map used and notes for the user.
#[derive(Debug, Clone)]
pub struct MatImport {
    pub record: Record,
    pub map: ColumnMap,
    pub notes: Vec<String>,
}

/// Reads the MAT-file at `path` as a log. `columns` maps signals to MATLAB paths; `None` guesses
/// the map from the Scope labels (stated in the notes).
pub fn read_mat_log(path: &Path, columns: Option<&str>) -> anyhow::Result<MatImport> {
    read_mat_log_on(path, columns, &servo_core::Transmission::GEAR)
}

/// [`read_mat_log`] on the axis `axis` (see [`import_on`]).
pub fn read_mat_log_on(
    path: &Path,
    columns: Option<&str>,
    axis: &servo_core::Transmission,
) -> anyhow::Result<MatImport> {
    let source = path.display().to_string();
    let file = read_mat_file(path).with_context(|| source.clone())?;
    import_on(&file, &source, columns, axis)
}

/// servo's reader of MATLAB MAT-files (`.mat`, Level 5, -v6/-v7) as logs.
pub struct MatReader;

impl crate::log_reader::LogReader for MatReader {
    fn name(&self) -> &'static str {
        "MAT-file"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["mat"]
    }
    /// Every mapped signal (the MAT-file is read whole; `want` is not used).
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        _want: Option<&[Signal]>,
        axis: &servo_core::Transmission,
    ) -> anyhow::Result<(Record, crate::LogMeta)> {
        let imp = read_mat_log_on(path, columns, axis)?;
        Ok((
            imp.record,
            crate::LogMeta {
                columns: Some(imp.map.to_string()),
                notes: imp.notes,
                ..crate::LogMeta::default()
            },
        ))
    }
    /// The variables, struct fields, sizes and Scope labels ([`describe`]) and the map servo
    /// would guess.
    fn inspect(&self, path: &Path) -> anyhow::Result<Vec<String>> {
        let source = path.display().to_string();
        let file = read_mat_file(path).with_context(|| source.clone())?;
        let mut out = vec![format!(
            "{source}: MAT-file, {} variables",
            file.variables.len()
        )];
        out.extend(describe(&file).into_iter().map(|l| format!("  {l}")));
        out.push(crate::log_reader::guessed(
            guess(&file).map(|m| m.to_string()),
        ));
        Ok(out)
    }
}

/// Builds a record from `file`; `source` names the file in messages.
pub fn import(file: &MatFile, source: &str, columns: Option<&str>) -> anyhow::Result<MatImport> {
    import_on(file, source, columns, &servo_core::Transmission::GEAR)
}

/// [`import`] on the axis `axis`: a signal in a length or linear speed unit becomes the load
/// shaft's equivalent rotation [rad] ([`crate::csv_read::read_csv_on`]).
pub fn import_on(
    file: &MatFile,
    source: &str,
    columns: Option<&str>,
    axis: &servo_core::Transmission,
) -> anyhow::Result<MatImport> {
    let mut notes = Vec::new();
    let map = match columns {
        Some(c) => ColumnMap::parse(c)?,
        None => {
            let m = guess(file).with_context(|| source.to_string())?;
            notes.push(format!("{source}: guessed the column map --columns {m}"));
            m
        }
    };
    let get = |e: &ColumnSpec| -> anyhow::Result<Series> {
        let p = MatPath::parse(&e.column).map_err(|m| anyhow!("--columns `{}`: {m}", e.signal))?;
        resolve(file, &p).map_err(|m| anyhow!("{source}: signal `{}`: {m}", e.signal))
    };
    let factors = map.factors_on(axis).with_context(|| source.to_string())?;
    let time_spec = map
        .get(Signal::Time)
        .ok_or_else(|| anyhow!("--columns: `time=<path>` is required"))?;
    let time: Vec<f64> = get(time_spec)?
        .values
        .iter()
        .map(|&t| time_spec.unit.to_si(t))
        .collect();
    if time.is_empty() {
        bail!("{source}: the time `{}` is empty", time_spec.column);
    }
    if let Some(k) =
        (0..time.len()).find(|&k| !time[k].is_finite() || (k > 0 && time[k] <= time[k - 1]))
    {
        bail!(
            "{source}: the time `{}` must be finite and increase strictly; sample {} is {} s{}",
            time_spec.column,
            k + 1,
            time[k],
            if k > 0 {
                format!(" after {} s", time[k - 1])
            } else {
                String::new()
            }
        );
    }
    let mut rec = Record {
        source: source.to_string(),
        time_s: time.clone(),
        ..Record::default()
    };
    for (e, &factor) in map
        .entries
        .iter()
        .zip(&factors)
        .filter(|(e, _)| e.signal != Signal::Time)
    {
        let s = get(e)?;
        let raw = match &s.own_time {
            Some((tpath, t)) if t.len() == s.values.len() && !same_time(t, &time) => {
                if let Some(k) =
                    (0..t.len()).find(|&k| !t[k].is_finite() || (k > 0 && t[k] <= t[k - 1]))
                {
                    bail!(
                        "{source}: `{}` (signal `{}`) has its own time `{tpath}`, which is not finite and strictly increasing at sample {}",
                        e.column,
                        e.signal,
                        k + 1
                    );
                }
                let (v, outside) = resample(t, &s.values, &time);
                let mut note = format!(
                    "{source}: `{}` ({}) has its own time `{tpath}` ({} samples, {:.4}..{:.4} s); resampled linearly onto `{}`",
                    e.column,
                    e.signal,
                    t.len(),
                    t[0],
                    t[t.len() - 1],
                    time_spec.column
                );
                if outside > 0 {
                    note.push_str(&format!(" ({outside} samples outside its time are NaN)"));
                }
                notes.push(note);
                v
            }
            _ if s.values.len() == time.len() => s.values,
            _ => bail!(
                "{source}: `{}` (signal `{}`) has {} samples, the time `{}` has {}{}",
                e.column,
                e.signal,
                s.values.len(),
                time_spec.column,
                time.len(),
                match &s.own_time {
                    Some((p, t)) => format!(" (its own time `{p}` has {})", t.len()),
                    None => String::new(),
                }
            ),
        };
        let nans = raw.iter().filter(|v| !v.is_finite()).count();
        if nans > 0 && !notes.iter().any(|n| n.contains(&e.column)) {
            notes.push(format!(
                "{source}: `{}` has {nans} non-finite values (kept as NaN)",
                e.column
            ));
        }
        let col: Vec<f64> = raw.iter().map(|&v| v * factor).collect();
        if e.signal != Signal::Time {
            e.signal.store(&mut rec, col);
        }
    }
    for s in &file.skipped {
        if s.contains("subsystem") {
            continue;
        }
        notes.push(format!("{source}: skipped {s}"));
    }
    Ok(MatImport {
        record: rec,
        map,
        notes,
    })
}

/// True when two time vectors are the same samples (within 1 ns).
fn same_time(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9)
}

/// Linear interpolation of (t, v) at `at` (sorted); NaN outside `t`. Returns the values and how
/// many were outside.
fn resample(t: &[f64], v: &[f64], at: &[f64]) -> (Vec<f64>, usize) {
    let mut out = Vec::with_capacity(at.len());
    let mut outside = 0;
    let mut k = 0;
    for &x in at {
        let (first, last) = (t[0], t[t.len() - 1]);
        if !(x >= first && x <= last) {
            outside += 1;
            out.push(f64::NAN);
            continue;
        }
        while k + 2 < t.len() && t[k + 1] < x {
            k += 1;
        }
        let (t0, t1) = (t[k], t[(k + 1).min(t.len() - 1)]);
        let (v0, v1) = (v[k], v[(k + 1).min(v.len() - 1)]);
        out.push(if t1 > t0 {
            v0 + (v1 - v0) * (x - t0) / (t1 - t0)
        } else {
            v0
        });
    }
    (out, outside)
}

/// A numeric vector of the file that may be a signal: its path, length, label and time path.
#[derive(Debug, Clone)]
struct Candidate {
    path: String,
    label: String,
    len: usize,
    time: Option<String>,
}

/// The vectors of the file that may be signals: the columns of every Simulink Scope signal and
/// the top-level numeric vectors.
fn candidates(file: &MatFile) -> Vec<Candidate> {
    let mut out = Vec::new();
    for var in &file.variables {
        match &var.value {
            MatValue::Struct(s) if s.len() == 1 => {
                let time = match s.field(0, "time") {
                    Some(MatValue::Numeric(t)) if t.real.len() > 1 => {
                        Some(format!("{}.time", var.name))
                    }
                    _ => None,
                };
                let Some(MatValue::Struct(sig)) = s.field(0, "signals") else {
                    continue;
                };
                for e in 0..sig.len() {
                    let Some(MatValue::Numeric(v)) = sig.field(e, "values") else {
                        continue;
                    };
                    let label = sig
                        .field(e, "label")
                        .and_then(MatValue::as_text)
                        .unwrap_or_default();
                    let rows = v.dims.first().copied().unwrap_or(0);
                    let cols = numel(&v.dims).checked_div(rows).unwrap_or(0);
                    let base = if sig.len() == 1 {
                        format!("{}.signals.values", var.name)
                    } else {
                        format!("{}.signals({}).values", var.name, e + 1)
                    };
                    for c in 0..cols {
                        out.push(Candidate {
                            path: if cols == 1 {
                                base.clone()
                            } else {
                                format!("{base}(:,{})", c + 1)
                            },
                            label: label.clone(),
                            len: rows,
                            time: time.clone(),
                        });
                    }
                }
            }
            MatValue::Numeric(a)
                if a.real.len() > 1 && a.dims.iter().filter(|&&d| d > 1).count() == 1 =>
            {
                out.push(Candidate {
                    path: var.name.clone(),
                    label: var.name.clone(),
                    len: a.real.len(),
                    time: None,
                })
            }
            _ => {}
        }
    }
    out
}

/// The header-style name of a Scope label (`ia_meas[A]` -> `ia_meas_A`, `w [rpm/s]` ->
/// `w_rpm_per_s`), for [`super::columns::guess_column`].
fn label_as_header(label: &str) -> String {
    let l = label.trim();
    let (name, unit) = match (l.find('['), l.rfind(']')) {
        (Some(a), Some(b)) if b > a => (&l[..a], Some(&l[a + 1..b])),
        _ => (l, None),
    };
    let mut h: String = name
        .trim()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if let Some(u) = unit {
        let u = u.trim().replace("^2", "2").replace('/', "_per_");
        h.push('_');
        h.push_str(&u);
    }
    h
}

/// Guesses the map from Scope labels with units (`thl[deg]`, `ia[A]`, `u[V]`), or variable names
/// with unit suffixes (`t_s`, `ia_A`). Fails listing the candidates when a signal has several or
/// no time can be told.
pub fn guess(file: &MatFile) -> anyhow::Result<ColumnMap> {
    let cands = candidates(file);
    let mut picked: Vec<(Signal, super::units::Unit, &Candidate)> = Vec::new();
    let mut clashes: Vec<String> = Vec::new();
    for c in &cands {
        let Some((sig, unit)) = super::columns::guess_column(&label_as_header(&c.label)) else {
            continue;
        };
        if let Some((_, _, other)) = picked.iter().find(|(s, _, _)| *s == sig) {
            clashes.push(format!(
                "`{sig}` could be `{}` ('{}') or `{}` ('{}')",
                other.path, other.label, c.path, c.label
            ));
            continue;
        }
        picked.push((sig, unit, c));
    }
    let listing = || {
        cands
            .iter()
            .map(|c| {
                format!(
                    "{} ({} samples{})",
                    c.path,
                    c.len,
                    if c.label.is_empty() || c.label == c.path {
                        String::new()
                    } else {
                        format!(", label '{}'", c.label)
                    }
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    if !clashes.is_empty() {
        bail!(
            "cannot guess the column map: {}; give --columns, e.g. --columns {EXAMPLE} (vectors in the file: {}; `servo inspect` lists them all)",
            clashes.join("; "),
            listing()
        );
    }
    let time_path = picked
        .iter()
        .find(|(s, _, _)| *s == Signal::Time)
        .map(|(_, _, c)| (c.path.clone(), super::units::Unit::Second))
        .or_else(|| {
            picked
                .iter()
                .find_map(|(_, _, c)| c.time.clone())
                .map(|p| (p, super::units::Unit::Second))
        });
    let non_time = picked.iter().filter(|(s, _, _)| *s != Signal::Time).count();
    let Some((tpath, tunit)) = time_path.filter(|_| non_time > 0) else {
        bail!(
            "cannot guess the column map: no signal has a label with a unit (like `thl[deg]`, `ia[A]`) or no time was found; give --columns, e.g. --columns {EXAMPLE} (vectors in the file: {}; `servo inspect` lists them all)",
            listing()
        );
    };
    let mut entries = vec![ColumnSpec {
        signal: Signal::Time,
        column: tpath,
        unit: tunit,
    }];
    for (sig, unit, c) in picked.into_iter().filter(|(s, _, _)| *s != Signal::Time) {
        entries.push(ColumnSpec {
            signal: sig,
            column: c.path.clone(),
            unit,
        });
    }
    Ok(ColumnMap { entries })
}

/// The lines `servo inspect` prints for a MAT-file: every variable, field, struct element and
/// cell with its size, class and label or short text.
pub fn describe(file: &MatFile) -> Vec<String> {
    let mut out = vec![format!("header: {}", file.header_text)];
    for v in &file.variables {
        walk(&v.name, &v.value, None, 0, &mut out);
    }
    for s in &file.skipped {
        out.push(format!("skipped: {s}"));
    }
    out
}

/// Most struct-array elements or cells listed one by one.
const LIST_ELEMENTS: usize = 16;

fn walk(path: &str, v: &MatValue, label: Option<&str>, depth: usize, out: &mut Vec<String>) {
    if out.len() > 2000 || depth > 12 {
        return;
    }
    let head = format!("{path}  {} {}", dims_text(v.dims()), v.class());
    match v {
        MatValue::Numeric(a) => {
            let mut line = head;
            if a.real.len() == 1 {
                line.push_str(&format!(" = {}", a.real[0]));
            } else if a.real.len() > 1 {
                let (lo, hi) = a
                    .real
                    .iter()
                    .filter(|x| x.is_finite())
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                        (l.min(x), h.max(x))
                    });
                if lo <= hi {
                    line.push_str(&format!("  range {lo}..{hi}"));
                }
            }
            if let Some(l) = label {
                line.push_str(&format!("  label '{l}'"));
            }
            out.push(line);
        }
        MatValue::Char { rows, .. } => {
            let t = rows.join(" | ");
            if t.chars().count() <= 72 {
                out.push(format!("{head} '{t}'"));
            } else {
                out.push(format!(
                    "{head} '{}...'",
                    t.chars().take(72).collect::<String>()
                ));
            }
        }
        MatValue::Cell { items, .. } => {
            out.push(head);
            for (k, it) in items.iter().enumerate().take(LIST_ELEMENTS) {
                walk(&format!("{path}{{{}}}", k + 1), it, None, depth + 1, out);
            }
            if items.len() > LIST_ELEMENTS {
                out.push(format!(
                    "{path}{{...}}  {} more cells",
                    items.len() - LIST_ELEMENTS
                ));
            }
        }
        MatValue::Struct(s) => {
            let scope = s.len() == 1
                && s.fields.iter().any(|f| f == "time")
                && s.fields.iter().any(|f| f == "signals");
            out.push(format!(
                "{head}  fields {}{}",
                s.fields.join(", "),
                if scope {
                    "  (Simulink Scope structure with time)"
                } else {
                    ""
                }
            ));
            let n = s.len();
            for e in 0..n.min(LIST_ELEMENTS) {
                let ep = if n == 1 {
                    path.to_string()
                } else {
                    format!("{path}({})", e + 1)
                };
                let lab = s.field(e, "label").and_then(MatValue::as_text);
                for f in &s.fields {
                    if let Some(fv) = s.field(e, f) {
                        let l = if f == "values" { lab.as_deref() } else { None };
                        walk(&format!("{ep}.{f}"), fv, l, depth + 1, out);
                    }
                }
            }
            if n > LIST_ELEMENTS {
                out.push(format!("{path}(...)  {} more elements", n - LIST_ELEMENTS));
            }
        }
        MatValue::Skipped { .. } => {
            out.push(format!("{head}  (skipped: servo does not read this class)"))
        }
    }
}
