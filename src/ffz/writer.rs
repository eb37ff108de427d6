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
use super::routes::{self, StoredRoutes};
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
    /// How the pairs of the counted rows got their visibility (spec §6.1): a resumed
    /// file's, plus what [`FfzWriter::add_routes`] adds. None: the index gets no route
    /// record.
    routes: Option<StoredRoutes>,
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

/// Opens `path` for writing (creating it empty when `create` and it is missing) and
/// takes the writer's lock on the file that is at `path` once the lock is held: a
/// writer that renamed a new file over it meanwhile is seen, and its file locked in
/// turn (which then fails while that writer lives).
fn open_locked(path: &Path, create: bool, what: &str) -> Result<File> {
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

/// Where a writer builds the file that replaces `path` (spec §9.1): `OUT.ffz.new`,
/// beside it, so that the rename that publishes it is atomic.
fn staging_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".new");
    s.into()
}

/// A new file at [`staging_path`], created empty and locked. Only the holder of the
/// lock of `path` calls this, so a file already there is a killed writer's leftover.
fn start_staging(path: &Path) -> Result<(File, PathBuf)> {
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
fn publish(file: &File, staging: &Path, path: &Path, fsync: bool) -> Result<()> {
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

/// The chunks of an existing file that a resume keeps, in file order.
struct KeptChunks {
    /// (offset, record length) of each.
    chunks: Vec<(u64, u64)>,
    row_chunk: Vec<u32>,
    presence: RowPresence,
    raw_bytes: u64,
    /// The kept chunks tile the file from the meta block to its end: nothing to drop.
    whole: bool,
    warnings: Vec<String>,
    /// The old index's route record (none when the file was scanned: a run that did
    /// not finish counted nothing).
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

    /// Reopen a partial or finished file to add the rows it lacks (spec §9.2). Checks
    /// that the file was written for the same problem (scene hash, n, layout and k,
    /// method, params), keeps every good chunk wherever it is (before or after a
    /// damaged region), and returns which rows are already there.
    ///
    /// A file that ends with its last good chunk is appended to in place. Any other
    /// (an old index and footer, a torn last chunk, a damaged region) is rewritten: the
    /// kept chunks are copied into a new file beside it that is renamed over it, so the
    /// file never shrinks under a reader (the copy needs that much free space; when the
    /// disk cannot hold it the old file is left as it was).
    ///
    /// # Errors
    /// `ResumeMismatch` naming the field that differs; `Header` when the file's header
    /// is unreadable; `Locked` while another writer has it; `Io` naming the path.
    pub fn resume(
        path: impl AsRef<Path>,
        meta: &FileMeta,
        opts: WriterOptions,
    ) -> Result<(Self, RowPresence)> {
        let path = path.as_ref();
        let target = open_locked(path, false, "open for resume")?;
        let (map, header, old) = map_and_meta(path, &target)?;
        check_resumable(path, &header, &old, meta)?;
        let kept = kept_chunks(path, &map, header.n, header.meta_len, old.layout);
        let (file, offsets, end) = if kept.whole {
            let end = kept.chunks.last().map_or(header.meta_len, |&(o, l)| o + l);
            (target, kept.chunks.iter().map(|c| c.0).collect(), end)
        } else {
            rewrite(path, &map, header.meta_len, &kept.chunks, opts.fsync)?
        };
        drop(map);
        let mut w = Self::empty(path, file, opts, meta, end);
        w.file
            .seek(SeekFrom::Start(w.pos))
            .map_err(|e| FfzError::io(path, "seek", e))?;
        w.chunk_offsets = offsets;
        w.row_chunk = kept.row_chunk;
        w.presence = kept.presence;
        w.raw_bytes = kept.raw_bytes;
        w.warnings = kept.warnings;
        w.routes = kept.routes;
        w.warnings
            .extend(routes::drop_overcount(&mut w.routes, &w.presence));
        let presence = w.presence.clone();
        Ok((w, presence))
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
    if old.method != meta.method {
        return mismatch(format!(
            "the file was computed with method {}, this run uses {}",
            old.method, meta.method
        ));
    }
    if let Some(what) = params_difference(&old.params, &meta.params) {
        return mismatch(what);
    }
    Ok(())
}

/// The first setting in which two params strings (spec §3.2: space-separated
/// `key=value` tokens) differ, ignoring the keys that end in `_path` (where an input
/// was read from, which does not determine the rows: the scene hash, or a `_hash` key,
/// stands for its content); None when they agree.
fn params_difference(old: &str, new: &str) -> Option<String> {
    fn settings(p: &str) -> Vec<(&str, &str)> {
        p.split_ascii_whitespace()
            .map(|t| t.split_once('=').unwrap_or((t, "")))
            .filter(|(k, _)| !k.ends_with("_path"))
            .collect()
    }
    let (a, b) = (settings(old), settings(new));
    fn value<'a>(s: &[(&str, &'a str)], key: &str) -> Option<&'a str> {
        s.iter().find(|(k, _)| *k == key).map(|kv| kv.1)
    }
    for &(k, v) in &a {
        match value(&b, k) {
            Some(w) if w == v => {}
            Some(w) => {
                return Some(format!(
                    "{k} differs: the file was computed with {k}={v}, this run has {k}={w}"
                ))
            }
            None => {
                return Some(format!(
                    "the file was computed with {k}={v}, this run has no {k}"
                ))
            }
        }
    }
    b.iter()
        .find(|(k, _)| value(&a, k).is_none())
        .map(|(k, v)| format!("this run has {k}={v}, the file was computed without {k}"))
}

