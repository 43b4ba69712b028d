//! One reader per log format behind one trait, registered in one list (as rerun's data
//! loaders): every command that reads a log goes through the [`Registry`] ([`crate::read_log`],
//! `servo inspect`, `servo export`).
//!
//! A reader says whether a file is its format ([`LogReader::can_read`], by the file's
//! extension), reads it into a [`Record`] and its [`LogMeta`] (notes for the user included), and
//! lists what it holds for `servo inspect`. A reader handed a file that is not its format
//! answers [`Error::Incompatible`]; the registry then asks the next one. Adding a format is one
//! file with its reader and one line in [`crate::BUILT_IN`] (or, from outside servo-io,
//! [`Registry::with`]).

use crate::error::{Error, Result};
use crate::units::Signal;
use crate::LogMeta;
use servo_core::record::Record;
use std::path::Path;

/// A log format servo reads.
pub trait LogReader: Send + Sync {
    /// The format's name in messages (`CSV`, `MAT-file`, `MCAP`).
    fn name(&self) -> &'static str;
    /// The file extensions of the format, lower case without the dot; the first one names the
    /// format in the "expected a .mat, .mcap or .csv file" message.
    fn extensions(&self) -> &'static [&'static str];
    /// Whether `path` is this format: by default, its extension is one of
    /// [`LogReader::extensions`] (case-insensitive).
    fn can_read(&self, path: &Path) -> bool {
        let ext = extension(path);
        self.extensions().contains(&ext.as_str())
    }
    /// Reads the log at `path`: `columns` is the user's `--columns` map (a reader whose files
    /// name their own signals refuses one), `want` the signals to build (time always; `None`:
    /// every signal), `axis` the model's transmission (a column in a length unit becomes the
    /// load shaft's equivalent rotation on a linear axis, and is refused on a rotary gear).
    /// [`Error::Incompatible`] when the file is not this format.
    fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        want: Option<&[Signal]>,
        axis: &servo_core::Transmission,
    ) -> Result<(Record, LogMeta)>;
    /// What the file holds, one line each (`servo inspect`): the first line names the file and
    /// the format, the next ones are indented by the caller's choice.
    fn inspect(&self, path: &Path) -> Result<Vec<String>>;
}

/// The lower-case extension of `path` ("" without one).
pub fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

/// The `servo inspect` line of the column map servo would guess, or why it guesses none.
pub fn guessed(map: Result<String>) -> String {
    match map {
        Ok(m) => format!("guessed map: --columns {m}"),
        Err(e) => format!("no guessed map: {e:#}"),
    }
}

/// The log readers a command asks, in order.
pub struct Registry {
    readers: Vec<&'static dyn LogReader>,
}

impl Default for Registry {
    fn default() -> Self {
        Registry::built_in()
    }
}

impl Registry {
    /// servo's formats ([`crate::BUILT_IN`]).
    pub fn built_in() -> Registry {
        Registry {
            readers: crate::BUILT_IN.to_vec(),
        }
    }

    /// The registry with `reader` asked after the others (a format of one's own).
    pub fn with(mut self, reader: &'static dyn LogReader) -> Registry {
        self.readers.push(reader);
        self
    }

    /// The readers, in order.
    pub fn readers(&self) -> &[&'static dyn LogReader] {
        &self.readers
    }

    /// The first reader that can read `path`; [`Error::UnknownFormat`] when none can.
    pub fn reader_for(&self, path: &Path) -> Result<&'static dyn LogReader> {
        self.readers
            .iter()
            .copied()
            .find(|r| r.can_read(path))
            .ok_or_else(|| self.unknown(path))
    }

    /// Reads `path` with the first reader that takes it (see [`LogReader::read`]): a reader
    /// answering [`Error::Incompatible`] passes it on to the next one that can read it.
    pub fn read(
        &self,
        path: &Path,
        columns: Option<&str>,
        want: Option<&[Signal]>,
        axis: &servo_core::Transmission,
    ) -> Result<(Record, LogMeta)> {
        for r in self.readers.iter().filter(|r| r.can_read(path)) {
            match r.read(path, columns, want, axis) {
                Err(Error::Incompatible { .. }) => continue,
                Ok((rec, mut meta)) => {
                    // Logs are what their headers say: the angle against the speed.
                    let notes = crate::crosscheck::check_speed_units(
                        &rec,
                        meta.columns.as_deref().or(columns),
                    )?;
                    meta.notes.extend(notes);
                    return Ok((rec, meta));
                }
                other => return other,
            }
        }
        Err(self.unknown(path))
    }

    /// What `path` holds (`servo inspect`), from the first reader that takes it.
    pub fn inspect(&self, path: &Path) -> Result<Vec<String>> {
        for r in self.readers.iter().filter(|r| r.can_read(path)) {
            match r.inspect(path) {
                Err(Error::Incompatible { .. }) => continue,
                other => return other,
            }
        }
        Err(self.unknown(path))
    }

    fn unknown(&self, path: &Path) -> Error {
        let mut names: Vec<String> = Vec::new();
        for n in self
            .readers
            .iter()
            .filter_map(|r| r.extensions().first().map(|e| format!(".{e}")))
        {
            // Two readers of one extension (a ROS 2 bag and servo's MCAP) name it once.
            if !names.contains(&n) {
                names.push(n);
            }
        }
        let expected = match names.split_last() {
            Some((last, [])) => last.clone(),
            Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
            None => "no format".to_string(),
        };
        Error::UnknownFormat {
            path: path.to_path_buf(),
            extension: extension(path),
            expected,
        }
    }
}
