//! Deterministic mutation fuzzing of servo's readers, shared by the test suite (`tests/e2e/fuzz.rs`)
//! and the `cargo fuzz` targets in `fuzz/`.
//!
//! Every reader of untrusted bytes (CSV, the TOML files, MCAP, `servo log recover`, the wire
//! protocol decoder, ...) must return an error, never panic, hang or allocate memory sized by a
//! length field rather than by its input. [`check_reader`] runs one reader over a seeded corpus of
//! mutations of valid inputs and reports every panic and every oversized allocation.
//!
//! Adding a reader (e.g. a MATLAB `.mat` reader) to the suite takes a few lines in
//! `tests/e2e/fuzz.rs`:
//!
//! ```no_run
//! # fn read_mat_bytes(_: &[u8]) -> anyhow::Result<()> { Ok(()) }
//! use servo_cli::fuzz::{check_reader, FuzzConfig};
//! let seeds: Vec<Vec<u8>> = vec![std::fs::read("a_valid_file.mat").unwrap()];
//! let report = check_reader("mat", &seeds, FuzzConfig::new(3000, 0x5eed), |bytes| {
//!     read_mat_bytes(bytes).map(drop)
//! });
//! assert!(report.failures.is_empty(), "{report}");
//! ```
//!
//! Oversized allocations are seen only in a binary that installs [`TrackingAlloc`] as its global
//! allocator (`tests/e2e/fuzz.rs` does); elsewhere only panics are checked.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::fmt;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// A small, fast, seeded generator (SplitMix64): the same seed gives the same corpus everywhere.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in 0..n (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// Tokens spliced into inputs: numbers that overflow or underflow, separators, TOML and CSV
/// syntax, huge lengths.
const TOKENS: &[&[u8]] = &[
    b"1e308",
    b"-1e308",
    b"1e30",
    b"1e-320",
    b"nan",
    b"inf",
    b"-inf",
    b"0",
    b"-0",
    b"99999999999999999999999",
    b"0x7fffffffffffffff",
    b",",
    b";",
    b"\t",
    b"\n",
    b"\r\n",
    b"\"",
    b"#",
    b"=",
    b"[",
    b"]",
    b"[[",
    b"{",
    b"}",
    b":",
    b"\xff\xfe",
    b"\0",
    b"1e9",
];

/// Mutates `input` into a new case: 1 to 4 random edits (bit flips, byte overwrites, 64-bit
/// overwrites with extreme values, which hit binary length fields, insertions, deletions,
/// truncation, duplication of a span, spliced tokens). The result is at most twice the input
/// plus 64 bytes long.
pub fn mutate(rng: &mut Rng, input: &[u8]) -> Vec<u8> {
    let mut v = input.to_vec();
    let edits = 1 + rng.below(4);
    for _ in 0..edits {
        let len = v.len();
        match rng.below(10) {
            0 if len > 0 => {
                let i = rng.below(len);
                v[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                v[i] = [0u8, 0xff, 0x7f, 0x80, 1, b'9'][rng.below(6)];
            }
            2 if len >= 8 => {
                let i = rng.below(len - 7);
                let x: u64 = match rng.below(6) {
                    0 => u64::MAX,
                    1 => 1 << 63,
                    2 => u32::MAX as u64,
                    3 => (len as u64) * 2,
                    4 => 0,
                    _ => rng.next_u64(),
                };
                v[i..i + 8].copy_from_slice(&x.to_le_bytes());
            }
            3 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                v.splice(i..i, bytes);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                v.drain(i..i + n);
            }
            5 if len > 0 => v.truncate(rng.below(len)),
            6 if len > 0 && len < 2 * input.len() + 64 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(256));
                let span = v[i..i + n].to_vec();
                let at = rng.below(len + 1);
                v.splice(at..at, span);
            }
            _ => {
                // Splice a token over a number-like spot or anywhere.
                let t = TOKENS[rng.below(TOKENS.len())];
                let i = rng.below(len + 1);
                let n = if len > i {
                    rng.below((len - i).min(8) + 1)
                } else {
                    0
                };
                v.splice(i..i + n, t.iter().copied());
            }
        }
    }
    v.truncate(2 * input.len() + 64);
    v
}

/// How many cases and which seed.
#[derive(Debug, Clone, Copy)]
pub struct FuzzConfig {
    /// Mutated cases (the seeds themselves are run first, in addition).
    pub cases: usize,
    /// Generator seed.
    pub seed: u64,
    /// Largest allocation allowed for an input of `n` bytes: `alloc_per_byte * n + alloc_base`
    /// (generous: real readers hold a few copies of their input plus fixed buffers such as a
    /// compressor's window).
    pub alloc_per_byte: usize,
    pub alloc_base: usize,
}

