//! What a file will take before it is written: the plan `compute` prints, and checks
//! against the free disk, before it subdivides the scene (issue: a 2-million-face OBJ
//! used to start a run whose dense file would have needed 16 TB).

use crate::ffz::{spec, Layout};

/// Slack for the header's variable part (method, parameters, creation line, group
/// names): far more than any real header holds beyond its patch table.
const HEADER_SLACK: u64 = 1 << 20;

/// The size of a complete file of `n` rows in `layout` before compression, with every
/// row present: header and patch table, row directories and values, chunk headers and
/// zstd's worst-case growth (a frame can exceed its input by 1/256 plus a few bytes when
/// nothing compresses), index and footer. zstd usually makes the file smaller (dense
/// rows of a closed room by 10-50 %, rows full of zeros by far more), so this is the
/// most the file can take, not what it will take. Saturates at `u64::MAX`.
pub fn file_bytes_bound(n: u64, layout: Layout, chunk_bytes: u64) -> u64 {
    let per_row = match layout {
        Layout::Dense => n.saturating_mul(4),
        Layout::TopK { k } => u64::from(k).min(n).saturating_mul(8),
    }
    .saturating_add(spec::ROW_DIR_ENTRY_LEN as u64);
    let rows = per_row.saturating_mul(n);
    let chunks = rows / chunk_bytes.max(1) + 1;
    let header = n
        .saturating_mul(spec::PATCH_RECORD_LEN as u64)
        .saturating_add(spec::HEADER_LEN as u64 + HEADER_SLACK);
    let index = chunks
        .saturating_add(n)
        .saturating_mul(8)
        .saturating_add(spec::INDEX_FIXED_LEN as u64);
    rows.saturating_add(rows / 256)
        .saturating_add(chunks.saturating_mul(spec::CHUNK_HEADER_LEN as u64 + 64))
        .saturating_add(header)
        .saturating_add(index)
        .saturating_add(spec::FOOTER_LEN as u64)
}

/// The most the spill file of a `--symmetric` run can hold (all half-row pieces, when
/// no block could be merged before the end): 8 bytes per stored entry of the n(n-1)/2
/// computed pairs and their mirrors, plus row directories. Blocks are merged as they
/// complete, so the spill usually holds a small part of this at any time.
pub fn spill_bytes_bound(n: u64) -> u64 {
    n.saturating_mul(n.saturating_sub(1))
        .saturating_mul(8)
        .saturating_add(n.saturating_mul(2 * spec::ROW_DIR_ENTRY_LEN as u64))
}

/// Bytes with a decimal unit (kB, MB, GB, TB, PB; 1 kB = 1000 B), 3 significant
/// digits: for plans and messages.
pub fn human_bytes(b: u64) -> String {
    let units = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1000.0 && u + 1 < units.len() {
        v /= 1000.0;
        u += 1;
    }
    match u {
        0 => format!("{b} B"),
        _ if v >= 100.0 => format!("{v:.0} {}", units[u]),
        _ if v >= 10.0 => format!("{v:.1} {}", units[u]),
        _ => format!("{v:.2} {}", units[u]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_grow_as_the_layout_says_and_saturate() {
        let d = file_bytes_bound(1000, Layout::Dense, 1 << 20);
        assert!(d > 4 * 1000 * 1000 && d < 4 * 1000 * 1000 * 103 / 100 + 2 * HEADER_SLACK);
        // Top-64 rows: 8 bytes per entry, far below dense once n is large (at n = 1000
        // the header's fixed slack still dominates).
        let k = file_bytes_bound(1000, Layout::TopK { k: 64 }, 1 << 20);
        assert!(k > 8 * 64 * 1000 && k < 8 * 64 * 1000 * 103 / 100 + 2 * HEADER_SLACK);
        let (d, k) = (
            file_bytes_bound(100_000, Layout::Dense, 1 << 20),
            file_bytes_bound(100_000, Layout::TopK { k: 64 }, 1 << 20),
        );
        assert!(k < d / 100, "{k} {d}");
        // k above n stores n entries per row at most.
        assert_eq!(
            file_bytes_bound(10, Layout::TopK { k: 1000 }, 1024),
            file_bytes_bound(10, Layout::TopK { k: 10 }, 1024)
        );
        assert_eq!(
            file_bytes_bound(u64::MAX / 2, Layout::Dense, 1024),
            u64::MAX
        );
        assert_eq!(spill_bytes_bound(1), 2 * spec::ROW_DIR_ENTRY_LEN as u64);
    }

    #[test]
    fn human_bytes_keeps_three_digits() {
        assert_eq!(human_bytes(999), "999 B");
        assert_eq!(human_bytes(1500), "1.50 kB");
        assert_eq!(human_bytes(16_000_000_000_000), "16.0 TB");
        assert_eq!(human_bytes(123_456_789), "123 MB");
    }
}
