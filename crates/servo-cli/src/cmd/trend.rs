//! `servo trend`: follow each actuator's parameters over many logs and say what is changing.
//!
//! ```text
//! servo trend fleet/ --model m.toml --time-from name:%Y%m%d --limit tau_sf=0.02 --json
//! ```
//!
//! The work is the library's ([`crate::trend`]): this file parses the flags, calls it and prints.

use crate::trend::{self, GroupBy, TimeFrom, TrendConfig};
use anyhow::bail;
use servo_core::trend::TrendOptions;
use std::path::PathBuf;

/// Follow each actuator's parameters over many logs and say what is changing.
#[derive(Debug, clap::Parser)]
pub struct Trend {
    /// Logs (MCAP, CSV, MAT) and directories of logs (searched recursively).
    #[arg(required = true, value_name = "LOG_OR_DIR")]
    pub inputs: Vec<PathBuf>,
    /// Model file fitted to every log: its base parameters, and every parameter of the effects
    /// it declares; its `[limits]` table gives the limits forecast.
    #[arg(long, value_name = "model.toml")]
    pub model: PathBuf,
    /// How logs are grouped into actuators: `dir` (the log's folder, the default), `file` (the
    /// file name up to its first `_`), or a metadata field of the log (an MCAP run's key).
    #[arg(
        long = "group-by",
        value_name = "dir|file|FIELD",
        default_value = "dir"
    )]
    pub group_by: GroupBy,
    /// Where each log's time comes from: `auto` (the MCAP run's start, the MAT-file's save date,
    /// a CSV date column such as `unix_time_s` or `date`, else the file's modification time),
    /// `name:PATTERN` (the file name, e.g. `name:%Y%m%d`), `column:NAME` or `mtime`.
    #[arg(long = "time-from", value_name = "SOURCE", default_value = "auto")]
    pub time_from: TimeFrom,
    /// A limit a parameter must not cross, `PARAMETER=VALUE` in SI units (`tau_sf=0.02`,
    /// `<effect>.<key>=0.03`); overrides the model file's `[limits]`. Repeat for several.
    #[arg(long = "limit", value_name = "PARAMETER=VALUE", value_parser = trend::parse_limit)]
    pub limit: Vec<(String, f64)>,
    /// Column map for foreign CSV and MAT logs (as for `servo identify`).
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// Cache directory (default: $XDG_CACHE_HOME/servo/trend or ~/.cache/servo/trend).
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Worker threads fitting logs (default: the cores available).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Smallest change over the logs' span that counts, in percent of the parameter's mean
    /// magnitude (or of its limit, when it has one and that is larger).
    #[arg(long = "min-change-pct", value_name = "PCT", default_value_t = 10.0)]
    pub min_change_pct: f64,
    /// Print one JSON object (schema servo.trend/1) instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write the HTML report with a chart per parameter over time.
    #[arg(long, value_name = "report.html")]
    pub report: Option<PathBuf>,
    /// No progress line on stderr.
    #[arg(long)]
    pub quiet: bool,
}

impl Trend {
    pub fn run(self) -> anyhow::Result<()> {
        if !(self.min_change_pct.is_finite() && self.min_change_pct >= 0.0) {
            bail!(
                "--min-change-pct must be a percentage >= 0, got {}",
                self.min_change_pct
            );
        }
        if self.jobs == Some(0) {
            bail!("--jobs must be at least 1");
        }
        let cfg = TrendConfig {
            inputs: self.inputs,
            model: self.model,
            columns: self.columns,
            group_by: self.group_by,
            time_from: self.time_from,
            limits: self.limit.into_iter().collect(),
            cache_dir: self.cache,
            workers: self
                .jobs
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
            options: TrendOptions {
                min_relative_change: self.min_change_pct / 100.0,
                ..TrendOptions::default()
            },
            progress: !self.quiet,
        };
        let report = trend::run(&cfg)?;
        if let Some(path) = &self.report {
            crate::io::output::write_file(path, "--report", trend::report::html(&report)?)?;
        }
        if self.json {
            crate::json_out::emit(&trend::report::to_json(&report))?;
        } else {
            out!("{}", trend::report::text(&report));
            if let Some(path) = &self.report {
                outln!("wrote {}", path.display());
            }
        }
        Ok(())
    }
}
