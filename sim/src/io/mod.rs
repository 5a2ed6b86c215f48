//! The project's one way of writing files: atomically, and (for Parquet) deterministically.
//!
//! * [`write_atomic`] writes bytes to a temporary file with a unique name in the destination's own
//!   folder, syncs it and renames it over the destination, so that a reader sees the old file or the
//!   new one, never a half-written one; on every failure the temporary file is removed.
//! * [`AtomicFile`] is the same for a file written piece by piece (a stream of Parquet row groups):
//!   the pieces go to the temporary file, and [`AtomicFile::commit`] syncs it and renames it over the
//!   destination; dropped without a commit, the temporary file is removed.
//! * [`deterministic_writer_properties`] fixes every Parquet writer setting that shapes the bytes, and
//!   [`ParquetStream`] writes record batches with them in row groups of a bounded size, handing the
//!   rows to the parquet writer in pieces of a fixed size ([`PARQUET_FEED_ROWS`]): the same rows always
//!   give the same bytes, however they were split into batches, and whatever the parquet crate's
//!   defaults become. [`parquet_bytes`] is the one-batch case.
//!
//! * [`StagedDir`] writes a folder of outputs as a whole (`robocal generate`, `dataset`, `diagnose
//!   --report`): every file goes into a hidden staging folder beside the destination, and only when all
//!   are written is the set moved into place, so that an interrupted run leaves the old set or the new
//!   one (see [`StagedDir::commit`] for the exact rule when the folder holds files of the user's).
//!
//! Every file that `sim`, `calib` and the `robocal` command line write goes through here (measurement
//! tables, `truth.parquet`, `truth.json`, calibrated models, predictions, sweep tables, reports).
//!
//! ```
//! let dir = std::env::temp_dir().join(format!("sim-io-doctest-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("hello.txt");
//! sim::io::write_atomic(&path, b"hello").unwrap();
//! assert_eq!(std::fs::read(&path).unwrap(), b"hello");
//! // Only the file itself is left in the folder: the temporary file was renamed over it.
//! assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

mod parquet_stream;

pub use parquet_stream::{
    PARQUET_FEED_ROWS, ParquetStream, deterministic_writer_properties, parquet_bytes,
};

use crate::error::{Result, SimError};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Temporary files written by this process so far: with the process id, a name no other writer uses.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to `path` atomically: to a temporary file `.NAME.tmp-PID-N` in `path`'s folder
/// (unique within and across processes), synced to disk, then renamed over `path`. On any failure the
/// temporary file is removed and `path` is left as it was.
///
/// # Errors
/// [`SimError::Io`] naming `path` when `path` has no file name, or the folder does not exist or is not
/// writable, or the write, sync or rename fails.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes).map_err(|e| f.error(e))?;
    f.commit()
}

/// A file written atomically piece by piece: [`std::io::Write`] goes to a temporary file
/// `.NAME.tmp-PID-N` in the destination's folder (buffered), [`AtomicFile::commit`] flushes it, syncs
/// it to disk and renames it over the destination. Dropped without a commit (an error, a panic), the
/// temporary file is removed and the destination is left as it was. [`write_atomic`] is the
/// one-piece case.
///
/// ```
/// use std::io::Write;
/// let dir = std::env::temp_dir().join(format!("sim-atomic-doctest-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("rows.txt");
/// let mut f = sim::io::AtomicFile::create(&path).unwrap();
/// f.write_all(b"row 1\n").unwrap();
/// f.write_all(b"row 2\n").unwrap();
/// assert!(!path.exists()); // nothing is visible before the commit
/// f.commit().unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "row 1\nrow 2\n");
/// assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
/// std::fs::remove_dir_all(&dir).unwrap();
/// ```
#[derive(Debug)]
pub struct AtomicFile {
    /// The destination.
    path: PathBuf,
    /// The temporary file beside it.
    tmp: PathBuf,
    /// The open temporary file; `None` once committed.
    file: Option<std::io::BufWriter<std::fs::File>>,
}

