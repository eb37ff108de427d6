//! Message layouts and tags of the MPI service, all in one place.
//!
//! Row ids always travel in the payload, never only in the tag: the MPI standard
//! guarantees tags only up to 32767 (MPI 4.0 §3.2.3, `MPI_TAG_UB`), and the paper's use
//! of the tag as row index breaks past that. All integers little-endian.
//!
//! | tag | direction | payload |
//! |---|---|---|
//! | `REQUEST` | worker → 0 | `u32` worker rank |
//! | `ASSIGN` | 0 → worker | `u32` count, then `count` × `u32` row ids (count 0 = no more work) |
//! | `CHUNK` | worker → 0 | chunk record bytes (formats/ffz-v1.md), then `rows` × `u32` row ids, `skipped` × `u32` skipped row ids, `u64` raw length, `u32` rows, `u32` skipped |
//! | `FAILED` | worker → 0 | `i64` row (−1: none), UTF-8 message |
//! | `DONE` | worker → 0 | `u64` rows, `f64` busy seconds, `u32` threads, `u64` peak RSS |
//! | `SETUP` | worker → 0 | UTF-8 message: why this rank could not set up |
//! | `GATHER_ROW` | worker → 0 | `u32` row, then n × `f64` (the `--gather` baseline only) |
//! | `PIECE` | worker → 0 | as `CHUNK`: a spill piece of partial rows (`--symmetric`) |
//! | `HALF_DONE` | worker → 0 | `count` × `u32` row ids: half rows whose pieces were all sent |
//! | `ALIVE` | worker → 0 | empty: the worker has sent nothing else for a while (liveness) |
//! | `FINISH` | 0 → worker | empty: the file is complete, finalise (see [`super::run`]) |
//!
//! The trailer of `CHUNK` sits after the chunk bytes so the master can cut it off in
//! place and hand the buffer to the writer without copying.

use mpi::Tag;

use crate::ffz::EncodedChunk;
use crate::service::job::LinkErrors;
use crate::service::{PairRoutes, ServiceError, WorkerStats};

pub(crate) const REQUEST: Tag = 1;
pub(crate) const ASSIGN: Tag = 2;
pub(crate) const CHUNK: Tag = 3;
pub(crate) const FAILED: Tag = 4;
pub(crate) const DONE: Tag = 5;
pub(crate) const SETUP: Tag = 6;
pub(crate) const GATHER_ROW: Tag = 7;
pub(crate) const PIECE: Tag = 8;
pub(crate) const HALF_DONE: Tag = 9;
pub(crate) const ALIVE: Tag = 10;
pub(crate) const FINISH: Tag = 11;

fn malformed(what: &str, rank: i32) -> ServiceError {
    ServiceError::Transport(format!("malformed {what} message from rank {rank}"))
}

pub(crate) fn encode_assign(rows: &[u32]) -> Vec<u32> {
    let mut v = Vec::with_capacity(rows.len() + 1);
    v.push(rows.len() as u32);
    v.extend_from_slice(rows);
    v
}

pub(crate) fn decode_assign(v: &[u32]) -> Result<Vec<u32>, ServiceError> {
    match v.split_first() {
        Some((&count, rows)) if rows.len() == count as usize => Ok(rows.to_vec()),
        _ => Err(malformed("ASSIGN", 0)),
    }
}

/// Chunk bytes followed by the trailer (row ids, skipped ids, raw length, counts).
pub(crate) fn encode_chunk_message(chunk: EncodedChunk) -> Vec<u8> {
    let mut v = chunk.bytes;
    v.reserve(4 * (chunk.row_ids.len() + chunk.skipped.len()) + 16);
    for r in chunk.row_ids.iter().chain(&chunk.skipped) {
        v.extend_from_slice(&r.to_le_bytes());
    }
    v.extend_from_slice(&chunk.raw_len.to_le_bytes());
    v.extend_from_slice(&(chunk.row_ids.len() as u32).to_le_bytes());
    v.extend_from_slice(&(chunk.skipped.len() as u32).to_le_bytes());
    v
}

