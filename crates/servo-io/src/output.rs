//! Every file servo writes goes through here: atomic replacement and numbered backups.
//!
//! * **Atomic**: the bytes go to a temporary file in the target's folder, are flushed and synced
//!   to disk, then renamed over the target (and the folder synced). A reader sees the old file or
//!   the new one, never a partial one; a failure (full disk, an error, a fault) leaves the old
//!   file whole and removes the temporary file.
//! * **Never replaced silently**: a target that exists, holds other bytes and was not written by
//!   this same process is kept beside the new one as `NAME.1` (`NAME.2`, ... : a backup never
//!   overwrites an older one) and [`Written::backup`] names it; [`AtomicFile::commit`] says so on
//!   stderr in one line ("note: kept the previous model.toml as model.toml.1"). A target with the
//!   same bytes is simply replaced.
//! * **Streaming** ([`Replacement::begin_partial`], the MCAP log of a run): the file grows under
//!   the visible name `NAME.partial`, readable as it grows, and is renamed to `NAME` only when
//!   finished; a process killed before that leaves `NAME.partial` for `servo log recover`.
//!
//! A target that exists and is not a regular file (a FIFO, `/dev/null`, a terminal) is written in
//! place: nothing can be renamed over it. A symbolic link is followed: the file it points to is
//! replaced, the link stays.

use crate::error::{self as anyhow, Context};
use std::collections::HashSet;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Suffix of a streaming file being written (`run.mcap.partial`).
pub const PARTIAL_SUFFIX: &str = ".partial";

/// Targets this process has written (absolute paths): written again, they are replaced without
/// a backup (a command that rewrites its own output keeps no copy of its first draft).
static WRITTEN: Mutex<Option<HashSet<PathBuf>>> = Mutex::new(None);
/// Temporary files in use (removed by [`remove_temporaries`], e.g. on a second Ctrl-C).
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
static COUNTER: AtomicU64 = AtomicU64::new(0);

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Removes the hidden temporary files of writes still in progress (not the `.partial` files of
/// streaming logs: they hold data). For a handler that exits the process at once.
pub fn remove_temporaries() {
    for p in lock(&TEMPORARIES).drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// What becomes of a previous file at the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Previous {
    /// Kept as `NAME.N` when it holds other bytes and this process did not write it.
    Keep,
    /// Replaced: for files whose previous contents the new one holds (an appended library)
    /// or that only ever hold a transient value (the device path of `servo board --path-file`).
    Replace,
}

/// What a committed write did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    /// The file written.
    pub path: PathBuf,
    /// Where the previous file at `path` was kept, if one was (`model.toml.1`).
    pub backup: Option<PathBuf>,
}

impl Written {
    /// The stderr line of a kept previous file ("kept the previous a.toml as a.toml.1").
    pub fn backup_note(&self) -> Option<String> {
        self.backup.as_ref().map(|b| {
            format!(
                "kept the previous {} as {}",
                self.path.display(),
                b.display()
            )
        })
    }
}

/// The target a write replaces: symbolic links followed (the link stays, its file is replaced).
fn resolve(path: &Path) -> PathBuf {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => {
            std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
        }
        _ => path.to_path_buf(),
    }
}

fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The target's folder ("." for a bare file name).
fn folder(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// `path` with `suffix` appended to its file name (`a.toml` + `.1` = `a.toml.1`).
fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_os_string();
    s.push(suffix);
    PathBuf::from(s)
}

/// True when `path` exists and is not a regular file (nothing can be renamed over it).
fn is_special(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file())
}

/// Whether the files `a` and `b` hold the same bytes (false on any error).
fn same_bytes(a: &Path, b: &Path) -> bool {
    let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) else {
        return false;
    };
    if ma.len() != mb.len() {
        return false;
    }
    let (Ok(mut fa), Ok(mut fb)) = (File::open(a), File::open(b)) else {
        return false;
    };
    let mut ba = vec![0u8; 1 << 16];
    let mut bb = vec![0u8; 1 << 16];
    loop {
        let Ok(n) = fa.read(&mut ba) else {
            return false;
        };
        if n == 0 {
            return true;
        }
        if fb.read_exact(&mut bb[..n]).is_err() || ba[..n] != bb[..n] {
            return false;
        }
    }
}

