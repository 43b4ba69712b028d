//! `--window START..END` and the enable column: the part of each log a command uses, cut by
//! [`servo_core::record::part::cut`] after the log is read (every format alike).

use anyhow::{bail, Context};
use serde_json::{json, Value};
use servo_core::record::part::{counts_match, cut, window_for, TimeWindow, UsedPart};
use servo_core::record::Record;
use std::path::Path;

/// The `--window` flag, flattened into every command that reads logs.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LogPartArgs {
    /// The part of a log to use: START..END in seconds, both ends included, either end open
    /// (`2.0..`, `..12.5`). Given once it applies to every log; repeated, once per log, it applies
    /// to the logs in order. A window outside a log's span, empty or reversed is refused. A log
    /// with an enable column (`--columns ...,enable=drv_on`: nonzero = drive on) is used from the
    /// drive's first on sample inside the window to the sample before its first off sample: what
    /// follows an off sample is not used (not joined across the gap).
    #[arg(long = "window", value_name = "START..END", value_parser = parse_window)]
    pub window: Vec<TimeWindow>,
}

fn parse_window(s: &str) -> Result<TimeWindow, String> {
    TimeWindow::parse(s).map_err(|e| e.to_string())
}

impl LogPartArgs {
    /// Refuses a `--window` count that is neither 0, 1 nor one per log.
    pub fn check(&self, n_logs: usize) -> anyhow::Result<()> {
        if !counts_match(self.window.len(), n_logs) {
            bail!(
                "--window given {} times for {} logs: give it once (for every log) or once per log, in the order of the logs",
                self.window.len(),
                n_logs
            );
        }
        Ok(())
    }

    /// The used part of log `k` of `n_logs` (read from `path`).
    pub fn cut(
        &self,
        rec: &Record,
        path: &Path,
        k: usize,
        n_logs: usize,
    ) -> anyhow::Result<(Record, UsedPart)> {
        self.check(n_logs)?;
        let w = window_for(&self.window, k, n_logs);
        let flag = match &w {
            Some(w) => format!("--window {w}"),
            None => "the enable column".to_string(),
        };
        cut(rec, w.as_ref()).with_context(|| format!("{flag} on log {}", path.display()))
    }

    /// Cuts `rec` in place and returns what was used.
    pub fn apply(
        &self,
        rec: &mut Record,
        path: &Path,
        k: usize,
        n_logs: usize,
    ) -> anyhow::Result<UsedPart> {
        let (part, used) = self.cut(rec, path, k, n_logs)?;
        *rec = part;
        Ok(used)
    }
}

/// The text lines of the parts used (one per log); empty when every log was used whole and none
/// had an enable column.
pub fn text(parts: &[UsedPart]) -> String {
    if parts.iter().all(|p| p.is_whole() && p.enable.is_none()) {
        return String::new();
    }
    parts.iter().map(|p| format!("part of log {p}\n")).collect()
}

/// The `log_parts` array of a command's `--json`.
pub fn json(parts: &[UsedPart]) -> Value {
    Value::Array(
        parts
            .iter()
            .map(|p| {
                json!({
                    "log": p.source,
                    "start_s": p.start_s,
                    "end_s": p.end_s,
                    "samples": p.samples,
                    "log_samples": p.log_samples,
                    "log_start_s": p.log_start_s,
                    "log_end_s": p.log_end_s,
                    "window": p.window.map(|w| w.to_string()),
                    "drive_off_at_s": p.enable.and_then(|e| e.off_at_s),
                })
            })
            .collect(),
    )
}
