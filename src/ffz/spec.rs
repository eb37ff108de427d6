//! On-disk structures of `.ffz` version 1, field for field as `formats/ffz-v1.md`
//! defines them. Each struct names its spec section; offsets in the comments are byte
//! offsets inside the structure. Everything is little-endian.
//!
//! These types only move bytes: they check what a single structure can check on its
//! own (magic, its checksum, reserved fields). Cross-checks (lengths against the file,
//! rows against n) live with the reader and the scanner.

/// File magic (spec §3.1): `\x89 F F Z \r \n \x1a \n`. The high byte catches 7-bit
/// transfers, CR LF catches newline translation, `\x1a` stops `type` on old systems.
pub(crate) const FILE_MAGIC: [u8; 8] = *b"\x89FFZ\r\n\x1a\n";
/// The version this code writes and reads (spec §2).
pub(crate) const VERSION: u32 = 1;
/// Chunk magic (spec §5.1).
pub(crate) const CHUNK_MAGIC: [u8; 4] = *b"FFZC";
/// Index magic (spec §6).
pub(crate) const INDEX_MAGIC: [u8; 4] = *b"FFZI";
/// Index flag (spec §6): a route record (§6.1) follows the row table.
pub(crate) const INDEX_FLAG_ROUTES: u32 = 1;
/// Index flag (with [`INDEX_FLAG_ROUTES`]): the route record has a tenth count, the
/// pairs short of their shadow tolerance (spec §6.1). Set only when that count is not
/// 0, so files without such pairs are as readers before it expect.
pub(crate) const INDEX_FLAG_ROUTES_UNMET: u32 = 2;
/// Footer magic, the last 8 bytes of a complete file (spec §7).
pub(crate) const FOOTER_MAGIC: [u8; 8] = *b"FFZ-END\n";

/// Size of [`HeaderV1`] (spec §3.1).
pub(crate) const HEADER_LEN: usize = 64;

/// Offset of `meta_len` in the fixed header (§3.1).
pub(crate) const META_LEN_AT: usize = 40;
/// Size of one [`PatchRecordV1`] (spec §4.1).
pub(crate) const PATCH_RECORD_LEN: usize = 168;
/// Size of [`ChunkHeaderV1`] (spec §5.1).
pub const CHUNK_HEADER_LEN: usize = 40;
/// Size of one [`RowDirEntryV1`] (spec §5.3).
pub(crate) const ROW_DIR_ENTRY_LEN: usize = 24;
/// Size of the fixed part of [`IndexV1`] (spec §6).
pub(crate) const INDEX_FIXED_LEN: usize = 24;
/// Size of [`FooterV1`] (spec §7).
pub(crate) const FOOTER_LEN: usize = 32;

/// `layout` code of a dense file (spec §3.1).
pub(crate) const LAYOUT_DENSE: u32 = 0;
/// `layout` code of a top-k sparse file (spec §3.1).
pub(crate) const LAYOUT_TOPK: u32 = 1;

/// Chunk flag (spec §5.1): float and column arrays are byte-shuffled (spec §5.5).
pub(crate) const CHUNK_FLAG_SHUFFLED: u32 = 1;
/// Row flag (spec §5.3): deliberately not computed; nnz = 0, no data.
pub const ROW_FLAG_SKIPPED: u32 = 1;
/// Row flag (spec §5.3): sparse row (columns + values); clear for dense rows.
pub const ROW_FLAG_SPARSE: u32 = 2;
/// Row directory flag (§5.7): the sparse row's data goes on with links to clusters.
pub const ROW_FLAG_LINKS: u32 = 4;
/// Row directory flag (§5.7, only with `ROW_FLAG_LINKS`): each link carries a slope.
pub const ROW_FLAG_SLOPES: u32 = 8;
/// Row flag (§5.7): a row with links ends with the writer's estimate of their error.
pub const ROW_FLAG_LINK_ERROR: u32 = 16;
/// Header flag (§3.1, §4.3): the meta block holds a cluster order and rows may link to
/// clusters of it (§5.7). Only with the top-k layout.
pub const HEADER_FLAG_CLUSTERS: u32 = 1;

/// Row state code in the index row table (spec §6).
pub(crate) const STATE_MISSING: u32 = 0;
/// Row state code in the index row table (spec §6).
pub(crate) const STATE_PRESENT: u32 = 1;
/// Row state code in the index row table (spec §6).
pub(crate) const STATE_SKIPPED: u32 = 2;
/// Chunk number of a missing row in the index row table (spec §6).
pub(crate) const NO_CHUNK: u32 = u32::MAX;

