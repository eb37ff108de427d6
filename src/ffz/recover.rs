//! Recovery scan (spec §8): walk the chunk area from the end of the meta block, keep
//! every chunk whose header and both checksums hold, and step over anything else by
//! searching for the next chunk magic. Used when the footer or the index is missing
//! or bad (a killed writer, a cut file) and by `resume`.

use super::chunk;
use super::meta::Layout;
use super::spec::{self, ChunkHeaderV1, RowDirEntryV1};

/// A chunk the scan accepted: where it is and its row directory (its row data is not
/// kept, so a scan of a large file holds one chunk's payload at a time).
#[derive(Debug)]
pub(crate) struct ScannedChunk {
    pub(crate) offset: u64,
    /// Record length (header + payload).
    pub(crate) len: u64,
    pub(crate) header: ChunkHeaderV1,
    pub(crate) entries: Vec<RowDirEntryV1>,
}

/// A byte range the scan could not use, with the first reason it saw.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadRegion {
    pub(crate) start: u64,
    pub(crate) end: u64,
    pub(crate) reason: String,
}

/// What a scan found.
#[derive(Debug, Default)]
pub(crate) struct ScanOutcome {
    pub(crate) chunks: Vec<ScannedChunk>,
    pub(crate) bad: Vec<BadRegion>,
}

/// Try to read one chunk at `file[pos..]`.
fn try_chunk(rest: &[u8], n: u32, layout: Layout) -> Result<ScannedChunk, (u64, String)> {
    let (h, len) = chunk::check_record(rest)?;
    let (header, entries) = chunk::decode_record(h, rest, n, layout)?.into_directory();
    Ok(ScannedChunk {
        offset: 0,
        len,
        header,
        entries,
    })
}

/// Scan `file[start..end]` for chunks: every good chunk, in file order, stepping over
/// what is not one by searching for the next chunk magic.
pub(crate) fn scan_chunks(
    file: &[u8],
    start: u64,
    end: u64,
    n: u32,
    layout: Layout,
) -> ScanOutcome {
    let end = end.min(file.len() as u64);
    let mut out = ScanOutcome::default();
    let mut pos = start;
    let mut open_bad: Option<BadRegion> = None;
    while pos < end {
        match try_chunk(&file[pos as usize..end as usize], n, layout) {
            Ok(mut c) => {
                if let Some(mut b) = open_bad.take() {
                    b.end = pos;
                    out.bad.push(b);
                }
                c.offset = pos;
                pos += c.len;
                out.chunks.push(c);
            }
            Err((rel, why)) => {
                if open_bad.is_none() {
                    let what = if file[pos as usize..].starts_with(&spec::INDEX_MAGIC) {
                        "an index (ignored by the scan)".to_string()
                    } else {
                        format!("{why} (at byte {})", pos + rel)
                    };
                    open_bad = Some(BadRegion {
                        start: pos,
                        end,
                        reason: what,
                    });
                }
                match find_magic(&file[(pos + 1) as usize..end as usize]) {
                    Some(k) => pos = pos + 1 + k as u64,
                    None => break,
                }
            }
        }
    }
    if let Some(mut b) = open_bad {
        // Nothing good followed: the region runs to the end of the scanned area.
        b.end = end;
        out.bad.push(b);
    }
    out
}

/// Position of the next chunk magic in `hay`.
fn find_magic(hay: &[u8]) -> Option<usize> {
    hay.windows(spec::CHUNK_MAGIC.len())
        .position(|w| w == spec::CHUNK_MAGIC)
}

/// `Some(length)` when the file at `path` ends inside its own meta block (spec §1, §3):
/// the run that made it was killed while writing its header, so no chunk, hence no
/// row, can be in it. That is: its bytes are a prefix of the file magic, or the magic
/// is complete and the file is shorter than the `meta_len` its header declares (or
/// than the bytes that declare it). `None` for anything else, including a file that
/// is not an `.ffz` at all (which `resume` then names).
///
/// # Errors
/// `Io` naming the path when it cannot be read.
pub fn torn_header(path: &std::path::Path) -> Result<Option<u64>, super::FfzError> {
    use std::io::Read;
    let io = |e| super::FfzError::io(path, "read for resume", e);
    let end = spec::META_LEN_AT + 8;
    let mut head = Vec::with_capacity(end);
    std::fs::File::open(path)
        .map_err(io)?
        .take(end as u64)
        .read_to_end(&mut head)
        .map_err(io)?;
    let len = std::fs::metadata(path).map_err(io)?.len();
    let magic_len = head.len().min(spec::FILE_MAGIC.len());
    if head[..magic_len] != spec::FILE_MAGIC[..magic_len] {
        return Ok(None);
    }
    let torn = match head.get(spec::META_LEN_AT..end) {
        None => true,
        Some(b) => len < u64::from_le_bytes(b.try_into().unwrap_or([0xff; 8])),
    };
    Ok(torn.then_some(len))
}
