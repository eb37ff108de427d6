//! Damage sweeps: every byte flipped in turn, and the file cut at every length, is
//! detected (an error naming the place, or rows recovered with the rest missing) and
//! never yields a wrong number or a panic. Also `resume` after every cut.

use crate::ffz_common::*;
use ffstream::ffz::{FfzError, FfzReader, FfzWriter, Layout, WriterOptions};
use ffstream::rows::Row;

fn small_file(
    dir: &std::path::Path,
    layout: Layout,
) -> (std::path::PathBuf, ffstream::ffz::FileMeta) {
    let n = 3;
    let path = dir.join("small.ffz");
    let m = meta(layout, patches(n, 9));
    let rows: Vec<Row> = [2, 0, 1].iter().map(|&i| row(5, i, n, layout)).collect();
    write(&path, &m, &rows, 1); // one row per chunk
    (path, m)
}

/// What a damaged file may do: fail to open with a header error, or open and hand out
/// only exact rows or errors naming a chunk. Returns true when the damage was noticed
/// (open error, warning, or a verify failure).
fn check_damaged(path: &std::path::Path, layout: Layout, what: &str) -> bool {
    let n = 3;
    let rd = match FfzReader::open(path) {
        Err(e) => {
            let msg = e.to_string();
            assert!(
                matches!(
                    e,
                    FfzError::Header { .. } | FfzError::NotFfz { .. } | FfzError::Version { .. }
                ),
                "{what}: unexpected open error {msg}"
            );
            assert!(
                msg.contains("small.ffz")
                    && (msg.contains("byte") || msg.contains("magic") || msg.contains("version")),
                "{what}: {msg}"
            );
            return true;
        }
        Ok(r) => r,
    };
    for i in 0..n {
        match rd.row(i) {
            Ok(Some(r)) => assert!(same(&r, &row(5, i, n, layout)), "{what}: row {i} is wrong"),
            Ok(None) => {}
            Err(e) => {
                let msg = e.to_string();
                assert!(
                    msg.contains("chunk") && msg.contains("byte"),
                    "{what}: {msg}"
                );
            }
        }
    }
    let _ = rd.scan(|r| {
        assert!(
            same(r, &row(5, r.index, n, layout)),
            "{what}: scan row {} is wrong",
            r.index
        )
    });
    let rep = rd.verify();
    for b in &rep.bad_chunks {
        assert!(!b.what.is_empty());
    }
    !rep.ok()
}

#[test]
fn every_byte_flipped_is_detected() {
    for layout in [Layout::Dense, Layout::TopK { k: 2 }] {
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = small_file(dir.path(), layout);
        let good = std::fs::read(&path).unwrap();
        assert!(
            !check_damaged(&path, layout, "intact"),
            "intact file reported damaged"
        );
        let bad = dir.path().join("small.ffz");
        for pos in 0..good.len() {
            let mut b = good.clone();
            b[pos] ^= 0xFF;
            std::fs::write(&bad, &b).unwrap();
            let noticed = check_damaged(&bad, layout, &format!("flip at {pos}"));
            assert!(
                noticed,
                "{layout}: flipping byte {pos} of {} went unnoticed",
                good.len()
            );
        }
    }
}

#[test]
fn every_cut_is_detected_and_keeps_complete_chunks() {
    for layout in [Layout::Dense, Layout::TopK { k: 2 }] {
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = small_file(dir.path(), layout);
        let good = std::fs::read(&path).unwrap();
        let rd = FfzReader::open(&path).unwrap();
        // Where each chunk ends, and its rows.
        let ends: Vec<(u64, u32)> = (0..rd.chunk_count() as u32)
            .map(|k| {
                let (_, len) = rd.chunk_record(k).unwrap();
                let row = (0..3).find(|&i| rd.chunk_of(i) == Some(k)).unwrap();
                (rd.chunk_offsets()[k as usize] + len, row)
            })
            .collect();
        drop(rd);
        for cut in 0..good.len() {
            std::fs::write(&path, &good[..cut]).unwrap();
            assert!(
                check_damaged(&path, layout, &format!("cut at {cut}")),
                "cut at {cut} unnoticed"
            );
            if let Ok(rd) = FfzReader::open(&path) {
                for &(end, r) in &ends {
                    let expect_present = end <= cut as u64;
                    assert_eq!(
                        rd.presence().get(r) != ffstream::ffz::RowState::Missing,
                        expect_present,
                        "cut at {cut}: row {r} (chunk ends {end})"
                    );
                }
            }
        }
    }
}

#[test]
fn resume_after_every_cut_completes_the_file() {
    let layout = Layout::TopK { k: 2 };
    let dir = tempfile::tempdir().unwrap();
    let (path, m) = small_file(dir.path(), layout);
    let good = std::fs::read(&path).unwrap();
    let meta_len = FfzReader::open(&path).unwrap().header().meta_len as usize;
    let opts = WriterOptions {
        fsync: false,
        ..Default::default()
    };
    for cut in 0..=good.len() {
        std::fs::write(&path, &good[..cut]).unwrap();
        let (mut w, presence) = match FfzWriter::resume(&path, &m, opts) {
            Ok(x) => x,
            Err(e) => {
                assert!(cut < meta_len, "cut at {cut}: resume failed: {e}");
                assert!(e.to_string().contains("small.ffz"), "{e}");
                continue;
            }
        };
        for i in presence.missing() {
            w.push_row(row(5, i, 3, layout)).unwrap();
        }
        w.finish().unwrap();
        let rd = FfzReader::open(&path).unwrap();
        assert!(
            rd.warnings().is_empty(),
            "cut at {cut}: {:?}",
            rd.warnings()
        );
        assert_eq!(
            check_against(&rd, &|i| row(5, i, 3, layout)),
            3,
            "cut at {cut}"
        );
        assert!(rd.verify().ok(), "cut at {cut}");
    }
}

#[test]
fn verify_lists_every_bad_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.ffz");
    let n = 40;
    let m = meta(Layout::Dense, patches(n, 3));
    let rows: Vec<Row> = (0..n).map(|i| row(8, i, n, Layout::Dense)).collect();
    write(&path, &m, &rows, 1); // 40 chunks
    let rd = FfzReader::open(&path).unwrap();
    let offs = rd.chunk_offsets().to_vec();
    drop(rd);
    let mut b = std::fs::read(&path).unwrap();
    for k in [3usize, 17, 29] {
        b[offs[k] as usize + 45] ^= 0x10; // inside the payload
    }
    std::fs::write(&path, &b).unwrap();
    let rd = FfzReader::open(&path).unwrap();
    let rep = rd.verify();
    let bad: Vec<u64> = rep.bad_chunks.iter().filter_map(|c| c.chunk).collect();
    assert_eq!(bad, vec![3, 17, 29]);
    for c in &rep.bad_chunks {
        assert!(
            c.what.contains(&format!("chunk {}", c.chunk.unwrap())) && c.what.contains("checksum"),
            "{}",
            c.what
        );
        assert_eq!(c.offset, offs[c.chunk.unwrap() as usize]);
    }
    // One row per chunk, written in order: chunk k holds row k.
    let expect = (0..n)
        .filter(|i| ![3, 17, 29].contains(i))
        .filter(|&i| {
            !matches!(
                row(8, i, n, Layout::Dense).values,
                ffstream::rows::RowValues::Skipped
            )
        })
        .count();
    assert_eq!(rep.rows_checked, expect as u64);
    let e = rd.scan(|_| {}).unwrap_err();
    assert!(e.to_string().contains("chunk 3 at byte"), "{e}");
}