/// What a resume keeps of the file mapped at `map`: the chunks its index lists when
/// they all pass their cheap checks, else every good chunk a scan finds (spec §8), a
/// chunk that repeats a row of an earlier one excepted. What is dropped is said in the
/// warnings.
fn kept_chunks(path: &Path, map: &[u8], n: u32, meta_len: u64, layout: Layout) -> KeptChunks {
    if let Some((ix, raw_bytes)) = trusted_index(map, n, meta_len) {
        let ends = ix
            .chunk_offsets
            .iter()
            .skip(1)
            .copied()
            .chain([ix.index_offset]);
        let chunks = ix
            .chunk_offsets
            .iter()
            .zip(ends)
            .map(|(&o, e)| (o, e - o))
            .collect();
        return KeptChunks {
            chunks,
            row_chunk: ix.row_chunk,
            presence: ix.presence,
            raw_bytes,
            // The old index and footer are dropped (`finish` writes new ones).
            whole: false,
            warnings: Vec::new(),
            routes: ix.routes,
        };
    }
    let scan = recover::scan_chunks(map, meta_len, map.len() as u64, n, layout);
    let mut kept = KeptChunks {
        chunks: Vec::with_capacity(scan.chunks.len()),
        row_chunk: vec![spec::NO_CHUNK; n as usize],
        presence: RowPresence::new(n),
        raw_bytes: 0,
        whole: scan.bad.is_empty(),
        warnings: Vec::new(),
        routes: None,
    };
    for c in &scan.chunks {
        if let Some(e) = c
            .entries
            .iter()
            .find(|e| kept.presence.get(e.row) != RowState::Missing)
        {
            kept.warnings.push(format!(
                "{}: the chunk at byte {} repeats row {} of an earlier chunk: it is dropped and its rows that no other chunk holds are computed again",
                path.display(),
                c.offset,
                e.row
            ));
            kept.whole = false;
            continue;
        }
        let k = kept.chunks.len() as u32;
        for e in &c.entries {
            kept.presence.set(e.row, e.state());
            kept.row_chunk[e.row as usize] = k;
        }
        kept.chunks.push((c.offset, c.len));
        kept.raw_bytes += c.header.raw_len;
    }
    for b in &scan.bad {
        kept.warnings.push(format!(
            "{}: bytes {}..{} dropped: {}",
            path.display(),
            b.start,
            b.end,
            b.reason
        ));
    }
    kept
}

