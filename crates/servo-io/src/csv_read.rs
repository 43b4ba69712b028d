//! Reading a CSV log (servo's own or a foreign one through a [`ColumnMap`]) into a [`Record`].

use super::columns::ColumnMap;
use super::units::Signal;
use crate::error::{self as anyhow, anyhow, bail, Context};
use servo_core::record::Record;
use servo_core::Transmission;
use std::path::Path;

/// A CSV read into a record, with the column map used and notes for the user (guessed map,
/// ignored columns, missing values).
#[derive(Debug, Clone)]
pub struct CsvImport {
    pub record: Record,
    pub map: ColumnMap,
    pub notes: Vec<String>,
}

/// Picks the delimiter from the first non-comment line: `,` unless only `;` or tabs appear.
fn sniff_delimiter(text: &str) -> u8 {
    let line = text
        .lines()
        .find(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty())
        .unwrap_or("");
    if line.contains(',') {
        b','
    } else if line.contains(';') {
        b';'
    } else if line.contains('\t') {
        b'\t'
    } else {
        b','
    }
}

/// Reads `path`. `columns` is the user's `--columns` map; `None` means servo's own header or a
/// guess from the header's unit suffixes (stated in the notes).
pub fn read_csv(path: &Path, columns: Option<&str>) -> anyhow::Result<CsvImport> {
    read_csv_signals(path, columns, None)
}

/// [`read_csv`] building only the signals in `want` (time always; `None`: all mapped signals);
/// the other mapped columns must exist but are not parsed.
pub fn read_csv_signals(
    path: &Path,
    columns: Option<&str>,
    want: Option<&[Signal]>,
) -> anyhow::Result<CsvImport> {
    read_csv_on(path, columns, want, &Transmission::GEAR)
}

/// [`read_csv_signals`] on the axis `axis`: a column in a length or linear speed unit (`x=q:mm`)
/// becomes the load shaft's equivalent rotation [rad] ([`servo_core::transmission`]); on a
/// rotary gear such a column is refused.
pub fn read_csv_on(
    path: &Path,
    columns: Option<&str>,
    want: Option<&[Signal]>,
    axis: &Transmission,
) -> anyhow::Result<CsvImport> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading CSV log {}", path.display()))?;
    parse_csv_on(&text, &path.display().to_string(), columns, want, axis)
}

/// servo's reader of CSV logs (`.csv`, `.txt`, `.tsv`; `,`, `;` or tab separated).
pub struct CsvReader;

impl crate::log_reader::LogReader for CsvReader {
    fn name(&self) -> &'static str {
        "CSV"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["csv", "txt", "tsv"]
    }
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        want: Option<&[Signal]>,
        axis: &Transmission,
    ) -> anyhow::Result<(Record, crate::LogMeta)> {
        let imp = read_csv_on(path, columns, want, axis)?;
        Ok((
            imp.record,
            crate::LogMeta {
                columns: Some(imp.map.to_string()),
                notes: imp.notes,
                ..crate::LogMeta::default()
            },
        ))
    }
    /// The header columns, the number of data rows and the map servo would guess.
    fn inspect(&self, path: &Path) -> anyhow::Result<Vec<String>> {
        let source = path.display().to_string();
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {source}"))?;
        let mut lines = text
            .lines()
            .filter(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty());
        let header = lines.next().unwrap_or("");
        let rows = lines.count();
        Ok(vec![
            format!("{source}: CSV, {rows} data rows"),
            format!("  columns: {header}"),
            crate::log_reader::guessed(parse_csv(&text, &source, None).map(|i| i.map.to_string())),
        ])
    }
}

/// Parses CSV `text`; `source` names the file in messages.
pub fn parse_csv(text: &str, source: &str, columns: Option<&str>) -> anyhow::Result<CsvImport> {
    parse_csv_signals(text, source, columns, None)
}

/// A field without the spaces around it.
fn trim_field(b: &[u8]) -> &[u8] {
    b.trim_ascii()
}

/// [`parse_csv`] building only the signals in `want` (see [`read_csv_signals`]). Rows are read
/// into one reused byte record and numbers parsed in place: no allocation per row.
pub fn parse_csv_signals(
    text: &str,
    source: &str,
    columns: Option<&str>,
    want: Option<&[Signal]>,
) -> anyhow::Result<CsvImport> {
    parse_csv_on(text, source, columns, want, &Transmission::GEAR)
}

