//! `servo inspect FILE`: what a log holds, to write its `--columns` map.
//!
//! ```text
//! servo inspect lab.mat      variables, struct fields, sizes, Scope labels, the guessed map
//! servo inspect lab.csv      header columns, rows, the guessed map
//! servo inspect run.mcap     channels, schemas, message counts, metadata keys, signals
//! ```

use crate::io::{mat_log, mat_read, LogFormat};
use anyhow::Context;
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
        let source = self.file.display().to_string();
        match LogFormat::of(&self.file)? {
            LogFormat::Mat => {
                let file = mat_read::read_mat_file(&self.file).with_context(|| source.clone())?;
                outln!("{source}: MAT-file, {} variables", file.variables.len());
                for line in mat_log::describe(&file) {
                    outln!("  {line}");
                }
                guessed(mat_log::guess(&file).map(|m| m.to_string()));
            }
            LogFormat::Csv => {
                let text = std::fs::read_to_string(&self.file)
                    .with_context(|| format!("reading {source}"))?;
                let mut lines = text
                    .lines()
                    .filter(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty());
                let header = lines.next().unwrap_or("");
                let rows = lines.count();
                outln!("{source}: CSV, {rows} data rows");
                outln!("  columns: {header}");
                guessed(
                    crate::io::csv_read::parse_csv(&text, &source, None).map(|i| i.map.to_string()),
                );
            }
            LogFormat::Mcap => {
                let bytes =
                    std::fs::read(&self.file).with_context(|| format!("reading {source}"))?;
                outln!("{source}: MCAP");
                match mcap::read::Summary::read(&bytes) {
                    Ok(Some(s)) => {
                        let counts = s.stats.as_ref().map(|st| st.channel_message_counts.clone());
                        for (id, c) in &s.channels {
                            let n = counts
                                .as_ref()
                                .and_then(|m| m.get(id))
                                .map(|n| format!(", {n} messages"))
                                .unwrap_or_default();
                            outln!(
                                "  channel {}: encoding {}, schema {}{n}",
                                c.topic,
                                c.message_encoding,
                                c.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("-")
                            );
                        }
                    }
                    Ok(None) => outln!("  (no summary section: an unfinished log?)"),
                    Err(e) => outln!("  (summary unreadable: {e})"),
                }
                match crate::io::read_log_with_meta(&self.file, None) {
                    Ok((rec, meta)) => {
                        outln!(
                            "  {} samples, {:.3} s, signals {}",
                            rec.len(),
                            rec.time_s.last().copied().unwrap_or(0.0)
                                - rec.time_s.first().copied().unwrap_or(0.0),
                            rec.signals().join(", ")
                        );
                        if !meta.entries.is_empty() {
                            let keys: Vec<&str> = meta.entries.keys().map(String::as_str).collect();
                            outln!("  metadata: {}", keys.join(", "));
                        }
                        for n in &meta.notes {
                            outln!("  note: {n}");
                        }
                    }
                    Err(e) => outln!("  not readable as a servo log: {e:#}"),
                }
            }
        }
        Ok(())
    }
}

fn guessed(map: crate::io::Result<String>) {
    match map {
        Ok(m) => outln!("guessed map: --columns {m}"),
        Err(e) => outln!("no guessed map: {e:#}"),
    }
}