/// Writes the meta block of `map` and its chunks `chunks` ((offset, length), in
/// order) into a new file and renames it over `path` ([`publish`]); returns the new
/// file, the chunks' new offsets and where the copy ends. On failure (a full disk)
/// the new file is removed and `path` is as it was.
fn rewrite(
    path: &Path,
    map: &[u8],
    meta_len: u64,
    chunks: &[(u64, u64)],
    fsync: bool,
) -> Result<(File, Vec<u64>, u64)> {
    let (mut file, staging) = start_staging(path)?;
    let mut copy = || -> std::io::Result<(Vec<u64>, u64)> {
        file.write_all(&map[..meta_len as usize])?;
        let mut pos = meta_len;
        let mut offsets = Vec::with_capacity(chunks.len());
        for &(o, l) in chunks {
            offsets.push(pos);
            file.write_all(&map[o as usize..(o + l) as usize])?;
            pos += l;
        }
        Ok((offsets, pos))
    };
    match copy() {
        Ok((offsets, end)) => {
            publish(&file, &staging, path, fsync)?;
            Ok((file, offsets, end))
        }
        Err(e) => {
            let _ = std::fs::remove_file(&staging);
            Err(FfzError::io(
                &staging,
                format!(
                    "copy the {} chunks a resume keeps (it rewrites a file it must cut, so that no reader sees it shrink; {} is unchanged)",
                    chunks.len(),
                    path.display()
                ),
                e,
            ))
        }
    }
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
            clusters: None,
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

    /// The route record (spec §6.1): written only when a run counted something, read
    /// back, added to by a resume, and lost (not guessed) when a scan rebuilds the
    /// index.
    #[test]
    fn route_counts_survive_a_resume_and_add_up() {
        use crate::ffz::{PairRoutes, StoredRoutes};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.ffz");
        let m = meta(3);
        let opts = WriterOptions {
            fsync: false,
            ..Default::default()
        };
        let counts = |rows: u64, evaluated: u64, exact: u64| StoredRoutes {
            rows,
            pairs: PairRoutes {
                evaluated,
                unoccludable: 1,
                exact,
                exact_points: 100 * exact,
                ..Default::default()
            },
        };
        // No counts: no record, the index as before.
        let mut w = FfzWriter::create(&path, &m, opts).unwrap();
        w.push_row(Row::dense(0, vec![0.0, 0.5, 0.25])).unwrap();
        let plain = w.finish().unwrap().bytes_on_disk;
        assert_eq!(FfzReader::open(&path).unwrap().routes(), None);
        // A run that counted its row.
        let mut w = FfzWriter::create(&path, &m, opts).unwrap();
        w.push_row(Row::dense(0, vec![0.0, 0.5, 0.25])).unwrap();
        w.add_routes(&counts(1, 2, 1));
        let with = w.finish().unwrap().bytes_on_disk;
        assert_eq!(with, plain + super::super::routes::ROUTES_LEN as u64);
        let r = FfzReader::open(&path).unwrap();
        assert!(
            r.is_indexed() && r.warnings().is_empty(),
            "{:?}",
            r.warnings()
        );
        assert_eq!(r.routes(), Some(&counts(1, 2, 1)));
        drop(r);
        // A resume adds the rows it computes.
        let (mut w, present) = FfzWriter::resume(&path, &m, opts).unwrap();
        assert_eq!(present.present_count(), 1);
        w.push_row(Row::dense(1, vec![0.5, 0.0, 0.25])).unwrap();
        w.push_row(Row::dense(2, vec![0.25, 0.25, 0.0])).unwrap();
        w.add_routes(&counts(2, 4, 2));
        w.finish().unwrap();
        let r = FfzReader::open(&path).unwrap();
        let want = StoredRoutes {
            rows: 3,
            pairs: PairRoutes {
                evaluated: 6,
                unoccludable: 2,
                exact: 3,
                exact_points: 300,
                ..Default::default()
            },
        };
        assert_eq!(r.routes(), Some(&want));
        drop(r);
        // Cut the footer off: the scan finds the rows, and no counts.
        let len = std::fs::metadata(&path).unwrap().len();
        let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        f.set_len(len - 1).unwrap();
        drop(f);
        let r = FfzReader::open(&path).unwrap();
        assert!(!r.is_indexed());
        assert_eq!(r.presence().present_count(), 3);
        assert_eq!(r.routes(), None);
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
