//! The error of the daylight inputs (weather files, sensor tables).

use std::path::{Path, PathBuf};

use crate::table;

/// Why a daylight input file (weather, sensors) could not be read; every message names
/// the file, and the line where there is one.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The OS's error, quoted in the message (and so not also the error's source,
    /// which `main` would print a second time).
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// Something wrong at a place in the file.
    #[error("{path}: line {line}: {what}")]
    At {
        path: PathBuf,
        line: usize,
        what: String,
    },
    /// Something wrong with the file as a whole.
    #[error("{path}: {what}")]
    File { path: PathBuf, what: String },
}

impl InputError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        InputError::Io {
            path: path.to_owned(),
            cause: source,
        }
    }

    pub(crate) fn at(path: &Path, line: usize, what: String) -> Self {
        InputError::At {
            path: path.to_owned(),
            line,
            what,
        }
    }

    pub(crate) fn file(path: &Path, what: impl Into<String>) -> Self {
        InputError::File {
            path: path.to_owned(),
            what: what.into(),
        }
    }

    /// A problem with field `col` (0-based) of `rec`, named by its 1-based column
    /// number and `name`.
    pub(crate) fn field(
        path: &Path,
        rec: &table::Record,
        col: usize,
        name: &str,
        what: String,
    ) -> Self {
        Self::at(
            path,
            rec.line,
            format!("column {} ({name}): {what}", col + 1),
        )
    }
}
