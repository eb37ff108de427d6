//! `export`'s text outputs (`--matrix`, `--sparse`, `--patches-csv`) written under a
//! temporary name beside the target and renamed over it once complete: a failed
//! export (a corrupt chunk met halfway, a full disk) leaves no partial file that
//! looks like a result, and an older file of that name as it was (issue 48). A
//! device (`/dev/null`, `/dev/stdout`) is written directly: it cannot be renamed over.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::ffz::FfzError;

use super::Result;

/// An output being written: the file to write to and, for a regular file, the
/// temporary name it has until [`Staged::commit`].
#[derive(Debug)]
pub(crate) struct Staged {
    target: PathBuf,
    temp: Option<PathBuf>,
}

impl Staged {
    /// Create the file for `target`: `.NAME.PID-K.part` beside it (PID this process,
    /// K a count of the files it staged), or `target` itself when it is a device.
    ///
    /// # Errors
    /// `Io` naming the file that cannot be created.
    pub(crate) fn create(target: &Path) -> Result<(Self, File)> {
        static MADE: AtomicU64 = AtomicU64::new(0);
        let device = std::fs::metadata(target).is_ok_and(|m| !m.is_file());
        let temp = (!device).then(|| {
            let mut name = std::ffi::OsString::from(".");
            name.push(target.file_name().unwrap_or(target.as_os_str()));
            name.push(format!(
                ".{}-{}.part",
                std::process::id(),
                MADE.fetch_add(1, Ordering::Relaxed)
            ));
            target.with_file_name(name)
        });
        let path = temp.as_deref().unwrap_or(target);
        let f = File::create(path).map_err(|e| FfzError::io(target, "create", e))?;
        Ok((
            Staged {
                target: target.to_owned(),
                temp,
            },
            f,
        ))
    }

    /// The output is complete: rename it over the target.
    ///
    /// # Errors
    /// `Io` naming the target when the rename fails (the temporary file is removed).
    pub(crate) fn commit(self) -> Result<()> {
        if let Some(temp) = &self.temp {
            if let Err(e) = std::fs::rename(temp, &self.target) {
                let _ = std::fs::remove_file(temp);
                return Err(FfzError::io(&self.target, "write", e));
            }
        }
        Ok(())
    }

    /// The export failed: remove what was written (a device keeps what it got).
    pub(crate) fn discard(self) {
        if let Some(temp) = &self.temp {
            let _ = std::fs::remove_file(temp);
        }
    }
}
