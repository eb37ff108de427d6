//! The `.ffz` file format: a self-describing, chunked, zstd-compressed store of the
//! form-factor matrix, written append-only while rows arrive in any order and read
//! through a memory map. The specification is `formats/ffz-v1.md`; every on-disk
//! structure here names its section there, and the spec wins where they disagree.
//!
//! One file per on-disk concern (the spec types, the meta block, the chunk codec, the
//! index, the writer with its lock, staging and resume, the reader, the recovery scan,
//! verification, the params string); the files are listed in docs/architecture.md §6.
//! The public types: [`FfzWriter`], [`FfzReader`], [`FileMeta`], [`Layout`],
//! [`ParamList`], [`compare`].
//!
//! What is made of a file for people and other programs (`info`, the printed `verify`,
//! the exports, `verify --unoccluded`) is not the format's: it is in [`crate::report`].

mod chunk;
mod error;
mod index;
mod meta;
pub mod params;
mod presence;
mod reader;
mod recover;
mod routes;
pub mod size;
pub mod spec;
mod verify;
mod writer;

pub use chunk::{
    check_record, decode_record, encode_chunk, encode_chunk_with, raw_row_len, ChunkEncoding,
    DecodedChunk, EncodedChunk, SHUFFLE_DEFAULT,
};
pub use error::FfzError;
pub use meta::{FileMeta, Layout};
pub use params::ParamList;
pub use presence::{RowPresence, RowState};
pub use reader::FfzReader;
pub use recover::{torn_header, BadRegion};
pub use routes::{PairRoutes, StoredRoutes};
pub use verify::{compare, BadChunk, CompareReport, VerifyOptions, VerifyReport, ROW_SUM_TOL};
pub use writer::{FfzWriter, WriterOptions, WriterStats};
