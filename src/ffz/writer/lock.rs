//! One writer per file: an exclusive advisory lock (`flock`) held for the writer's
//! lifetime, taken on the file that is at the path once the lock is held (spec §9.1).

use std::fs::{File, OpenOptions};
use std::path::Path;

use crate::ffz::error::{FfzError, Result};

/// One writer per file: take an exclusive advisory lock (`flock`) for the lifetime of
/// the writer (it is released when the file is closed, also when the process dies). A
/// second writer, e.g. a `--resume` started while the killed job's rank 0 is still
/// alive, gets [`FfzError::Locked`] instead of interleaving its chunks with the first's.
pub(super) fn lock_for_writing(path: &Path, file: &File) -> Result<()> {
    // Retry briefly: the lock belongs to the open file description, which a child
    // process forked elsewhere in this program shares until its exec closes it
    // (close-on-exec), so a writer just dropped can hold it for a moment longer. A
    // writer that is really alive holds it for good and gets the error.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
    loop {
        match file.try_lock() {
            Ok(()) => return Ok(()),
            Err(std::fs::TryLockError::WouldBlock) if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(FfzError::Locked {
                    path: path.to_path_buf(),
                })
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(FfzError::io(path, "lock", e)),
        }
    }
}

/// Opens `path` for writing (creating it empty when `create` and it is missing) and
/// takes the writer's lock on the file that is at `path` once the lock is held: a
/// writer that renamed a new file over it meanwhile is seen, and its file locked in
/// turn (which then fails while that writer lives).
pub(super) fn open_locked(path: &Path, create: bool, what: &str) -> Result<File> {
    use std::os::unix::fs::MetadataExt;
    loop {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(create)
            .truncate(false)
            .open(path)
            .map_err(|e| FfzError::io(path, what, e))?;
        lock_for_writing(path, &file)?;
        let held = file.metadata().map_err(|e| FfzError::io(path, "stat", e))?;
        match std::fs::metadata(path) {
            Ok(now) if (now.dev(), now.ino()) == (held.dev(), held.ino()) => return Ok(file),
            Ok(_) => continue,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && create => continue,
            Err(e) => return Err(FfzError::io(path, what, e)),
        }
    }
}