/// CRC-32C (Castagnoli), the checksum used everywhere in the file (spec §2).
#[inline]
pub(crate) fn crc(bytes: &[u8]) -> u32 {
    crc32c::crc32c(bytes)
}

/// Little-endian reader over a byte slice that never panics: every read past the end
/// returns `None`.
#[derive(Clone, Debug)]
pub(crate) struct Le<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Le<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Le { buf, pos: 0 }
    }
    pub(crate) fn pos(&self) -> usize {
        self.pos
    }
    pub(crate) fn take(&mut self, len: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(len)?;
        let s = self.buf.get(self.pos..end)?;
        self.pos = end;
        Some(s)
    }
    pub(crate) fn array<const N: usize>(&mut self) -> Option<[u8; N]> {
        self.take(N)?.try_into().ok()
    }
    pub(crate) fn u32(&mut self) -> Option<u32> {
        self.array().map(u32::from_le_bytes)
    }
    pub(crate) fn i32(&mut self) -> Option<i32> {
        self.array().map(i32::from_le_bytes)
    }
    pub(crate) fn u64(&mut self) -> Option<u64> {
        self.array().map(u64::from_le_bytes)
    }
    pub(crate) fn f32(&mut self) -> Option<f32> {
        self.array().map(f32::from_le_bytes)
    }
    pub(crate) fn f64(&mut self) -> Option<f64> {
        self.array().map(f64::from_le_bytes)
    }
}

/// Fixed file header, spec §3.1 (64 bytes at offset 0).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HeaderV1 {
    // 0: magic [8] = FILE_MAGIC
    // 8: version u32 = 1
    /// 12: flags u32: `HEADER_FLAG_CLUSTERS` or 0.
    pub(crate) flags: u32,
    /// 16: n u32, the number of patches = rows = columns.
    pub n: u32,
    /// 20: layout u32 (`LAYOUT_DENSE` | `LAYOUT_TOPK`).
    pub layout: u32,
    /// 24: k u32, entries kept per row for top-k; 0 for dense.
    pub k: u32,
    /// 28: zstd_level i32, the level the writer used (information only).
    pub zstd_level: i32,
    /// 32: scene_hash u64 ([`crate::patch::PatchSet::content_hash`] of the patches).
    pub scene_hash: u64,
    /// 40: meta_len u64, bytes from offset 0 to the end of the meta block (§3.3),
    /// i.e. the offset of the first chunk.
    pub meta_len: u64,
    /// 48: method_len u32, UTF-8 bytes of the method string.
    pub method_len: u32,
    /// 52: params_len u32.
    pub params_len: u32,
    /// 56: created_len u32.
    pub created_len: u32,
    // 60: header_crc u32 = crc32c(bytes 0..60)
}

/// Why a header could not be read: the offset of the failing field and what failed.
pub(crate) type Fault = (u64, String);

impl HeaderV1 {
    pub(crate) fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0..8].copy_from_slice(&FILE_MAGIC);
        b[8..12].copy_from_slice(&VERSION.to_le_bytes());
        b[12..16].copy_from_slice(&self.flags.to_le_bytes());
        b[16..20].copy_from_slice(&self.n.to_le_bytes());
        b[20..24].copy_from_slice(&self.layout.to_le_bytes());
        b[24..28].copy_from_slice(&self.k.to_le_bytes());
        b[28..32].copy_from_slice(&self.zstd_level.to_le_bytes());
        b[32..40].copy_from_slice(&self.scene_hash.to_le_bytes());
        b[META_LEN_AT..META_LEN_AT + 8].copy_from_slice(&self.meta_len.to_le_bytes());
        b[48..52].copy_from_slice(&self.method_len.to_le_bytes());
        b[52..56].copy_from_slice(&self.params_len.to_le_bytes());
        b[56..60].copy_from_slice(&self.created_len.to_le_bytes());
        let c = crc(&b[0..60]);
        b[60..64].copy_from_slice(&c.to_le_bytes());
        b
    }

    /// Decode the 64 header bytes. Magic and version are the caller's to check first
    /// (they get their own error kinds); this checks the checksum and the fields.
    pub fn decode(b: &[u8; HEADER_LEN]) -> Result<Self, Fault> {
        let mut r = Le::new(b);
        let _magic: [u8; 8] = r.array().unwrap_or_default();
        let _version = r.u32();
        let get = |r: &mut Le<'_>| r.u32().unwrap_or_default();
        let flags = get(&mut r);
        let n = get(&mut r);
        let layout = get(&mut r);
        let k = get(&mut r);
        let zstd_level = r.i32().unwrap_or_default();
        let scene_hash = r.u64().unwrap_or_default();
        let meta_len = r.u64().unwrap_or_default();
        let method_len = get(&mut r);
        let params_len = get(&mut r);
        let created_len = get(&mut r);
        let stored = get(&mut r);
        let actual = crc(&b[0..60]);
        if stored != actual {
            return Err((
                60,
                format!(
                    "header checksum mismatch (stored {stored:#010x}, computed {actual:#010x})"
                ),
            ));
        }
        if flags & !HEADER_FLAG_CLUSTERS != 0 {
            return Err((12, format!("unknown header flags {flags:#x}")));
        }
        if flags & HEADER_FLAG_CLUSTERS != 0 && layout != LAYOUT_TOPK {
            return Err((12, "a cluster order without the top-k layout".into()));
        }
        match layout {
            LAYOUT_DENSE if k != 0 => return Err((24, format!("dense layout with k = {k}"))),
            LAYOUT_TOPK if k == 0 => return Err((24, "top-k layout with k = 0".into())),
            LAYOUT_DENSE | LAYOUT_TOPK => {}
            other => return Err((20, format!("unknown layout code {other}"))),
        }
        Ok(HeaderV1 {
            flags,
            n,
            layout,
            k,
            zstd_level,
            scene_hash,
            meta_len,
            method_len,
            params_len,
            created_len,
        })
    }
}

