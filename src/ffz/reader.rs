//! `FfzReader`: memory-mapped reading of a `.ffz` file (spec §9): validate the header
//! and meta block, load the index from the footer (or recover by a scan, with a
//! warning), then random row access through a small decompressed-chunk cache, or a
//! sequential scan in file order. Every chunk read checks both checksums.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use memmap2::Mmap;

use super::chunk::{self, DecodedChunk};
use super::error::{FfzError, Result};
use super::index;
use super::meta::{self, FileMeta, Layout};
use super::presence::{RowPresence, RowState};
use super::recover::{self, BadRegion};
use super::routes::StoredRoutes;
use super::spec::{self, HeaderV1};
use crate::rows::Row;

/// Decompressed chunks kept for random access (most recently used last).
const CACHE_CHUNKS: usize = 4;

/// A reader over one `.ffz` file. `Sync`: rows may be fetched from several threads.
pub struct FfzReader {
    path: PathBuf,
    map: Mmap,
    header: HeaderV1,
    meta: FileMeta,
    /// File offset of each chunk the reader uses, ascending.
    chunk_offsets: Vec<u64>,
    /// Chunk number of each row (`spec::NO_CHUNK` when missing).
    row_chunk: Vec<u32>,
    presence: RowPresence,
    /// End of the chunk area (index offset, or file length after a scan).
    chunk_area_end: u64,
    /// True when footer and index were valid; false after a recovery scan.
    indexed: bool,
    /// Regions a recovery scan could not read.
    bad_regions: Vec<BadRegion>,
    warnings: Vec<String>,
    cache: Mutex<Vec<(u32, Arc<DecodedChunk>)>>,
    /// The index's route record (spec §6.1), when it has one.
    routes: Option<StoredRoutes>,
}

/// Map a file and check the header and meta block: shared by the reader and `resume`.
pub(crate) fn map_and_meta(
    path: &Path,
    file: &std::fs::File,
) -> Result<(Mmap, HeaderV1, FileMeta)> {
    let stat = file.metadata().map_err(|e| FfzError::io(path, "stat", e))?;
    if !stat.is_file() {
        let kind = if stat.is_dir() {
            "a directory"
        } else {
            "a special file (device, pipe or socket)"
        };
        return Err(FfzError::NotAFile {
            path: path.into(),
            kind,
        });
    }
    let len = stat.len();
    if len < spec::HEADER_LEN as u64 {
        return Err(FfzError::Header {
            path: path.into(),
            offset: len,
            what: format!("file has {len} bytes, shorter than the 64-byte header"),
        });
    }
    // SAFETY: the map is read-only and lives as long as the reader. ffstream never
    // rewrites or cuts a file in place (the writer only appends; `--force` and a resume
    // that must drop bytes write a new file and rename it over the old one, which this
    // map keeps alive); another process shrinking the file under us would be outside
    // the file's contract (spec §9).
    let map = unsafe { Mmap::map(file) }.map_err(|e| FfzError::io(path, "mmap", e))?;
    if map[0..8] != spec::FILE_MAGIC {
        return Err(FfzError::NotFfz {
            path: path.into(),
            found: map[0..8].to_vec(),
        });
    }
    let version = u32::from_le_bytes([map[8], map[9], map[10], map[11]]);
    if version != spec::VERSION {
        return Err(FfzError::Version {
            path: path.into(),
            version,
        });
    }
    let header_err = |(offset, what): spec::Fault| FfzError::Header {
        path: path.into(),
        offset,
        what,
    };
    let header = meta::decode_header(&map).map_err(header_err)?;
    let meta = meta::decode_meta(&map, &header).map_err(header_err)?;
    Ok((map, header, meta))
}