/// Inverse of [`encode_chunk_message`]; reuses the buffer for the chunk bytes.
pub(crate) fn decode_chunk_message(
    mut v: Vec<u8>,
    rank: i32,
) -> Result<EncodedChunk, ServiceError> {
    let bad = || malformed("CHUNK", rank);
    let len = v.len();
    if len < 16 {
        return Err(bad());
    }
    let u32_at = |o: usize| u32::from_le_bytes([v[o], v[o + 1], v[o + 2], v[o + 3]]);
    let (rows, skipped) = (u32_at(len - 8) as usize, u32_at(len - 4) as usize);
    let raw_len = u64::from(u32_at(len - 16)) | (u64::from(u32_at(len - 12)) << 32);
    let ids_bytes = rows
        .checked_add(skipped)
        .and_then(|c| c.checked_mul(4))
        .ok_or_else(bad)?;
    let ids_start = (len - 16).checked_sub(ids_bytes).ok_or_else(bad)?;
    let ids: Vec<u32> = v[ids_start..len - 16]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    v.truncate(ids_start);
    Ok(EncodedChunk {
        row_ids: ids[..rows].to_vec(),
        skipped: ids[rows..].to_vec(),
        bytes: v,
        raw_len,
    })
}

pub(crate) fn encode_rows(rows: &[u32]) -> Vec<u8> {
    rows.iter().flat_map(|r| r.to_le_bytes()).collect()
}