impl FuzzConfig {
    pub fn new(cases: usize, seed: u64) -> FuzzConfig {
        FuzzConfig {
            cases,
            seed,
            alloc_per_byte: 64,
            alloc_base: 64 << 20,
        }
    }
}

/// One failing case.
#[derive(Debug, Clone)]
pub struct FuzzFailure {
    /// Case number (0.. for the seeds, then the mutations).
    pub case: usize,
    /// The panic message or the oversized allocation.
    pub what: String,
    /// The input, to reproduce.
    pub input: Vec<u8>,
}

/// What a run of [`check_reader`] saw.
#[derive(Debug, Clone, Default)]
pub struct FuzzReport {
    pub reader: String,
    /// Cases run (seeds included).
    pub cases: usize,
    /// Cases the reader accepted and refused with an error.
    pub accepted: usize,
    pub refused: usize,
    /// Panics and oversized allocations.
    pub failures: Vec<FuzzFailure>,
    /// Largest single allocation seen [bytes] (0 without [`TrackingAlloc`]).
    pub max_alloc_bytes: usize,
    /// A few of the error messages, for a look at their quality.
    pub sample_errors: Vec<String>,
}

impl fmt::Display for FuzzReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} cases, {} accepted, {} refused with an error, {} failures, largest allocation {} bytes",
            self.reader,
            self.cases,
            self.accepted,
            self.refused,
            self.failures.len(),
            self.max_alloc_bytes
        )?;
        for x in self.failures.iter().take(5) {
            write!(
                f,
                "\n  case {}: {} (input {} bytes: {:?})",
                x.case,
                x.what,
                x.input.len(),
                String::from_utf8_lossy(&x.input[..x.input.len().min(200)])
            )?;
        }
        Ok(())
    }
}

/// Runs `reader` on each seed and on `cfg.cases` mutations of them; catches panics and (with
/// [`TrackingAlloc`] installed) allocations larger than the config allows.
pub fn check_reader<T, E: fmt::Display>(
    name: &str,
    seeds: &[Vec<u8>],
    cfg: FuzzConfig,
    reader: impl Fn(&[u8]) -> Result<T, E>,
) -> FuzzReport {
    let mut rng = Rng::new(cfg.seed ^ fnv(name.as_bytes()));
    let mut rep = FuzzReport {
        reader: name.to_string(),
        ..FuzzReport::default()
    };
    let total = seeds.len() + cfg.cases;
    // Panics are caught and reported; keep the default hook from printing thousands of them.
    for case in 0..total {
        let input = if case < seeds.len() {
            seeds[case].clone()
        } else if seeds.is_empty() {
            Vec::new()
        } else {
            let s = &seeds[rng.below(seeds.len())];
            // Sometimes mutate a mutation (deeper changes).
            let once = mutate(&mut rng, s);
            if rng.below(4) == 0 {
                mutate(&mut rng, &once)
            } else {
                once
            }
        };
        reset_max_alloc();
        let r = catch_unwind(AssertUnwindSafe(|| reader(&input).map(drop)));
        let biggest = take_max_alloc();
        rep.max_alloc_bytes = rep.max_alloc_bytes.max(biggest);
        rep.cases += 1;
        match r {
            Ok(Ok(())) => rep.accepted += 1,
            Ok(Err(e)) => {
                rep.refused += 1;
                if rep.sample_errors.len() < 8 && case % 97 == 0 {
                    rep.sample_errors.push(e.to_string());
                }
            }
            Err(p) => {
                let msg = p
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| p.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "panic".into());
                rep.failures.push(FuzzFailure {
                    case,
                    what: format!("panicked: {msg}"),
                    input: input.clone(),
                });
            }
        }
        let allowed = cfg
            .alloc_per_byte
            .saturating_mul(input.len())
            .saturating_add(cfg.alloc_base);
        if biggest > allowed {
            rep.failures.push(FuzzFailure {
                case,
                what: format!(
                    "allocated {biggest} bytes at once for an input of {} bytes",
                    input.len()
                ),
                input,
            });
        }
    }
    rep
}

fn fnv(b: &[u8]) -> u64 {
    b.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &x| {
        (h ^ x as u64).wrapping_mul(0x100_0000_01b3)
    })
}

thread_local! {
    static MAX_ALLOC: Cell<usize> = const { Cell::new(0) };
}

fn reset_max_alloc() {
    let _ = MAX_ALLOC.try_with(|m| m.set(0));
}

