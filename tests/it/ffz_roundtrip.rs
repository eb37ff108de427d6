//! Round trips: random dense and sparse matrices written with rows in shuffled order
//! read back bitwise equal, by random access and by scan.

use crate::ffz_common::*;
use ffstream::ffz::{
    encode_chunk, FfzError, FfzReader, FfzWriter, Layout, RowState, WriterOptions,
};
use ffstream::rows::{Row, RowValues};

fn round_trip(n: u32, layout: Layout, seed: u64, chunk_bytes: usize) -> FfzReader {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ffz");
    let m = meta(layout, patches(n, seed));
    let mut ids: Vec<u32> = (0..n).collect();
    SplitMix64::new(seed).shuffle(&mut ids);
    let rows: Vec<Row> = ids.iter().map(|&i| row(seed, i, n, layout)).collect();
    write(&path, &m, &rows, chunk_bytes);
    let rd = FfzReader::open(&path).unwrap();
    assert!(rd.warnings().is_empty(), "{:?}", rd.warnings());
    assert_eq!(rd.meta(), &m, "meta block round trip");
    let held = check_against(&rd, &|i| row(seed, i, n, layout));
    assert_eq!(held, n as u64);
    let skipped = (0..n)
        .filter(|&i| matches!(row(seed, i, n, layout).values, RowValues::Skipped))
        .count();
    assert_eq!(rd.presence().skipped_count(), skipped as u64);
    assert!(rd.presence().is_complete());
    let rep = rd.verify();
    assert!(rep.ok(), "{rep:?}");
    // The tempdir goes away but the map keeps the data alive (unlinked file).
    rd
}

#[test]
fn dense_random_shuffled() {
    for (n, chunk) in [(1, 1), (2, 64), (37, 1000), (300, 64 << 10)] {
        let rd = round_trip(n, Layout::Dense, 0xD15E + n as u64, chunk);
        if n > 2 && chunk < 4 * n as usize * 4 {
            assert!(rd.chunk_count() > 1, "n = {n}: expected several chunks");
        }
    }
}

#[test]
fn sparse_random_shuffled() {
    for (n, k, chunk) in [(1, 1, 1), (2, 5, 64), (50, 7, 500), (400, 40, 16 << 10)] {
        round_trip(n, Layout::TopK { k }, 0x5BA5E + n as u64, chunk);
    }
}

#[test]
fn sparse_100k_rows() {
    let rd = round_trip(100_000, Layout::TopK { k: 8 }, 77, 1 << 20);
    assert!(rd.chunk_count() > 3);
}

#[test]
fn empty_rows_and_n_one() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("e.ffz");
    let m = meta(Layout::TopK { k: 3 }, patches(4, 1));
    let rows = vec![
        Row {
            index: 2,
            values: RowValues::Sparse {
                cols: vec![],
                vals: vec![],
            },
            dropped: 0.0,
            links: Vec::new(),
            link_error: None,
        },
        Row {
            index: 0,
            values: RowValues::Sparse {
                cols: vec![3],
                vals: vec![0.5],
            },
            dropped: 0.25,
            links: Vec::new(),
            link_error: None,
        },
    ];
    write(&p, &m, &rows, 1);
    let rd = FfzReader::open(&p).unwrap();
    assert_eq!(rd.row(2).unwrap(), Some(rows[0].clone()));
    assert_eq!(rd.row(0).unwrap(), Some(rows[1].clone()));
    assert_eq!(rd.row(1).unwrap(), None);
    assert_eq!(rd.presence().missing(), vec![1, 3]);
    // true row sum = stored + dropped (spec §5.6)
    assert_eq!(rd.row(0).unwrap().unwrap().true_sum(), 0.75);
    assert!(matches!(
        rd.row(4),
        Err(FfzError::RowOutOfRange { row: 4, .. })
    ));
    let rep = rd.verify();
    assert_eq!(rep.rows_missing, 2);
    assert!(!rep.ok(), "missing rows must fail verify");
}

