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

/// Longest line of a CSV log servo reads [bytes]: 1 MiB (a header of 10 000 columns of 30
/// characters is 300 kB). A longer line, or a quoted record spanning lines beyond it, is refused
/// with the file, the line and a short excerpt: memory stays bounded whatever the file holds
/// (a file of NUL bytes, a header that is one 64 MB line).
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Bytes a record may exceed [`MAX_LINE_BYTES`] by before it is refused, for the readers'
/// buffers ahead of the record being parsed.
const RECORD_SLACK_BYTES: u64 = 128 << 10;

/// Picks the delimiter from the first non-comment line: `,` unless only `;` or tabs appear.
fn sniff_delimiter(line: &[u8]) -> u8 {
    if line.contains(&b',') {
        b','
    } else if line.contains(&b';') {
        b';'
    } else if line.contains(&b'\t') {
        b'\t'
    } else {
        b','
    }
}

/// Whether a line is a comment or blank (not the header).
fn skipped_line(line: &[u8]) -> bool {
    let t = line.trim_ascii_start();
    t.is_empty() || t[0] == b'#'
}

/// Where the record being read starts: (byte offset, line number), set by the parser after
/// each record.
type RecordStart = std::rc::Rc<std::cell::Cell<(u64, u64)>>;

/// A reader that refuses a line longer than `max` bytes, and a record (quoted fields may span
/// lines) longer than `max` plus the buffers' slack, with an I/O error naming the line and
/// quoting its start; nothing is buffered here beyond the line's first bytes.
struct LineCapped<R> {
    inner: R,
    max: usize,
    /// Lines read so far (the line being read is `line + 1`).
    line: u64,
    /// Bytes of the line being read so far.
    line_len: usize,
    /// Its first bytes, for the message.
    head: Vec<u8>,
    /// Bytes read in all.
    read: u64,
    record_start: RecordStart,
}

impl<R: std::io::Read> LineCapped<R> {
    const HEAD: usize = 4 * crate::excerpt::CELL_CHARS + 4;

    fn keep_head(&mut self, bytes: &[u8]) {
        let room = Self::HEAD.saturating_sub(self.head.len());
        self.head.extend_from_slice(&bytes[..bytes.len().min(room)]);
    }

    fn too_long(&self) -> std::io::Error {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "line {} is longer than {} bytes (it starts `{}`), beyond any line of a servo log; \
                 is this a CSV log?",
                self.line + 1,
                self.max,
                crate::excerpt::excerpt_start(&self.head, crate::excerpt::CELL_CHARS)
            ),
        )
    }
}

impl<R: std::io::Read> std::io::Read for LineCapped<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let mut rest = &buf[..n];
        while let Some(i) = rest.iter().position(|&b| b == b'\n') {
            if self.line_len + i > self.max {
                self.keep_head(&rest[..i]);
                return Err(self.too_long());
            }
            self.line += 1;
            self.line_len = 0;
            self.head.clear();
            rest = &rest[i + 1..];
        }
        self.keep_head(rest);
        self.line_len += rest.len();
        if self.line_len > self.max {
            return Err(self.too_long());
        }
        self.read += n as u64;
        let (start, line) = self.record_start.get();
        if self.read.saturating_sub(start) > self.max as u64 + RECORD_SLACK_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "the record starting at line {line} spans more than {} bytes (a quoted field \
                     never closed?), beyond any record of a servo log",
                    self.max
                ),
            ));
        }
        Ok(n)
    }
}

