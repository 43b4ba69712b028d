//! The time of a log: from its content (the MCAP run's start time, the MAT-file's save date in
//! its header, a date column of a CSV), from its file name (`--time-from name:%Y%m%d`), else its
//! modification time; always with the source, so the report can say which.
//!
//! Dates are UTC, computed with the proleptic Gregorian calendar (no time-zone database).

use std::path::Path;

/// Where the times of the logs come from (`--time-from`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TimeFrom {
    /// The log's content (MCAP start time, MAT header date, a CSV date column), else the file's
    /// modification time.
    Auto,
    /// The file name, matched against a pattern of `%Y %m %d %H %M %S` and literal characters
    /// (anywhere in the name).
    Name(String),
    /// The first value of this CSV column (Unix seconds, or an ISO date `YYYY-MM-DD[THH:MM:SS]`).
    Column(String),
    /// The file's modification time.
    Mtime,
}

impl std::str::FromStr for TimeFrom {
    type Err = String;
    fn from_str(s: &str) -> Result<TimeFrom, String> {
        match s {
            "auto" => Ok(TimeFrom::Auto),
            "mtime" => Ok(TimeFrom::Mtime),
            _ => {
                if let Some(p) = s.strip_prefix("name:") {
                    if !p.contains('%') {
                        return Err(format!(
                            "--time-from name:PATTERN needs fields such as %Y%m%d, got `{p}`"
                        ));
                    }
                    check_pattern(p).map_err(|e| format!("--time-from {s}: {e}"))?;
                    Ok(TimeFrom::Name(p.to_string()))
                } else if let Some(c) = s.strip_prefix("column:") {
                    if c.is_empty() {
                        return Err("--time-from column:NAME needs a column name".into());
                    }
                    Ok(TimeFrom::Column(c.to_string()))
                } else {
                    Err(format!(
                        "--time-from: expected auto, mtime, name:PATTERN (e.g. name:%Y%m%d) or column:NAME, got `{s}`"
                    ))
                }
            }
        }
    }
}

/// CSV columns read as the log's date in `auto` mode.
pub const DATE_COLUMNS: [&str; 6] = [
    "unix_time_s",
    "time_unix_s",
    "timestamp",
    "date",
    "datetime",
    "recorded_at",
];

/// Metadata key of an MCAP run's start [Unix ns] (servo-io's writer).
pub const MCAP_START_KEY: &str = "start_time_unix_ns";

/// Days from 1970-01-01 to the civil date (y, m, d) (H. Hinnant's algorithm).
pub fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m as i64 + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d as i64 - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The civil date (y, m, d) of a day count from 1970-01-01.
pub fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (
        if m <= 2 {
            yoe + era * 400 + 1
        } else {
            yoe + era * 400
        },
        m,
        d,
    )
}

