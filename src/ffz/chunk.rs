//! The chunk codec (spec §5): a batch of rows becomes one self-delimiting record,
//! `ChunkHeaderV1` + zstd payload, and back.
//!
//! Encoding is a free function so that compute workers compress their own rows and the
//! I/O master only appends finished records (docs/architecture.md §3.5: rank 0 bounded by the disk,
//! not by its CPU). Decoding checks both checksums before a number leaves this module.

use super::error::{FfzError, Result};
use super::meta::Layout;
use super::spec::{self, ChunkHeaderV1, RowDirEntryV1};
use crate::rows::{links_match_dropped, Link, Row, RowValues};

/// Whether the writer byte-shuffles float and column arrays (spec §5.5). The spec
/// records the measurement behind this choice.
pub const SHUFFLE_DEFAULT: bool = true;

/// A finished chunk record, ready to be appended to a file by
/// [`FfzWriter::append_chunk`](super::FfzWriter::append_chunk).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodedChunk {
    /// Row ids in the order of the chunk's row directory.
    pub row_ids: Vec<u32>,
    /// The subset of `row_ids` stored as skipped (ascending).
    pub skipped: Vec<u32>,
    /// The complete on-disk record: chunk header (40 bytes) + compressed payload.
    pub bytes: Vec<u8>,
    /// Length of the decompressed payload (row directory + row data).
    pub raw_len: u64,
}

/// Knobs of the chunk encoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkEncoding {
    pub zstd_level: i32,
    /// Byte-shuffle float and column arrays (spec §5.5).
    pub shuffle: bool,
}

/// Encode rows into one chunk record (spec §5) with the default shuffle setting.
/// Rows may come in any order; each row id may appear once.
///
/// # Errors
/// `InvalidRow` when a row does not fit the layout (dense row in a top-k file or the
/// other way round, wrong length, columns not strictly ascending or ≥ n, negative or
/// non-finite dropped mass, row id ≥ n or repeated); `Compress` when zstd fails.
pub fn encode_chunk(
    rows: &[Row],
    meta_layout: Layout,
    n: u32,
    zstd_level: i32,
) -> Result<EncodedChunk> {
    encode_chunk_with(
        rows,
        meta_layout,
        n,
        ChunkEncoding {
            zstd_level,
            shuffle: SHUFFLE_DEFAULT,
        },
    )
}

/// [`encode_chunk`] with every knob exposed (benchmarks compare shuffle on and off).
///
/// # Errors
/// As [`encode_chunk`].
pub fn encode_chunk_with(
    rows: &[Row],
    layout: Layout,
    n: u32,
    enc: ChunkEncoding,
) -> Result<EncodedChunk> {
    let raw = encode_raw(rows, layout, n, enc.shuffle)?;
    let bytes = record(&raw.bytes, rows.len() as u32, enc)?;
    Ok(EncodedChunk {
        row_ids: raw.row_ids,
        skipped: raw.skipped,
        bytes,
        raw_len: raw.bytes.len() as u64,
    })
}

/// The chunk record (header and compressed payload, spec §5.1) of a raw payload of
/// `row_count` rows.
fn record(raw: &[u8], row_count: u32, enc: ChunkEncoding) -> Result<Vec<u8>> {
    let payload = zstd::bulk::compress(raw, enc.zstd_level).map_err(FfzError::Compress)?;
    let header = ChunkHeaderV1 {
        flags: if enc.shuffle {
            spec::CHUNK_FLAG_SHUFFLED
        } else {
            0
        },
        compressed_len: payload.len() as u64,
        raw_len: raw.len() as u64,
        row_count,
        crc_compressed: spec::crc(&payload),
        crc_raw: spec::crc(raw),
    };
    let mut bytes = Vec::with_capacity(spec::CHUNK_HEADER_LEN + payload.len());
    bytes.extend_from_slice(&header.encode());
    bytes.extend_from_slice(&payload);
    Ok(bytes)
}

/// The decompressed payload of a chunk and the rows it names.
pub(crate) struct RawPayload {
    pub(crate) bytes: Vec<u8>,
    pub(crate) row_ids: Vec<u32>,
    pub(crate) skipped: Vec<u32>,
}