/// A CSV reader over `input` with its header read: lines capped at `max_line` bytes
/// ([`LineCapped`]), the delimiter sniffed from the first line that is not a comment.
#[allow(clippy::type_complexity)]
fn open_csv<'a, R: std::io::Read + 'a>(
    input: R,
    source: &str,
    max_line: usize,
) -> anyhow::Result<(
    csv::Reader<Box<dyn std::io::Read + 'a>>,
    Vec<String>,
    RecordStart,
)> {
    use std::io::BufRead;
    let record_start: RecordStart = Default::default();
    let capped = LineCapped {
        inner: input,
        max: max_line,
        line: 0,
        line_len: 0,
        head: Vec::new(),
        read: 0,
        record_start: record_start.clone(),
    };
    let mut rest = std::io::BufReader::with_capacity(64 << 10, capped);
    // The lines before the header (comments, blanks) and the header, read to sniff the
    // delimiter, then handed to the CSV reader ahead of the rest.
    let mut pre = Vec::new();
    let mut delimiter = b',';
    let mut lines = 0u64;
    loop {
        let start = pre.len();
        record_start.set((start as u64, lines + 1));
        let n = rest
            .read_until(b'\n', &mut pre)
            .map_err(|e| anyhow!("{source}: {e}"))?;
        if n == 0 {
            break;
        }
        if !skipped_line(&pre[start..]) {
            delimiter = sniff_delimiter(&pre[start..]);
            record_start.set((start as u64, lines + 1));
            break;
        }
        lines += 1;
        if pre.len() > max_line {
            // Comment lines without end: the CSV reader reads them as comments.
            break;
        }
    }
    let stream: Box<dyn std::io::Read + 'a> =
        Box::new(std::io::Read::chain(std::io::Cursor::new(pre), rest));
    let mut rdr = csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .comment(Some(b'#'))
        .trim(csv::Trim::Headers)
        .has_headers(true)
        .from_reader(stream);
    let header: Vec<String> = rdr
        .headers()
        .map_err(|e| {
            anyhow!(
                "{source}: cannot read the CSV header: {}",
                csv_error_text(&e)
            )
        })?
        .iter()
        .map(str::to_string)
        .collect();
    if header.iter().all(|h| h.is_empty()) {
        bail!("{source}: the file is empty or has no header line (expected e.g. `time_s,u_V,theta_l_rad,i_a_A`)");
    }
    let p = rdr.position();
    record_start.set((p.byte(), p.line()));
    Ok((rdr, header, record_start))
}

/// The header and the number of data rows of a CSV (`servo inspect`), read as a stream with
/// lines capped at `max_line` bytes; an error when the file is not a readable CSV (no header,
/// rows of another length than the header, a line beyond the cap).
pub fn scan_csv<R: std::io::Read>(
    input: R,
    source: &str,
    max_line: usize,
) -> anyhow::Result<(Vec<String>, u64)> {
    let (mut rdr, header, record_start) = open_csv(input, source, max_line)?;
    let mut row = csv::ByteRecord::new();
    let mut rows = 0u64;
    loop {
        match rdr.read_byte_record(&mut row) {
            Ok(true) => rows += 1,
            Ok(false) => break,
            Err(e) => bail!("{}", row_error(source, &e)),
        }
        let p = rdr.position();
        record_start.set((p.byte(), p.line()));
    }
    Ok((header, rows))
}