/// One patch record of the patch table, spec §4.1 (168 bytes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchRecordV1 {
    /// 0: n_corners u32 (3 or 4).
    pub n_corners: u32,
    /// 4: group u32, index into the group name table (§4.2).
    pub group: u32,
    /// 8: face u32, the scene face the patch was cut from.
    pub face: u32,
    // 12: reserved u32 = 0
    /// 16: corners, 4 × (x, y, z) f64; corner 3 carries no meaning for a triangle.
    pub corners: [[f64; 3]; 4],
    /// 112: unit normal (x, y, z) f64.
    pub normal: [f64; 3],
    /// 136: area f64.
    pub area: f64,
    /// 144: rho (r, g, b) f32, diffuse reflectance.
    pub rho: [f32; 3],
    /// 156: emission (r, g, b) f32, emitted exitance.
    pub emission: [f32; 3],
}

impl PatchRecordV1 {
    pub(crate) fn encode_into(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.n_corners.to_le_bytes());
        out.extend_from_slice(&self.group.to_le_bytes());
        out.extend_from_slice(&self.face.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        for c in &self.corners {
            for x in c {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        for x in &self.normal {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&self.area.to_le_bytes());
        for x in self.rho.iter().chain(&self.emission) {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }

    /// Decode one record; `Err` holds the offset inside the record and the reason.
    pub fn decode(b: &[u8]) -> Result<Self, Fault> {
        let mut r = Le::new(b);
        let short = || (0u64, "patch record cut short".to_string());
        let n_corners = r.u32().ok_or_else(short)?;
        let group = r.u32().ok_or_else(short)?;
        let face = r.u32().ok_or_else(short)?;
        let reserved = r.u32().ok_or_else(short)?;
        let mut corners = [[0.0; 3]; 4];
        for c in &mut corners {
            for x in c.iter_mut() {
                *x = r.f64().ok_or_else(short)?;
            }
        }
        let mut normal = [0.0; 3];
        for x in &mut normal {
            *x = r.f64().ok_or_else(short)?;
        }
        let area = r.f64().ok_or_else(short)?;
        let mut rho = [0.0; 3];
        let mut emission = [0.0; 3];
        for x in rho.iter_mut().chain(emission.iter_mut()) {
            *x = r.f32().ok_or_else(short)?;
        }
        if n_corners != 3 && n_corners != 4 {
            return Err((0, format!("n_corners = {n_corners} (must be 3 or 4)")));
        }
        if reserved != 0 {
            return Err((12, format!("reserved field = {reserved:#x} (must be 0)")));
        }
        Ok(PatchRecordV1 {
            n_corners,
            group,
            face,
            corners,
            normal,
            area,
            rho,
            emission,
        })
    }
}

/// Chunk header, spec §5.1 (40 bytes in front of every chunk payload).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkHeaderV1 {
    // 0: magic [4] = CHUNK_MAGIC
    /// 4: flags u32 (`CHUNK_FLAG_SHUFFLED`).
    pub flags: u32,
    /// 8: compressed_len u64, bytes of the zstd payload that follows the header.
    pub compressed_len: u64,
    /// 16: raw_len u64, bytes of the payload once decompressed.
    pub raw_len: u64,
    /// 24: row_count u32, entries in the row directory.
    pub row_count: u32,
    /// 28: crc_compressed u32 = crc32c(compressed payload).
    pub crc_compressed: u32,
    /// 32: crc_raw u32 = crc32c(decompressed payload).
    pub crc_raw: u32,
    // 36: header_crc u32 = crc32c(bytes 0..36)
}

impl ChunkHeaderV1 {
    pub(crate) fn encode(&self) -> [u8; CHUNK_HEADER_LEN] {
        let mut b = [0u8; CHUNK_HEADER_LEN];
        b[0..4].copy_from_slice(&CHUNK_MAGIC);
        b[4..8].copy_from_slice(&self.flags.to_le_bytes());
        b[8..16].copy_from_slice(&self.compressed_len.to_le_bytes());
        b[16..24].copy_from_slice(&self.raw_len.to_le_bytes());
        b[24..28].copy_from_slice(&self.row_count.to_le_bytes());
        b[28..32].copy_from_slice(&self.crc_compressed.to_le_bytes());
        b[32..36].copy_from_slice(&self.crc_raw.to_le_bytes());
        let c = crc(&b[0..36]);
        b[36..40].copy_from_slice(&c.to_le_bytes());
        b
    }

    /// Decode a chunk header: checks magic, checksum and flags.
    pub fn decode(b: &[u8]) -> Result<Self, Fault> {
        let Some(b) = b.get(..CHUNK_HEADER_LEN) else {
            return Err((
                0,
                format!(
                    "chunk header cut short ({} of {CHUNK_HEADER_LEN} bytes)",
                    b.len()
                ),
            ));
        };
        if b[0..4] != CHUNK_MAGIC {
            return Err((0, format!("bad chunk magic {:02x?}", &b[0..4])));
        }
        let mut r = Le::new(&b[4..]);
        let flags = r.u32().unwrap_or_default();
        let compressed_len = r.u64().unwrap_or_default();
        let raw_len = r.u64().unwrap_or_default();
        let row_count = r.u32().unwrap_or_default();
        let crc_compressed = r.u32().unwrap_or_default();
        let crc_raw = r.u32().unwrap_or_default();
        let stored = r.u32().unwrap_or_default();
        let actual = crc(&b[0..36]);
        if stored != actual {
            return Err((
                36,
                format!("chunk header checksum mismatch (stored {stored:#010x}, computed {actual:#010x})"),
            ));
        }
        if flags & !CHUNK_FLAG_SHUFFLED != 0 {
            return Err((4, format!("unknown chunk flags {flags:#x}")));
        }
        Ok(ChunkHeaderV1 {
            flags,
            compressed_len,
            raw_len,
            row_count,
            crc_compressed,
            crc_raw,
        })
    }
}

/// One row directory entry, spec §5.3 (24 bytes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowDirEntryV1 {
    /// 0: row u32, the row index i.
    pub row: u32,
    /// 4: flags u32 (`ROW_FLAG_SKIPPED`, `ROW_FLAG_SPARSE`, `ROW_FLAG_LINKS`,
    /// `ROW_FLAG_SLOPES`).
    pub flags: u32,
    /// 8: nnz u32, values stored (n for dense, 0 for skipped).
    pub nnz: u32,
    /// 12: dropped f32, mass removed by top-k (spec §5.6).
    pub dropped: f32,
    /// 16: offset u64 of the row's data from the start of the decompressed payload.
    pub offset: u64,
}

impl RowDirEntryV1 {
    pub(crate) fn encode_into(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.row.to_le_bytes());
        out.extend_from_slice(&self.flags.to_le_bytes());
        out.extend_from_slice(&self.nnz.to_le_bytes());
        out.extend_from_slice(&self.dropped.to_le_bytes());
        out.extend_from_slice(&self.offset.to_le_bytes());
    }