/// Keeps `target` under the first free name `target.N` (N = 1, 2, ...): a hard link, so that
/// `target` itself never disappears (a copy where links are not supported). Never overwrites.
fn keep_numbered(target: &Path) -> std::io::Result<PathBuf> {
    for n in 1u32..10_000 {
        let b = with_suffix(target, &format!(".{n}"));
        if std::fs::symlink_metadata(&b).is_ok() {
            continue;
        }
        match std::fs::hard_link(target, &b) {
            Ok(()) => return Ok(b),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(_) => {
                // No links here (some network or FAT file systems): a copy, never over a file.
                let mut src = File::open(target)?;
                let mut dst = match OpenOptions::new().write(true).create_new(true).open(&b) {
                    Ok(f) => f,
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                    Err(e) => return Err(e),
                };
                let copied = std::io::copy(&mut src, &mut dst).and_then(|_| dst.sync_all());
                if let Err(e) = copied {
                    let _ = std::fs::remove_file(&b);
                    return Err(e);
                }
                return Ok(b);
            }
        }
    }
    Err(std::io::Error::other(format!(
        "{}.1 to .9999 all exist",
        target.display()
    )))
}

/// Syncs a folder's entries (a rename in it) to disk; ignored where folders cannot be opened.
fn sync_folder(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

/// The replacement of one target by a file being written beside it; see the module doc.
#[derive(Debug)]
pub struct Replacement {
    /// The file to replace (symbolic links resolved).
    target: PathBuf,
    /// The file being written (the target itself when `direct`).
    tmp: PathBuf,
    /// The target is not a regular file: written in place.
    direct: bool,
    /// A streaming file: kept when the replacement is dropped uncommitted (it holds data).
    keep_on_drop: bool,
    done: bool,
}

impl Replacement {
    /// Starts replacing `path`: a hidden temporary file `.NAME.PID-N.servo-tmp` in its folder,
    /// removed again if the replacement is dropped without [`Replacement::commit`].
    pub fn begin(path: &Path) -> anyhow::Result<(Replacement, File)> {
        let target = resolve(path);
        if is_special(&target) {
            return Self::direct(target);
        }
        let name = target
            .file_name()
            .ok_or_else(|| anyhow::anyhow!("{}: not a file name", path.display()))?
            .to_string_lossy()
            .into_owned();
        let dir = folder(&target);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!(".{name}.{}-{n}.servo-tmp", std::process::id()));
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .with_context(|| {
                format!(
                    "creating a temporary file for {} in {}",
                    path.display(),
                    dir.display()
                )
            })?;
        lock(&TEMPORARIES).push(tmp.clone());
        Ok((
            Replacement {
                target,
                tmp,
                direct: false,
                keep_on_drop: false,
                done: false,
            },
            file,
        ))
    }

    /// Starts a streaming replacement of `path`: the file grows as `NAME.partial` (readable as
    /// it grows; kept if the process stops before [`Replacement::commit`]). A `NAME.partial`
    /// left by an earlier run is kept as `NAME.partial.1` (said on stderr), never overwritten.
    pub fn begin_partial(path: &Path) -> anyhow::Result<(Replacement, File)> {
        let target = resolve(path);
        if is_special(&target) {
            return Self::direct(target);
        }
        let tmp = with_suffix(&target, PARTIAL_SUFFIX);
        let file = loop {
            match OpenOptions::new().write(true).create_new(true).open(&tmp) {
                Ok(f) => break f,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let kept = keep_numbered(&tmp)
                        .with_context(|| format!("keeping the earlier {}", tmp.display()))?;
                    std::fs::remove_file(&tmp)
                        .with_context(|| format!("moving the earlier {} aside", tmp.display()))?;
                    eprintln!(
                        "note: kept the earlier unfinished {} as {}",
                        tmp.display(),
                        kept.display()
                    );
                }
                Err(e) => {
                    return Err(crate::Error::Io(e))
                        .with_context(|| format!("creating {}", tmp.display()))
                }
            }
        };
        Ok((
            Replacement {
                target,
                tmp,
                direct: false,
                keep_on_drop: true,
                done: false,
            },
            file,
        ))
    }

    fn direct(target: PathBuf) -> anyhow::Result<(Replacement, File)> {
        let file = OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(&target)
            .with_context(|| format!("opening {}", target.display()))?;
        Ok((
            Replacement {
                tmp: target.clone(),
                target,
                direct: true,
                keep_on_drop: true,
                done: false,
            },
            file,
        ))
    }

    /// The file being written (`NAME.partial`, a hidden temporary file, or the target itself
    /// when it is not a regular file).
    pub fn writing(&self) -> &Path {
        &self.tmp
    }

    /// The file this replaces.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Syncs `file` (everything written to it) to disk, keeps a previous target that holds
    /// other bytes and was not written by this process as `NAME.N`, renames the new file over
    /// the target and syncs the folder. On an error the previous target is untouched.
    pub fn commit(self, file: File) -> anyhow::Result<Written> {
        self.commit_with(file, Previous::Keep)
    }

    /// [`Replacement::commit`], keeping the previous target or not (`previous`).
    pub fn commit_with(mut self, file: File, previous: Previous) -> anyhow::Result<Written> {
        let target = self.target.clone();
        if self.direct {
            self.done = true;
            return Ok(Written {
                path: target,
                backup: None,
            });
        }
        file.sync_all()
            .with_context(|| format!("syncing {} to disk", self.tmp.display()))?;
        drop(file);
        let key = absolute(&target);
        let mine = lock(&WRITTEN).as_ref().is_some_and(|s| s.contains(&key));
        let backup = match std::fs::symlink_metadata(&target) {
            Ok(m)
                if previous == Previous::Keep
                    && m.is_file()
                    && !mine
                    && !same_bytes(&target, &self.tmp) =>
            {
                Some(keep_numbered(&target).with_context(|| {
                    format!(
                        "keeping the previous {} before replacing it (nothing replaced; the new \
                         file is not written)",
                        target.display()
                    )
                })?)
            }
            _ => None,
        };
        // The new file gets the old one's permissions.
        if let Ok(m) = std::fs::metadata(&target) {
            let _ = std::fs::set_permissions(&self.tmp, m.permissions());
        }
        if let Err(e) = std::fs::rename(&self.tmp, &target) {
            if let Some(b) = &backup {
                let _ = std::fs::remove_file(b);
            }
            return Err(crate::Error::Io(e)).with_context(|| {
                format!(
                    "renaming {} to {} (the previous file is unchanged)",
                    self.tmp.display(),
                    target.display()
                )
            });
        }
        self.done = true;
        lock(&TEMPORARIES).retain(|p| p != &self.tmp);
        sync_folder(&folder(&target));
        lock(&WRITTEN).get_or_insert_with(HashSet::new).insert(key);
        Ok(Written {
            path: target,
            backup,
        })
    }
}