/// `YYYY-MM-DD` of a Unix time [s] (UTC).
pub fn date_text(unix_s: f64) -> String {
    if !unix_s.is_finite() {
        return "never".into();
    }
    let (y, m, d) = civil_from_days((unix_s / 86_400.0).floor() as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// `YYYY-MM-DDTHH:MM:SSZ` of a Unix time [s] (UTC).
pub fn datetime_text(unix_s: f64) -> String {
    let secs = unix_s.floor() as i64;
    let day = secs.div_euclid(86_400);
    let s = secs.rem_euclid(86_400);
    let (y, m, d) = civil_from_days(day);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        s / 3600,
        (s / 60) % 60,
        s % 60
    )
}

/// Unix seconds of a civil date and time, checked.
fn unix(y: i64, mo: u32, d: u32, h: u32, mi: u32, s: u32) -> Result<f64, String> {
    if !(1..=12).contains(&mo) || !(1..=31).contains(&d) || h > 23 || mi > 59 || s > 60 {
        return Err(format!(
            "not a date: {y:04}-{mo:02}-{d:02} {h:02}:{mi:02}:{s:02}"
        ));
    }
    Ok((days_from_civil(y, mo, d) * 86_400 + (h * 3600 + mi * 60 + s) as i64) as f64)
}

/// A name pattern's fields are known.
fn check_pattern(pattern: &str) -> Result<(), String> {
    let mut p = pattern.chars();
    while let Some(c) = p.next() {
        if c == '%' {
            match p.next() {
                Some('Y' | 'm' | 'd' | 'H' | 'M' | 'S') => {}
                Some(other) => {
                    return Err(format!("unknown field %{other} (use %Y %m %d %H %M %S)"))
                }
                None => return Err("a pattern ends with %".into()),
            }
        }
    }
    Ok(())
}

/// Reads `text` from its start with `pattern` (`%Y` 4 digits, `%m %d %H %M %S` 2 digits, other
/// characters literal); Unix seconds.
fn parse_with_pattern(text: &str, pattern: &str) -> Result<f64, String> {
    let (mut y, mut mo, mut d, mut h, mut mi, mut s) = (1970i64, 1u32, 1u32, 0u32, 0u32, 0u32);
    let t = text.as_bytes();
    let mut i = 0usize;
    let mut p = pattern.chars().peekable();
    let digits = |n: usize, i: &mut usize| -> Result<u32, String> {
        let part = t.get(*i..*i + n).ok_or("the name is too short")?;
        if !part.iter().all(u8::is_ascii_digit) {
            return Err(format!(
                "expected {n} digits at `{}`",
                String::from_utf8_lossy(part)
            ));
        }
        *i += n;
        std::str::from_utf8(part)
            .map_err(|e| e.to_string())?
            .parse::<u32>()
            .map_err(|e| e.to_string())
    };
    let mut fields = 0;
    while let Some(c) = p.next() {
        if c == '%' {
            let f = p.next().ok_or("a pattern ends with %")?;
            match f {
                'Y' => y = digits(4, &mut i)? as i64,
                'm' => mo = digits(2, &mut i)?,
                'd' => d = digits(2, &mut i)?,
                'H' => h = digits(2, &mut i)?,
                'M' => mi = digits(2, &mut i)?,
                'S' => s = digits(2, &mut i)?,
                other => return Err(format!("unknown field %{other} (use %Y %m %d %H %M %S)")),
            }
            fields += 1;
        } else {
            let mut buf = [0u8; 4];
            let lit = c.encode_utf8(&mut buf).as_bytes();
            if t.get(i..i + lit.len()) != Some(lit) {
                return Err(format!("expected `{c}`"));
            }
            i += lit.len();
        }
    }
    if fields == 0 {
        return Err("the pattern has no date field".into());
    }
    unix(y, mo, d, h, mi, s)
}

/// The first place in `name` where `pattern` reads a date; Unix seconds.
pub fn time_from_name(name: &str, pattern: &str) -> Option<f64> {
    (0..name.len())
        .filter(|&k| name.is_char_boundary(k))
        .find_map(|k| parse_with_pattern(&name[k..], pattern).ok())
}

/// An ISO date `YYYY-MM-DD`, `YYYY-MM-DDTHH:MM:SS[Z]` (or with a space) or Unix seconds.
pub fn parse_date_value(v: &str) -> Option<f64> {
    let v = v.trim().trim_matches('"');
    if let Ok(x) = v.parse::<f64>() {
        return (x.is_finite() && x > 1e8).then_some(x);
    }
    let v = v.trim_end_matches('Z');
    parse_with_pattern(v, "%Y-%m-%dT%H:%M:%S")
        .or_else(|_| parse_with_pattern(v, "%Y-%m-%d %H:%M:%S"))
        .or_else(|_| parse_with_pattern(v, "%Y-%m-%d"))
        .ok()
}

/// The save date in a MAT-file's header text (`... Created on: Thu Dec  3 06:03:34 2026`).
pub fn mat_header_time(bytes: &[u8]) -> Option<f64> {
    let head = String::from_utf8_lossy(bytes.get(..116)?);
    let at = head.find("Created on:")?;
    let words: Vec<&str> = head[at + "Created on:".len()..]
        .split_whitespace()
        .collect();
    // Weekday Month Day HH:MM:SS Year
    let months = [
        "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
    ];
    let mo = months.iter().position(|m| Some(m) == words.get(1))? as u32 + 1;
    let d: u32 = words.get(2)?.parse().ok()?;
    let hms: Vec<u32> = words
        .get(3)?
        .split(':')
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    let y: i64 = words
        .get(4)?
        .chars()
        .take(4)
        .collect::<String>()
        .parse()
        .ok()?;
    unix(y, mo, d, *hms.first()?, *hms.get(1)?, *hms.get(2)?).ok()
}

/// The header and first data row of a CSV (comment lines `#` skipped) as (column, value) pairs,
/// at most 64 columns of values up to 200 characters; empty when the text is not a CSV.
pub fn csv_first_row(bytes: &[u8]) -> Vec<(String, String)> {
    let Some(text) = bytes
        .get(..bytes.len().min(64 * 1024))
        .and_then(|b| std::str::from_utf8(b).ok())
    else {
        return Vec::new();
    };
    let mut lines = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'));
    let (Some(header), Some(row)) = (lines.next(), lines.next()) else {
        return Vec::new();
    };
    header
        .split(',')
        .zip(row.split(','))
        .take(64)
        .map(|(h, v)| (h.trim().to_string(), v.trim().to_string()))
        .filter(|(h, v)| !h.is_empty() && !v.is_empty() && v.len() <= 200)
        .collect()
}

/// The first value of column `name` (or, with `None`, of the first of [`DATE_COLUMNS`]) of a CSV
/// as a date; Unix seconds and the column's name.
pub fn csv_column_time(bytes: &[u8], name: Option<&str>) -> Option<(f64, String)> {
    let text = std::str::from_utf8(bytes.get(..bytes.len().min(64 * 1024))?).ok()?;
    let mut lines = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'));
    let header: Vec<&str> = lines.next()?.split(',').map(str::trim).collect();
    let row: Vec<&str> = lines.next()?.split(',').collect();
    let col = match name {
        Some(n) => header.iter().position(|h| *h == n)?,
        None => header.iter().position(|h| DATE_COLUMNS.contains(h))?,
    };
    parse_date_value(row.get(col)?).map(|t| (t, header[col].to_string()))
}

/// The file's modification time [Unix s].
pub fn mtime(path: &Path) -> Option<f64> {
    let m = std::fs::metadata(path).ok()?.modified().ok()?;
    m.duration_since(std::time::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_round_trip_and_patterns_read_names() {
        for (y, m, d) in [(1970, 1, 1), (2000, 2, 29), (2026, 12, 3), (1969, 12, 31)] {
            assert_eq!(civil_from_days(days_from_civil(y, m, d)), (y, m, d));
        }
        let t = time_from_name("arm-3_20260105_run.csv", "%Y%m%d").unwrap();
        assert_eq!(date_text(t), "2026-01-05");
        assert!(time_from_name("arm-3.csv", "%Y%m%d").is_none());
        assert_eq!(
            datetime_text(parse_date_value("2026-03-04T05:06:07Z").unwrap()),
            "2026-03-04T05:06:07Z"
        );
        let mut head =
            b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: Thu Dec  3 06:03:34 2026"
                .to_vec();
        head.resize(128, b' ');
        assert_eq!(
            datetime_text(mat_header_time(&head).unwrap()),
            "2026-12-03T06:03:34Z"
        );
        assert!("name:nope".parse::<TimeFrom>().is_err());
        assert!("name:%Q".parse::<TimeFrom>().is_err());
        assert_eq!(
            "name:%Y%m%d".parse::<TimeFrom>(),
            Ok(TimeFrom::Name("%Y%m%d".into()))
        );
    }
}
