//! The file that replaces another (spec §9.1): written under a staging name beside it,
//! locked, and published by an atomic rename, so that a reader that has the old file
//! open keeps reading it whole and the file never shrinks under a reader.

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};

use super::lock::lock_for_writing;
use crate::ffz::error::{FfzError, Result};

/// Where a writer builds the file that replaces `path` (spec §9.1): `OUT.ffz.new`,
/// beside it, so that the rename that publishes it is atomic.
fn staging_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".new");
    s.into()
}

/// A new file at [`staging_path`], created empty and locked. Only the holder of the
/// lock of `path` calls this, so a file already there is a killed writer's leftover.
pub(super) fn start_staging(path: &Path) -> Result<(File, PathBuf)> {
    let staging = staging_path(path);
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&staging)
        .map_err(|e| {
            FfzError::io(
                &staging,
                "create (the new file, renamed over the old one once its start is written)",
                e,
            )
        })?;
    lock_for_writing(&staging, &file)?;
    Ok((file, staging))
}

/// Gives the staged file `file` the name `path`, atomically: a reader that has the
/// old file open keeps reading it, whole; one that opens `path` afterwards gets the
/// new one. With `fsync`, the new file's bytes and then the rename are made durable.
pub(super) fn publish(file: &File, staging: &Path, path: &Path, fsync: bool) -> Result<()> {
    if fsync {
        file.sync_all()
            .map_err(|e| FfzError::io(staging, "fsync", e))?;
    }
    std::fs::rename(staging, path).map_err(|e| {
        let _ = std::fs::remove_file(staging);
        FfzError::io(path, format!("rename {} to it", staging.display()), e)
    })?;
    if fsync {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        // A directory that cannot be opened or synced (some network file systems)
        // leaves the rename to the file system's own schedule: not an error.
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}
