//! The part of a log a command uses: a time window `START..END` and the drive's enable column.
//!
//! Every command that reads logs cuts each record with [`cut`] after reading it (whatever the
//! format), so a window and an enable column mean the same thing everywhere.
//!
//! # Rules
//! * The window keeps the samples with `START <= t <= END` [s] (either end open). A bound outside
//!   the log's span (by more than half a sample period), an empty or reversed window are errors
//!   naming the window and the span.
//! * The enable column (nonzero = drive on; 0 or a missing value = off): inside the window, the
//!   samples before the drive is first on are skipped, and the first off sample after it ends the
//!   usable part. Samples after the off sample are not used, even where the drive comes back on:
//!   the plant coasted in between, and joining the parts across the gap would make one motion of
//!   two. Row k's voltage acts from t_k to t_{k+1} (see [`super::Record`]), so the off row itself
//!   (whose voltage was not applied) is the first one left out.

use super::Record;
use alloc::format;
use alloc::string::String;
use core::fmt;

/// A time [s] with up to 6 decimals, trailing zeros dropped (`0.54`, not `0.5400000000000001`).
pub struct Secs(pub f64);

impl fmt::Display for Secs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = format!("{:.6}", self.0);
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            s.as_str()
        };
        f.write_str(if s == "-0" { "0" } else { s })
    }
}

/// Fewest samples a used part may have.
pub const MIN_SAMPLES: usize = 2;

/// A time window `START..END` [s]; `None`: open at that end.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct TimeWindow {
    /// First time kept [s].
    pub start_s: Option<f64>,
    /// Last time kept [s].
    pub end_s: Option<f64>,
}

/// Why a window could not be parsed or applied to a log.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PartError {
    /// The text is not `START..END`.
    #[error("`{0}` is not START..END in seconds (e.g. 2.0..12.5, 2.0.. or ..12.5)")]
    Syntax(String),
    /// The end is not after the start.
    #[error("{window}: the end is not after the start (an empty or reversed window)")]
    Reversed { window: String },
    /// A bound lies outside the log's span.
    #[error("{window} s lies outside the log's span {start} .. {end} s ({log})", start = Secs(*.span_start_s), end = Secs(*.span_end_s))]
    Outside {
        window: String,
        span_start_s: f64,
        span_end_s: f64,
        log: String,
    },
    /// Too few samples are left.
    #[error("{what} leaves {samples} sample(s) of the log's span {start} .. {end} s ({log}); at least {MIN_SAMPLES} are needed", start = Secs(*.span_start_s), end = Secs(*.span_end_s))]
    TooShort {
        what: String,
        samples: usize,
        span_start_s: f64,
        span_end_s: f64,
        log: String,
    },
}

impl TimeWindow {
    /// Parses `START..END` (seconds; `2.0..`, `..12.5` open at one end).
    pub fn parse(text: &str) -> Result<TimeWindow, PartError> {
        let bad = || PartError::Syntax(String::from(text));
        let (a, b) = text.trim().split_once("..").ok_or_else(bad)?;
        let num = |s: &str| -> Result<Option<f64>, PartError> {
            let s = s.trim();
            if s.is_empty() {
                return Ok(None);
            }
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(Some(v)),
                _ => Err(bad()),
            }
        };
        let w = TimeWindow {
            start_s: num(a)?,
            end_s: num(b)?,
        };
        if let (Some(a), Some(b)) = (w.start_s, w.end_s) {
            if b <= a {
                return Err(PartError::Reversed {
                    window: format!("{w}"),
                });
            }
        }
        Ok(w)
    }
}

impl fmt::Display for TimeWindow {
    /// The `START..END` form (open ends left empty).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(a) = self.start_s {
            write!(f, "{}", Secs(a))?;
        }
        f.write_str("..")?;
        if let Some(b) = self.end_s {
            write!(f, "{}", Secs(b))?;
        }
        Ok(())
    }
}

/// What ended (or started) the used part.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EnableCut {
    /// Time of the first off sample after the drive was on [s] (`None`: on to the end).
    pub off_at_s: Option<f64>,
    /// Samples skipped at the start because the drive was not yet on.
    pub skipped_before: usize,
    /// Samples left out after the first off sample.
    pub dropped_after: usize,
}

/// The part of a log a command used.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct UsedPart {
    /// The log (its record's source).
    pub source: String,
    /// Time of the first and last samples used [s].
    pub start_s: f64,
    pub end_s: f64,
    /// Index of the first sample used in the log (to cut signals kept beside the record).
    pub first_sample: usize,
    /// Samples used, of the log's samples.
    pub samples: usize,
    pub log_samples: usize,
    /// The log's whole span [s].
    pub log_start_s: f64,
    pub log_end_s: f64,
    /// The window asked for (`None`: the whole log).
    pub window: Option<TimeWindow>,
    /// What the enable column did (`None`: the log has none).
    pub enable: Option<EnableCut>,
}