/// Raw size a row adds to a chunk (directory entry + data, spec §5.3, §5.4).
pub fn raw_row_len(row: &Row) -> usize {
    spec::ROW_DIR_ENTRY_LEN
        + match &row.values {
            RowValues::Dense(v) => 4 * v.len(),
            RowValues::Sparse { cols, .. } => 8 * cols.len() + links_len(row),
            RowValues::Skipped => 0,
        }
}

/// Bytes a row's links take after its patch entries (spec §5.7): none without links,
/// else the count and 24 bytes a link (12 without slopes, which ffstream no longer
/// writes).
fn links_len(row: &Row) -> usize {
    match row.links.len() {
        0 => 0,
        m => 4 + 24 * m + 4 * usize::from(row.link_error.is_some()),
    }
}

pub(crate) fn check_row(row: &Row, layout: Layout, n: u32) -> Result<()> {
    let bad = |what: String| {
        Err(FfzError::InvalidRow {
            row: row.index,
            what,
        })
    };
    if row.index >= n {
        return bad(format!("row id ≥ n = {n}"));
    }
    if !(row.dropped.is_finite() && row.dropped >= 0.0) {
        return bad(format!(
            "dropped mass {} is not a finite number ≥ 0",
            row.dropped
        ));
    }
    match row.link_error {
        Some(e) if !(e.is_finite() && e >= 0.0) => {
            return bad(format!("link error {e} is not a finite number ≥ 0"));
        }
        Some(_) if row.links.is_empty() => return bad("a link error without links".into()),
        _ => {}
    }
    match (&row.values, layout) {
        (RowValues::Skipped, _) if row.dropped.to_bits() != 0 => {
            bad("skipped row with dropped mass ≠ 0".into())
        }
        (RowValues::Skipped, _) => Ok(()),
        (RowValues::Dense(v), Layout::Dense) if v.len() == n as usize => Ok(()),
        (RowValues::Dense(v), Layout::Dense) => {
            bad(format!("dense row has {} values, n = {n}", v.len()))
        }
        (RowValues::Sparse { cols, vals }, Layout::TopK { k }) => {
            if cols.len() != vals.len() {
                return bad(format!("{} columns but {} values", cols.len(), vals.len()));
            }
            if cols.len() > k.min(n) as usize {
                return bad(format!(
                    "{} entries, more than min(k = {k}, n = {n})",
                    cols.len()
                ));
            }
            if let Some(w) = cols.windows(2).position(|w| w[0] >= w[1]) {
                return bad(format!("columns not strictly ascending at entry {}", w + 1));
            }
            if let Some(&c) = cols.last().filter(|&&c| c >= n) {
                return bad(format!("column {c} ≥ n = {n}"));
            }
            match check_links(&row.links, n) {
                Err(what) => bad(what),
                Ok(())
                    if !row.links.is_empty()
                        && !links_match_dropped(row.linked_sum(), row.dropped) =>
                {
                    bad(format!(
                        "dropped mass {:e} is not the sum of its links {:e}",
                        row.dropped,
                        row.linked_sum()
                    ))
                }
                Ok(()) => Ok(()),
            }
        }
        _ if !row.links.is_empty() => bad("links on a row that is not sparse".into()),
        (RowValues::Dense(_), Layout::TopK { .. }) => bad("dense row in a top-k file".into()),
        (RowValues::Sparse { .. }, Layout::Dense) => bad("sparse row in a dense file".into()),
    }
}

/// Spec §5.7: links non-empty, inside [0, n), ascending and disjoint.
pub(crate) fn check_links(links: &[Link], n: u32) -> std::result::Result<(), String> {
    let mut end = 0u64;
    for (m, l) in links.iter().enumerate() {
        if l.len == 0 {
            return Err(format!("link {m} is empty"));
        }
        if u64::from(l.start) < end {
            return Err(format!(
                "link {m} starts at {} inside the previous link (which ends at {end})",
                l.start
            ));
        }
        end = l.end();
        if end > u64::from(n) {
            return Err(format!("link {m} ends at {end}, beyond n = {n}"));
        }
    }
    Ok(())
}