    /// Decode an entry (the caller has checked that 24 bytes are there).
    pub fn decode(b: &[u8]) -> Option<Self> {
        let mut r = Le::new(b);
        Some(RowDirEntryV1 {
            row: r.u32()?,
            flags: r.u32()?,
            nnz: r.u32()?,
            dropped: r.f32()?,
            offset: r.u64()?,
        })
    }

    /// The state of a row this entry stores: Skipped or Present (spec §5.3).
    pub(crate) fn state(&self) -> super::presence::RowState {
        if self.flags & ROW_FLAG_SKIPPED != 0 {
            super::presence::RowState::Skipped
        } else {
            super::presence::RowState::Present
        }
    }

    /// Bytes of row data this entry describes inside `raw`, the decompressed payload:
    /// [`RowDirEntryV1::data_len`], plus for a row with links (§5.7) the link count
    /// and the links, whose count is read from the payload, and its link error if any. `None` when that count
    /// lies beyond the payload or cannot be a count of disjoint ranges of `n` positions.
    pub(crate) fn data_len_in(&self, raw: &[u8], n: u32) -> Option<u64> {
        let entries = self.data_len();
        if self.flags & ROW_FLAG_LINKS == 0 {
            return Some(entries);
        }
        let at = usize::try_from(self.offset.checked_add(entries)?).ok()?;
        let m = u32::from_le_bytes(raw.get(at..at.checked_add(4)?)?.try_into().ok()?);
        let error = match self.flags & ROW_FLAG_LINK_ERROR {
            0 => 0,
            _ => 4,
        };
        (m <= n).then(|| entries + 4 + self.link_len() * u64::from(m) + error)
    }

