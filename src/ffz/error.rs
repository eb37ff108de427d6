//! The error type of the `.ffz` layer.
//!
//! Every variant that comes from a file names the file, and every variant that comes
//! from corrupt data names the place: the chunk number (0-based, in file order) and the
//! byte offset where that chunk starts, or the byte offset of the header, index or
//! footer field that failed (spec sections in `formats/ffz-v1.md`).

use std::path::PathBuf;

/// Errors of the `.ffz` reader, writer and tools.
#[derive(Debug, thiserror::Error)]
pub enum FfzError {
    /// An operating-system error (open, read, write, fsync, disk full, ...).
    #[error("{path}: {op}: {cause}")]
    Io {
        path: PathBuf,
        /// What was being done ("write chunk", "fsync", ...).
        op: String,
        cause: std::io::Error,
    },
    /// The path names a directory, a device or another thing that is not a file.
    #[error("{path}: is {kind}, not an .ffz file")]
    NotAFile { path: PathBuf, kind: &'static str },
    /// The file does not start with the `.ffz` magic (spec §3).
    #[error("{path}: not an .ffz file (magic at byte 0 is {found:02x?})")]
    NotFfz { path: PathBuf, found: Vec<u8> },
    /// A version this reader does not know (spec §2).
    #[error("{path}: .ffz version {version} is not supported (this program reads version 1)")]
    Version { path: PathBuf, version: u32 },
    /// The header or the patch table is corrupt or cut short (spec §3, §4).
    #[error("{path}: header at byte {offset}: {what}")]
    Header {
        path: PathBuf,
        offset: u64,
        what: String,
    },
    /// A chunk is corrupt or cut short (spec §5).
    #[error("{path}: chunk {chunk} at byte {offset}: {what}")]
    Chunk {
        path: PathBuf,
        chunk: u64,
        offset: u64,
        what: String,
    },
    /// The index or the footer is inconsistent (spec §6, §7).
    #[error("{path}: index at byte {offset}: {what}")]
    Index {
        path: PathBuf,
        offset: u64,
        what: String,
    },
    /// A row handed to the encoder does not fit the file (wrong layout, bad columns...).
    #[error("row {row}: {what}")]
    InvalidRow { row: u32, what: String },
    /// Metadata handed to the writer cannot be stored (spec §3, §4 limits).
    #[error("invalid file metadata: {0}")]
    InvalidMeta(String),
    /// A chunk handed to [`crate::ffz::FfzWriter::append_chunk`] is not a well-formed record.
    #[error("{path}: chunk handed to the writer is malformed: {what}")]
    BadEncodedChunk { path: PathBuf, what: String },
    /// The spill file of a `--symmetric` run (service::symmetric) holds a piece that
    /// cannot be used: wrong rows, bad checksum, an entry given twice.
    #[error("{path}: spill file: {what}")]
    Spill { path: PathBuf, what: String },
    /// A row id that is already in the file (or in the same chunk).
    #[error(
        "{path}: row {row} is already in the file (chunk {chunk}); each row may be written once"
    )]
    DuplicateRow { path: PathBuf, row: u32, chunk: u64 },
    /// `resume` found a file written for something else.
    #[error("{path}: another process is writing this file (it holds the writer's lock); wait for it to end, or stop it, then rerun")]
    Locked { path: PathBuf },

    #[error("{path}: cannot export for uDALES: {why}")]
    NotUdales { path: PathBuf, why: String },

    #[error("{path}: cannot resume: {what}")]
    ResumeMismatch { path: PathBuf, what: String },
    /// A row index at or past n.
    #[error("{path}: row {row} out of range (n = {n})")]
    RowOutOfRange { path: PathBuf, row: u64, n: u32 },
    /// zstd failed to compress (out of memory, bad level).
    #[error("zstd compression failed: {0}")]
    Compress(std::io::Error),
    /// The writer saw an I/O error earlier and refuses to append after a torn record.
    #[error("{path}: writer stopped after an earlier error; the file is recoverable by `resume`")]
    Poisoned { path: PathBuf },
}

impl FfzError {
    pub(crate) fn io(path: &std::path::Path, op: impl Into<String>, cause: std::io::Error) -> Self {
        FfzError::Io {
            path: path.to_path_buf(),
            op: op.into(),
            cause,
        }
    }
}

/// Shorthand for results of this layer.
pub(crate) type Result<T, E = FfzError> = std::result::Result<T, E>;
