//! `FfzWriter`: the append-only, crash-safe writer (spec §9.1).
//!
//! Memory is O(n) for the row index plus one chunk of buffered rows, whatever n is.
//! The file is valid for a recovery scan after every appended chunk: a crash, a kill or
//! a full disk loses at most the chunk being written, and [`FfzWriter::resume`] picks
//! up from there.
//!
//! This file holds the writer and its appends; [`lock`] the one-writer-per-file lock,
//! [`staging`] the new file written beside the old one and renamed over it, and
//! [`resume`] the reopening of a partial or finished file (spec §9.2).

use std::collections::HashSet;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::chunk::{self, EncodedChunk};
use super::error::{FfzError, Result};
use super::index;
use super::meta::{self, FileMeta, Layout};
use super::presence::{RowPresence, RowState};
use super::routes::{self, StoredRoutes};
use super::spec;
use crate::rows::Row;

mod lock;
mod resume;
mod staging;
#[cfg(test)]
mod tests;

use lock::open_locked;
use staging::{publish, start_staging};

/// Writer settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterOptions {
    /// zstd level for chunks the writer encodes itself (`push_row`); recorded in the header.
    pub zstd_level: i32,
    /// Raw (uncompressed) bytes of rows `push_row` gathers before it encodes a chunk.
    pub chunk_bytes: usize,
    /// fsync the file in `finish` (and after `resume` truncates).
    pub fsync: bool,
}

impl Default for WriterOptions {
    /// Level 1 and 1 MiB chunks: see spec §5.5 for the measurements behind them.
    fn default() -> Self {
        WriterOptions {
            zstd_level: 1,
            chunk_bytes: 1 << 20,
            fsync: true,
        }
    }
}

/// What has been written so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Rows in the file (present + skipped).
    pub rows: u64,
    /// Of which skipped on purpose.
    pub(crate) skipped: u64,
    pub chunks: u64,
    /// File length (including the index and footer after `finish`).
    pub bytes_on_disk: u64,
    /// Σ of the decompressed chunk payloads (row directories + row data).
    pub raw_bytes: u64,
}

/// Append-only writer of one `.ffz` file.
pub struct FfzWriter {
    path: PathBuf,
    file: File,
    opts: WriterOptions,
    n: u32,
    layout: Layout,
    /// End of the data written so far.
    pos: u64,
    chunk_offsets: Vec<u64>,
    row_chunk: Vec<u32>,
    presence: RowPresence,
    pending: Vec<Row>,
    pending_ids: HashSet<u32>,
    pending_bytes: usize,
    raw_bytes: u64,
    poisoned: bool,
    finished: bool,
    warnings: Vec<String>,
    /// How the pairs of the counted rows got their visibility (spec §6.1): a resumed
    /// file's, plus what [`FfzWriter::add_routes`] adds. None: the index gets no route
    /// record.
    routes: Option<StoredRoutes>,
}

impl FfzWriter {
    /// Create (or overwrite) `path` and write the meta block (spec §3, §4).
    ///
    /// An existing regular file is not cut in place: the new file is written beside it
    /// and renamed over it (spec §9.1), so a reader that has the old one open keeps
    /// reading it whole instead of being killed by a signal when its pages vanish.
    ///
    /// # Errors
    /// `InvalidMeta` when the metadata cannot be stored; `Locked` while another writer
    /// has the file; `Io` naming the path.
    pub fn create(path: impl AsRef<Path>, meta: &FileMeta, opts: WriterOptions) -> Result<Self> {
        let path = path.as_ref();
        let block = meta::encode_meta(meta, opts.zstd_level)?;
        // Take the lock of what is there first: a file another process is still
        // writing is refused, never replaced.
        let target = open_locked(path, true, "create")?;
        // (Only regular files can be replaced; a device such as /dev/full is written.)
        let file = if target.metadata().is_ok_and(|m| m.is_file()) {
            let (mut file, staging) = start_staging(path)?;
            file.write_all(&block).map_err(|e| {
                let _ = std::fs::remove_file(&staging);
                FfzError::io(&staging, "write header", e)
            })?;
            publish(&file, &staging, path, opts.fsync)?;
            file
        } else {
            let mut device = target;
            device
                .write_all(&block)
                .map_err(|e| FfzError::io(path, "write header", e))?;
            device
        };
        Ok(Self::empty(path, file, opts, meta, block.len() as u64))
    }