/// Write `words` as 4-byte little-endian values, byte-shuffled when asked (spec §5.5:
/// all first bytes, then all second bytes, ...).
fn put_words<I: ExactSizeIterator<Item = u32>>(out: &mut Vec<u8>, words: I, shuffle: bool) {
    if !shuffle {
        for w in words {
            out.extend_from_slice(&w.to_le_bytes());
        }
        return;
    }
    let m = words.len();
    let start = out.len();
    out.resize(start + 4 * m, 0);
    let dst = &mut out[start..];
    for (k, w) in words.enumerate() {
        let b = w.to_le_bytes();
        dst[k] = b[0];
        dst[m + k] = b[1];
        dst[2 * m + k] = b[2];
        dst[3 * m + k] = b[3];
    }
}

/// Inverse of [`put_words`]: `src` holds exactly `4 m` bytes.
fn get_words(src: &[u8], shuffle: bool) -> Vec<u32> {
    let m = src.len() / 4;
    if !shuffle {
        return src
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
    }
    let (p0, rest) = src.split_at(m);
    let (p1, rest) = rest.split_at(m);
    let (p2, p3) = rest.split_at(m);
    (0..m)
        .map(|k| u32::from_le_bytes([p0[k], p1[k], p2[k], p3[k]]))
        .collect()
}

/// Build the decompressed payload: row directory then row data (spec §5.2 to §5.5).
pub(crate) fn encode_raw(
    rows: &[Row],
    layout: Layout,
    n: u32,
    shuffle: bool,
) -> Result<RawPayload> {
    if u32::try_from(rows.len()).is_err() {
        return Err(FfzError::InvalidRow {
            row: 0,
            what: "more than 2^32 rows in one chunk".into(),
        });
    }
    let mut ids: Vec<u32> = rows.iter().map(|r| r.index).collect();
    ids.sort_unstable();
    if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
        return Err(FfzError::InvalidRow {
            row: w[0],
            what: "appears twice in one chunk".into(),
        });
    }
    let mut total = spec::ROW_DIR_ENTRY_LEN * rows.len();
    for r in rows {
        check_row(r, layout, n)?;
        total += raw_row_len(r) - spec::ROW_DIR_ENTRY_LEN;
    }
    let mut out = Vec::with_capacity(total);
    let mut offset = (spec::ROW_DIR_ENTRY_LEN * rows.len()) as u64;
    let mut skipped = Vec::new();
    for r in rows {
        let (flags, nnz) = match &r.values {
            RowValues::Dense(v) => (0, v.len() as u32),
            RowValues::Sparse { cols, .. } if r.links.is_empty() => {
                (spec::ROW_FLAG_SPARSE, cols.len() as u32)
            }
            RowValues::Sparse { cols, .. } => (
                spec::ROW_FLAG_SPARSE
                    | spec::ROW_FLAG_LINKS
                    | spec::ROW_FLAG_SLOPES
                    | r.link_error.map_or(0, |_| spec::ROW_FLAG_LINK_ERROR),
                cols.len() as u32,
            ),
            RowValues::Skipped => {
                skipped.push(r.index);
                (spec::ROW_FLAG_SKIPPED, 0)
            }
        };
        let e = RowDirEntryV1 {
            row: r.index,
            flags,
            nnz,
            dropped: r.dropped,
            offset,
        };
        offset += e.data_len() + links_len(r) as u64;
        e.encode_into(&mut out);
    }
    for r in rows {
        match &r.values {
            RowValues::Dense(v) => put_words(&mut out, v.iter().map(|x| x.to_bits()), shuffle),
            RowValues::Sparse { cols, vals } => {
                // Columns delta-encoded (spec §5.4): first absolute, then differences ≥ 1.
                let deltas = cols.iter().scan(0u32, |prev, &c| {
                    let d = c - *prev;
                    *prev = c;
                    Some(d)
                });
                put_words(&mut out, ExactLen(deltas, cols.len()), shuffle);
                put_words(&mut out, vals.iter().map(|x| x.to_bits()), shuffle);
                if !r.links.is_empty() {
                    put_links(&mut out, &r.links, shuffle);
                    if let Some(e) = r.link_error {
                        out.extend_from_slice(&e.to_le_bytes());
                    }
                }
            }
            RowValues::Skipped => {}
        }
    }
    debug_assert_eq!(out.len(), total);
    skipped.sort_unstable();
    Ok(RawPayload {
        bytes: out,
        row_ids: rows.iter().map(|r| r.index).collect(),
        skipped,
    })
}