impl Drop for Replacement {
    /// An uncommitted hidden temporary file is removed (the target stays as it was); a
    /// `.partial` streaming file stays (it holds the data written so far).
    fn drop(&mut self) {
        if !self.done && !self.keep_on_drop {
            let _ = std::fs::remove_file(&self.tmp);
            lock(&TEMPORARIES).retain(|p| p != &self.tmp);
        }
    }
}

/// A file written atomically: [`Write`] into it, then [`AtomicFile::commit`]. Dropped without a
/// commit (an error, a panic), it leaves the target as it was and no temporary file.
#[derive(Debug)]
pub struct AtomicFile {
    rep: Replacement,
    w: BufWriter<File>,
    /// "model file PATH": the file in messages.
    label: String,
    previous: Previous,
}

impl AtomicFile {
    /// Starts writing `path` (`what` names it in messages: "model file", "CSV", ...).
    pub fn create(path: &Path, what: &str) -> anyhow::Result<AtomicFile> {
        let (rep, file) = Replacement::begin(path).with_context(|| format!("writing {what}"))?;
        Ok(AtomicFile {
            rep,
            w: BufWriter::with_capacity(1 << 16, file),
            label: format!("{what} {}", path.display()),
            previous: Previous::Keep,
        })
    }

    /// Flushes, syncs and renames over the target ([`Replacement::commit`]); prints the
    /// "kept the previous ..." line on stderr when a previous file was kept.
    pub fn commit(self) -> anyhow::Result<Written> {
        let AtomicFile {
            rep,
            w,
            label,
            previous,
        } = self;
        let unchanged = unchanged_sentence(rep.target());
        let file = w.into_inner().map_err(|e| crate::Error::Context {
            context: format!("writing {label} ({unchanged})"),
            source: Box::new(crate::Error::Io(e.into_error())),
        })?;
        let written = rep
            .commit_with(file, previous)
            .with_context(|| format!("writing {label} ({unchanged})"))?;
        if let Some(n) = written.backup_note() {
            eprintln!("note: {n}");
        }
        Ok(written)
    }

