//! The `.ffz` file format: a self-describing, chunked, zstd-compressed store of the
//! form-factor matrix, written append-only while rows arrive in any order and read
//! through a memory map. The specification is `formats/ffz-v1.md`; every on-disk
//! structure here names its section there, and the spec wins where they disagree.
//!
//! | file | holds |
//! |---|---|
//! | `spec.rs` | on-disk structures (`HeaderV1`, `ChunkHeaderV1`, ...), magics, CRC-32C |
//! | `meta.rs` | [`Layout`], [`FileMeta`], the meta block (header + patch table) |
//! | `chunk.rs` | [`encode_chunk`] (runs on workers) and chunk decoding |
//! | `index.rs` | the row → chunk index and the footer |
//! | `writer/` | [`FfzWriter`]: create, append, finish; its lock, staging file and resume |
//! | `recover.rs` | the recovery scan for files without a usable index |
//! | `reader.rs` | [`FfzReader`]: open, random row access, sequential scan |
//! | `verify.rs` | [`FfzReader::verify`] and [`compare`] |
//! | `params.rs` | [`ParamList`]: the header's params string as key=value settings, and the resume's comparison of two |
//! | `presence.rs` | [`RowPresence`]: which rows a file holds |
//! | `routes.rs` | [`PairRoutes`]: how the pairs got their visibility, kept in the index |
//! | `size.rs` | what a file will take before it is written (the plan `compute` prints) |
//! | `error.rs` | `FfzError`, the error type of this layer |
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