pub(crate) fn decode_rows(v: &[u8], rank: i32) -> Result<Vec<u32>, ServiceError> {
    if !v.len().is_multiple_of(4) {
        return Err(malformed("HALF_DONE", rank));
    }
    Ok(v.chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// FAILED: the row as an i64, −1 for none (`Option<u32>` on either side), then the
/// message's UTF-8 bytes.
pub(crate) fn encode_failed(row: Option<u32>, message: &str) -> Vec<u8> {
    let mut v = row.map_or(-1, i64::from).to_le_bytes().to_vec();
    v.extend_from_slice(message.as_bytes());
    v
}

pub(crate) fn decode_failed(v: &[u8], rank: i32) -> Result<(Option<u32>, String), ServiceError> {
    if v.len() < 8 {
        return Err(malformed("FAILED", rank));
    }
    let row = i64::from_le_bytes(v[..8].try_into().map_err(|_| malformed("FAILED", rank))?);
    let row = match row {
        -1 => None,
        r => Some(u32::try_from(r).map_err(|_| malformed("FAILED", rank))?),
    };
    Ok((row, String::from_utf8_lossy(&v[8..]).into_owned()))
}

/// Length of a DONE message: rows, busy seconds, threads, peak RSS, the nine counts of
/// [`PairRoutes`], then the link errors (rows, sum, row and value of the largest).
const DONE_LEN: usize = 28 + 8 * 9 + 24;

pub(crate) fn encode_done(s: &WorkerStats) -> Vec<u8> {
    let mut v = Vec::with_capacity(DONE_LEN);
    v.extend_from_slice(&s.rows.to_le_bytes());
    v.extend_from_slice(&s.busy_seconds.to_le_bytes());
    v.extend_from_slice(&s.threads.to_le_bytes());
    v.extend_from_slice(&s.peak_rss.to_le_bytes());
    for x in s.pairs.to_words() {
        v.extend_from_slice(&x.to_le_bytes());
    }
    let (row, max) = s.links.max.unwrap_or((0, 0.0));
    v.extend_from_slice(&s.links.rows.to_le_bytes());
    v.extend_from_slice(&s.links.sum.to_le_bytes());
    v.extend_from_slice(&row.to_le_bytes());
    v.extend_from_slice(&max.to_le_bytes());
    v
}

pub(crate) fn decode_done(v: &[u8], rank: i32) -> Result<WorkerStats, ServiceError> {
    if v.len() != DONE_LEN {
        return Err(malformed("DONE", rank));
    }
    let u64_at = |o: usize| {
        u64::from_le_bytes([
            v[o],
            v[o + 1],
            v[o + 2],
            v[o + 3],
            v[o + 4],
            v[o + 5],
            v[o + 6],
            v[o + 7],
        ])
    };
    Ok(WorkerStats {
        rank,
        rows: u64_at(0),
        busy_seconds: f64::from_bits(u64_at(8)),
        threads: u32::from_le_bytes([v[16], v[17], v[18], v[19]]),
        peak_rss: u64_at(20),
        pairs: PairRoutes::from_words(std::array::from_fn(|k| u64_at(28 + 8 * k))),
        links: {
            let at = 28 + 8 * 9;
            let rows = u64_at(at);
            let u32_at = |o: usize| u32::from_le_bytes([v[o], v[o + 1], v[o + 2], v[o + 3]]);
            LinkErrors {
                rows,
                sum: f64::from_bits(u64_at(at + 8)),
                max: (rows > 0).then(|| (u32_at(at + 16), f32::from_bits(u32_at(at + 20)))),
            }
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunk_message_round_trip_keeps_bytes_and_ids() {
        let chunk = EncodedChunk {
            row_ids: vec![7, 70_000, 3],
            skipped: vec![9],
            bytes: vec![1, 2, 3, 4, 5],
            raw_len: 1 << 40 | 1234,
        };
        let back = decode_chunk_message(encode_chunk_message(chunk.clone()), 1).unwrap();
        assert_eq!(back.row_ids, chunk.row_ids);
        assert_eq!(back.skipped, chunk.skipped);
        assert_eq!(back.bytes, chunk.bytes);
        assert_eq!(back.raw_len, 1 << 40 | 1234);
    }

    #[test]
    fn truncated_chunk_message_is_an_error_not_a_panic() {
        let msg = encode_chunk_message(EncodedChunk {
            row_ids: vec![1, 2],
            skipped: vec![],
            bytes: vec![9; 3],
            raw_len: 5,
        });
        for cut in 0..msg.len() {
            let _ = decode_chunk_message(msg[cut..].to_vec(), 2);
        }
        assert!(decode_chunk_message(vec![0; 5], 2).is_err());
        assert!(decode_chunk_message(vec![0xff; 40], 2).is_err());
    }

    #[test]
    fn assign_and_done_round_trip() {
        assert_eq!(decode_assign(&encode_assign(&[5, 6])).unwrap(), vec![5, 6]);
        assert_eq!(
            decode_assign(&encode_assign(&[])).unwrap(),
            Vec::<u32>::new()
        );
        assert!(decode_assign(&[3, 1]).is_err());
        assert_eq!(
            decode_rows(&encode_rows(&[1, 70_000]), 1).unwrap(),
            vec![1, 70_000]
        );
        assert!(decode_rows(&[1, 2, 3], 1).is_err());
        let s = WorkerStats {
            rank: 4,
            rows: 9,
            busy_seconds: 1.5,
            threads: 2,
            peak_rss: 77,
            pairs: PairRoutes {
                evaluated: 100,
                unoccludable: 60,
                exact: 30,
                fallback: 2,
                rays: 7,
                exact_visible: 11,
                exact_hidden: 5,
                exact_points: 1 << 40,
                exact_unmet: 3,
            },
            links: LinkErrors {
                rows: 8,
                sum: 0.25,
                max: Some((6, 0.125)),
            },
        };
        let d = decode_done(&encode_done(&s), 4).unwrap();
        assert_eq!(
            (
                d.rows,
                d.busy_seconds,
                d.threads,
                d.peak_rss,
                d.pairs,
                d.links
            ),
            (9, 1.5, 2, 77, s.pairs, s.links)
        );
        assert!(decode_done(&encode_done(&s)[..28], 4).is_err());
    }
}