    /// A writer for `meta` with no chunk yet, appending at `pos` (the end of the meta
    /// block): the common start of `create` and `resume`.
    fn empty(path: &Path, file: File, opts: WriterOptions, meta: &FileMeta, pos: u64) -> Self {
        let n = meta.n();
        FfzWriter {
            path: path.to_path_buf(),
            file,
            opts,
            n,
            layout: meta.layout,
            pos,
            chunk_offsets: Vec::new(),
            row_chunk: vec![spec::NO_CHUNK; n as usize],
            presence: RowPresence::new(n),
            pending: Vec::new(),
            pending_ids: HashSet::new(),
            pending_bytes: 0,
            raw_bytes: 0,
            poisoned: false,
            finished: false,
            warnings: Vec::new(),
            routes: None,
        }
    }

    /// Count the pairs of `r.rows` more rows in the route record `finish` writes
    /// (spec §6.1): a run adds what its workers reported, once, before `finish`.
    pub fn add_routes(&mut self, r: &StoredRoutes) {
        self.routes.get_or_insert_with(StoredRoutes::default).add(r);
    }

    /// Notes from `resume` (bytes dropped, ...).
    pub(crate) fn warnings(&self) -> &[String] {
        &self.warnings
    }

    fn check_usable(&self) -> Result<()> {
        if self.poisoned {
            return Err(FfzError::Poisoned {
                path: self.path.clone(),
            });
        }
        Ok(())
    }

    /// Append a finished chunk record (the I/O master path: checks the record's header
    /// and compressed checksum and the row ids, then appends bytes; no decompression).
    ///
    /// # Errors
    /// `BadEncodedChunk` for a malformed record; `DuplicateRow` when a row is already in
    /// the file; `RowOutOfRange`; `Io` (then the writer refuses further appends, and
    /// everything appended before stays recoverable).
    pub fn append_chunk(&mut self, c: EncodedChunk) -> Result<()> {
        self.check_usable()?;
        let bad = |what: String| FfzError::BadEncodedChunk {
            path: self.path.clone(),
            what,
        };
        let (h, len) = chunk::check_record(&c.bytes).map_err(|(_, w)| bad(w))?;
        if len != c.bytes.len() as u64 {
            return Err(bad(format!(
                "record is {len} bytes but {} were handed over",
                c.bytes.len()
            )));
        }
        if h.raw_len != c.raw_len || h.row_count as usize != c.row_ids.len() {
            return Err(bad(
                "row count or raw length disagree with the record header".into(),
            ));
        }
        if self.chunk_offsets.len() >= spec::NO_CHUNK as usize {
            return Err(bad("too many chunks for one file (2^32 - 1)".into()));
        }
        let mut seen = HashSet::with_capacity(c.row_ids.len());
        for &r in &c.row_ids {
            if r >= self.n {
                return Err(FfzError::RowOutOfRange {
                    path: self.path.clone(),
                    row: r as u64,
                    n: self.n,
                });
            }
            if !seen.insert(r) {
                return Err(FfzError::DuplicateRow {
                    path: self.path.clone(),
                    row: r,
                    chunk: self.chunk_offsets.len() as u64,
                });
            }
            if self.presence.get(r) != RowState::Missing || self.pending_ids.contains(&r) {
                let chunk = self.row_chunk[r as usize];
                return Err(FfzError::DuplicateRow {
                    path: self.path.clone(),
                    row: r,
                    chunk: if chunk == spec::NO_CHUNK {
                        self.chunk_offsets.len() as u64
                    } else {
                        chunk as u64
                    },
                });
            }
        }
        if let Some(s) = c.skipped.iter().find(|s| !seen.contains(s)) {
            return Err(bad(format!(
                "skipped row {s} is not among the chunk's rows"
            )));
        }
        self.append_unchecked(&c, h.raw_len)
    }

    fn append_unchecked(&mut self, c: &EncodedChunk, raw_len: u64) -> Result<()> {
        if let Err(e) = self.file.write_all(&c.bytes) {
            self.poisoned = true;
            return Err(FfzError::io(
                &self.path,
                format!("write chunk at byte {}", self.pos),
                e,
            ));
        }
        let k = self.chunk_offsets.len() as u32;
        self.chunk_offsets.push(self.pos);
        self.pos += c.bytes.len() as u64;
        self.raw_bytes += raw_len;
        for &r in &c.row_ids {
            self.row_chunk[r as usize] = k;
            self.presence.set(r, RowState::Present);
        }
        for &r in &c.skipped {
            self.presence.set(r, RowState::Skipped);
        }
        Ok(())
    }

