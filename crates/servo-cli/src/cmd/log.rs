//! `servo log recover`: salvages an unfinished MCAP log into a finished, indexed file (the
//! recovery itself is [`crate::io::mcap_recover`]).

pub use crate::io::mcap_recover::{recover, recover_bytes, RecoveryReport};
use anyhow::bail;
use std::path::PathBuf;

/// Log utilities.
#[derive(Debug, clap::Parser)]
pub struct Log {
    #[command(subcommand)]
    pub cmd: LogCmd,
}

/// `servo log` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum LogCmd {
    /// Salvage an unfinished MCAP log (e.g. after kill -9) into a finished file.
    Recover(Recover),
}

/// `servo log recover BROKEN.mcap -o FIXED.mcap`
#[derive(Debug, clap::Parser)]
pub struct Recover {
    /// The unfinished MCAP file.
    #[arg(value_name = "BROKEN.mcap")]
    pub input: PathBuf,
    /// Where to write the recovered, finished MCAP file.
    #[arg(short = 'o', long = "output", value_name = "FIXED.mcap")]
    pub output: PathBuf,
}

impl Log {
    pub fn run(self) -> anyhow::Result<()> {
        match self.cmd {
            LogCmd::Recover(r) => r.run(),
        }
    }
}

impl Recover {
    pub fn run(self) -> anyhow::Result<()> {
        if self.input == self.output {
            bail!(
                "--output must differ from the input file {}",
                self.input.display()
            );
        }
        let r = recover(&self.input, &self.output)?;
        let first = r.first_log_time_ns.map_or(0.0, |t| t as f64 * 1e-9);
        let last = r.last_log_time_ns.map_or(0.0, |t| t as f64 * 1e-9);
        outln!(
            "recovered {} messages on {} topic(s) [{}] spanning {:.3} s (log time {:.3} s .. {:.3} s)",
            r.messages,
            r.topics.len(),
            r.topics.iter().cloned().collect::<Vec<_>>().join(", "),
            r.span_s(),
            first,
            last
        );
        outln!(
            "read {} of {} bytes; {} metadata record(s), {} attachment(s) copied",
            r.good_bytes,
            r.total_bytes,
            r.metadata,
            r.attachments
        );
        match (&r.stopped_because, r.was_complete) {
            (_, true) => outln!("the input was already a finished MCAP file; rewritten as is"),
            (Some(why), _) => outln!("stopped at byte {}: {why}", r.good_bytes),
            (None, _) => outln!("the input ended cleanly between records but had no footer"),
        }
        for n in &r.notes {
            outln!("kept the log's note in the recovered log: {n}");
        }
        outln!("wrote {}", self.output.display());
        Ok(())
    }
}