impl UsedPart {
    /// True when the whole log is used.
    pub fn is_whole(&self) -> bool {
        self.samples == self.log_samples
    }
    /// The used rows of a signal kept beside the record (same length as the log).
    pub fn slice_of<'a, T>(&self, v: &'a [T]) -> &'a [T] {
        let a = self.first_sample.min(v.len());
        &v[a..(a + self.samples).min(v.len())]
    }
}

impl fmt::Display for UsedPart {
    /// One line: `log.csv: used 0 .. 5.999 s (6000 of 10000 samples; --window ..6; the drive
    /// was off from 6 s)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: used {} .. {} s ({} of {} samples",
            self.source,
            Secs(self.start_s),
            Secs(self.end_s),
            self.samples,
            self.log_samples
        )?;
        if let Some(w) = &self.window {
            write!(f, "; window {w}")?;
        }
        if let Some(e) = &self.enable {
            if e.skipped_before > 0 {
                write!(
                    f,
                    "; drive off for the first {} sample(s)",
                    e.skipped_before
                )?;
            }
            match e.off_at_s {
                Some(t) => write!(
                    f,
                    "; the drive was off from {} s, {} later sample(s) not used",
                    Secs(t),
                    e.dropped_after
                )?,
                None => f.write_str("; the drive was on throughout")?,
            }
        }
        f.write_str(")")
    }
}

/// Cuts `rec` to `window` and, when the record has an enable column, to the part where the drive
/// was on (see the module doc); returns the part and what was used.
pub fn cut(rec: &Record, window: Option<&TimeWindow>) -> Result<(Record, UsedPart), PartError> {
    let n = rec.len();
    let (t0, t1) = match (rec.time_s.first(), rec.time_s.last()) {
        (Some(a), Some(b)) => (*a, *b),
        _ => (f64::NAN, f64::NAN),
    };
    let too_short = |what: String, samples: usize| PartError::TooShort {
        what,
        samples,
        span_start_s: t0,
        span_end_s: t1,
        log: rec.source.clone(),
    };
    let (mut a, mut b) = (0usize, n);
    if let Some(w) = window {
        let tol = if rec.len() >= 2 {
            0.5 * rec.sample_period_s()
        } else {
            0.0
        };
        let outside = |v: f64| !(v >= t0 - tol && v <= t1 + tol);
        if w.start_s.is_some_and(outside) || w.end_s.is_some_and(outside) {
            return Err(PartError::Outside {
                window: format!("{w}"),
                span_start_s: t0,
                span_end_s: t1,
                log: rec.source.clone(),
            });
        }
        if let (Some(s), Some(e)) = (w.start_s, w.end_s) {
            if e <= s {
                return Err(PartError::Reversed {
                    window: format!("{w}"),
                });
            }
        }
        if let Some(s) = w.start_s {
            a = rec.time_s.partition_point(|&t| t < s);
        }
        if let Some(e) = w.end_s {
            b = rec.time_s.partition_point(|&t| t <= e).max(a);
        }
        if b - a < MIN_SAMPLES {
            return Err(too_short(format!("the window {w} s"), b - a));
        }
    }
    let enable = match &rec.enable {
        Some(en) => {
            let on = |k: usize| en.get(k).is_some_and(|v| *v != 0.0 && !v.is_nan());
            let first_on = (a..b).find(|&k| on(k)).unwrap_or(b);
            let first_off = (first_on..b).find(|&k| !on(k));
            let cut = EnableCut {
                off_at_s: first_off.map(|k| rec.time_s[k]),
                skipped_before: first_on - a,
                dropped_after: first_off.map_or(0, |k| b - k),
            };
            let end = first_off.unwrap_or(b);
            if end - first_on < MIN_SAMPLES {
                let what = match window {
                    Some(w) => format!("the enable column (drive on) inside the window {w} s"),
                    None => String::from("the enable column (drive on)"),
                };
                return Err(too_short(what, end - first_on));
            }
            a = first_on;
            b = end;
            Some(cut)
        }
        None => None,
    };
    let part = rec.slice(a, b);
    let used = UsedPart {
        source: rec.source.clone(),
        start_s: part.time_s.first().copied().unwrap_or(f64::NAN),
        end_s: part.time_s.last().copied().unwrap_or(f64::NAN),
        first_sample: a,
        samples: part.len(),
        log_samples: n,
        log_start_s: t0,
        log_end_s: t1,
        window: window.copied(),
        enable,
    };
    Ok((part, used))
}

