//! The commands as a library, for hosts that embed servo (the Python package, `python/`): a
//! command line in, the command's `--json` object out, through the same code as `servo ...
//! --json` ([`crate::json_out::capture`]), so the results of both are the same object.
//!
//! Errors come back as [`Failure`] with the CLI's message (`error: ...` without the prefix);
//! a panic (a bug) is caught and reported as a failure, never unwound into the host.

use crate::cmd::Command;
use crate::Cli;
use clap::Parser;
use serde_json::Value;
use servo_core::diagnose::cancel::Cancel;
use servo_core::fit::FitError;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

/// Why a command failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Failure {
    /// The message `servo` prints after `error: ` (the whole context chain).
    pub message: String,
    /// What kind of failure it is.
    pub kind: FailureKind,
}

/// The kinds of [`Failure`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailureKind {
    /// The command line did not parse (a flag's value, a missing argument): clap's message.
    Usage,
    /// The cancel flag was set during a diagnosis.
    Cancelled,
    /// The command failed (bad file, bad model, a fit that cannot be done...).
    Command,
    /// A bug: the command panicked (the message says where).
    Panic,
}

impl Failure {
    fn new(kind: FailureKind, message: impl Into<String>) -> Failure {
        Failure {
            message: message.into(),
            kind,
        }
    }
}

/// Runs `servo ARGS...` (without the program name; the command must be given `--json`) and
/// returns the JSON object it emits instead of printing it. `cancel`: a flag that stops a
/// diagnosis at its next check ([`servo_core::diagnose::cancel`]).
pub fn run_json(args: &[String], cancel: Option<Arc<AtomicBool>>) -> Result<Value, Failure> {
    let mut emitted = run_captured(args, cancel)?;
    if emitted.is_empty() {
        return Err(Failure::new(
            FailureKind::Usage,
            "the command emitted no JSON object (give it --json)",
        ));
    }
    Ok(emitted.swap_remove(0))
}

/// Runs `servo ARGS...` as [`run_json`] does, for a command without `--json` (`servo run`):
/// its text output goes to stdout as the CLI's does.
pub fn run(args: &[String]) -> Result<(), Failure> {
    run_captured(args, None).map(|_| ())
}

/// Runs the command line; returns the JSON objects it emitted (none without `--json`).
fn run_captured(args: &[String], cancel: Option<Arc<AtomicBool>>) -> Result<Vec<Value>, Failure> {
    let argv = std::iter::once("servo".to_string()).chain(args.iter().cloned());
    let mut cli = Cli::try_parse_from(argv).map_err(|e| {
        Failure::new(
            FailureKind::Usage,
            e.render()
                .to_string()
                .trim_start_matches("error: ")
                .trim_end()
                .to_string(),
        )
    })?;
    if let (Command::Diagnose(d), Some(flag)) = (&mut cli.command, cancel) {
        d.cancel = Cancel::on(flag);
    }
    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        crate::json_out::capture(|| cli.command.run())
    }));
    let (result, emitted) = match run {
        Ok(r) => r,
        Err(p) => {
            let what = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            return Err(Failure::new(
                FailureKind::Panic,
                format!("internal error (a bug in servo, please report it): {what}"),
            ));
        }
    };
    if let Err(e) = result {
        let cancelled = e
            .chain()
            .any(|c| c.downcast_ref::<FitError>() == Some(&FitError::Cancelled))
            || e.chain().any(|c| c.to_string().ends_with("cancelled"));
        let kind = if cancelled {
            FailureKind::Cancelled
        } else {
            FailureKind::Command
        };
        return Err(Failure::new(kind, format!("{e:#}")));
    }
    Ok(emitted)
}

/// [`run_json`] over many command lines on `workers` threads (at least 1) taking the next job
/// as each finishes: one job per worker in memory at a time, results in the order of `jobs`.
/// Once `cancel` is set, the jobs not started fail with [`FailureKind::Cancelled`].
pub fn run_many(
    jobs: &[Vec<String>],
    workers: usize,
    cancel: Option<Arc<AtomicBool>>,
) -> Vec<Result<Value, Failure>> {
    let workers = workers.max(1).min(jobs.len().max(1));
    let next = AtomicUsize::new(0);
    let mut out: Vec<Option<Result<Value, Failure>>> = jobs.iter().map(|_| None).collect();
    let stopped = || cancel.as_ref().is_some_and(|f| f.load(Ordering::Relaxed));
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                let (next, cancel, stopped) = (&next, &cancel, &stopped);
                s.spawn(move || {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(job) = jobs.get(i) else { break };
                        let r = if stopped() {
                            Err(Failure::new(FailureKind::Cancelled, "cancelled"))
                        } else {
                            run_json(job, cancel.clone())
                        };
                        done.push((i, r));
                    }
                    done
                })
            })
            .collect();
        for h in handles {
            // run_json catches panics, so a worker cannot panic; a job it never returned
            // is reported below.
            if let Ok(v) = h.join() {
                for (i, r) in v {
                    out[i] = Some(r);
                }
            }
        }
    });
    out.into_iter()
        .map(|r| r.unwrap_or_else(|| Err(Failure::new(FailureKind::Panic, "a worker thread died"))))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn a_design_comes_back_as_its_json_object() {
        let v = run_json(&args("design --wc 30 --pm 60 --json"), None).unwrap();
        assert_eq!(v["schema"], "servo.design/1");
    }

    #[test]
    fn failures_carry_the_cli_message_and_kind() {
        let e = run_json(&args("design --wc 30 --pm 60 --alpha -1 --json"), None).unwrap_err();
        assert_eq!(e.kind, FailureKind::Command);
        assert!(
            e.message.starts_with("--alpha must be > 0"),
            "{}",
            e.message
        );
        let e = run_json(&args("design --wc nope --json"), None).unwrap_err();
        assert_eq!(e.kind, FailureKind::Usage);
        assert!(e.message.contains("--wc"), "{}", e.message);
        let e = run_json(&args("design --wc 30 --pm 60"), None).unwrap_err();
        assert!(e.message.contains("no JSON"), "{}", e.message);
    }

    #[test]
    fn many_jobs_come_back_in_order() {
        let jobs: Vec<Vec<String>> = [20.0, 30.0, 40.0]
            .iter()
            .map(|w| args(&format!("design --wc {w} --pm 60 --json")))
            .collect();
        let got = run_many(&jobs, 2, None);
        assert_eq!(got.len(), 3);
        for (r, w) in got.iter().zip([20.0, 30.0, 40.0]) {
            let v = r.as_ref().unwrap();
            let s = v.to_string();
            assert!(s.contains(&format!("{w}")), "{s}");
        }
        let stop = Arc::new(AtomicBool::new(true));
        let got = run_many(&jobs, 2, Some(stop));
        assert!(got
            .iter()
            .all(|r| r.as_ref().err().map(|e| e.kind) == Some(FailureKind::Cancelled)));
    }
}
