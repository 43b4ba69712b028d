//! Room on disk for a log that streams: a run of hours writes gigabytes, and a disk that fills
//! up halfway through loses the end of the run (and starves everything else on the machine).
//! [`ensure_room_for_log`] refuses such a run before it starts, as `rosbag record --min-space`
//! does.

use crate::error::{self as anyhow, bail};
use crate::mcap_write::LogEncoding;
use std::path::Path;

/// The fewest bytes one control sample takes in an MCAP log (compressed; measured: ~94 B for
/// protobuf with LZ4, ~70 B with zstd, more for JSON): estimates made with it are lower bounds.
pub const MIN_LOG_BYTES_PER_SAMPLE: f64 = 50.0;

/// Free space left to the log's user after the log is written [bytes]: the run is refused if
/// less would be left.
pub const KEEP_FREE_BYTES: f64 = 256.0 * 1024.0 * 1024.0;

/// Bytes available to an unprivileged user on the file system holding `path` (or its parent
/// directory when `path` does not exist yet), or `None` where that cannot be told.
pub fn available_bytes(path: &Path) -> Option<u64> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    available_bytes_in(dir)
}

#[cfg(unix)]
fn available_bytes_in(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `c` is a NUL-terminated path and `st` points at writable memory of the right
    // type; statvfs initialises it when it returns 0, and only then is it read.
    let rc = unsafe { libc::statvfs(c.as_ptr(), st.as_mut_ptr()) };
    if rc != 0 {
        return None;
    }
    // SAFETY: statvfs returned 0, so `st` is initialised.
    let st = unsafe { st.assume_init() };
    #[allow(clippy::unnecessary_cast)] // the field types differ between platforms
    Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
}

#[cfg(not(unix))]
fn available_bytes_in(_dir: &Path) -> Option<u64> {
    None
}

/// Refuses a log of `samples` control samples at `path` when even its smallest size
/// ([`MIN_LOG_BYTES_PER_SAMPLE`] per sample) would leave less than [`KEEP_FREE_BYTES`] free.
/// Passes when the free space cannot be told (the writer still reports a full disk).
pub fn ensure_room_for_log(path: &Path, samples: f64, encoding: LogEncoding) -> anyhow::Result<()> {
    let per_sample = match encoding {
        LogEncoding::Json => 2.0 * MIN_LOG_BYTES_PER_SAMPLE,
        LogEncoding::Protobuf => MIN_LOG_BYTES_PER_SAMPLE,
    };
    let need = samples * per_sample;
    let Some(free) = available_bytes(path) else {
        return Ok(());
    };
    if need + KEEP_FREE_BYTES > free as f64 {
        bail!(
            "log {}: {samples:e} samples need at least {} but the disk holding it has {} free \
             (servo keeps {} free); shorten --duration or log elsewhere",
            path.display(),
            human_bytes(need),
            human_bytes(free as f64),
            human_bytes(KEEP_FREE_BYTES)
        );
    }
    Ok(())
}

/// `bytes` with a binary prefix: "1.5 GiB".
pub fn human_bytes(bytes: f64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB"];
    let mut v = bytes;
    let mut i = 0;
    while v >= 1024.0 && i + 1 < units.len() {
        v /= 1024.0;
        i += 1;
    }
    format!("{v:.1} {}", units[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_free_space_of_the_temp_dir_is_known_and_a_huge_log_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("run.mcap");
        let free = available_bytes(&path).expect("statvfs of a temp dir");
        assert!(free > 0);
        // A small log fits; a log larger than the disk does not, and the error says why.
        ensure_room_for_log(&path, 1000.0, LogEncoding::Protobuf).expect("1000 samples fit");
        let samples = 2.0 * free as f64 / MIN_LOG_BYTES_PER_SAMPLE;
        let e = ensure_room_for_log(&path, samples, LogEncoding::Protobuf)
            .expect_err("a log twice the disk's free space")
            .to_string();
        assert!(
            e.contains("run.mcap") && e.contains("free") && e.contains("--duration"),
            "{e}"
        );
    }

    #[test]
    fn byte_counts_read_with_binary_prefixes() {
        assert_eq!(human_bytes(512.0), "512.0 B");
        assert_eq!(human_bytes(1536.0), "1.5 KiB");
        assert_eq!(human_bytes(3.0 * 1024.0f64.powi(4)), "3.0 TiB");
    }
}