    /// Bytes of one link (§5.7): 12, or 24 with slopes.
    pub(crate) fn link_len(&self) -> u64 {
        match self.flags & ROW_FLAG_SLOPES {
            0 => 12,
            _ => 24,
        }
    }

    /// Bytes of row data of the entry's patch entries (spec §5.4); a row with links has
    /// its links after them (§5.7, [`RowDirEntryV1::data_len_in`]).
    pub(crate) fn data_len(&self) -> u64 {
        if self.flags & ROW_FLAG_SKIPPED != 0 {
            0
        } else if self.flags & ROW_FLAG_SPARSE != 0 {
            8 * self.nnz as u64
        } else {
            4 * self.nnz as u64
        }
    }
}

/// Fixed part of the index, spec §6 (24 bytes, then the chunk table and the row table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct IndexV1 {
    // 0: magic [4] = INDEX_MAGIC
    /// 4: flags u32: [`INDEX_FLAG_ROUTES`], with [`INDEX_FLAG_ROUTES_UNMET`] or not; or
    /// 0.
    pub(crate) flags: u32,
    /// 8: n_chunks u64.
    pub(crate) n_chunks: u64,
    /// 16: n_rows u64, must equal the header's n.
    pub(crate) n_rows: u64,
}

impl IndexV1 {
    pub(crate) fn encode_into(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&INDEX_MAGIC);
        out.extend_from_slice(&self.flags.to_le_bytes());
        out.extend_from_slice(&self.n_chunks.to_le_bytes());
        out.extend_from_slice(&self.n_rows.to_le_bytes());
    }

    /// Total index length for this many chunks and rows, with these flags (spec §6).
    pub(crate) fn total_len(n_chunks: u64, n_rows: u64, flags: u32) -> Option<u64> {
        let chunk_table = n_chunks.checked_mul(8)?;
        let row_table = n_rows.checked_mul(8)?;
        let routes = record_len(flags) as u64;
        (INDEX_FIXED_LEN as u64)
            .checked_add(chunk_table)?
            .checked_add(row_table)?
            .checked_add(routes)
    }
}

/// Bytes of a route record (`ffz::routes`) without the tenth count (spec §6.1): nine u64.
pub(crate) const ROUTES_LEN: usize = 72;

/// Bytes of the route record an index with these flags has (spec §6.1): none without
/// [`INDEX_FLAG_ROUTES`], nine u64 with it, ten with
/// [`INDEX_FLAG_ROUTES_UNMET`] too.
pub(crate) fn record_len(flags: u32) -> usize {
    match (
        flags & INDEX_FLAG_ROUTES != 0,
        flags & INDEX_FLAG_ROUTES_UNMET != 0,
    ) {
        (false, _) => 0,
        (true, false) => ROUTES_LEN,
        (true, true) => ROUTES_LEN + 8,
    }
}

/// Footer, spec §7 (the last 32 bytes of a complete file).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct FooterV1 {
    /// 0: index_offset u64.
    pub(crate) index_offset: u64,
    /// 8: index_len u64.
    pub(crate) index_len: u64,
    /// 16: index_crc u32 = crc32c(index bytes).
    pub(crate) index_crc: u32,
    // 20: footer_crc u32 = crc32c(footer bytes 0..20)
    // 24: magic [8] = FOOTER_MAGIC
}