impl AtomicFile {
    /// Creates the temporary file for the destination `path`.
    ///
    /// # Errors
    /// [`SimError::Io`] naming `path` when it has no file name, or its folder does not exist or is not
    /// writable.
    pub fn create(path: &Path) -> Result<AtomicFile> {
        let io_err = |source: std::io::Error| SimError::Io {
            path: path.to_path_buf(),
            source,
        };
        let name = path.file_name().ok_or_else(|| {
            io_err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a file name",
            ))
        })?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let tmp = dir.join(temp_name(name));
        let file = std::fs::File::create(&tmp).map_err(io_err)?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            tmp,
            file: Some(std::io::BufWriter::with_capacity(1 << 20, file)),
        })
    }

    /// The destination.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A [`SimError::Io`] naming the destination (for a failed write).
    pub fn error(&self, source: std::io::Error) -> SimError {
        SimError::Io {
            path: self.path.clone(),
            source,
        }
    }

    /// Flushes, syncs and renames the temporary file over the destination.
    ///
    /// # Errors
    /// [`SimError::Io`] naming the destination; the temporary file is removed and the destination left
    /// as it was.
    pub fn commit(mut self) -> Result<()> {
        let Some(buffered) = self.file.take() else {
            return Ok(());
        };
        let result = (|| {
            let f = buffered.into_inner().map_err(|e| e.into_error())?;
            f.sync_all()?;
            drop(f);
            std::fs::rename(&self.tmp, &self.path)
        })();
        result.map_err(|source| {
            // The temporary file may be gone already; nothing else can be done about it.
            let _ = std::fs::remove_file(&self.tmp);
            self.error(source)
        })
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.file {
            Some(f) => f.write(buf),
            None => Err(std::io::Error::other("the file is committed")),
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.file {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            // Best effort: nothing else can be done about a file that cannot be removed.
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// The temporary name `.NAME.tmp-PID-N` of `name` (a file of [`write_atomic`] or a folder of
/// [`StagedDir`]).
fn temp_name(name: &std::ffi::OsStr) -> String {
    format!(
        ".{}.tmp-{}-{}",
        name.to_string_lossy(),
        std::process::id(),
        TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// True when `entry` is a temporary name `.NAME.tmp-PID-N` of `name` left by a process that no longer
/// runs (Linux: no `/proc/PID`; elsewhere never, so nothing is removed).
fn is_stale_temp(entry: &str, name: &str) -> bool {
    let Some(rest) = entry
        .strip_prefix('.')
        .and_then(|r| r.strip_prefix(name))
        .and_then(|r| r.strip_prefix(".tmp-"))
    else {
        return false;
    };
    let Some((pid, n)) = rest.split_once('-') else {
        return false;
    };
    let (Ok(pid), true) = (
        pid.parse::<u32>(),
        !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()),
    ) else {
        return false;
    };
    cfg!(target_os = "linux")
        && pid != std::process::id()
        && Path::new("/proc/self").exists()
        && !Path::new(&format!("/proc/{pid}")).exists()
}

/// Removes the temporary files and folders of `names` inside `dir` that a killed process left (see
/// [`is_stale_temp`]). Best effort: what cannot be removed stays.
fn remove_stale_temps(dir: &Path, names: &[&str]) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let entry = e.file_name().to_string_lossy().into_owned();
        if names.iter().any(|n| is_stale_temp(&entry, n)) {
            let p = e.path();
            let _ = match e.file_type() {
                Ok(t) if t.is_dir() => std::fs::remove_dir_all(&p),
                _ => std::fs::remove_file(&p),
            };
        }
    }
}

/// Swaps two paths atomically (Linux `renameat2(RENAME_EXCHANGE)`); `Unsupported` elsewhere or when
/// the file system cannot.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_bytes())
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    };
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: `a` and `b` are NUL-terminated strings that outlive the call; the system call only
    // reads them and takes no other pointer.
    let r = unsafe {
        libc::syscall(
            libc::SYS_renameat2,
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Swaps two paths atomically: not available on this system.
#[cfg(not(target_os = "linux"))]
fn exchange(_a: &Path, _b: &Path) -> std::io::Result<()> {
    Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
}

/// A folder of outputs written as a whole. Files are written into [`StagedDir::path`], a hidden
/// staging folder `.NAME.tmp-PID-N` beside the destination `NAME` (same file system, so the final
/// moves are renames); [`StagedDir::commit`] moves them into place. Dropped without a commit (an
/// error, an early return, a panic), the staging folder and everything in it is removed. Staging
/// folders and temporary files that a killed run left beside the destination are removed when the
/// next one starts (on Linux, where it can tell that their process is gone).
///
/// ```
/// let dir = std::env::temp_dir().join(format!("sim-staged-doctest-{}", std::process::id()));
/// let _ = std::fs::remove_dir_all(&dir);
/// let out = dir.join("out");
/// let stage = sim::io::StagedDir::new(&out).unwrap();
/// sim::io::write_atomic(&stage.path().join("a.txt"), b"a").unwrap();
/// assert!(!out.exists()); // nothing is visible before the commit
/// stage.commit(&|name: &str| name == "a.txt").unwrap();
/// assert_eq!(std::fs::read(out.join("a.txt")).unwrap(), b"a");
/// assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1); // no staging folder left
/// std::fs::remove_dir_all(&dir).unwrap();
/// ```
#[derive(Debug)]
pub struct StagedDir {
    /// The destination as given (for messages).
    target: PathBuf,
    /// The destination, its folder resolved.
    resolved: PathBuf,
    /// The staging folder.
    staging: PathBuf,
    /// The staging folder is inside the destination (its parent was not writable).
    inside: bool,
    /// Set by a successful commit: nothing to clean up.
    committed: bool,
}

impl StagedDir {
    /// Creates the staging folder for the destination folder `target` (whose parent folders are
    /// created when missing).
    ///
    /// # Errors
    /// [`SimError::Io`] naming `target` when it exists but is not a folder, or a folder cannot be
    /// created.
    pub fn new(target: &Path) -> Result<StagedDir> {
        let io_err = |source: std::io::Error| SimError::Io {
            path: target.to_path_buf(),
            source,
        };
        if std::fs::symlink_metadata(target).is_ok() && !target.is_dir() {
            return Err(io_err(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "exists and is not a folder",
            )));
        }
        let resolved = if target.exists() {
            std::fs::canonicalize(target).map_err(io_err)?
        } else {
            let parent = match target.parent() {
                Some(p) if !p.as_os_str().is_empty() => p,
                _ => Path::new("."),
            };
            std::fs::create_dir_all(parent).map_err(io_err)?;
            let name = target.file_name().ok_or_else(|| {
                io_err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "not a folder name",
                ))
            })?;
            std::fs::canonicalize(parent).map_err(io_err)?.join(name)
        };
        let (Some(parent), Some(name)) = (resolved.parent(), resolved.file_name()) else {
            return Err(io_err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the root folder cannot be replaced",
            )));
        };
        let name_text = name.to_string_lossy();
        remove_stale_temps(parent, &[&name_text]);
        let staging = parent.join(temp_name(name));
        let (staging, inside) = match std::fs::create_dir(&staging) {
            Ok(()) => (staging, false),
            // The folder exists but its parent is not writable (`--out ~`, say): stage inside it
            // instead; the set is then replaced entry by entry (see `commit`).
            Err(_) if resolved.is_dir() => {
                remove_stale_temps(&resolved, &[&name_text]);
                let inner = resolved.join(temp_name(name));
                std::fs::create_dir(&inner).map_err(io_err)?;
                (inner, true)
            }
            Err(e) => return Err(io_err(e)),
        };
        Ok(StagedDir {
            target: target.to_path_buf(),
            resolved,
            staging,
            inside,
            committed: false,
        })
    }

    /// The staging folder: write every output here.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// An error about a file of the staging folder (a write failure, or a table that does not pass
    /// its checks), renamed to name the destination instead (what the user asked for), e.g.
    /// `out/truth.json` rather than `out/../.out.tmp-12-0/truth.json`.
    pub fn user_error(&self, mut e: SimError) -> SimError {
        let named = |path: PathBuf| match path.strip_prefix(&self.staging) {
            Ok(rel) => self.target.join(rel),
            Err(_) => path,
        };
        match &mut e {
            SimError::Io { path, .. } => *path = named(std::mem::take(path)),
            SimError::Table { file, .. } => {
                *file = named(PathBuf::from(&*file)).display().to_string();
            }
            _ => {}
        }
        e
    }

    /// Moves the staged outputs into the destination. `is_ours(name)` tells which names the command
    /// writes into the folder (a file or folder it may replace). The rule:
    ///
    /// * the destination does not exist: the staging folder is renamed to it (atomic);
    /// * it holds nothing but entries that are ours (old outputs): the two folders are swapped in one
    ///   atomic rename (Linux `RENAME_EXCHANGE`) and the old one is removed, so a reader sees the
    ///   whole old set or the whole new one. Not when it is (or holds) the current folder, which a
    ///   shell may be sitting in; then, or without the atomic swap, as in the next case;
    /// * it also holds entries that are not ours (files of the user's): those are kept, and each
    ///   staged entry replaces its namesake by a rename, one after the other once every output is
    ///   complete; only an interruption between these renames (microseconds) can mix the sets.
    ///   An entry whose namesake is a folder where the output is a file (or the reverse) is refused
    ///   before anything moves. This is also how a set staged inside the destination is moved (when
    ///   the destination's parent folder is not writable).
    ///
    /// # Errors
    /// [`SimError::Io`] naming the destination entry that cannot be replaced; the staging folder is
    /// removed.
    pub fn commit(mut self, is_ours: &dyn Fn(&str) -> bool) -> Result<()> {
        let target = self.resolved.clone();
        let io_err = |path: &Path, source: std::io::Error| SimError::Io {
            path: path.to_path_buf(),
            source,
        };
        if std::fs::symlink_metadata(&target).is_err() {
            std::fs::rename(&self.staging, &target).map_err(|e| io_err(&self.target, e))?;
            self.committed = true;
            return Ok(());
        }
        let names_of = |dir: &Path| entries(dir).map_err(|e| io_err(&self.target, e));
        let staged = names_of(&self.staging)?;
        let staged_names: Vec<String> = staged
            .iter()
            .map(|(n, _)| n.to_string_lossy().into_owned())
            .collect();
        let name_refs: Vec<&str> = staged_names.iter().map(String::as_str).collect();
        remove_stale_temps(&target, &name_refs);
        let staging_name = self.staging.file_name().map(|n| n.to_os_string());
        let existing: Vec<_> = names_of(&target)?
            .into_iter()
            .filter(|(n, _)| Some(n) != staging_name.as_ref())
            .collect();
        let in_cwd = std::env::current_dir()
            .ok()
            .and_then(|c| std::fs::canonicalize(c).ok())
            .is_some_and(|c| c.starts_with(&target));
        // A folder of ours (a dataset's) counts as ours only if the new one has everything it holds.
        let all_ours = existing.iter().all(|(n, is_dir)| {
            is_ours(&n.to_string_lossy())
                && (!*is_dir || covered(&target.join(n), &self.staging.join(n)))
        });
        if all_ours && !in_cwd && !self.inside {
            if let Ok(meta) = std::fs::metadata(&target) {
                let _ = std::fs::set_permissions(&self.staging, meta.permissions());
            }
            if exchange(&self.staging, &target).is_ok() {
                // The staging path now holds the old set.
                self.committed = true;
                let _ = std::fs::remove_dir_all(&self.staging);
                return Ok(());
            }
        }
        // One entry at a time: first check that every rename can succeed.
        check_kinds(&self.staging, &target, &self.target)?;
        merge(&self.staging, &target, &self.target, &self.staging)?;
        // Only old folders set aside are left in the staging folder; Drop removes it.
        Ok(())
    }
}