#[test]
fn duplicate_rows_are_refused_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("d.ffz");
    let m = meta(Layout::Dense, patches(3, 2));
    let mut w = FfzWriter::create(&p, &m, WriterOptions::default()).unwrap();
    let c = encode_chunk(&[Row::dense(1, vec![0.0, 0.0, 0.5])], Layout::Dense, 3, 1).unwrap();
    w.append_chunk(c.clone()).unwrap();
    let e = w.append_chunk(c).unwrap_err();
    assert!(
        matches!(
            e,
            FfzError::DuplicateRow {
                row: 1,
                chunk: 0,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string().contains("row 1") && e.to_string().contains("d.ffz"),
        "{e}"
    );
    let e = w.push_row(Row::dense(1, vec![0.0; 3])).unwrap_err();
    assert!(matches!(e, FfzError::DuplicateRow { row: 1, .. }), "{e}");
    w.push_row(Row::dense(2, vec![0.0; 3])).unwrap();
    let e = w.push_row(Row::dense(2, vec![0.0; 3])).unwrap_err();
    assert!(matches!(e, FfzError::DuplicateRow { row: 2, .. }), "{e}");
    let c = encode_chunk(&[Row::skipped(2)], Layout::Dense, 3, 1).unwrap();
    assert!(matches!(
        w.append_chunk(c),
        Err(FfzError::DuplicateRow { row: 2, .. })
    ));
    let st = w.finish().unwrap();
    assert_eq!((st.rows, st.chunks), (2, 2));
    let rd = FfzReader::open(&p).unwrap();
    assert_eq!(rd.presence().get(0), RowState::Missing);
}

#[test]
fn append_chunk_checks_the_record() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("b.ffz");
    let m = meta(Layout::Dense, patches(2, 3));
    let mut w = FfzWriter::create(&p, &m, WriterOptions::default()).unwrap();
    let good = encode_chunk(&[Row::dense(0, vec![0.0, 0.5])], Layout::Dense, 2, 1).unwrap();
    let mut torn = good.clone();
    torn.bytes.pop();
    assert!(matches!(
        w.append_chunk(torn),
        Err(FfzError::BadEncodedChunk { .. })
    ));
    let mut flipped = good.clone();
    let last = flipped.bytes.len() - 1;
    flipped.bytes[last] ^= 1;
    assert!(matches!(
        w.append_chunk(flipped),
        Err(FfzError::BadEncodedChunk { .. })
    ));
    let mut lying = good.clone();
    lying.row_ids = vec![1];
    lying.skipped = vec![0];
    assert!(w.append_chunk(lying).is_err());
    w.append_chunk(good).unwrap();
    w.finish().unwrap();
}

#[test]
fn resume_refuses_another_problem() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("r.ffz");
    let m = meta(Layout::Dense, patches(5, 4));
    write(&p, &m, &[row(1, 0, 5, Layout::Dense)], 1 << 20);
    let mut other = m.clone();
    other.scene_hash ^= 1;
    let e = FfzWriter::resume(&p, &other, WriterOptions::default())
        .err()
        .unwrap();
    assert!(matches!(e, FfzError::ResumeMismatch { .. }), "{e}");
    assert!(e.to_string().contains("scene hash"), "{e}");
    let mut other = m.clone();
    other.layout = Layout::TopK { k: 2 };
    let e = FfzWriter::resume(&p, &other, WriterOptions::default())
        .err()
        .unwrap();
    assert!(e.to_string().contains("layout"), "{e}");
    // Same claimed scene hash but a different n.
    let mut other = meta(Layout::Dense, patches(6, 4));
    other.scene_hash = m.scene_hash;
    let e = FfzWriter::resume(&p, &other, WriterOptions::default())
        .err()
        .unwrap();
    assert!(e.to_string().contains("n = 5"), "{e}");
    // The same problem resumes: the finished file's rows are kept, the rest added.
    let (mut w, pres) = FfzWriter::resume(&p, &m, WriterOptions::default()).unwrap();
    assert_eq!(pres.missing(), vec![1, 2, 3, 4]);
    for i in pres.missing() {
        w.push_row(row(1, i, 5, Layout::Dense)).unwrap();
    }
    w.finish().unwrap();
    let rd = FfzReader::open(&p).unwrap();
    assert!(rd.warnings().is_empty());
    assert_eq!(check_against(&rd, &|i| row(1, i, 5, Layout::Dense)), 5);
}