/// A row's links (spec §5.7): their count, then the starts as gaps (the first start,
/// then each start less the previous link's end), the lengths, the values and the
/// slopes' x, y and z components.
fn put_links(out: &mut Vec<u8>, links: &[Link], shuffle: bool) {
    out.extend_from_slice(&(links.len() as u32).to_le_bytes());
    let gaps = links.iter().scan(0u32, |end, l| {
        let gap = l.start - *end;
        *end = l.start + l.len;
        Some(gap)
    });
    put_words(out, ExactLen(gaps, links.len()), shuffle);
    put_words(out, links.iter().map(|l| l.len), shuffle);
    put_words(out, links.iter().map(|l| l.value.to_bits()), shuffle);
    for c in 0..3 {
        put_words(out, links.iter().map(|l| l.slope[c].to_bits()), shuffle);
    }
}

/// Inverse of [`put_links`] on the `12 m` bytes after the count `m`, or `24 m` with
/// slopes; checks the links against n (spec §5.7).
fn get_links(
    src: &[u8],
    n: u32,
    shuffle: bool,
    slopes: bool,
) -> std::result::Result<Vec<Link>, String> {
    let words = if slopes { 6 } else { 3 };
    let m = src.len() / (4 * words);
    let array = |k: usize| get_words(&src[4 * k * m..4 * (k + 1) * m], shuffle);
    let (gaps, lens, vals) = (array(0), array(1), array(2));
    let slope: Vec<Vec<u32>> = match slopes {
        true => (3..6).map(array).collect(),
        false => vec![vec![0; m]; 3],
    };
    let mut links = Vec::with_capacity(m);
    let mut end = 0u64;
    for k in 0..m {
        let start = end + u64::from(gaps[k]);
        let l = Link {
            start: u32::try_from(start).map_err(|_| format!("link {k} starts beyond n = {n}"))?,
            len: lens[k],
            value: f32::from_bits(vals[k]),
            slope: std::array::from_fn(|c| f32::from_bits(slope[c][k])),
        };
        end = l.end();
        links.push(l);
    }
    check_links(&links, n)?;
    Ok(links)
}

/// An iterator with a known length (`Scan` does not report one).
struct ExactLen<I>(I, usize);
impl<I: Iterator<Item = u32>> Iterator for ExactLen<I> {
    type Item = u32;
    fn next(&mut self) -> Option<u32> {
        let x = self.0.next()?;
        self.1 -= 1;
        Some(x)
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.1, Some(self.1))
    }
}
impl<I: Iterator<Item = u32>> ExactSizeIterator for ExactLen<I> {}

/// Where a chunk failed: byte offset relative to the chunk start (or, for payload
/// faults, of the chunk start) and the reason.
pub(crate) type ChunkFault = (u64, String);

/// Check a chunk record that starts at `rec[0]` (which may run on past the chunk):
/// header, length, checksum of the compressed payload. Returns the header and the
/// record length (header + payload). Cheap: no decompression.
pub fn check_record(rec: &[u8]) -> std::result::Result<(ChunkHeaderV1, u64), ChunkFault> {
    let h = ChunkHeaderV1::decode(rec)?;
    let total = (spec::CHUNK_HEADER_LEN as u64)
        .checked_add(h.compressed_len)
        .ok_or((8, "compressed length overflows".to_string()))?;
    if (rec.len() as u64) < total {
        return Err((
            rec.len() as u64,
            format!(
                "chunk cut short: needs {total} bytes, only {} remain in the file",
                rec.len()
            ),
        ));
    }
    let payload = &rec[spec::CHUNK_HEADER_LEN..total as usize];
    let c = spec::crc(payload);
    if c != h.crc_compressed {
        return Err((
            spec::CHUNK_HEADER_LEN as u64,
            format!(
                "compressed payload checksum mismatch (stored {:#010x}, computed {c:#010x})",
                h.crc_compressed
            ),
        ));
    }
    Ok((h, total))
}