/// [`parse_csv_signals`] on the axis `axis` (see [`read_csv_on`]).
pub fn parse_csv_on(
    text: &str,
    source: &str,
    columns: Option<&str>,
    want: Option<&[Signal]>,
    axis: &Transmission,
) -> anyhow::Result<CsvImport> {
    let mut rdr = csv::ReaderBuilder::new()
        .delimiter(sniff_delimiter(text))
        .comment(Some(b'#'))
        .trim(csv::Trim::Headers)
        .has_headers(true)
        .from_reader(text.as_bytes());
    let header: Vec<String> = rdr
        .headers()
        .map_err(|e| anyhow!("{source}: cannot read the CSV header: {e}"))?
        .iter()
        .map(str::to_string)
        .collect();
    let header_refs: Vec<&str> = header.iter().map(String::as_str).collect();
    if header.iter().all(|h| h.is_empty()) {
        bail!("{source}: the file is empty or has no header line (expected e.g. `time_s,u_V,theta_l_rad,i_a_A`)");
    }
    let mut notes = Vec::new();
    let map = match columns {
        Some(c) => ColumnMap::parse(c)?,
        None => match ColumnMap::servo_own(&header_refs) {
            Some(m) => m,
            None => {
                let (m, ignored) =
                    ColumnMap::guess(&header_refs).with_context(|| source.to_string())?;
                let mut note = format!("{source}: guessed the column map --columns {m}");
                if !ignored.is_empty() {
                    note.push_str(&format!(" (ignored: {})", ignored.join(", ")));
                }
                notes.push(note);
                m
            }
        },
    };
    // Column index of every mapped signal.
    let mut idx = Vec::with_capacity(map.entries.len());
    for e in &map.entries {
        let i = header.iter().position(|h| h == &e.column).ok_or_else(|| {
            anyhow!(
                "{source}: no column `{}` (for signal `{}`); the header is `{}`",
                e.column,
                e.signal,
                header.join(",")
            )
        })?;
        idx.push(i);
    }
    let factors = map.factors_on(axis).with_context(|| source.to_string())?;
    // The mapped columns read: (entry, column index, values, non-finite count, factor to the
    // record's unit).
    #[allow(clippy::type_complexity)]
    let mut cols: Vec<(&super::columns::ColumnSpec, usize, Vec<f64>, usize, f64)> = map
        .entries
        .iter()
        .zip(&idx)
        .zip(&factors)
        .filter(|((e, _), _)| {
            e.signal == Signal::Time || want.is_none_or(|w| w.contains(&e.signal))
        })
        .map(|((e, &i), &f)| (e, i, Vec::new(), 0usize, f))
        .collect();
    let mut last_t = f64::NEG_INFINITY;
    let mut row = csv::ByteRecord::new();
    loop {
        match rdr.read_byte_record(&mut row) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => {
                let line = e.position().map(|p| p.line()).unwrap_or(0);
                bail!("{source}: line {line}: {}", csv_error_text(&e));
            }
        }
        for (e, i, col, nans, factor) in cols.iter_mut() {
            let i = *i;
            let cell = trim_field(row.get(i).unwrap_or(b""));
            let v = if cell.is_empty() || cell.eq_ignore_ascii_case(b"nan") {
                f64::NAN
            } else {
                match std::str::from_utf8(cell).ok().and_then(|c| c.parse::<f64>().ok()) {
                    Some(v) => v,
                    None => bail!(
                        "{source}: line {}, column {} (`{}`, signal `{}`): expected a number in {}, got `{}`",
                        line_of(&row),
                        i + 1,
                        e.column,
                        e.signal,
                        e.unit,
                        String::from_utf8_lossy(cell)
                    ),
                }
            };
            if e.signal == Signal::Time {
                let t = e.unit.to_si(v);
                if !t.is_finite() {
                    bail!("{source}: line {}, column {} (`{}`): time must be a finite number, got `{}`", line_of(&row), i + 1, e.column, String::from_utf8_lossy(cell));
                }
                if t <= last_t {
                    bail!(
                        "{source}: line {}, column {} (`{}`): time must increase strictly, got {} s after {} s",
                        line_of(&row),
                        i + 1,
                        e.column,
                        seconds(t),
                        seconds(last_t)
                    );
                }
                last_t = t;
                col.push(t);
            } else {
                let si = if *factor == 1.0 { v } else { v * *factor };
                if !v.is_finite() {
                    *nans += 1;
                } else if !si.is_finite() || si.abs() > plausible_limit(e.signal) {
                    bail!(
                        "{source}: line {}, column {} (`{}`, signal `{}`): {} {} is {si:e} in SI units, \
                         beyond any DC servomotor (|{}| <= {:e}); wrong column or unit?",
                        line_of(&row),
                        i + 1,
                        e.column,
                        e.signal,
                        String::from_utf8_lossy(cell),
                        e.unit,
                        e.signal,
                        plausible_limit(e.signal)
                    );
                }
                col.push(si);
            }
        }
    }
    let mut rec = Record {
        source: source.to_string(),
        ..Record::default()
    };
    for (e, _, col, nans, _) in cols {
        if nans > 0 {
            notes.push(format!(
                "{source}: column `{}` has {nans} empty or non-finite values (kept as NaN)",
                e.column
            ));
        }
        e.signal.store(&mut rec, col);
    }
    if rec.time_s.is_empty() {
        bail!(
            "{source}: no data rows after the header `{}`",
            header.join(",")
        );
    }
    check_sample_period(&rec.time_s, &map, source)?;
    Ok(CsvImport {
        record: rec,
        map,
        notes,
    })
}

