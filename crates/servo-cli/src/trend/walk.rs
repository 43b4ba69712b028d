//! The logs of `servo trend`: the files given, and the logs under the directories given
//! (recursively, by extension: `.mcap`, `.csv`, `.mat`), hidden files and folders skipped.

use std::path::{Path, PathBuf};

/// Extensions read as logs.
pub const LOG_EXTENSIONS: [&str; 3] = ["mcap", "csv", "mat"];

/// Every log of `inputs`, sorted, without duplicates; `skip` (the cache) is not entered. A
/// missing input is an error naming it.
pub fn collect(inputs: &[PathBuf], skip: Option<&Path>) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for input in inputs {
        let meta = std::fs::metadata(input)
            .map_err(|e| anyhow::anyhow!("LOG_OR_DIR {}: {e}", input.display()))?;
        if meta.is_dir() {
            let mut stack = vec![input.clone()];
            while let Some(dir) = stack.pop() {
                if skip.is_some_and(|s| same(s, &dir)) {
                    continue;
                }
                let entries = std::fs::read_dir(&dir)
                    .map_err(|e| anyhow::anyhow!("reading directory {}: {e}", dir.display()))?;
                for entry in entries.flatten() {
                    let p = entry.path();
                    let hidden = p
                        .file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with('.'));
                    if hidden {
                        continue;
                    }
                    if p.is_dir() {
                        stack.push(p);
                    } else if is_log(&p) {
                        out.push(p);
                    }
                }
            }
        } else {
            out.push(input.clone());
        }
    }
    out.sort();
    out.dedup();
    Ok(out)
}

fn is_log(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| LOG_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

fn same(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}