/// A decompressed, checked chunk.
#[derive(Debug)]
pub struct DecodedChunk {
    pub(crate) header: ChunkHeaderV1,
    raw: Vec<u8>,
    entries: Vec<RowDirEntryV1>,
    /// (row id, entry number), sorted by row id, for lookups.
    by_row: Vec<(u32, u32)>,
}

impl DecodedChunk {
    /// Directory entries in stored order.
    pub(crate) fn entries(&self) -> &[RowDirEntryV1] {
        &self.entries
    }

    /// The header and the row directory, without the row data.
    pub(crate) fn into_directory(self) -> (ChunkHeaderV1, Vec<RowDirEntryV1>) {
        (self.header, self.entries)
    }

    /// The directory entry of row `row`, if this chunk holds it.
    pub(crate) fn find(&self, row: u32) -> Option<&RowDirEntryV1> {
        let k = self.by_row.binary_search_by_key(&row, |&(r, _)| r).ok()?;
        self.entries.get(self.by_row[k].1 as usize)
    }

    /// Materialize one row. `Err` names the row and what is wrong (the caller adds the
    /// chunk and offset).
    pub(crate) fn row(&self, e: &RowDirEntryV1, n: u32) -> std::result::Result<Row, String> {
        let shuffle = self.header.flags & spec::CHUNK_FLAG_SHUFFLED != 0;
        let all = e
            .data_len_in(&self.raw, n)
            .and_then(|len| usize::try_from(len).ok())
            .and_then(|len| {
                let start = usize::try_from(e.offset).ok()?;
                self.raw.get(start..start.checked_add(len)?)
            })
            .ok_or_else(|| format!("row {}: data out of bounds", e.row))?;
        let (data, link_data) = all.split_at(e.data_len() as usize);
        // The link error, last (its length is in data_len_in's).
        let (link_data, link_error) = match e.flags & spec::ROW_FLAG_LINK_ERROR {
            0 => (link_data, None),
            _ => {
                let at = link_data
                    .len()
                    .checked_sub(4)
                    .ok_or_else(|| format!("row {}: the link error flag with no link", e.row))?;
                let (links, error) = link_data.split_at(at);
                let x = f32::from_le_bytes(error.try_into().expect("4 bytes"));
                if !(x.is_finite() && x >= 0.0) {
                    return Err(format!(
                        "row {}: link error {x} is not a finite number ≥ 0",
                        e.row
                    ));
                }
                (links, Some(x))
            }
        };
        let links = match link_data.len() {
            0 => Vec::new(),
            4 => return Err(format!("row {}: the links flag with no link", e.row)),
            _ => {
                let slopes = e.flags & spec::ROW_FLAG_SLOPES != 0;
                get_links(&link_data[4..], n, shuffle, slopes)
                    .map_err(|w| format!("row {}: {w}", e.row))?
            }
        };
        let values = if e.flags & spec::ROW_FLAG_SKIPPED != 0 {
            RowValues::Skipped
        } else if e.flags & spec::ROW_FLAG_SPARSE != 0 {
            let (dc, dv) = data.split_at(data.len() / 2);
            let deltas = get_words(dc, shuffle);
            let mut cols = Vec::with_capacity(deltas.len());
            let mut c: u32 = 0;
            for (k, d) in deltas.into_iter().enumerate() {
                if k > 0 && d == 0 {
                    return Err(format!("row {}: column delta 0 at entry {k}", e.row));
                }
                c = c
                    .checked_add(d)
                    .filter(|&c| c < n)
                    .ok_or_else(|| format!("row {}: column at entry {k} is ≥ n = {n}", e.row))?;
                cols.push(c);
            }
            let vals = get_words(dv, shuffle)
                .into_iter()
                .map(f32::from_bits)
                .collect();
            RowValues::Sparse { cols, vals }
        } else {
            RowValues::Dense(
                get_words(data, shuffle)
                    .into_iter()
                    .map(f32::from_bits)
                    .collect(),
            )
        };
        let row = Row {
            index: e.row,
            values,
            dropped: e.dropped,
            links,
            link_error,
        };
        if !row.links.is_empty() && !links_match_dropped(row.linked_sum(), row.dropped) {
            return Err(format!(
                "row {}: dropped mass {:e} is not the sum of its links {:e}",
                e.row,
                row.dropped,
                row.linked_sum()
            ));
        }
        Ok(row)
    }
}

