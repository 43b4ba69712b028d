//! `servo inspect FILE`: what a log holds, to write its `--columns` map.
//!
//! ```text
//! servo inspect lab.mat      variables, struct fields, sizes, Scope labels, the guessed map
//! servo inspect lab.csv      header columns, rows, the guessed map
//! servo inspect run.mcap     channels, schemas, message counts, metadata keys, signals
//! ```

use std::path::PathBuf;

/// List the variables, fields, shapes and labels of a .mat file (or a CSV's columns, an MCAP's
/// channels), and the column map servo would guess.
#[derive(Debug, clap::Parser)]
pub struct Inspect {
    /// The file (.mat, .csv or .mcap).
    pub file: PathBuf,
}

impl Inspect {
    pub fn run(self) -> anyhow::Result<()> {
        for line in crate::io::Registry::built_in().inspect(&self.file)? {
            outln!("{line}");
        }
        Ok(())
    }
}
