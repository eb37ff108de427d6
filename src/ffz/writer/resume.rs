//! [`FfzWriter::resume`]: reopening a partial or finished file to add the rows it lacks
//! (spec §9.2). The file must have been written for the same problem; every good chunk
//! is kept (from the index when it can be trusted, else from a recovery scan, spec §8),
//! and a file that does not end with its last good chunk is rewritten beside itself.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::Path;

use super::lock::open_locked;
use super::staging::{publish, start_staging};
use super::{FfzWriter, WriterOptions};
use crate::ffz::chunk;
use crate::ffz::error::{FfzError, Result};
use crate::ffz::index;
use crate::ffz::meta::{FileMeta, Layout};
use crate::ffz::params::ParamList;
use crate::ffz::presence::{RowPresence, RowState};
use crate::ffz::reader::map_and_meta;
use crate::ffz::recover;
use crate::ffz::routes::{self, StoredRoutes};
use crate::ffz::spec;

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
    // Compared as settings (spec §3.2, §9.2), so that a file of any version is judged
    // by the keys it has.
    if let Some(what) = ParamList::parse(&old.params).difference(&ParamList::parse(&meta.params)) {
        return mismatch(what);
    }
    Ok(())
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