fn take_max_alloc() -> usize {
    MAX_ALLOC.try_with(|m| m.replace(0)).unwrap_or(0)
}

/// The system allocator, remembering (per thread) the largest single allocation since the last
/// case, so that [`check_reader`] can tell a reader that sized a buffer by a corrupted length
/// field. Install it in a test binary with
/// `#[global_allocator] static A: servo_cli::fuzz::TrackingAlloc = servo_cli::fuzz::TrackingAlloc;`.
pub struct TrackingAlloc;

// SAFETY: forwards to `System`; the bookkeeping neither allocates nor unwinds.
unsafe impl GlobalAlloc for TrackingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        System.realloc(ptr, layout, new_size)
    }
}

fn note(size: usize) {
    let _ = MAX_ALLOC.try_with(|m| {
        if size > m.get() {
            m.set(size)
        }
    });
}

/// The report and chart writers on arbitrary names (the `report` fuzz target and the seeded
/// corpus of `tests/e2e/fuzz.rs`): `data`'s UTF-8 text (lossy), split at `\u{1f}` (unit
/// separator), fills a chart's title, axis labels and series labels and values placed in text,
/// attribute and URL contexts of a report page (with the report's Content-Security-Policy and
/// the chart inlined). Panics when a chart does not render or any document has
/// [`servo_io::markup::problems`] (an event handler, a script, broken markup); returns the
/// chart, the stacked charts and the page, for the caller to parse as XML.
pub fn check_report_writers(data: &[u8]) -> [String; 3] {
    use crate::plot::{line_chart_svg, Chart, Series};
    use servo_io::markup::{problems, Attr, Markup, Url, CSP_META};
    let text = String::from_utf8_lossy(data);
    let mut f: Vec<&str> = text.split('\u{1f}').collect();
    f.resize(8, "");
    let x = [0.1, 0.2, 0.5, 1.0, 2.0];
    let y = [1.0, -1.0, 0.5, f64::NAN, 2.0];
    let chart = Chart {
        title: f[0],
        x_label: f[1],
        y_label: f[2],
        log_x: data.first().is_some_and(|b| b & 1 == 1),
        scatter: data.first().is_some_and(|b| b & 2 == 2),
        ..Chart::default()
    };
    let series = [
        Series {
            label: f[3],
            x: &x,
            y: &y,
        },
        Series {
            label: f[4],
            x: &x,
            y: &x,
        },
    ];
    let svg = match line_chart_svg(&chart, &series) {
        Ok(svg) => svg,
        Err(e) => panic!("the chart does not render: {e:#}"),
    };
    let p = problems(&svg);
    assert!(p.is_empty(), "the chart: {p:?}");
    let stacked = crate::cmd::compare::stack_svg(&[svg.clone(), svg.clone()]);
    let p = problems(&stacked);
    assert!(p.is_empty(), "the stacked charts: {p:?}");
    let mut h = Markup::new();
    h.lit("<!DOCTYPE html><html><head>")
        .lit(CSP_META)
        .lit("</head><body>");
    servo_io::markup!(
        h,
        "<div class=\"panel\" data-log=\"{}\" title='{}'><h3>{}</h3><a href=\"{}\">{}</a>",
        f[5],
        Attr(f[6]),
        f[5],
        Url(f[7]),
        f[6]
    );
    h.push(&Markup::from_rendered_svg(&svg))
        .lit("</div></body></html>");
    let page = h.into_string();
    let p = problems(&page);
    assert!(p.is_empty(), "the report page: {p:?}");
    [svg, stacked, page]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_are_deterministic_and_bounded() {
        let input = b"time_s,u_V\n0,1\n0.001,2\n".to_vec();
        let a: Vec<Vec<u8>> = {
            let mut r = Rng::new(7);
            (0..200).map(|_| mutate(&mut r, &input)).collect()
        };
        let b: Vec<Vec<u8>> = {
            let mut r = Rng::new(7);
            (0..200).map(|_| mutate(&mut r, &input)).collect()
        };
        assert_eq!(a, b);
        assert!(a.iter().all(|m| m.len() <= 2 * input.len() + 64));
        assert!(a.iter().filter(|m| **m != input).count() > 190);
    }

    #[test]
    fn a_panicking_reader_is_reported() {
        let seeds = vec![b"abc".to_vec()];
        let rep = check_reader("panicky", &seeds, FuzzConfig::new(50, 1), |b| {
            if b.len() > 3 {
                panic!("too long");
            }
            Ok::<(), String>(())
        });
        assert!(!rep.failures.is_empty());
        assert!(rep.failures[0].what.contains("too long"), "{rep}");
    }
}