/// Most a zstd payload can expand: a block holds at most 128 KiB and takes at least
/// 4 bytes (a 3-byte block header and one byte of a run-length block), so no payload
/// decompresses to more than 32768 times its size.
const MAX_ZSTD_EXPANSION: u64 = 32_768;

/// Check a declared raw length against its payload before anything is allocated: the
/// bound of [`decode_record`] lets a chunk of n rows of a large n claim 80 GB, and a
/// forged header (checksums recomputed) made every reader abort allocating it (issue
/// 48). The length must be the zstd frame's declared content size, when the frame has
/// one, and at most [`MAX_ZSTD_EXPANSION`] times the payload.
fn raw_len_fits(h: &ChunkHeaderV1, payload: &[u8]) -> std::result::Result<(), ChunkFault> {
    if let Ok(Some(declared)) = zstd::zstd_safe::get_frame_content_size(payload) {
        if declared != h.raw_len {
            return Err((
                16,
                format!(
                    "raw length {} but the zstd frame declares {declared} bytes",
                    h.raw_len
                ),
            ));
        }
    }
    if h.raw_len > (payload.len() as u64).saturating_mul(MAX_ZSTD_EXPANSION) {
        return Err((
            16,
            format!(
                "raw length {} impossible for a payload of {} bytes (zstd expands at most {MAX_ZSTD_EXPANSION}-fold)",
                h.raw_len,
                payload.len()
            ),
        ));
    }
    Ok(())
}

/// Decompress `payload`, reading at most `raw_len + 1` bytes out of it. Memory follows
/// what actually comes out (the buffer starts at 64 MiB at most and grows), not the
/// size a header declares, so a lie about it costs nothing.
fn decompress_at_most(payload: &[u8], raw_len: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    const FIRST: u64 = 64 << 20;
    let mut raw = Vec::with_capacity(raw_len.min(FIRST) as usize);
    zstd::stream::read::Decoder::with_buffer(payload)?
        .take(raw_len.saturating_add(1))
        .read_to_end(&mut raw)?;
    Ok(raw)
}

/// Decompress and check the payload of a record that [`check_record`] accepted
/// (spec §5.2 to §5.4): length and checksum of the raw bytes, then every directory
/// entry against n, the layout and the canonical packing.
pub fn decode_record(
    h: ChunkHeaderV1,
    rec: &[u8],
    n: u32,
    layout: Layout,
) -> std::result::Result<DecodedChunk, ChunkFault> {
    let here = |w: String| (0u64, w);
    let payload = usize::try_from(h.compressed_len)
        .ok()
        .and_then(|len| rec.get(spec::CHUNK_HEADER_LEN..spec::CHUNK_HEADER_LEN.checked_add(len)?))
        .ok_or_else(|| here("chunk cut short".into()))?;
    let dir_len = h.row_count as u64 * spec::ROW_DIR_ENTRY_LEN as u64;
    // Bound the allocation by what the header can honestly claim (spec §5.2).
    let max_raw =
        (h.row_count as u64).saturating_mul(spec::ROW_DIR_ENTRY_LEN as u64 + 4 + 32 * n as u64);
    if h.raw_len < dir_len || h.raw_len > max_raw || h.row_count > n {
        return Err((
            16,
            format!(
                "raw length {} impossible for {} rows of n = {n}",
                h.raw_len, h.row_count
            ),
        ));
    }
    raw_len_fits(&h, payload)?;
    let raw = decompress_at_most(payload, h.raw_len)
        .map_err(|e| here(format!("zstd payload does not decompress: {e}")))?;
    if raw.len() as u64 != h.raw_len {
        return Err(here(format!(
            "payload decompresses to {} bytes, header says {}",
            raw.len(),
            h.raw_len
        )));
    }
    let c = spec::crc(&raw);
    if c != h.crc_raw {
        return Err(here(format!(
            "decompressed payload checksum mismatch (stored {:#010x}, computed {c:#010x})",
            h.crc_raw
        )));
    }
    let mut entries = Vec::with_capacity(h.row_count as usize);
    let mut next = dir_len;
    for (k, b) in raw[..dir_len as usize]
        .chunks_exact(spec::ROW_DIR_ENTRY_LEN)
        .enumerate()
    {
        let e = RowDirEntryV1::decode(b)
            .ok_or_else(|| here(format!("directory entry {k} cut short")))?;
        let bad = |w: &str| here(format!("directory entry {k} (row {}): {w}", e.row));
        check_dir_entry(&e, k, n, layout, next)?;
        next += e
            .data_len_in(&raw, n)
            .ok_or_else(|| bad("link count beyond the payload or above n"))?;
        entries.push(e);
    }
    if next != h.raw_len {
        return Err(here(format!(
            "row data ends at {next}, payload is {} bytes",
            h.raw_len
        )));
    }
    let mut by_row: Vec<(u32, u32)> = entries
        .iter()
        .enumerate()
        .map(|(k, e)| (e.row, k as u32))
        .collect();
    by_row.sort_unstable();
    if let Some(w) = by_row.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(here(format!(
            "row {} appears twice in the directory",
            w[0].0
        )));
    }
    Ok(DecodedChunk {
        header: h,
        raw,
        entries,
        by_row,
    })
}