/// The window of log `k` of `n_logs` from the values of a repeatable flag: none, one for every
/// log, or one per log in order (`None` too on a count mismatch: check [`counts_match`] first).
pub fn window_for(windows: &[TimeWindow], k: usize, n_logs: usize) -> Option<TimeWindow> {
    match windows.len() {
        0 => None,
        1 => Some(windows[0]),
        m if m == n_logs => windows.get(k).copied(),
        _ => None,
    }
}

/// Checks a repeatable flag's count against the logs: 0, 1 or one per log.
pub fn counts_match(given: usize, n_logs: usize) -> bool {
    given <= 1 || given == n_logs
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec::Vec;

    fn rec(n: usize, dt: f64) -> Record {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        Record {
            source: "test.csv".into(),
            u_v: Some(t.iter().map(|x| x * 2.0).collect()),
            time_s: t,
            ..Record::default()
        }
    }

    #[test]
    fn parses_windows() {
        let w = TimeWindow::parse("2.0..12.5").unwrap();
        assert_eq!((w.start_s, w.end_s), (Some(2.0), Some(12.5)));
        assert_eq!(TimeWindow::parse("2..").unwrap().end_s, None);
        assert_eq!(TimeWindow::parse("..1e1").unwrap().end_s, Some(10.0));
        assert_eq!(TimeWindow::parse("..").unwrap(), TimeWindow::default());
        for bad in ["2", "a..b", "1..inf", "2.0-3.0"] {
            assert!(
                matches!(TimeWindow::parse(bad), Err(PartError::Syntax(_))),
                "{bad}"
            );
        }
        let e = TimeWindow::parse("5..2").unwrap_err().to_string();
        assert!(e.contains("5..2") && e.contains("reversed"), "{e}");
        assert!(TimeWindow::parse("3..3").is_err());
    }

    #[test]
    fn cuts_by_window_inclusive() {
        let r = rec(101, 0.01); // 0 .. 1 s
        let w = TimeWindow::parse("0.2..0.5").unwrap();
        let (p, used) = cut(&r, Some(&w)).unwrap();
        assert_eq!(p.len(), 31);
        assert!((p.time_s[0] - 0.2).abs() < 1e-12 && (used.end_s - 0.5).abs() < 1e-12);
        assert_eq!(p.u_v.as_ref().unwrap()[0], r.u_v.as_ref().unwrap()[20]);
        assert_eq!(used.log_samples, 101);
        let text = used.to_string();
        assert!(
            text.contains("31 of 101") && text.contains("0.2..0.5"),
            "{text}"
        );
    }

    #[test]
    fn refuses_windows_outside_the_span() {
        let r = rec(101, 0.01);
        for w in ["2..3", "..1.5", "-1..0.5"] {
            let e = cut(&r, Some(&TimeWindow::parse(w).unwrap()))
                .unwrap_err()
                .to_string();
            assert!(e.contains("outside the log's span 0 .. 1 s"), "{w}: {e}");
        }
        // inside the span but between two samples
        let e = cut(&r, Some(&TimeWindow::parse("0.501..0.502").unwrap())).unwrap_err();
        assert!(matches!(e, PartError::TooShort { samples: 0, .. }), "{e}");
    }

    #[test]
    fn enable_ends_the_part_at_the_first_off_sample() {
        let mut r = rec(100, 0.01);
        // off for 5 samples, on for 50, off for 10, on again for the rest
        let en: Vec<f64> = (0..100)
            .map(|k| {
                if (5..55).contains(&k) || k >= 65 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        r.enable = Some(en);
        let (p, used) = cut(&r, None).unwrap();
        assert_eq!(p.len(), 50);
        assert!((p.time_s[0] - 0.05).abs() < 1e-12);
        assert!((p.time_s[49] - 0.54).abs() < 1e-12);
        let e = used.enable.unwrap();
        assert_eq!(e.skipped_before, 5);
        assert_eq!(e.dropped_after, 45);
        assert!((e.off_at_s.unwrap() - 0.55).abs() < 1e-12);
        // a window starting in the second on-part uses that one
        let (p, _) = cut(&r, Some(&TimeWindow::parse("0.6..").unwrap())).unwrap();
        assert_eq!(p.len(), 35);
        // drive never on
        r.enable = Some(alloc::vec![0.0; 100]);
        assert!(matches!(
            cut(&r, None),
            Err(PartError::TooShort { samples: 0, .. })
        ));
    }

    #[test]
    fn window_per_log() {
        let ws = [
            TimeWindow::parse("1..").unwrap(),
            TimeWindow::parse("..2").unwrap(),
        ];
        assert_eq!(window_for(&ws[..1], 1, 3), Some(ws[0]));
        assert_eq!(window_for(&ws, 1, 2), Some(ws[1]));
        assert!(counts_match(0, 3) && counts_match(1, 3) && counts_match(2, 2));
        assert!(!counts_match(2, 3));
    }
}
