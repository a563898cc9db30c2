//! Atomic writes: a temporary file beside the destination, fsynced, then renamed over it
//! (see [the module documentation](super) for why); the clean-up of temporary files left by
//! interrupted writes, and the check that an output can be written before a render starts.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::OutputError;

/// The temporary-file prefix of `path`'s writes: `.{file name}.tmp-`.
fn temp_prefix(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    Some(format!(".{name}.tmp-"))
}

/// Whether process `pid` is alive in this PID namespace, where that can be told (Linux:
/// `/proc/PID`). A PID that is not alive here may still be a live writer elsewhere.
fn process_alive(pid: u32) -> Option<bool> {
    if !Path::new("/proc/self").exists() {
        return None;
    }
    Some(Path::new("/proc").join(pid.to_string()).exists())
}

/// Removes temporary files `.{file name}.tmp-{pid}-{n}` of this output left by writes that
/// never finished (a process killed during the write, a second Ctrl-C): those no live writer
/// holds. A writer holds an exclusive lock (`flock`) on its temporary file from its creation
/// to its rename ([`write_atomically`]), and the kernel releases it when the writer dies, so
/// a temp file that can be locked belongs to no live writer — whatever PID namespace or
/// machine the writer ran in (a container on a shared volume sees other PIDs, or none, in
/// its `/proc`, so a PID that is not alive here proves nothing). Removed: the files whose PID
/// is not alive here and which this cleaner can lock. Files of live local PIDs, locked
/// files, and anything that does not match the pattern are left alone. Returns the files
/// removed.
pub fn clean_stale_temps(path: &Path) -> Vec<PathBuf> {
    let Some(prefix) = temp_prefix(path) else {
        return Vec::new();
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let Ok(entries) = fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)) else {
            continue;
        };
        let Some((pid, n)) = rest.split_once('-') else {
            continue;
        };
        let (Ok(pid), true) = (
            pid.parse::<u32>(),
            !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()),
        ) else {
            continue;
        };
        // A writer of this PID namespace that is alive keeps its files whether or not it
        // locked them (a version that did not lock, or one between creation and lock).
        if pid == std::process::id() || process_alive(pid) != Some(false) {
            continue;
        }
        if !e.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        // Removed while locked: a writer that opened it just now and waits for the lock
        // finds it gone and starts another ([`write_atomically`]).
        let Ok(file) = fs::OpenOptions::new().read(true).open(e.path()) else {
            continue;
        };
        if file.try_lock().is_ok() && fs::remove_file(e.path()).is_ok() {
            removed.push(e.path());
        }
    }
    removed
}

/// Creates the temporary file `tmp` and holds an exclusive lock on it (see
/// [`clean_stale_temps`]): `None` when a cleaner removed it between its creation and the
/// lock, so that the caller takes another name.
fn create_locked(tmp: &Path) -> io::Result<Option<fs::File>> {
    let file = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(tmp)?;
    file.lock()?;
    // Locked: still the file under that name, or a cleaner got there first.
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let ours = file.metadata()?;
        match fs::metadata(tmp) {
            Ok(m) if m.ino() == ours.ino() && m.dev() == ours.dev() => {}
            _ => return Ok(None),
        }
    }
    Ok(Some(file))
}

/// Checks, without leaving anything behind, that `path` can be written later: it is not a
/// directory, and its folder (or, if that does not exist yet, the nearest existing ancestor,
/// where the writer will create it) accepts a new file. Renders call this for each output
/// before they start, so a bad output path costs nothing.
pub fn check_writable(path: &Path) -> Result<(), OutputError> {
    let io_err = |source| OutputError::Io {
        path: path.to_owned(),
        source,
    };
    if path.file_name().is_none() {
        return Err(io_err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "path has no file name",
        )));
    }
    if path.is_dir() {
        return Err(io_err(io::Error::new(
            io::ErrorKind::IsADirectory,
            "is a directory",
        )));
    }
    let mut dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    while !dir.exists() {
        match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => dir = p.to_owned(),
            _ => dir = PathBuf::from("."),
        }
        if dir == Path::new(".") {
            break;
        }
    }
    if !dir.is_dir() {
        return Err(OutputError::CreateDir {
            path: path.to_owned(),
            dir: dir.clone(),
            source: io::Error::new(io::ErrorKind::NotADirectory, "not a directory"),
        });
    }
    let probe = dir.join(format!(
        ".{}.tmp-{}-probe",
        path.file_name().unwrap_or_default().to_string_lossy(),
        std::process::id()
    ));
    match fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
        Err(source) => Err(OutputError::Io {
            path: path.to_owned(),
            source: io::Error::new(
                source.kind(),
                format!("folder {} is not writable: {source}", dir.display()),
            ),
        }),
    }
}

/// Removes the temporary file when dropped, unless disarmed.
struct TempGuard<'a> {
    path: &'a Path,
    armed: bool,
}

impl Drop for TempGuard<'_> {
    fn drop(&mut self) {
        if self.armed {
            let _ = fs::remove_file(self.path);
        }
    }
}

/// Produces `path` atomically: creates missing parent directories, lets `write` fill a
/// temporary file `.{file name}.tmp-{pid}-{n}` in the same directory, fsyncs it, renames
/// it over `path` and (on Unix) fsyncs the directory. When `write`, the sync or the rename
/// fails, the temporary file is removed and any existing file at `path` is left untouched.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), OutputError>,
) -> Result<(), OutputError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);

    let io_err = |source| OutputError::Io {
        path: path.to_owned(),
        source,
    };
    let file_name = path.file_name().ok_or_else(|| {
        io_err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "path has no file name",
        ))
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    fs::create_dir_all(&dir).map_err(|source| OutputError::CreateDir {
        path: path.to_owned(),
        dir: dir.clone(),
        source,
    })?;

    for stale in clean_stale_temps(path) {
        tracing::info!("removed {}, left by an interrupted write", stale.display());
    }
    // The temporary file is created and locked before it is written, and stays locked until
    // it is renamed: a cleaner elsewhere removes only unlocked ones.
    let (tmp, _lock) = loop {
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(file_name);
        tmp_name.push(format!(
            ".tmp-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let tmp = dir.join(tmp_name);
        match create_locked(&tmp) {
            Ok(Some(lock)) => break (tmp, lock),
            Ok(None) => continue,
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(io_err(e)),
        }
    };
    let mut guard = TempGuard {
        path: &tmp,
        armed: true,
    };

    write(&tmp)?;
    // Flush the data to disk before the rename makes it visible under the final name.
    fs::OpenOptions::new()
        .write(true)
        .open(&tmp)
        .and_then(|f| f.sync_all())
        .map_err(io_err)?;
    fs::rename(&tmp, path).map_err(io_err)?;
    guard.armed = false;
    drop(guard);

    #[cfg(unix)]
    {
        // Best effort: persist the directory entry. Failure here does not undo the write.
        if let Ok(d) = fs::File::open(&dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}
