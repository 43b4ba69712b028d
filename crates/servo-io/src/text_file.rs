//! The TOML files servo reads (model, gains, experiment, effects, recipe), read within a size
//! cap, and their parse errors quoted within a length cap: a file that is not one of them (a
//! log, 2 GB of NUL bytes, one line of 64 MB) costs neither memory nor a message sized by it.

use std::path::Path;

/// Largest TOML file servo reads [bytes]: 16 MiB (its files are a few kB).
pub const MAX_TEXT_FILE_BYTES: u64 = 16 << 20;

/// Longest TOML parse error quoted whole [bytes]; a longer one (the parser quotes the line,
/// which may be megabytes long) is cut to its start ([`crate::excerpt`]).
const MAX_ERROR_BYTES: usize = 2000;

/// The text of `path`, refused with an I/O error (kind `InvalidData`) beyond
/// [`MAX_TEXT_FILE_BYTES`], before more than that is read.
pub fn read_text(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let file = std::fs::File::open(path)?;
    let mut text = String::new();
    file.take(MAX_TEXT_FILE_BYTES + 1)
        .read_to_string(&mut text)?;
    if text.len() as u64 > MAX_TEXT_FILE_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "the file is larger than {} MiB, beyond any servo TOML file (a few kB): is it the right file?",
                MAX_TEXT_FILE_BYTES >> 20
            ),
        ));
    }
    Ok(text)
}

/// A TOML parse error as a message: the parser's own (with the line quoted and marked) when
/// short, else cut to [`MAX_ERROR_BYTES`] with an excerpt's marks.
pub fn toml_error(e: &toml::de::Error) -> String {
    let msg = e.to_string();
    let msg = msg.trim_end();
    if msg.len() <= MAX_ERROR_BYTES {
        return msg.to_string();
    }
    crate::excerpt::excerpt_str(msg, MAX_ERROR_BYTES / 4)
}
