//! The code's shape, as two resolved issues promised it, checked so that a later change that
//! undoes it fails here rather than in a reviewer's grep:
//! - effects are plug-ins (#11): a catalogue effect lives in its own file, so its name appears in
//!   at most 3 source files under `crates/*/src` (its own file, the registry, and one user);
//! - the CLI is thin (#13): a command file parses flags, calls the libraries and prints, so no
//!   file under `crates/servo-cli/src/cmd/` is longer than 400 lines.

use std::fs;
use std::path::{Path, PathBuf};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `dir`, recursively, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries = fs::read_dir(&d).unwrap_or_else(|e| panic!("reading {}: {e}", d.display()));
        for entry in entries {
            let path = entry
                .unwrap_or_else(|e| panic!("reading {}: {e}", d.display()))
                .path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The source files of every crate: `crates/*/src/**.rs`.
fn crate_sources() -> Vec<PathBuf> {
    let crates = workspace().join("crates");
    let mut out = Vec::new();
    for entry in fs::read_dir(&crates).expect("crates/ lists") {
        let src = entry.expect("crates/ entry").path().join("src");
        if src.is_dir() {
            out.extend(rust_files(&src));
        }
    }
    assert!(
        out.len() > 20,
        "found only {} source files under {}",
        out.len(),
        crates.display()
    );
    out
}

#[test]
fn each_catalogue_effect_name_appears_in_at_most_three_source_files() {
    let sources: Vec<(PathBuf, String)> = crate_sources()
        .into_iter()
        .map(|p| {
            let text = fs::read_to_string(&p)
                .unwrap_or_else(|e| panic!("reading {}: {e}", p.display()))
                .to_lowercase();
            (p, text)
        })
        .collect();
    let mut failures = Vec::new();
    for word in ["imbalance", "cogging", "backlash", "stribeck", "deadzone"] {
        let files: Vec<String> = sources
            .iter()
            .filter(|(_, text)| text.contains(word))
            .map(|(p, _)| {
                p.strip_prefix(workspace())
                    .unwrap_or(p)
                    .display()
                    .to_string()
            })
            .collect();
        // Its own file at least: a name found nowhere means the scan is broken.
        assert!(!files.is_empty(), "`{word}` appears in no source file");
        if files.len() > 3 {
            failures.push(format!(
                "`{word}` in {} files: {}",
                files.len(),
                files.join(", ")
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "a catalogue effect's name should appear in at most 3 source files (its own file, the \
         registry, one user); name effects through the registry instead:\n{}",
        failures.join("\n")
    );
}

#[test]
fn no_command_file_is_longer_than_400_lines() {
    let cmd = workspace().join("crates/servo-cli/src/cmd");
    let files = rust_files(&cmd);
    assert!(
        files.len() > 5,
        "found only {} files under {}",
        files.len(),
        cmd.display()
    );
    let long: Vec<String> = files
        .iter()
        .filter_map(|p| {
            let lines = fs::read_to_string(p).ok()?.lines().count();
            (lines > 400).then(|| format!("{} ({lines} lines)", p.display()))
        })
        .collect();
    assert!(
        long.is_empty(),
        "a command file parses flags, calls the libraries and prints; move computations into \
         servo-core/servo-io/servo-hw:\n{}",
        long.join("\n")
    );
}
