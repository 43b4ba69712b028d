//! The `servo` command-line tool. One file per subcommand in [`cmd`], each a `clap::Parser`
//! struct with `run(self) -> anyhow::Result<()>`.

/// `println!` that never panics: when stdout is closed (`servo ... | head`), the line is dropped
/// and the command goes on (a run still finishes its log). Plain `println!` would panic.
/// Prints nothing while [`quiet`] (the commands `servo demo` runs for its short story).
macro_rules! outln {
    () => {{
        use std::io::Write as _;
        if !$crate::quiet() {
            let _ = writeln!(std::io::stdout());
        }
    }};
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if !$crate::quiet() {
            let _ = writeln!(std::io::stdout(), $($arg)*);
        }
    }};
}

/// `print!` that never panics (see `outln!`).
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if !$crate::quiet() {
            let _ = write!(std::io::stdout(), $($arg)*);
        }
    }};
}

/// While set, `outln!` and `out!` print nothing: `servo demo` runs its commands this way and
/// prints each one's headline (its `--verbose` prints every command's full text).
static QUIET: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether the commands' text is muted (see [`QUIET`]).
pub fn quiet() -> bool {
    QUIET.load(std::sync::atomic::Ordering::Relaxed)
}

/// Mutes (`true`) or restores (`false`) the commands' text; returns the previous state.
pub fn set_quiet(on: bool) -> bool {
    QUIET.swap(on, std::sync::atomic::Ordering::Relaxed)
}

pub mod axis;
pub mod cmd;

pub mod api;
pub mod fuzz;
pub mod io;
pub mod json_out;
pub mod live;
pub mod log_part;
pub mod plant_args;
pub mod plot;
pub mod trend;

pub use servo_io::{effects_file, gains_file, model_file, reference_file};

use clap::Parser;

/// servo: from datasheet to a tuned, identified and understood DC-servomotor position loop.
#[derive(Debug, Parser)]
#[command(name = "servo", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: cmd::Command,
}

/// Parses `args` and runs the command; errors are printed with their context chain.
pub fn main_with_args<I, T>(args: I) -> std::process::ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                std::process::ExitCode::from(2)
            } else {
                std::process::ExitCode::SUCCESS
            };
        }
    };
    match cli.command.run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<live::Interrupted>().is_some() {
                // Like a shell after SIGINT.
                std::process::ExitCode::from(130)
            } else {
                std::process::ExitCode::FAILURE
            }
        }
    }
}