/// The checks of directory entry `k` of a chunk against n, the layout and the canonical
/// packing (spec §5.3), its data expected at byte `next` of the payload.
fn check_dir_entry(
    e: &RowDirEntryV1,
    k: usize,
    n: u32,
    layout: Layout,
    next: u64,
) -> std::result::Result<(), ChunkFault> {
    let here = |w: String| (0u64, w);
    let sparse = layout.is_sparse();
    let skipped = e.flags & spec::ROW_FLAG_SKIPPED != 0;
    let bad = |w: &str| here(format!("directory entry {k} (row {}): {w}", e.row));
    if e.row >= n {
        return Err(bad(&format!("row id ≥ n = {n}")));
    }
    if e.flags & spec::ROW_FLAG_LINKS != 0 && e.flags & spec::ROW_FLAG_SPARSE == 0 {
        return Err(bad("links on a row that is not sparse"));
    }
    if e.flags & spec::ROW_FLAG_SLOPES != 0 && e.flags & spec::ROW_FLAG_LINKS == 0 {
        return Err(bad("link slopes on a row without links"));
    }
    if e.flags & spec::ROW_FLAG_LINK_ERROR != 0 && e.flags & spec::ROW_FLAG_LINKS == 0 {
        return Err(bad("a link error on a row without links"));
    }
    let known = spec::ROW_FLAG_SKIPPED
        | spec::ROW_FLAG_SPARSE
        | spec::ROW_FLAG_LINKS
        | spec::ROW_FLAG_SLOPES
        | spec::ROW_FLAG_LINK_ERROR;
    if e.flags & !known != 0 {
        return Err(bad(&format!("unknown row flags {:#x}", e.flags)));
    }
    if skipped && (e.nnz != 0 || e.flags & spec::ROW_FLAG_SPARSE != 0 || e.dropped.to_bits() != 0) {
        return Err(bad("skipped row with data or dropped mass"));
    }
    if !skipped && (e.flags & spec::ROW_FLAG_SPARSE != 0) != sparse {
        return Err(bad("row kind does not match the file layout"));
    }
    if !skipped && !sparse && e.nnz != n {
        return Err(bad(&format!("dense row with {} values, n = {n}", e.nnz)));
    }
    if let Layout::TopK { k } = layout {
        if e.nnz > k.min(n) {
            return Err(bad(&format!(
                "{} entries, more than min(k = {k}, n = {n})",
                e.nnz
            )));
        }
    }
    if e.offset != next {
        return Err(bad(&format!("data offset {} (expected {next})", e.offset)));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