/// The message of an error reading a data row.
fn row_error(source: &str, e: &csv::Error) -> String {
    match (e.kind(), e.position()) {
        (_, Some(p)) => format!("{source}: line {}: {}", p.line(), csv_error_text(e)),
        _ => format!("{source}: {}", csv_error_text(e)),
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
    let file =
        std::fs::File::open(path).with_context(|| format!("reading CSV log {}", path.display()))?;
    parse_reader(
        file,
        &path.display().to_string(),
        columns,
        want,
        axis,
        MAX_LINE_BYTES,
    )
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
    /// The header columns, the number of data rows and the map servo would guess; an error
    /// when the file is not a readable CSV (read as a stream, lines capped at
    /// [`MAX_LINE_BYTES`]).
    fn inspect(&self, path: &Path) -> anyhow::Result<Vec<String>> {
        let source = path.display().to_string();
        let file = std::fs::File::open(path).with_context(|| format!("reading {source}"))?;
        let (header, rows) = scan_csv(file, &source, MAX_LINE_BYTES)?;
        Ok(vec![
            format!("{source}: CSV, {rows} data rows"),
            format!(
                "  columns: {}",
                crate::excerpt::join_excerpt(&header, ",", 4 * crate::excerpt::HEADER_CHARS)
            ),
            crate::log_reader::guessed(read_csv(path, None).map(|i| i.map.to_string())),
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
    parse_reader(text.as_bytes(), source, columns, want, axis, MAX_LINE_BYTES)
}

/// [`parse_csv`] with lines capped at `max_line` bytes instead of [`MAX_LINE_BYTES`] (the fuzz
/// targets reach the cap with small inputs).
pub fn parse_csv_capped(
    text: &str,
    source: &str,
    columns: Option<&str>,
    max_line: usize,
) -> anyhow::Result<CsvImport> {
    parse_reader(
        text.as_bytes(),
        source,
        columns,
        None,
        &Transmission::GEAR,
        max_line,
    )
}

/// Reads a CSV log from `input` as a stream (see [`read_csv_on`]): memory holds one record and
/// the columns read, never the file; a line beyond `max_line` bytes is refused.
pub fn parse_reader<R: std::io::Read>(
    input: R,
    source: &str,
    columns: Option<&str>,
    want: Option<&[Signal]>,
    axis: &Transmission,
    max_line: usize,
) -> anyhow::Result<CsvImport> {
    let (mut rdr, header, record_start) = open_csv(input, source, max_line)?;
    let header_refs: Vec<&str> = header.iter().map(String::as_str).collect();
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
                    note.push_str(&format!(
                        " (ignored: {})",
                        crate::excerpt::join_excerpt(&ignored, ", ", crate::excerpt::HEADER_CHARS)
                    ));
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
                crate::excerpt::join_excerpt(&header, ",", crate::excerpt::HEADER_CHARS)
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
            Err(e) => bail!("{}", row_error(source, &e)),
        }
        {
            let p = rdr.position();
            record_start.set((p.byte(), p.line()));
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
                        crate::excerpt::excerpt(cell, crate::excerpt::CELL_CHARS)
                    ),
                }
            };
            if e.signal == Signal::Time {
                let t = e.unit.to_si(v);
                if !t.is_finite() {
                    bail!("{source}: line {}, column {} (`{}`): time must be a finite number, got `{}`", line_of(&row), i + 1, e.column, crate::excerpt::excerpt(cell, crate::excerpt::CELL_CHARS));
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
                        crate::excerpt::excerpt(cell, crate::excerpt::CELL_CHARS),
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
                "{source}: column `{}` has {nans} empty or non-finite values (kept as NaN; \
                 a command that needs the signal there refuses the log: fill or drop those \
                 rows, or take a part of the log without them with --window START..END)",
                e.column
            ));
        }
        e.signal.store(&mut rec, col);
    }
    if rec.time_s.is_empty() {
        bail!(
            "{source}: no data rows after the header `{}`",
            crate::excerpt::join_excerpt(&header, ",", crate::excerpt::HEADER_CHARS)
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
    fn lines_and_records_beyond_the_cap_are_refused_with_an_excerpt() {
        let ok = "# a comment with a \" quote\ntime_s,u_V\n0,1\n0.001,2\n0.002,3\n";
        let r = parse_csv_capped(ok, "ok.csv", None, 40).unwrap();
        assert_eq!(r.record.time_s.len(), 3);
        // A data line beyond the cap: its number and its start, not the whole line.
        let long = format!("time_s,u_V\n0,1\n0.001,{}\n", "7".repeat(5000));
        let e = format!(
            "{:#}",
            parse_csv_capped(&long, "long.csv", None, 1000).unwrap_err()
        );
        assert!(
            e.starts_with("long.csv: line 3 is longer than 1000 bytes (it starts `0.001,777"),
            "{e}"
        );
        assert!(e.len() < 300, "{e}");
        // The header itself, and a file without any newline.
        let e = format!(
            "{:#}",
            parse_csv_capped(&"a,".repeat(3000), "h.csv", None, 1000).unwrap_err()
        );
        assert!(e.contains("h.csv") && e.contains("line 1 is longer"), "{e}");
        let nul = "\0".repeat(5000);
        let e = format!(
            "{:#}",
            parse_csv_capped(&nul, "nul.csv", None, 1000).unwrap_err()
        );
        assert!(
            e.contains("line 1 is longer") && e.contains("\\0\\0"),
            "{e}"
        );
        assert!(e.len() < 400, "{e}");
        // A quoted field never closed: short lines, one endless record.
        let mut q = String::from("time_s,u_V\n0,\"1\n");
        for _ in 0..40_000 {
            q.push_str("2,3\n");
        }
        let e = format!(
            "{:#}",
            parse_csv_capped(&q, "q.csv", None, 1000).unwrap_err()
        );
        assert!(
            e.contains("q.csv") && e.contains("record starting at line 2"),
            "{e}"
        );
        // At the default cap, the same files read as before.
        assert!(parse_csv(&long, "long.csv", None).is_ok());
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