/// Largest magnitude (SI units) a signal of a DC servomotor log may take: values beyond are a
/// wrong column or unit (or garbage), and would overflow the fits (1e30 V gives a fit of
/// -3.4e29 %, 1e308 makes the least squares NaN).
pub fn plausible_limit(signal: Signal) -> f64 {
    match signal {
        Signal::Time => f64::INFINITY,
        Signal::U => 1e4,
        Signal::IA => 1e5,
        Signal::ThetaL | Signal::ThetaM | Signal::Ref => 1e9,
        Signal::OmegaL | Signal::OmegaM => 1e7,
        Signal::Enable => 1e9,
        Signal::IRef => 1e5,
        Signal::VSupply => 1e4,
        Signal::Duty => 1e3,
    }
}

/// Sample periods a servo log may have [s]: 10 us .. 1 s.
pub const SAMPLE_PERIOD_RANGE_S: (f64, f64) = (1e-5, 1.0);

/// Refuses a log whose median time step lies outside [`SAMPLE_PERIOD_RANGE_S`]: the time column's
/// unit is almost certainly not the one it was read in (nanoseconds read as seconds give dt =
/// 1e6 s).
fn check_sample_period(time_s: &[f64], map: &ColumnMap, source: &str) -> anyhow::Result<()> {
    if time_s.len() < 2 {
        return Ok(());
    }
    let mut d: Vec<f64> = time_s.windows(2).map(|w| w[1] - w[0]).collect();
    let mid = d.len() / 2;
    let dt = *d.select_nth_unstable_by(mid, f64::total_cmp).1;
    let (lo, hi) = SAMPLE_PERIOD_RANGE_S;
    if dt >= lo && dt <= hi {
        return Ok(());
    }
    let Some(e) = map.entries.iter().find(|e| e.signal == Signal::Time) else {
        return Ok(());
    };
    let guesses: Vec<String> = [("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)]
        .into_iter()
        .filter(|(_, f)| {
            let p = dt / e.unit.to_si(1.0) * f;
            p >= lo && p <= hi
        })
        .map(|(u, f)| {
            format!(
                "`--columns time={}:{u}` (T_s = {:e} s)",
                e.column,
                dt / e.unit.to_si(1.0) * f
            )
        })
        .collect();
    bail!(
        "{source}: column `{}` read in {} gives a sample period of {dt:e} s, outside {lo:e} .. {hi} s; \
         which unit is the time column in?{}",
        e.column,
        e.unit,
        if guesses.is_empty() {
            String::new()
        } else {
            format!(" If it is {}, give {}", if guesses.len() > 1 { "one of these" } else { "this" }, guesses.join(" or "))
        }
    )
}

/// The file line of a record, for messages.
fn line_of(row: &csv::ByteRecord) -> u64 {
    row.position().map(|p| p.line()).unwrap_or(0)
}

fn csv_error_text(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => {
            format!("expected {expected_len} fields like the header, found {len}")
        }
        csv::ErrorKind::Utf8 { .. } => "not valid UTF-8 text".to_string(),
        _ => e.to_string(),
    }
}

/// A time [s] as a message shows it: as read below a million seconds, in scientific notation
/// beyond (a corrupt cell of 1e300 would print 301 digits).
fn seconds(t: f64) -> String {
    if t.abs() < 1e6 {
        format!("{t}")
    } else {
        format!("{t:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_csv() {
        let t = "time_s,u_V,theta_l_rad,i_a_A,ref_rad\n0,1,0,0.1,1\n0.001,2,0.01,0.2,1\n";
        let r = parse_csv(t, "x.csv", None).unwrap();
        assert!(r.notes.is_empty());
        assert_eq!(r.record.time_s, [0.0, 0.001]);
        assert_eq!(r.record.u_v.as_deref(), Some(&[1.0, 2.0][..]));
        assert_eq!(r.record.ref_rad.as_deref(), Some(&[1.0, 1.0][..]));
        assert!(r.record.theta_m_rad.is_none());
    }

    #[test]
    fn foreign_with_map_and_units() {
        let t = "t_ms;pos_deg;I_mA\n0;180;100\n1;90;-50\n";
        let r = parse_csv(
            t,
            "f.csv",
            Some("time=t_ms:ms,theta_l=pos_deg:deg,i_a=I_mA:mA"),
        )
        .unwrap();
        assert_eq!(r.record.time_s, [0.0, 0.001]);
        let th = r.record.theta_l_rad.unwrap();
        assert!((th[0] - std::f64::consts::PI).abs() < 1e-12);
        assert!((r.record.i_a_a.unwrap()[1] + 0.05).abs() < 1e-15);
    }

    #[test]
    fn guessed_map_is_noted() {
        let t = "t_s,thl_meas_deg,u_V\n0,0,1\n0.001,1,1\n";
        let r = parse_csv(t, "g.csv", None).unwrap();
        assert!(
            r.notes[0].contains("--columns time=t_s,theta_l=thl_meas_deg:deg,u=u_V"),
            "{:?}",
            r.notes
        );
    }

    #[test]
    fn errors_name_line_and_column() {
        let t = "time_s,u_V,theta_l_rad\n0,1,0\n0.001,abc,0\n";
        let e = format!("{:#}", parse_csv(t, "bad.csv", None).unwrap_err());
        assert!(
            e.contains("bad.csv: line 3, column 2 (`u_V`") && e.contains("got `abc`"),
            "{e}"
        );
        let t = "time_s,u_V\n0,1\n0,2\n";
        let e = format!("{:#}", parse_csv(t, "bad.csv", None).unwrap_err());
        assert!(
            e.contains("line 3") && e.contains("increase strictly"),
            "{e}"
        );
        let t = "time_s,u_V\n0,1\n0.001,2,3\n";
        let e = format!("{:#}", parse_csv(t, "bad.csv", None).unwrap_err());
        assert!(
            e.contains("line 3") && e.contains("expected 2 fields"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            parse_csv(t, "bad.csv", Some("time=t,u=u_V")).unwrap_err()
        );
        assert!(
            e.contains("no column `t`") && e.contains("time_s,u_V"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            parse_csv("a,b\n1,2\n", "bad.csv", None).unwrap_err()
        );
        assert!(
            e.contains("bad.csv") && e.contains("`a,b`") && e.contains("--columns"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            parse_csv("time_s,u_V\n", "empty.csv", None).unwrap_err()
        );
        assert!(e.contains("no data rows"), "{e}");
    }

    #[test]
    fn absurd_values_and_time_units_are_refused() {
        for v in ["1e308", "1e30", "-1e300"] {
            let t = format!("time_s,u_V,theta_l_rad\n0,1,0\n0.001,{v},0\n0.002,1,0\n");
            let e = format!("{:#}", parse_csv(&t, "big.csv", None).unwrap_err());
            assert!(
                e.contains("big.csv: line 3, column 2 (`u_V`")
                    && e.contains("wrong column or unit"),
                "{e}"
            );
        }
        // Time in nanoseconds read as seconds: dt = 1e6 s.
        let t = "time_s,u_V\n0,1\n1000000,1\n2000000,1\n";
        let e = format!("{:#}", parse_csv(t, "ns.csv", None).unwrap_err());
        assert!(
            e.contains("which unit") && e.contains("--columns time=time_s:ns"),
            "{e}"
        );
        let r = parse_csv(t, "ns.csv", Some("time=time_s:ns,u=u_V")).unwrap();
        assert_eq!(r.record.time_s[1], 1e-3);
        // Too slow as well: 10 s.
        let t = "time_s,u_V\n0,1\n10,1\n20,1\n";
        let e = format!("{:#}", parse_csv(t, "slow.csv", None).unwrap_err());
        assert!(e.contains("outside"), "{e}");
    }
}