/// Entries of `dir`: name and whether it is a folder (not following links), sorted.
fn entries(dir: &Path) -> std::io::Result<Vec<(std::ffi::OsString, bool)>> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        let is_dir = e.file_type().map(|t| t.is_dir()).unwrap_or(false);
        v.push((e.file_name(), is_dir));
    }
    v.sort();
    Ok(v)
}

/// True when every entry below the folder `old` has a namesake of the same kind below `new`: replacing
/// `old` by `new` loses nothing that `new` does not replace.
fn covered(old: &Path, new: &Path) -> bool {
    let (Ok(o), Ok(n)) = (entries(old), entries(new)) else {
        return false;
    };
    o.iter().all(|(name, is_dir)| {
        n.iter().any(|(m, d)| m == name && d == is_dir)
            && (!is_dir || covered(&old.join(name), &new.join(name)))
    })
}

/// Refuses (before anything moves) a staged entry of `src` whose namesake in `dst` is of the other
/// kind (a folder where a file goes, or the reverse), recursively; `shown` is `dst` as the user named
/// it.
fn check_kinds(src: &Path, dst: &Path, shown: &Path) -> Result<()> {
    let io_err = |path: PathBuf, source: std::io::Error| SimError::Io { path, source };
    for (n, is_dir) in entries(src).map_err(|e| io_err(shown.to_path_buf(), e))? {
        let Ok(m) = std::fs::symlink_metadata(dst.join(&n)) else {
            continue;
        };
        if m.is_dir() != is_dir {
            let what = if is_dir { "a file" } else { "a folder" };
            return Err(io_err(
                shown.join(&n),
                std::io::Error::new(
                    std::io::ErrorKind::AlreadyExists,
                    format!("is {what} of the same name; move it away first"),
                ),
            ));
        }
        if is_dir {
            check_kinds(&src.join(&n), &dst.join(&n), &shown.join(&n))?;
        }
    }
    Ok(())
}

