//! `FfzWriter`: the append-only, crash-safe writer (spec §9.1).
//!
//! Memory is O(n) for the row index plus one chunk of buffered rows, whatever n is.
//! The file is valid for a recovery scan after every appended chunk: a crash, a kill or
//! a full disk loses at most the chunk being written, and [`FfzWriter::resume`] picks
//! up from there.

use std::collections::HashSet;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::chunk::{self, EncodedChunk};
use super::error::{FfzError, Result};
use super::index;
use super::meta::{self, FileMeta, Layout};
use super::presence::{RowPresence, RowState};
use super::reader::map_and_meta;
use super::recover;
use super::spec;
use crate::rows::Row;

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
}

/// One writer per file: take an exclusive advisory lock (`flock`) for the lifetime of
/// the writer (it is released when the file is closed, also when the process dies). A
/// second writer, e.g. a `--resume` started while the killed job's rank 0 is still
/// alive, gets [`FfzError::Locked`] instead of interleaving its chunks with the first's.
fn lock_for_writing(path: &Path, file: &File) -> Result<()> {
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

impl FfzWriter {
    /// Create (or overwrite) `path` and write the meta block (spec §3, §4).
    ///
    /// # Errors
    /// `InvalidMeta` when the metadata cannot be stored; `Io` naming the path.
    pub fn create(path: impl AsRef<Path>, meta: &FileMeta, opts: WriterOptions) -> Result<Self> {
        let path = path.as_ref();
        let block = meta::encode_meta(meta, opts.zstd_level)?;
        // Open without truncating, take the writer's lock, then truncate: a file another
        // process is still writing is refused, never clobbered.
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| FfzError::io(path, "create", e))?;
        lock_for_writing(path, &file)?;
        // (Only regular files have a length to cut; a device such as /dev/full has none.)
        if file.metadata().is_ok_and(|m| m.is_file()) {
            file.set_len(0)
                .map_err(|e| FfzError::io(path, "truncate", e))?;
        }
        file.write_all(&block)
            .map_err(|e| FfzError::io(path, "write header", e))?;
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
        }
    }

    /// Reopen a partial or finished file to add the rows it lacks. Checks that the file
    /// was written for the same problem (scene hash, n, layout and k, method, params),
    /// keeps every good chunk, cuts off a torn last chunk and the old index and footer,
    /// and returns which rows are already there.
    ///
    /// # Errors
    /// `ResumeMismatch` naming the field that differs; `Header` when the file's header
    /// is unreadable; `Io` naming the path.
    pub fn resume(
        path: impl AsRef<Path>,
        meta: &FileMeta,
        opts: WriterOptions,
    ) -> Result<(Self, RowPresence)> {
        let path = path.as_ref();
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| FfzError::io(path, "open for resume", e))?;
        lock_for_writing(path, &file)?;
        let (map, header, old) = map_and_meta(path, &file)?;
        check_resumable(path, &header, &old, meta)?;
        let n = header.n;
        let mut w = Self::empty(path, file, opts, meta, header.meta_len);
        let keep = match trusted_index(&map, n, header.meta_len) {
            Some((ix, raw)) => {
                w.chunk_offsets = ix.chunk_offsets;
                w.row_chunk = ix.row_chunk;
                w.presence = ix.presence;
                w.raw_bytes = raw;
                ix.index_offset
            }
            None => w.adopt_scanned_chunks(&map, header.meta_len),
        };
        drop(map);
        w.file
            .set_len(keep)
            .map_err(|e| FfzError::io(path, "truncate for resume", e))?;
        w.file
            .seek(SeekFrom::Start(keep))
            .map_err(|e| FfzError::io(path, "seek", e))?;
        if opts.fsync {
            w.file
                .sync_all()
                .map_err(|e| FfzError::io(path, "fsync", e))?;
        }
        w.pos = keep;
        let presence = w.presence.clone();
        Ok((w, presence))
    }

    /// Adopts the complete chunks of the unindexed file `map` (a killed run's) in file
    /// order, up to the first that repeats a row of an earlier one; returns where the
    /// kept part ends. What is cut off is said in `warnings`.
    fn adopt_scanned_chunks(&mut self, map: &[u8], meta_len: u64) -> u64 {
        let n = self.n;
        let file_len = map.len() as u64;
        let scan = recover::scan_chunks(map, meta_len, file_len, n, self.layout, true);
        let mut keep = meta_len;
        'chunks: for c in &scan.chunks[..scan.prefix_chunks] {
            for e in c.decoded.entries() {
                if self.presence.get(e.row) != RowState::Missing {
                    self.warnings.push(format!(
                        "{}: chunk at byte {} repeats row {}; it and what follows are dropped",
                        self.path.display(),
                        c.offset,
                        e.row
                    ));
                    break 'chunks;
                }
            }
            let k = self.chunk_offsets.len() as u32;
            for e in c.decoded.entries() {
                let s = if e.flags & spec::ROW_FLAG_SKIPPED != 0 {
                    RowState::Skipped
                } else {
                    RowState::Present
                };
                self.presence.set(e.row, s);
                self.row_chunk[e.row as usize] = k;
            }
            self.chunk_offsets.push(c.offset);
            self.raw_bytes += c.decoded.header.raw_len;
            keep = c.offset + c.len;
        }
        if keep < file_len {
            self.warnings.push(format!(
                "{}: dropped {} bytes after byte {keep} (torn last chunk, or an old index that is rewritten at finish)",
                self.path.display(),
                file_len - keep
            ));
        }
        keep
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

