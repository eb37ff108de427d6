//! Errors of the solve layer: row data that cannot be used, inputs that make no sense,
//! and the CSV/PLY files this layer reads and writes.

use std::path::PathBuf;

/// Everything that can go wrong while solving or writing results.
#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    /// The row source itself failed (the `.ffz` reader names file, chunk and offset).
    #[error("reading rows: {0}")]
    Source(Box<dyn std::error::Error + Send + Sync>),

    /// A row the solve needs was never delivered (a crash left it out of the file).
    #[error(
        "row {row} (group \"{group}\") is needed {needed_for} but is missing from the row \
         source ({missing} needed rows missing in all); finish the file with `compute --resume`"
    )]
    MissingRow {
        row: u32,
        group: String,
        needed_for: &'static str,
        missing: usize,
    },

    /// A row the solve needs is marked Skipped: it was left out on purpose because the
    /// file was computed for a patch that neither reflects nor emits.
    #[error(
        "row {row} (group \"{group}\") is needed {needed_for} but the file marks it Skipped \
         (computed with only the rows the scene's own materials need); recompute with all rows"
    )]
    SkippedRow {
        row: u32,
        group: String,
        needed_for: &'static str,
    },

    /// The same row index arrived twice in one scan.
    #[error("row {row} appears twice in one scan of the row source")]
    DuplicateRow { row: u32 },

    /// A row index (or a column inside a row) is not below the patch count.
    #[error("row {row}: index {index} is out of range for {n} patches")]
    OutOfRange { row: u32, index: u64, n: usize },

    /// A row whose content is inconsistent (wrong length, NaN, ...).
    #[error("row {row}: {message}")]
    BadRow { row: u32, message: String },

    /// Emission sets, reflectances or configuration that cannot be solved.
    #[error("invalid solve input: {0}")]
    InvalidInput(String),

    /// Reading or writing a file.
    #[error("{}: {cause}", path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },

    /// A malformed line in an input CSV.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

impl SolveError {
    /// Wrap an error of the layer below (the row source).
    pub(crate) fn source_error(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        SolveError::Source(Box::new(e))
    }

    pub(crate) fn io(path: &std::path::Path, cause: std::io::Error) -> Self {
        SolveError::Io {
            path: path.to_path_buf(),
            cause,
        }
    }
}