/// Moves every entry of `src` over its namesake in `dst`, one rename each; a folder whose old
/// namesake holds nothing it does not replace is swapped as a whole, else merged entry by entry (so
/// that files of the user's inside are kept). Old folders set aside go into `aside_dir`.
fn merge(src: &Path, dst: &Path, shown: &Path, aside_dir: &Path) -> Result<()> {
    let io_err = |name: &std::ffi::OsStr, source: std::io::Error| SimError::Io {
        path: shown.join(name),
        source,
    };
    for (n, is_dir) in entries(src).map_err(|e| SimError::Io {
        path: shown.to_path_buf(),
        source: e,
    })? {
        let (s, d) = (src.join(&n), dst.join(&n));
        if is_dir && d.is_dir() {
            if !covered(&d, &s) {
                merge(&s, &d, &shown.join(&n), aside_dir)?;
                continue;
            }
            if exchange(&s, &d).is_ok() {
                let _ = std::fs::remove_dir_all(&s);
                continue;
            }
            let aside = aside_dir.join(temp_name(&n));
            std::fs::rename(&d, &aside).map_err(|e| io_err(&n, e))?;
        }
        std::fs::rename(&s, &d).map_err(|e| io_err(&n, e))?;
    }
    Ok(())
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: it may be gone already.
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// Bytes free for an unprivileged user on the file system that holds `path`, or its nearest existing
/// parent folder (`statvfs`: available blocks × fragment size); `None` where this cannot be told
/// (another system, a failing call).
pub fn available_bytes(path: &Path) -> Option<u64> {
    let absolute = std::path::absolute(path).ok()?;
    let existing = absolute.ancestors().find(|p| p.exists())?;
    statvfs_available(existing)
}

#[cfg(unix)]
fn statvfs_available(path: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).ok()?;
    let mut s = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `c` is a NUL-terminated path that outlives the call, and `s` points to writable memory
    // of the struct's size, which the call fills on success (checked before it is read).
    let r = unsafe { libc::statvfs(c.as_ptr(), s.as_mut_ptr()) };
    if r != 0 {
        return None;
    }
    // SAFETY: the call succeeded, so it initialised the struct.
    let s = unsafe { s.assume_init() };
    // The field types differ between platforms (u32 or u64).
    #[allow(clippy::unnecessary_cast)]
    Some((s.f_bavail as u64).saturating_mul(s.f_frsize as u64))
}