/// Refuses to resume a file made for another scene, size, layout, method or settings.
fn check_resumable(
    path: &Path,
    header: &spec::HeaderV1,
    old: &FileMeta,
    meta: &FileMeta,
) -> Result<()> {
    let mismatch = |what: String| {
        Err(FfzError::ResumeMismatch {
            path: path.into(),
            what,
        })
    };
    if old.scene_hash != meta.scene_hash {
        return mismatch(format!(
            "file was computed for scene hash {:#018x}, this run has {:#018x}",
            old.scene_hash, meta.scene_hash
        ));
    }
    if header.n != meta.n() {
        return mismatch(format!(
            "file has n = {}, this run has n = {}",
            header.n,
            meta.n()
        ));
    }
    if old.layout != meta.layout {
        return mismatch(format!(
            "file layout is {}, this run asks for {}",
            old.layout, meta.layout
        ));
    }
    if old.method != meta.method || old.params != meta.params {
        return mismatch(format!(
            "file was computed with method '{}' params '{}', this run has method '{}' params '{}'",
            old.method, old.params, meta.method, meta.params
        ));
    }
    Ok(())
}

/// The index of a finished file whose chunks all pass their cheap checks (and tile
/// the space before the index), with the chunks' raw bytes; None when anything is off
/// (the file is then scanned instead).
fn trusted_index(map: &[u8], n: u32, meta_len: u64) -> Option<(index::IndexData, u64)> {
    let ix = index::read_index(map, n, meta_len).ok()?;
    let mut raw = 0;
    for (k, &o) in ix.chunk_offsets.iter().enumerate() {
        let end = ix
            .chunk_offsets
            .get(k + 1)
            .copied()
            .unwrap_or(ix.index_offset);
        let (h, len) = chunk::check_record(&map[o as usize..end as usize]).ok()?;
        if o + len != end {
            return None;
        }
        raw += h.raw_len;
    }
    Some((ix, raw))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ffz::FfzReader;
    use crate::patch::{Patch, PatchSet};

    fn meta(n: u32) -> FileMeta {
        let p = Patch {
            corners: [
                glam::DVec3::ZERO,
                glam::DVec3::X,
                glam::DVec3::Y,
                glam::DVec3::ZERO,
            ],
            n_corners: 3,
            normal: glam::DVec3::Z,
            area: 0.5,
            group: 0,
            face: 0,
            rho: [0.5; 3],
            emission: [0.0; 3],
        };
        let patches = PatchSet {
            patches: vec![p; n as usize],
            groups: vec!["g".into()],
        };
        FileMeta {
            layout: Layout::Dense,
            method: "point".into(),
            params: String::new(),
            scene_hash: patches.content_hash(),
            created: String::new(),
            patches,
        }
    }

    #[test]
    fn dropped_writer_keeps_buffered_rows_for_resume() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.ffz");
        let m = meta(3);
        let opts = WriterOptions {
            fsync: false,
            ..Default::default()
        };
        let mut w = FfzWriter::create(&path, &m, opts).unwrap();
        w.push_row(Row::dense(1, vec![0.25, 0.0, 0.5])).unwrap();
        assert_eq!(
            w.stats().chunks,
            0,
            "1 MiB chunks: the row is still buffered"
        );
        drop(w); // an error path: no finish
        let r = FfzReader::open(&path).unwrap();
        assert!(!r.is_indexed());
        assert_eq!(r.row(1).unwrap(), Some(Row::dense(1, vec![0.25, 0.0, 0.5])));
        assert_eq!(r.presence().missing(), vec![0, 2]);
        drop(r);
        let (w, presence) = FfzWriter::resume(&path, &m, opts).unwrap();
        assert_eq!(presence.missing(), vec![0, 2]);
        let st = w.finish().unwrap();
        assert_eq!((st.rows, st.chunks), (1, 1));
        assert_eq!(st.bytes_on_disk, std::fs::metadata(&path).unwrap().len());
    }

    #[test]
    fn io_error_names_the_path() {
        // /dev/full accepts the open and fails every write with ENOSPC.
        let path = Path::new("/dev/full");
        assert!(
            path.exists(),
            "this test needs /dev/full (every Linux has it)"
        );
        let e = FfzWriter::create(path, &meta(2), WriterOptions::default())
            .err()
            .unwrap();
        let msg = e.to_string();
        assert!(
            msg.contains("/dev/full") && msg.contains("write header"),
            "{msg}"
        );
    }
}
