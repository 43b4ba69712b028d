//! The CLI's side of a run: Ctrl-C handling and live progress on stderr, around the library's
//! loop ([`servo_hw::run`]). The run loop, its configuration and output, the log sink, the
//! programs, the speed estimator and controller and the step metrics live in the library crates
//! (servo-hw, servo-core), and the controller resolution in [`servo_io::controller`]: commands
//! import them from there.
//!
//! Ctrl-C (with [`run_loop`]): the loop stops at the next sample, the backend is stopped at 0 V,
//! the log is flushed and the output says [`StopReason::Interrupted`]; a second Ctrl-C exits at
//! once with status 130. With a [`Progress`], long runs show their progress on stderr: run time
//! elapsed and left, and the missed deadlines of a board.

use servo_hw::run::{LogSink, RunConfig, RunError, RunMonitor, RunOutput};

use servo_hw::Backend;
use std::sync::atomic::{AtomicBool, Ordering};

/// The error of a run stopped by Ctrl-C (after the board was stopped and the logs closed):
/// `servo` exits with status 130 on it, like a shell.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("interrupted by Ctrl-C at t = {at_s:.3} s")]
pub struct Interrupted {
    /// Run time of the last sample [s].
    pub at_s: f64,
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);
static HANDLER: std::sync::Once = std::sync::Once::new();

/// Installs the Ctrl-C handler (once per process): the first Ctrl-C asks running loops to stop,
/// the second exits with status 130.
pub fn install_ctrlc_handler() {
    HANDLER.call_once(|| {
        let r = ctrlc::set_handler(|| {
            if INTERRUPTED.swap(true, Ordering::SeqCst) {
                eprintln!("\nsecond Ctrl-C: exiting without cleanup");
                crate::io::output::remove_temporaries();
                std::process::exit(130);
            }
            eprintln!("\nCtrl-C: stopping the loop (0 V) and closing the log; press again to exit at once");
        });
        if let Err(e) = r {
            eprintln!("warning: cannot install the Ctrl-C handler ({e}); Ctrl-C will kill the run without closing the log");
        }
    });
}

/// For a host that handles Ctrl-C itself (the Python binding: KeyboardInterrupt): no handler is
/// ever installed in this process, so runs do not stop on Ctrl-C and the host's own handler
/// stays. Call before the first run.
pub fn leave_ctrlc_to_host() {
    HANDLER.call_once(|| {});
}

/// True once Ctrl-C was pressed.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// The CLI's [`RunMonitor`]: stops on Ctrl-C, prints the warnings and the progress on stderr.
#[derive(Debug)]
pub struct CliMonitor {
    progress: Option<ProgressState>,
}

impl CliMonitor {
    /// Installs the Ctrl-C handler; shows `progress` (None: silent).
    pub fn new(progress: Option<Progress>) -> CliMonitor {
        install_ctrlc_handler();
        CliMonitor {
            progress: progress.map(|p| ProgressState {
                next_s: p.interval_s,
                cfg: p,
                start: std::time::Instant::now(),
                shown: false,
            }),
        }
    }
}

impl RunMonitor for CliMonitor {
    fn stop_requested(&mut self) -> bool {
        interrupted()
    }
    fn sample(&mut self, t_s: f64, planned_s: f64, backend: &dyn Backend) {
        if let Some(p) = self.progress.as_mut() {
            p.tick(t_s, planned_s, backend);
        }
    }
    fn warning(&mut self, text: &str) {
        eprintln!("warning: {text}");
    }
    fn finished(&mut self) {
        if let Some(p) = &self.progress {
            p.finish();
        }
    }
}

/// Runs the library's loop with Ctrl-C handled and `progress` shown (None: silent).
pub fn run_loop_with_progress(
    backend: &mut dyn Backend,
    cfg: &RunConfig,
    sink: Option<&mut dyn LogSink>,
    progress: Option<Progress>,
) -> Result<RunOutput, RunError> {
    servo_hw::run::run_loop_monitored(backend, cfg, sink, &mut CliMonitor::new(progress))
}

/// Runs the library's loop with Ctrl-C handled, no progress.
pub fn run_loop(
    backend: &mut dyn Backend,
    cfg: &RunConfig,
    sink: Option<&mut dyn LogSink>,
) -> Result<RunOutput, RunError> {
    run_loop_with_progress(backend, cfg, sink, None)
}

/// When and how a run shows its progress on stderr.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// What runs (`servo run`, `identify_friction`, ...), the start of each line.
    pub label: String,
    /// Wall-clock time between two updates [s]; the first comes after one interval, so short
    /// runs print nothing.
    pub interval_s: f64,
    /// Rewrite one line in place (a terminal) instead of printing a line per update (a log).
    pub in_place: bool,
}

/// How `--progress` is chosen on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ProgressMode {
    /// When stderr is a terminal: one line updated in place twice a second.
    #[default]
    Auto,
    /// Always: in place on a terminal, else a line every 2 s (for logs and CI).
    Always,
    /// Never.
    Never,
}

impl Progress {
    /// The progress `mode` asks for, labelled `label` (None: silent).
    pub fn from_mode(mode: ProgressMode, label: &str) -> Option<Progress> {
        use std::io::IsTerminal;
        let tty = std::io::stderr().is_terminal();
        let show = match mode {
            ProgressMode::Auto => tty,
            ProgressMode::Always => true,
            ProgressMode::Never => false,
        };
        show.then(|| Progress {
            label: label.to_string(),
            interval_s: if tty { 0.5 } else { 2.0 },
            in_place: tty,
        })
    }

    /// The text of one update: run time elapsed and planned [s], time left, missed deadlines
    /// (None: the backend has no deadlines).
    pub fn line(&self, t_s: f64, total_s: f64, missed: Option<u64>) -> String {
        let mut s = format!(
            "{}: {t_s:.1} s of {total_s:.1} s, {:.1} s left",
            self.label,
            (total_s - t_s).max(0.0)
        );
        if let Some(m) = missed {
            s.push_str(&format!(
                ", {m} missed deadline{}",
                if m == 1 { "" } else { "s" }
            ));
        }
        s
    }
}

/// The progress display of one run.
#[derive(Debug)]
struct ProgressState {
    cfg: Progress,
    start: std::time::Instant,
    next_s: f64,
    shown: bool,
}

impl ProgressState {
    fn tick(&mut self, t_s: f64, total_s: f64, backend: &dyn Backend) {
        let wall = self.start.elapsed().as_secs_f64();
        if wall < self.next_s {
            return;
        }
        self.next_s = wall + self.cfg.interval_s;
        let line = self.cfg.line(t_s, total_s, backend.missed_deadlines());
        if self.cfg.in_place {
            eprint!("\r{line}\x1b[K");
        } else {
            eprintln!("{line}");
        }
        self.shown = true;
    }
    fn finish(&self) {
        if self.shown && self.cfg.in_place {
            eprint!("\r\x1b[K");
        }
    }
}