#[cfg(not(unix))]
fn statvfs_available(_path: &Path) -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sim-io-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temporary_file() {
        let dir = temp_dir("replace");
        let p = dir.join("a.txt");
        std::fs::write(&p, "old").unwrap();
        write_atomic(&p, b"new").unwrap();
        write_atomic(&p, b"newer").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "newer");
        assert_eq!(names(&dir), vec!["a.txt".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failures_name_the_file_and_leave_nothing_behind() {
        let dir = temp_dir("fail");
        // The folder does not exist: the temporary file cannot even be created.
        let e = write_atomic(&dir.join("no/such/dir/a.txt"), b"x").unwrap_err();
        assert!(matches!(e, SimError::Io { .. }), "{e}");
        assert!(e.to_string().contains("no/such/dir/a.txt"), "{e}");
        // The destination is a non-empty folder: the rename fails after the write, and the temporary
        // file is removed again.
        let blocker = dir.join("b");
        std::fs::create_dir_all(blocker.join("inside")).unwrap();
        let e = write_atomic(&blocker, b"x").unwrap_err();
        assert!(matches!(e, SimError::Io { .. }), "{e}");
        assert_eq!(names(&dir), vec!["b".to_string()]);
        // No file name at all.
        assert!(matches!(
            write_atomic(Path::new("/"), b"x"),
            Err(SimError::Io { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn staged_folders_replace_the_set_and_keep_the_users_files() {
        let dir = temp_dir("staged");
        let out = dir.join("out");
        let ours = |n: &str| n == "a" || n == "b";
        let stage_with = |files: &[(&str, &str)]| {
            let st = StagedDir::new(&out).unwrap();
            for (n, t) in files {
                write_atomic(&st.path().join(n), t.as_bytes()).unwrap();
            }
            st
        };
        let read = |n: &str| std::fs::read_to_string(out.join(n)).unwrap();
        // A new folder.
        stage_with(&[("a", "1"), ("b", "1")]).commit(&ours).unwrap();
        assert_eq!((read("a"), read("b")), ("1".into(), "1".into()));
        // Only our files in it: swapped as a whole.
        stage_with(&[("a", "2"), ("b", "2")]).commit(&ours).unwrap();
        assert_eq!((read("a"), read("b")), ("2".into(), "2".into()));
        assert_eq!(names(&dir), vec!["out".to_string()]);
        // A file of the user's: kept, ours replaced.
        std::fs::write(out.join("mine"), "m").unwrap();
        stage_with(&[("a", "3"), ("b", "3")]).commit(&ours).unwrap();
        assert_eq!(names(&out), vec!["a", "b", "mine"]);
        assert_eq!((read("a"), read("mine")), ("3".into(), "m".into()));
        // Dropped without a commit (an error): nothing changes, nothing is left.
        drop(stage_with(&[("a", "4")]));
        assert_eq!(read("a"), "3");
        assert_eq!(names(&dir), vec!["out".to_string()]);
        // A folder where an output file goes: refused before anything moves.
        std::fs::remove_file(out.join("b")).unwrap();
        std::fs::create_dir_all(out.join("b/inside")).unwrap();
        let e = stage_with(&[("a", "5"), ("b", "5")])
            .commit(&ours)
            .unwrap_err();
        assert!(e.to_string().contains("out/b"), "{e}");
        assert_eq!(read("a"), "3");
        assert_eq!(names(&dir), vec!["out".to_string()]);
        // Errors about staged files name the destination.
        let st = StagedDir::new(&out).unwrap();
        let e = st.user_error(SimError::Io {
            path: st.path().join("a"),
            source: std::io::Error::other("x"),
        });
        assert_eq!(
            e.to_string(),
            format!("{}: cannot write: x", out.join("a").display())
        );
        let e = st.user_error(SimError::Table {
            file: st.path().join("t.parquet").display().to_string(),
            row: Some(3),
            line: None,
            column: Some("temp".into()),
            message: "bad".into(),
        });
        assert_eq!(
            e.to_string(),
            format!(
                "{}: row 3, column temp: bad",
                out.join("t.parquet").display()
            )
        );
        // Subfolders of ours (a suite's datasets): swapped, or merged when they hold a file of the
        // user's, which is kept.
        let suite = dir.join("suite");
        let stage_sub = |t: &str| {
            let st = StagedDir::new(&suite).unwrap();
            std::fs::create_dir_all(st.path().join("d")).unwrap();
            write_atomic(&st.path().join("d/f"), t.as_bytes()).unwrap();
            st
        };
        let is_d = |n: &str| n == "d";
        stage_sub("1").commit(&is_d).unwrap();
        stage_sub("2").commit(&is_d).unwrap();
        assert_eq!(std::fs::read_to_string(suite.join("d/f")).unwrap(), "2");
        std::fs::write(suite.join("d/mine"), "m").unwrap();
        stage_sub("3").commit(&is_d).unwrap();
        assert_eq!(std::fs::read_to_string(suite.join("d/f")).unwrap(), "3");
        assert_eq!(std::fs::read_to_string(suite.join("d/mine")).unwrap(), "m");
        std::fs::write(suite.join("top"), "t").unwrap();
        stage_sub("4").commit(&is_d).unwrap();
        assert_eq!(names(&suite), vec!["d", "top"]);
        assert_eq!(names(&suite.join("d")), vec!["f", "mine"]);
        assert_eq!(std::fs::read_to_string(suite.join("d/f")).unwrap(), "4");
        std::fs::remove_dir_all(&suite).unwrap();
        // A file where the folder should be.
        let file = dir.join("file");
        std::fs::write(&file, "x").unwrap();
        assert!(matches!(StagedDir::new(&file), Err(SimError::Io { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stale_temporary_names_are_recognised() {
        // PID 0 never names a user process; our own PID is alive.
        assert!(!is_stale_temp(".out.tmp-0", "out"));
        assert!(!is_stale_temp("out.tmp-1-2", "out"));
        assert!(!is_stale_temp(".other.tmp-1-2", "out"));
        let me = format!(".out.tmp-{}-3", std::process::id());
        assert!(!is_stale_temp(&me, "out"));
        if cfg!(target_os = "linux") {
            // PIDs are below 2^22 on Linux: this one cannot be running.
            assert!(is_stale_temp(".out.tmp-4294967295-0", "out"));
        }
    }

    #[test]
    fn temporary_names_are_unique() {
        let dir = temp_dir("unique");
        std::thread::scope(|s| {
            for k in 0..8 {
                let p = dir.join("same.txt");
                s.spawn(move || write_atomic(&p, format!("{k}").as_bytes()).unwrap());
            }
        });
        assert_eq!(names(&dir), vec!["same.txt".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_atomic_file_appears_only_when_committed() {
        let dir = temp_dir("atomic_file");
        let p = dir.join("f.bin");
        std::fs::write(&p, "old").unwrap();
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"new ").unwrap();
        f.write_all(b"bytes").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        drop(f);
        // Dropped without a commit: the old file, and no temporary file.
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        assert_eq!(names(&dir), vec!["f.bin".to_string()]);
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"new").unwrap();
        f.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new");
        assert_eq!(names(&dir), vec!["f.bin".to_string()]);
        // Free space: known on this system for an existing folder and for one still to be made.
        if cfg!(unix) {
            let here = available_bytes(&dir).unwrap();
            assert!(here > 0);
            assert!(available_bytes(&dir.join("not/yet")).is_some());
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
