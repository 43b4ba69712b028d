//! The per-log cache of `servo trend`: one small JSON file per (log content, model, servo
//! version), so that a re-run reads each log already fitted from the cache and fits only the
//! new ones, and an interrupted run resumes where it stopped.
//!
//! The key is the FNV-1a 64-bit hash of the log's bytes (a stable hash: the same bytes give the
//! same key on every machine and version of Rust), the length of the log, the hash of the model
//! file's text with the options that change a fit, and servo's version. Each entry is written to
//! a temporary file in the cache directory and renamed into place, so a run stopped halfway
//! leaves whole entries or none.

use std::path::{Path, PathBuf};

/// FNV-1a, 64 bits, over `bytes` (continuing from `h`; start at [`FNV_OFFSET`]).
pub fn fnv1a(mut h: u64, bytes: &[u8]) -> u64 {
    for b in bytes {
        h ^= *b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    h
}

/// The FNV-1a 64-bit offset basis.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// The content hash of a log as the cache names it: 16 hex digits of FNV-1a and the length.
pub fn content_key(bytes: &[u8]) -> String {
    format!("{:016x}-{}", fnv1a(FNV_OFFSET, bytes), bytes.len())
}

/// The entries' format: raised when [`super::fit_log::LogFit`] changes what it holds (2: a CSV's
/// first-row values in its metadata, for `--group-by`), so an older entry is a miss.
const FORMAT: u32 = 2;

/// A cache directory for one model and servo version.
#[derive(Debug, Clone)]
pub struct Cache {
    pub dir: PathBuf,
    /// Hash of the model file and the fit options, hex.
    pub model_key: String,
}

impl Cache {
    /// The cache in `dir` (created) for the model key `model_key`.
    pub fn open(dir: &Path, model_key: String) -> anyhow::Result<Cache> {
        std::fs::create_dir_all(dir).map_err(|e| {
            anyhow::anyhow!(
                "--cache {}: cannot create the cache directory: {e}",
                dir.display()
            )
        })?;
        Ok(Cache {
            dir: dir.to_path_buf(),
            model_key,
        })
    }

    fn path(&self, content: &str) -> PathBuf {
        self.dir.join(format!(
            "{content}-{}-v{}-f{FORMAT}.json",
            self.model_key,
            env!("CARGO_PKG_VERSION")
        ))
    }

    /// The entry of a log's content, if cached and readable (a damaged entry is a miss).
    pub fn get<T: serde::de::DeserializeOwned>(&self, content: &str) -> Option<T> {
        let text = std::fs::read_to_string(self.path(content)).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// Stores the entry of a log's content atomically (a temporary file renamed into place).
    pub fn put<T: serde::Serialize>(&self, content: &str, value: &T) -> anyhow::Result<()> {
        let path = self.path(content);
        let tmp = self.dir.join(format!(
            ".tmp-{}-{:?}-{content}",
            std::process::id(),
            std::thread::current().id()
        ));
        let text = serde_json::to_string(value)?;
        std::fs::write(&tmp, text)
            .and_then(|_| std::fs::rename(&tmp, &path))
            .map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                anyhow::anyhow!("writing the cache entry {}: {e}", path.display())
            })
    }
}

/// The default cache directory: `$XDG_CACHE_HOME/servo/trend`, else `~/.cache/servo/trend`, else
/// `.servo-trend-cache` in the current directory.
pub fn default_dir() -> PathBuf {
    if let Some(x) = std::env::var_os("XDG_CACHE_HOME").filter(|v| !v.is_empty()) {
        return PathBuf::from(x).join("servo/trend");
    }
    if let Some(h) = std::env::var_os("HOME").filter(|v| !v.is_empty()) {
        return PathBuf::from(h).join(".cache/servo/trend");
    }
    PathBuf::from(".servo-trend-cache")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv_is_the_published_function_and_entries_round_trip() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(fnv1a(FNV_OFFSET, b""), 0xcbf29ce484222325);
        assert_eq!(fnv1a(FNV_OFFSET, b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(fnv1a(FNV_OFFSET, b"foobar"), 0x85944171f73967e8);
        let dir = tempfile::tempdir().unwrap();
        let c = Cache::open(&dir.path().join("c"), "m1".into()).unwrap();
        let k = content_key(b"log bytes");
        assert_eq!(c.get::<Vec<f64>>(&k), None);
        c.put(&k, &vec![1.5, 2.5]).unwrap();
        assert_eq!(c.get::<Vec<f64>>(&k), Some(vec![1.5, 2.5]));
        let other = Cache::open(&dir.path().join("c"), "m2".into()).unwrap();
        assert_eq!(other.get::<Vec<f64>>(&k), None, "another model misses");
    }
}