    /// Buffer one row; a chunk is encoded and appended once `chunk_bytes` raw bytes
    /// are buffered.
    ///
    /// # Errors
    /// `InvalidRow` when the row does not fit the file, `DuplicateRow`, or the errors of
    /// [`FfzWriter::append_chunk`].
    pub fn push_row(&mut self, row: Row) -> Result<()> {
        self.check_usable()?;
        chunk::check_row(&row, self.layout, self.n)?;
        let r = row.index;
        if self.presence.get(r) != RowState::Missing || self.pending_ids.contains(&r) {
            let chunk = self.row_chunk[r as usize];
            return Err(FfzError::DuplicateRow {
                path: self.path.clone(),
                row: r,
                chunk: if chunk == spec::NO_CHUNK {
                    self.chunk_offsets.len() as u64
                } else {
                    chunk as u64
                },
            });
        }
        self.pending_bytes += chunk::raw_row_len(&row);
        self.pending_ids.insert(r);
        self.pending.push(row);
        if self.pending_bytes >= self.opts.chunk_bytes {
            self.flush()?;
        }
        Ok(())
    }

    /// Encode and append the rows buffered by `push_row` (no-op when none are).
    ///
    /// # Errors
    /// As [`FfzWriter::append_chunk`].
    pub(crate) fn flush(&mut self) -> Result<()> {
        self.check_usable()?;
        if self.pending.is_empty() {
            return Ok(());
        }
        let c = chunk::encode_chunk(&self.pending, self.layout, self.n, self.opts.zstd_level)?;
        self.pending.clear();
        self.pending_ids.clear();
        self.pending_bytes = 0;
        let raw = c.raw_len;
        self.append_unchecked(&c, raw)
    }

    /// Counts so far.
    pub(crate) fn stats(&self) -> WriterStats {
        WriterStats {
            rows: self.presence.present_count() + self.presence.skipped_count(),
            skipped: self.presence.skipped_count(),
            chunks: self.chunk_offsets.len() as u64,
            bytes_on_disk: self.pos,
            raw_bytes: self.raw_bytes,
        }
    }

    /// Flush buffered rows, write the index and footer (spec §6, §7) and fsync.
    /// Rows never written are recorded as missing; a later `resume` adds them.
    ///
    /// # Errors
    /// `Io` naming the path (the chunks stay recoverable by a scan).
    pub fn finish(mut self) -> Result<WriterStats> {
        self.flush()?;
        let index_offset = self.pos;
        let mut crc = 0u32;
        let mut out = std::io::BufWriter::with_capacity(1 << 16, &self.file);
        let mut sink = |b: &[u8]| {
            crc = crc32c::crc32c_append(crc, b);
            out.write_all(b)
        };
        let res = index::write_index(
            &self.chunk_offsets,
            &self.row_chunk,
            &self.presence,
            routes::to_write(self.routes.as_ref(), &self.presence),
            &mut sink,
        )
        .and_then(|len| {
            let footer = spec::FooterV1 {
                index_offset,
                index_len: len,
                index_crc: crc,
            };
            out.write_all(&footer.encode())?;
            out.flush()?;
            Ok(len)
        });
        drop(out);
        let index_len = match res {
            Ok(l) => l,
            Err(e) => {
                self.poisoned = true;
                return Err(FfzError::io(&self.path, "write index and footer", e));
            }
        };
        if self.opts.fsync {
            self.file
                .sync_all()
                .map_err(|e| FfzError::io(&self.path, "fsync", e))?;
        }
        self.pos = index_offset + index_len + spec::FOOTER_LEN as u64;
        self.finished = true;
        Ok(self.stats())
    }
}

impl Drop for FfzWriter {
    /// A writer dropped without `finish` (an error path) still appends its buffered
    /// rows as a chunk, so a `resume` need not compute them again. No index is written.
    fn drop(&mut self) {
        if !self.finished && !self.poisoned && !self.pending.is_empty() {
            let _ = self.flush();
        }
    }
}
