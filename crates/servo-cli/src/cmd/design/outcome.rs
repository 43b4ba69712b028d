//! `servo design`: a design and what it achieves, and the writer of its text.

use super::*;

/// A design and what it achieves on the loop that runs.
pub(super) struct Outcome {
    pub(super) report: DesignReport,
    /// The controller structure around the gains (given, or chosen by --meet-specs).
    pub(super) structure: LoopStructure,
    /// The check of the time-domain specs, when the design comes from them.
    pub(super) check: Option<RangeCheck>,
    /// The --meet-specs search and its run time [ms].
    pub(super) meet: Option<(MeetResult, f64)>,
    /// The time-domain specs checked through `servo run`'s loop on the design's plant.
    pub(super) run_check: Option<RunCheck>,
    /// `--ff`: the design verified on the model without and with its compensation.
    pub(super) compensated: Option<compensated::CompensatedCheck>,
}

impl Outcome {
    /// Whether the time-domain specs are met: on the design's loop model and through `servo run`.
    pub(super) fn time_specs_met(&self) -> Option<bool> {
        let c = self.check.as_ref()?;
        Some(c.met() && self.run_check.as_ref().is_none_or(RunCheck::met))
    }
}

/// Writes to stdout; a closed pipe (`servo design | head`) is not an error.
pub(super) fn emit(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.context("writing to stdout"),
    }
}