impl FfzReader {
    /// Open a file. A missing or bad footer/index is not an error: the chunks are
    /// recovered by a scan and [`FfzReader::warnings`] says so.
    ///
    /// # Errors
    /// `Io` when the file cannot be opened or mapped; `NotFfz`, `Version`, `Header`
    /// when the header or meta block is unreadable (nothing can be trusted then).
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = std::fs::File::open(path).map_err(|e| FfzError::io(path, "open", e))?;
        let (map, header, meta) = map_and_meta(path, &file)?;
        let n = header.n;
        let mut r = FfzReader {
            path: path.to_path_buf(),
            header,
            meta,
            chunk_offsets: Vec::new(),
            row_chunk: Vec::new(),
            presence: RowPresence::new(n),
            chunk_area_end: 0,
            indexed: false,
            bad_regions: Vec::new(),
            warnings: Vec::new(),
            cache: Mutex::new(Vec::new()),
            routes: None,
            map,
        };
        match index::read_index(&r.map, n, r.header.meta_len) {
            Ok(ix) => {
                r.chunk_offsets = ix.chunk_offsets;
                r.row_chunk = ix.row_chunk;
                r.presence = ix.presence;
                r.chunk_area_end = ix.index_offset;
                r.routes = ix.routes;
                r.indexed = true;
            }
            Err((offset, why)) => r.recover(offset, &why),
        }
        Ok(r)
    }

    /// Rebuild the index by scanning every chunk (spec §8).
    fn recover(&mut self, offset: u64, why: &str) {
        let n = self.header.n;
        let end = self.map.len() as u64;
        let scan = recover::scan_chunks(&self.map, self.header.meta_len, end, n, self.meta.layout);
        self.row_chunk = vec![spec::NO_CHUNK; n as usize];
        let mut duplicates = 0u64;
        for (k, c) in scan.chunks.iter().enumerate() {
            self.chunk_offsets.push(c.offset);
            for e in &c.entries {
                if self.row_chunk[e.row as usize] != spec::NO_CHUNK {
                    // Only a faulty writer repeats a row; keep the first copy.
                    duplicates += 1;
                    continue;
                }
                self.row_chunk[e.row as usize] = k as u32;
                self.presence.set(e.row, e.state());
            }
        }
        self.chunk_area_end = end;
        let lost: u64 = scan.bad.iter().map(|b| b.end - b.start).sum();
        self.warnings.push(format!(
            "{}: footer or index unusable (byte {offset}: {why}); recovered {} chunks ({} rows present, {} skipped, {} missing) by scanning{}",
            self.path.display(),
            scan.chunks.len(),
            self.presence.present_count(),
            self.presence.skipped_count(),
            self.presence.missing_count(),
            if lost > 0 { format!("; {lost} bytes in {} regions unreadable", scan.bad.len()) } else { String::new() }
        ));
        for b in &scan.bad {
            self.warnings.push(format!(
                "{}: bytes {}..{} skipped: {}",
                self.path.display(),
                b.start,
                b.end,
                b.reason
            ));
        }
        if duplicates > 0 {
            self.warnings.push(format!(
                "{}: {duplicates} rows appear in more than one chunk; the first copy is used",
                self.path.display()
            ));
        }
        self.bad_regions = scan.bad;
    }

    pub fn meta(&self) -> &FileMeta {
        &self.meta
    }

    /// The fixed header as stored (spec §3.1).
    pub fn header(&self) -> &HeaderV1 {
        &self.header
    }

    /// Number of rows and columns.
    pub fn n(&self) -> u32 {
        self.header.n
    }

    pub fn layout(&self) -> Layout {
        self.meta.layout
    }

    /// Which rows the file holds.
    pub fn presence(&self) -> &RowPresence {
        &self.presence
    }

    /// What went wrong while opening (footer or index missing, recovered by a scan,
    /// unreadable regions). Empty for a good, finished file.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// How the pairs of the counted rows got their visibility (spec §6.1): None when
    /// the index has no route record (a file written before there was one, or by a
    /// writer that counted nothing) or the file was recovered by a scan.
    pub fn routes(&self) -> Option<&StoredRoutes> {
        self.routes.as_ref()
    }

    /// True when the footer and index were valid (no recovery scan was needed).
    pub fn is_indexed(&self) -> bool {
        self.indexed
    }

    /// Number of chunks in use.
    pub fn chunk_count(&self) -> usize {
        self.chunk_offsets.len()
    }

    /// File offset of each chunk in use, ascending.
    pub fn chunk_offsets(&self) -> &[u64] {
        &self.chunk_offsets
    }

    /// File length in bytes.
    pub(crate) fn file_len(&self) -> u64 {
        self.map.len() as u64
    }

    /// End of the chunk area (where the index starts, or the file end after a scan).
    pub(crate) fn chunk_area_end(&self) -> u64 {
        self.chunk_area_end
    }

    /// Regions a recovery scan could not read (empty when the index was used).
    pub(crate) fn bad_regions(&self) -> &[BadRegion] {
        &self.bad_regions
    }

    /// Chunk number that holds row `i` (`None` when missing).
    pub fn chunk_of(&self, i: u32) -> Option<u32> {
        self.row_chunk
            .get(i as usize)
            .copied()
            .filter(|&c| c != spec::NO_CHUNK)
    }

    pub(crate) fn chunk_err(&self, k: u32, rel: u64, what: String) -> FfzError {
        let offset = self.chunk_offsets.get(k as usize).copied().unwrap_or(0);
        let what = if rel > 0 {
            format!("{what} (field at byte {})", offset + rel)
        } else {
            what
        };
        FfzError::Chunk {
            path: self.path.clone(),
            chunk: k as u64,
            offset,
            what,
        }
    }

    /// Header of chunk `k` and its record length, checked (header checksum, bounds,
    /// compressed checksum) without decompressing.
    ///
    /// # Errors
    /// `Chunk` naming the chunk and its offset.
    pub fn chunk_record(&self, k: u32) -> Result<(spec::ChunkHeaderV1, u64)> {
        let Some(&start) = self.chunk_offsets.get(k as usize) else {
            return Err(self.chunk_err(
                k,
                0,
                format!("no such chunk (the file has {})", self.chunk_offsets.len()),
            ));
        };
        let end = self
            .chunk_offsets
            .get(k as usize + 1)
            .copied()
            .unwrap_or(self.chunk_area_end);
        let rec = &self.map[start as usize..end as usize];
        chunk::check_record(rec).map_err(|(rel, w)| self.chunk_err(k, rel, w))
    }

    /// Header of chunk `k` if it decodes (checksum of the header only; for `info`).
    pub(crate) fn chunk_header(&self, k: u32) -> Option<spec::ChunkHeaderV1> {
        let start = *self.chunk_offsets.get(k as usize)? as usize;
        spec::ChunkHeaderV1::decode(&self.map[start..]).ok()
    }

    /// Decompress and check chunk `k` (not cached).
    ///
    /// # Errors
    /// `Chunk` naming the chunk and its offset when any check fails.
    pub(crate) fn decode_chunk(&self, k: u32) -> Result<DecodedChunk> {
        let (h, _) = self.chunk_record(k)?;
        let start = self.chunk_offsets[k as usize] as usize; // exists: chunk_record checked k
        let decoded = chunk::decode_record(h, &self.map[start..], self.header.n, self.meta.layout)
            .map_err(|(rel, w)| self.chunk_err(k, rel, w));
        self.release(start, spec::CHUNK_HEADER_LEN + h.compressed_len as usize);
        decoded
    }

    /// Let the kernel drop our mapping of bytes `start..start + len` (a chunk just
    /// decoded into memory of its own): the pages stay in the page cache, but no longer
    /// count in this process's resident set, so a sweep over a file larger than memory
    /// has a peak RSS of one chunk, not of the file.
    fn release(&self, start: usize, len: usize) {
        let len = len.min(self.map.len().saturating_sub(start));
        #[cfg(unix)]
        if len > 0 {
            // SAFETY: the map is a read-only shared mapping of a file: after
            // MADV_DONTNEED a read faults the same bytes in again from the page cache
            // (or the file), so no reader, even one holding a slice of these bytes,
            // sees anything else. (Only private or anonymous mappings lose data.)
            let _ = unsafe {
                self.map
                    .unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, start, len)
            };
        }
    }

    fn cached_chunk(&self, k: u32) -> Result<Arc<DecodedChunk>> {
        {
            let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(pos) = cache.iter().position(|(c, _)| *c == k) {
                let hit = cache.remove(pos);
                let d = hit.1.clone();
                cache.push(hit);
                return Ok(d);
            }
        }
        // Decode outside the lock so other threads keep reading.
        let d = Arc::new(self.decode_chunk(k)?);
        let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        if cache.len() >= CACHE_CHUNKS {
            cache.remove(0);
        }
        cache.push((k, d.clone()));
        Ok(d)
    }

    /// Row `i`: `None` when the file does not hold it, a `RowValues::Skipped` row when
    /// it was skipped on purpose.
    ///
    /// # Errors
    /// `RowOutOfRange` for `i >= n`; `Chunk` (naming chunk and offset) when the chunk
    /// holding the row is corrupt or does not list the row.
    pub fn row(&self, i: u32) -> Result<Option<Row>> {
        if i >= self.header.n {
            return Err(FfzError::RowOutOfRange {
                path: self.path.clone(),
                row: i as u64,
                n: self.header.n,
            });
        }
        let k = match self.presence.get(i) {
            RowState::Missing => return Ok(None),
            // Skipped rows carry nothing but their id (spec §5.3).
            RowState::Skipped => return Ok(Some(Row::skipped(i))),
            RowState::Present => self.row_chunk[i as usize],
        };
        let d = self.cached_chunk(k)?;
        let e = d.find(i).ok_or_else(|| {
            self.chunk_err(
                k,
                0,
                format!("the index puts row {i} here but the chunk does not hold it"),
            )
        })?;
        let row = d
            .row(e, self.header.n)
            .map_err(|w| self.chunk_err(k, 0, w))?;
        Ok(Some(row))
    }

    /// Visit every row the file holds, in file order (the fast path for a Jacobi
    /// sweep: one decompression per chunk, no cache). Skipped rows are visited as
    /// `RowValues::Skipped`. Each row is visited once.
    ///
    /// # Errors
    /// The first corrupt chunk stops the scan with a `Chunk` error (rows before it have
    /// been visited). Use [`FfzReader::verify`](crate::ffz::FfzReader::verify) to list
    /// all bad chunks.
    pub fn scan<F: FnMut(&Row)>(&self, mut f: F) -> Result<()> {
        for k in 0..self.chunk_offsets.len() as u32 {
            let d = self.decode_chunk(k)?;
            for e in d.entries() {
                if self.row_chunk[e.row as usize] != k {
                    if self.indexed {
                        return Err(self.chunk_err(
                            k,
                            0,
                            format!(
                                "holds row {} which the index puts in chunk {}",
                                e.row, self.row_chunk[e.row as usize] as i64
                            ),
                        ));
                    }
                    continue; // a duplicate a recovery scan already took from an earlier chunk
                }
                let row = d
                    .row(e, self.header.n)
                    .map_err(|w| self.chunk_err(k, 0, w))?;
                f(&row);
            }
        }
        Ok(())
    }

    /// Visit chunks in file order, handing each decoded chunk (or its error) to `f`:
    /// the building block of `verify` and `compare`, which must go on past bad chunks.
    pub(crate) fn for_each_chunk(&self, mut f: impl FnMut(u32, Result<DecodedChunk>)) {
        for k in 0..self.chunk_offsets.len() as u32 {
            f(k, self.decode_chunk(k));
        }
    }

    /// True when chunk `k` is where row `row` is taken from (false for a duplicate a
    /// recovery scan skipped).
    pub(crate) fn owns(&self, k: u32, row: u32) -> bool {
        self.row_chunk.get(row as usize) == Some(&k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reader_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<FfzReader>();
    }
}