    /// The error of a write into this file, saying what was kept ("the previous X is
    /// unchanged" or "X was not written").
    pub fn error(&self, e: impl Into<crate::Error>) -> crate::Error {
        crate::Error::Context {
            context: format!(
                "writing {} ({})",
                self.label,
                unchanged_sentence(self.rep.target())
            ),
            source: Box::new(e.into()),
        }
    }
}

/// "the previous X is unchanged" when X exists, else "nothing was written to X".
pub fn unchanged_sentence(target: &Path) -> String {
    if target.exists() {
        format!("the previous {} is unchanged", target.display())
    } else {
        format!("nothing was written to {}", target.display())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.w.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.w.write_all(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.w.flush()
    }
}

/// Writes `bytes` to `path` atomically ([`AtomicFile`]): `what` names the file in messages
/// ("model file", "report"). Prints "note: kept the previous ..." when a previous file was kept.
pub fn write_file(path: &Path, what: &str, bytes: impl AsRef<[u8]>) -> anyhow::Result<Written> {
    write_file_with(path, what, bytes, Previous::Keep)
}

/// [`write_file`], keeping a previous file or not (`previous`).
pub fn write_file_with(
    path: &Path,
    what: &str,
    bytes: impl AsRef<[u8]>,
    previous: Previous,
) -> anyhow::Result<Written> {
    let mut f = AtomicFile::create(path, what)?;
    f.previous = previous;
    if let Err(e) = f.write_all(bytes.as_ref()) {
        return Err(f.error(e));
    }
    f.commit()
}

/// The atomic writer's invariants on one case made from `data` (the `atomic_writer` fuzz target
/// and a seeded loop of the unit tests): in a fresh folder, an optional previous file, an
/// optional older backup `NAME.1`, then a write of the rest of `data` in pieces, committed or
/// abandoned, through [`write_file`], [`AtomicFile`] or a streaming [`Replacement`]. Panics when
/// the target is not exactly the old or the new bytes, a previous file with other bytes is not
/// kept (once, under the first free number), an older backup is touched, or a temporary file
/// is left. Returns false when the case could not be set up (no temporary folder).
#[doc(hidden)]
pub fn check_atomic_writer(data: &[u8]) -> bool {
    let Some((&flags, rest)) = data.split_first() else {
        return true;
    };
    let (split, rest) = match rest.split_first() {
        Some((&s, r)) => (s as usize % (r.len() + 1), r),
        None => (0, rest),
    };
    let (old, new) = rest.split_at(split);
    let old_exists = flags & 1 != 0;
    let commit = flags & 2 != 0;
    let old: &[u8] = if flags & 4 != 0 { new } else { old };
    let older_backup = flags & 8 != 0;
    let mode = (flags >> 4) % 3;
    let dir = std::env::temp_dir().join(format!(
        "servo-atomic-check-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    if std::fs::create_dir(&dir).is_err() {
        return false;
    }
    let target = dir.join("out.dat");
    let b1 = dir.join("out.dat.1");
    if old_exists {
        std::fs::write(&target, old).expect("setting up the previous file");
    }
    if older_backup {
        std::fs::write(&b1, b"older").expect("setting up an older backup");
    }
    let pieces: Vec<&[u8]> = new.chunks(1 + (flags as usize % 7) * 97).collect();
    let result = match mode {
        0 if commit => Some(write_file(&target, "fuzz file", new).expect("write_file")),
        0 => None,
        1 => {
            let mut f = AtomicFile::create(&target, "fuzz file").expect("AtomicFile::create");
            for p in &pieces {
                f.write_all(p).expect("writing a piece");
            }
            commit.then(|| f.commit().expect("commit"))
        }
        _ => {
            let (rep, mut f) = Replacement::begin_partial(&target).expect("begin_partial");
            for p in &pieces {
                f.write_all(p).expect("writing a piece");
            }
            commit.then(|| rep.commit(f).expect("commit"))
        }
    };
    let read = |p: &Path| std::fs::read(p).ok();
    let mut expected: Vec<String> = Vec::new();
    match &result {
        Some(w) => {
            assert_eq!(
                read(&target).as_deref(),
                Some(new),
                "the target is not the new file"
            );
            expected.push("out.dat".into());
            let kept = old_exists && old != new;
            match (&w.backup, kept) {
                (Some(b), true) => {
                    let want = if older_backup {
                        "out.dat.2"
                    } else {
                        "out.dat.1"
                    };
                    assert_eq!(
                        b,
                        &dir.join(want),
                        "the backup is not the first free number"
                    );
                    assert_eq!(
                        read(b).as_deref(),
                        Some(old),
                        "the backup is not the old file"
                    );
                    expected.push(want.into());
                }
                (None, false) => {}
                (b, _) => panic!("backup {b:?} where a backup kept = {kept}"),
            }
        }
        None => {
            if old_exists {
                assert_eq!(read(&target).as_deref(), Some(old), "the old file changed");
                expected.push("out.dat".into());
            } else {
                assert!(!target.exists(), "an abandoned write created the target");
            }
            if mode == 2 {
                // An uncommitted streaming file stays: it holds the data.
                expected.push("out.dat.partial".into());
            }
        }
    }
    if older_backup {
        assert_eq!(
            read(&b1).as_deref(),
            Some(&b"older"[..]),
            "an older backup changed"
        );
        expected.push("out.dat.1".into());
    }
    expected.sort();
    expected.dedup();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(names, expected, "files left in the folder");
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_new_file_is_written_with_no_backup_and_no_temporary_left() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.toml");
        let w = write_file(&p, "test file", "x = 1\n").unwrap();
        assert_eq!(w.backup, None);
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "x = 1\n");
        assert_eq!(names(d.path()), vec!["a.toml"]);
    }

    #[test]
    fn a_foreign_file_is_kept_numbered_and_backups_never_overwrite_each_other() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("m.toml");
        std::fs::write(&p, "hand made\n").unwrap();
        std::fs::write(d.path().join("m.toml.1"), "older backup\n").unwrap();
        let w = write_file(&p, "test file", "new\n").unwrap();
        let b = w.backup.clone().unwrap();
        assert_eq!(b, d.path().join("m.toml.2"));
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "hand made\n");
        assert_eq!(
            std::fs::read_to_string(d.path().join("m.toml.1")).unwrap(),
            "older backup\n"
        );
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new\n");
        assert!(w.backup_note().unwrap().contains("m.toml.2"));
        // Written again by the same process: replaced, no third copy.
        let w2 = write_file(&p, "test file", "newer\n").unwrap();
        assert_eq!(w2.backup, None);
        assert_eq!(names(d.path()), vec!["m.toml", "m.toml.1", "m.toml.2"]);
    }

    #[test]
    fn the_same_bytes_need_no_backup() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("g.toml");
        std::fs::write(&p, "same\n").unwrap();
        let w = write_file(&p, "test file", "same\n").unwrap();
        assert_eq!(w.backup, None);
        assert_eq!(names(d.path()), vec!["g.toml"]);
    }

    #[test]
    fn an_abandoned_write_leaves_the_old_file_whole_and_no_temporary() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("o.csv");
        std::fs::write(&p, "old,whole\n").unwrap();
        {
            let mut f = AtomicFile::create(&p, "CSV").unwrap();
            f.write_all(&[b'x'; 200_000]).unwrap();
            // Dropped: an error happened before the commit.
        }
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old,whole\n");
        assert_eq!(names(d.path()), vec!["o.csv"]);
    }

    #[test]
    fn a_missing_folder_is_an_error_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("no/such/dir/x.toml");
        let e = write_file(&p, "model file", "x").unwrap_err();
        let m = format!("{e:#}");
        assert!(m.contains("x.toml") && m.contains("model file"), "{m}");
    }

    #[test]
    fn a_partial_file_grows_visibly_and_takes_the_name_at_commit() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("run.mcap");
        std::fs::write(&p, "old log").unwrap();
        std::fs::write(d.path().join("run.mcap.partial"), "killed run").unwrap();
        let (rep, mut f) = Replacement::begin_partial(&p).unwrap();
        assert_eq!(rep.writing(), d.path().join("run.mcap.partial"));
        // The earlier unfinished log was kept, not overwritten.
        assert_eq!(
            std::fs::read_to_string(d.path().join("run.mcap.partial.1")).unwrap(),
            "killed run"
        );
        f.write_all(b"new log").unwrap();
        assert_eq!(
            std::fs::read_to_string(d.path().join("run.mcap.partial")).unwrap(),
            "new log"
        );
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old log");
        let w = rep.commit(f).unwrap();
        assert_eq!(w.backup, Some(d.path().join("run.mcap.1")));
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new log");
        assert_eq!(
            names(d.path()),
            vec!["run.mcap", "run.mcap.1", "run.mcap.partial.1"]
        );
    }

    #[test]
    fn an_uncommitted_partial_file_stays() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("r.mcap");
        {
            let (_rep, mut f) = Replacement::begin_partial(&p).unwrap();
            f.write_all(b"samples").unwrap();
        }
        assert_eq!(names(d.path()), vec!["r.mcap.partial"]);
    }

    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_is_followed_and_stays_a_link() {
        let d = tempfile::tempdir().unwrap();
        let real = d.path().join("real.toml");
        std::fs::write(&real, "old").unwrap();
        let link = d.path().join("link.toml");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let w = write_file(&link, "test file", "new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(&real).unwrap(), "new");
        assert_eq!(w.backup, Some(d.path().join("real.toml.1")));
    }

    #[cfg(unix)]
    #[test]
    fn a_special_file_is_written_in_place() {
        let w = write_file(Path::new("/dev/null"), "test file", "x").unwrap();
        assert_eq!(w.backup, None);
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device());
    }

    /// The fuzz target's check over 500 seeded cases (every flag combination, twice).
    #[test]
    fn the_atomic_writer_keeps_its_invariants_on_seeded_cases() {
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for case in 0..500u32 {
            let len = (next() % 600) as usize;
            let mut data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if let Some(f) = data.first_mut() {
                *f = case as u8;
            }
            assert!(check_atomic_writer(&data));
        }
    }

    /// A reader in another thread never sees an empty or partial file while it is rewritten.
    #[test]
    fn a_concurrent_reader_sees_the_old_or_the_new_file_only() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("c.txt");
        let a = "a".repeat(100_000);
        let b = "b".repeat(150_000);
        write_file(&p, "test file", &a).unwrap();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (s, rp, a2, b2) = (stop.clone(), p.clone(), a.clone(), b.clone());
        let reader = std::thread::spawn(move || {
            let mut reads = 0u32;
            while !s.load(Ordering::Relaxed) {
                let t = std::fs::read_to_string(&rp).unwrap();
                assert!(t == a2 || t == b2, "a read saw {} bytes", t.len());
                reads += 1;
            }
            reads
        });
        for i in 0..100 {
            write_file(&p, "test file", if i % 2 == 0 { &b } else { &a }).unwrap();
        }
        stop.store(true, Ordering::Relaxed);
        assert!(reader.join().unwrap() > 0);
        assert_eq!(names(d.path()), vec!["c.txt"]);
    }
}
