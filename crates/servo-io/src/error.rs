//! The error of servo-io: what went wrong, with the file, line, key or flag, and the lower-level
//! cause as its [`std::error::Error::source`].
//!
//! Readers add context as they go ([`Context::context`]: "in gains file gains.toml", "reading
//! run.mcap"); printed with its sources (anyhow's `{:#}`) an error reads as one sentence from the
//! outermost context to the root cause.

use std::fmt::Display;

/// Everything servo-io can fail with.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An input is not what servo expects; the message names the file, line, key or flag and
    /// what was expected.
    #[error("{0}")]
    Invalid(String),
    /// A file no log reader takes (by its extension): `expected` lists the registry's formats
    /// (".mat, .mcap or .csv").
    #[error("{}: unknown log format `.{extension}`; expected a {expected} file", path.display())]
    UnknownFormat {
        path: std::path::PathBuf,
        extension: String,
        expected: String,
    },
    /// A log reader handed a file that is not its format ([`crate::LogReader::read`]): the
    /// registry asks the next reader.
    #[error("{}: not a {format} file", path.display())]
    Incompatible {
        path: std::path::PathBuf,
        format: &'static str,
    },
    /// A lower-level error with what servo-io was doing when it happened. `{}` shows the
    /// context, `{:#}` the context and every cause after it.
    #[error(fmt = fmt_context)]
    Context {
        context: String,
        #[source]
        source: Box<Error>,
    },
    /// Reading or writing a file.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A CSV file.
    #[error(transparent)]
    Csv(#[from] csv::Error),
    /// A TOML file that does not parse.
    #[error(transparent)]
    TomlDe(#[from] toml::de::Error),
    /// A value that TOML cannot represent.
    #[error(transparent)]
    TomlSer(#[from] toml::ser::Error),
    /// JSON (MCAP messages, schemas).
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// An MCAP file.
    #[error(transparent)]
    Mcap(#[from] mcap::McapError),
    /// A MATLAB MAT-file.
    #[error(transparent)]
    Mat(#[from] crate::mat_read::MatError),
    /// A setpoint program (speed profile of an experiment recipe).
    #[error(transparent)]
    Program(#[from] servo_core::control::ProgramError),
    /// A unit in a column map or header.
    #[error(transparent)]
    Unit(#[from] crate::units::UnitError),
}

fn fmt_context(
    context: &String,
    source: &Error,
    f: &mut std::fmt::Formatter<'_>,
) -> std::fmt::Result {
    if f.alternate() {
        write!(f, "{context}: {source:#}")
    } else {
        f.write_str(context)
    }
}

/// `Result` with servo-io's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Adds what was being done to an error (as `anyhow::Context` does, with a typed error).
pub trait Context<T> {
    /// Wraps the error with `context`.
    fn context<C: Display>(self, context: C) -> Result<T>;
    /// Wraps the error with the context `f` builds (only on error).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: context.to_string(),
            source: Box::new(e.into()),
        })
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: f().to_string(),
            source: Box::new(e.into()),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.ok_or_else(|| Error::Invalid(context.to_string()))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.ok_or_else(|| Error::Invalid(f().to_string()))
    }
}

/// An [`Error::Invalid`] from a format string. (The readers moved here from servo-cli keep
/// anyhow's spelling, `anyhow!`, `bail!`, `anyhow::Result`, through `use crate::error::{self as
/// anyhow, ...}`, so that the move stayed a rename; the type is this module's [`Error`].)
macro_rules! anyhow {
    ($($arg:tt)*) => { $crate::error::Error::Invalid(format!($($arg)*)) };
}

/// Returns early with an [`Error::Invalid`] from a format string.
macro_rules! bail {
    ($($arg:tt)*) => { return Err($crate::error::Error::Invalid(format!($($arg)*)).into()) };
}

pub(crate) use {anyhow, bail};