impl FooterV1 {
    pub(crate) fn encode(&self) -> [u8; FOOTER_LEN] {
        let mut b = [0u8; FOOTER_LEN];
        b[0..8].copy_from_slice(&self.index_offset.to_le_bytes());
        b[8..16].copy_from_slice(&self.index_len.to_le_bytes());
        b[16..20].copy_from_slice(&self.index_crc.to_le_bytes());
        let c = crc(&b[0..20]);
        b[20..24].copy_from_slice(&c.to_le_bytes());
        b[24..32].copy_from_slice(&FOOTER_MAGIC);
        b
    }

    pub(crate) fn decode(b: &[u8]) -> Result<Self, Fault> {
        let Some(b) = b.get(..FOOTER_LEN) else {
            return Err((0, "footer cut short".into()));
        };
        if b[24..32] != FOOTER_MAGIC {
            return Err((
                24,
                "no footer magic (file not finished, or cut short)".into(),
            ));
        }
        let mut r = Le::new(b);
        let index_offset = r.u64().unwrap_or_default();
        let index_len = r.u64().unwrap_or_default();
        let index_crc = r.u32().unwrap_or_default();
        let stored = r.u32().unwrap_or_default();
        let actual = crc(&b[0..20]);
        if stored != actual {
            return Err((
                20,
                format!(
                    "footer checksum mismatch (stored {stored:#010x}, computed {actual:#010x})"
                ),
            ));
        }
        Ok(FooterV1 {
            index_offset,
            index_len,
            index_crc,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_structures_have_spec_sizes_and_round_trip() {
        let h = HeaderV1 {
            flags: 0,
            n: 7,
            layout: LAYOUT_TOPK,
            k: 3,
            zstd_level: -2,
            scene_hash: 0x0123_4567_89ab_cdef,
            meta_len: 1234,
            method_len: 5,
            params_len: 6,
            created_len: 7,
        };
        let b = h.encode();
        assert_eq!(b.len(), HEADER_LEN);
        assert_eq!(&b[0..8], &FILE_MAGIC);
        assert_eq!(HeaderV1::decode(&b), Ok(h));

        let c = ChunkHeaderV1 {
            flags: CHUNK_FLAG_SHUFFLED,
            compressed_len: 99,
            raw_len: 1000,
            row_count: 4,
            crc_compressed: 1,
            crc_raw: 2,
        };
        assert_eq!(ChunkHeaderV1::decode(&c.encode()), Ok(c));

        let f = FooterV1 {
            index_offset: 10,
            index_len: 20,
            index_crc: 30,
        };
        assert_eq!(FooterV1::decode(&f.encode()), Ok(f));

        let p = PatchRecordV1 {
            n_corners: 4,
            group: 1,
            face: 2,
            corners: [[1.0, 2.0, 3.0]; 4],
            normal: [0.0, 0.0, 1.0],
            area: 0.5,
            rho: [0.1, 0.2, 0.3],
            emission: [1.0, 2.0, 3.0],
        };
        let mut v = Vec::new();
        p.encode_into(&mut v);
        assert_eq!(v.len(), PATCH_RECORD_LEN);
        assert_eq!(PatchRecordV1::decode(&v), Ok(p));

        let e = RowDirEntryV1 {
            row: 5,
            flags: ROW_FLAG_SPARSE,
            nnz: 3,
            dropped: 0.25,
            offset: 48,
        };
        let mut v = Vec::new();
        e.encode_into(&mut v);
        assert_eq!(v.len(), ROW_DIR_ENTRY_LEN);
        assert_eq!(RowDirEntryV1::decode(&v), Some(e));
    }

    #[test]
    fn any_single_bit_flip_in_a_fixed_header_is_caught() {
        let c = ChunkHeaderV1 {
            flags: 0,
            compressed_len: 99,
            raw_len: 1000,
            row_count: 4,
            crc_compressed: 1,
            crc_raw: 2,
        };
        let b = c.encode();
        for bit in 0..b.len() * 8 {
            let mut x = b;
            x[bit / 8] ^= 1 << (bit % 8);
            assert!(ChunkHeaderV1::decode(&x).is_err(), "bit {bit}");
        }
    }

    #[test]
    fn crc32c_known_answer() {
        // RFC 3720 (iSCSI) appendix B.4: CRC-32C of "123456789" is 0xE3069283.
        assert_eq!(crc(b"123456789"), 0xE306_9283);
    }
}
