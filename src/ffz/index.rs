//! The index and footer at the end of a finished file (spec §6, §7): where each chunk
//! starts and which chunk holds each row.

use super::presence::{RowPresence, RowState};
use super::routes::StoredRoutes;
use super::spec::{self, FooterV1, IndexV1, Le};

/// The index in memory: O(chunks + n).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct IndexData {
    /// File offset of each chunk, ascending (chunk number = position).
    pub(crate) chunk_offsets: Vec<u64>,
    /// Chunk number of each row, `spec::NO_CHUNK` when missing.
    pub(crate) row_chunk: Vec<u32>,
    pub(crate) presence: RowPresence,
    /// Offset of the index = end of the chunk area.
    pub(crate) index_offset: u64,
    /// How the counted rows' pairs got their visibility, when the index says.
    pub(crate) routes: Option<StoredRoutes>,
}

/// Stream the index bytes (spec §6) to `sink` in pieces, so that no second O(n) buffer
/// is needed. Returns the index length.
pub(crate) fn write_index(
    chunk_offsets: &[u64],
    row_chunk: &[u32],
    presence: &RowPresence,
    routes: Option<&StoredRoutes>,
    sink: &mut dyn FnMut(&[u8]) -> std::io::Result<()>,
) -> std::io::Result<u64> {
    let mut head = Vec::with_capacity(spec::INDEX_FIXED_LEN);
    let flags = routes.map_or(0, StoredRoutes::flags);
    IndexV1 {
        flags,
        n_chunks: chunk_offsets.len() as u64,
        n_rows: row_chunk.len() as u64,
    }
    .encode_into(&mut head);
    sink(&head)?;
    let mut buf = Vec::with_capacity(64 * 1024);
    for o in chunk_offsets {
        buf.extend_from_slice(&o.to_le_bytes());
        if buf.len() >= 64 * 1024 {
            sink(&buf)?;
            buf.clear();
        }
    }
    for (i, &c) in row_chunk.iter().enumerate() {
        let state = match presence.get(i as u32) {
            RowState::Missing => spec::STATE_MISSING,
            RowState::Present => spec::STATE_PRESENT,
            RowState::Skipped => spec::STATE_SKIPPED,
        };
        buf.extend_from_slice(&c.to_le_bytes());
        buf.extend_from_slice(&state.to_le_bytes());
        if buf.len() >= 64 * 1024 {
            sink(&buf)?;
            buf.clear();
        }
    }
    if let Some(r) = routes {
        buf.extend_from_slice(&r.encode());
    }
    sink(&buf)?;
    Ok(
        IndexV1::total_len(chunk_offsets.len() as u64, row_chunk.len() as u64, flags)
            .expect("an index of chunks and rows in memory has a length"),
    )
}

/// Read footer and index from a whole file image (spec §7 then §6). `Err` holds the
/// file offset of the failing field and the reason; the caller falls back to a scan.
pub(crate) fn read_index(file: &[u8], n: u32, meta_len: u64) -> Result<IndexData, spec::Fault> {
    let len = file.len() as u64;
    if len < meta_len + spec::FOOTER_LEN as u64 {
        return Err((
            len,
            "no room for a footer (file not finished, or cut short)".into(),
        ));
    }
    let foot_at = len - spec::FOOTER_LEN as u64;
    let f = FooterV1::decode(&file[foot_at as usize..]).map_err(|(o, w)| (foot_at + o, w))?;
    let end = f.index_offset.checked_add(f.index_len);
    if f.index_offset < meta_len || end != Some(foot_at) {
        return Err((
            foot_at,
            format!(
                "footer places the index at {}..+{}, which is not between the meta block (ends {meta_len}) and the footer ({foot_at})",
                f.index_offset, f.index_len
            ),
        ));
    }
    let ix = &file[f.index_offset as usize..foot_at as usize];
    let c = spec::crc(ix);
    if c != f.index_crc {
        return Err((
            foot_at + 16,
            format!(
                "index checksum mismatch (stored {:#010x}, computed {c:#010x})",
                f.index_crc
            ),
        ));
    }
    let at = |r: &Le<'_>| f.index_offset + r.pos() as u64;
    let mut r = Le::new(ix);
    let magic: [u8; 4] = r
        .array()
        .ok_or((f.index_offset, "index cut short".to_string()))?;
    if magic != spec::INDEX_MAGIC {
        return Err((f.index_offset, format!("bad index magic {magic:02x?}")));
    }
    let short = |r: &Le<'_>| (at(r), "index cut short".to_string());
    let flags = r.u32().ok_or_else(|| short(&r))?;
    let n_chunks = r.u64().ok_or_else(|| short(&r))?;
    let n_rows = r.u64().ok_or_else(|| short(&r))?;
    let known = spec::INDEX_FLAG_ROUTES | spec::INDEX_FLAG_ROUTES_UNMET;
    if flags & !known != 0 || flags == spec::INDEX_FLAG_ROUTES_UNMET {
        return Err((
            f.index_offset + 4,
            format!("unknown index flags {flags:#x}"),
        ));
    }
    if n_rows != n as u64 {
        return Err((
            f.index_offset + 16,
            format!("index has {n_rows} rows, header says n = {n}"),
        ));
    }
    if IndexV1::total_len(n_chunks, n_rows, flags) != Some(f.index_len) {
        return Err((
            f.index_offset + 8,
            format!(
                "index length {} does not fit {n_chunks} chunks and {n_rows} rows",
                f.index_len
            ),
        ));
    }
    let mut chunk_offsets = Vec::with_capacity(n_chunks as usize);
    let mut prev = None;
    for k in 0..n_chunks {
        let pos = at(&r);
        let o = r.u64().ok_or_else(|| short(&r))?;
        let ok = o >= meta_len
            // checked: a damaged offset near u64::MAX must be an error, not an overflow
            && o.checked_add(spec::CHUNK_HEADER_LEN as u64)
                .is_some_and(|e| e <= f.index_offset)
            && prev.is_none_or(|p| o > p);
        if !ok {
            return Err((
                pos,
                format!("chunk {k} offset {o} out of order or outside the chunk area"),
            ));
        }
        prev = Some(o);
        chunk_offsets.push(o);
    }
    let mut row_chunk = Vec::with_capacity(n as usize);
    let mut presence = RowPresence::new(n);
    for i in 0..n {
        let pos = at(&r);
        let c = r.u32().ok_or_else(|| short(&r))?;
        let s = r.u32().ok_or_else(|| short(&r))?;
        let state = match (s, c) {
            (spec::STATE_MISSING, spec::NO_CHUNK) => RowState::Missing,
            (spec::STATE_PRESENT, c) if (c as u64) < n_chunks => RowState::Present,
            (spec::STATE_SKIPPED, c) if (c as u64) < n_chunks => RowState::Skipped,
            _ => return Err((pos, format!("row {i}: chunk {c} / state {s} invalid"))),
        };
        presence.set(i, state);
        row_chunk.push(c);
    }
    let routes = if flags & spec::INDEX_FLAG_ROUTES != 0 {
        let pos = at(&r);
        Some(StoredRoutes::decode(&mut r, n, flags).map_err(|(o, why)| (pos + o as u64, why))?)
    } else {
        None
    };
    Ok(IndexData {
        chunk_offsets,
        row_chunk,
        presence,
        index_offset: f.index_offset,
        routes,
    })
}
