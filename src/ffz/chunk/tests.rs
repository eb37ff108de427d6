//! Tests of the chunk codec: rows of every kind round-trip (with and without the byte
//! shuffle, linked rows with their slopes and link error), and rows that do not fit the
//! file, or bad links, are refused.

use super::*;

/// The one row of a one-row chunk `bytes`, or the decoder's message.
fn decode_one(bytes: &[u8], n: u32, layout: Layout) -> Result<Row, String> {
    let (h, _) = check_record(bytes).unwrap();
    let d = decode_record(h, bytes, n, layout).map_err(|e| e.1)?;
    d.row(&d.entries()[0], n)
}

/// `row` comes back unchanged from a one-row chunk, shuffled or not.
fn assert_round_trips(row: &Row, n: u32, layout: Layout) {
    for shuffle in [false, true] {
        let enc = ChunkEncoding {
            zstd_level: 1,
            shuffle,
        };
        let c = encode_chunk_with(std::slice::from_ref(row), layout, n, enc).unwrap();
        assert_eq!(decode_one(&c.bytes, n, layout).unwrap(), *row);
    }
}

#[test]
fn shuffle_round_trips() {
    let w: Vec<u32> = (0..37).map(|i| i * 0x0102_0304 + 7).collect();
    for shuffle in [false, true] {
        let mut out = Vec::new();
        put_words(&mut out, w.iter().copied(), shuffle);
        assert_eq!(get_words(&out, shuffle), w);
    }
    let mut out = Vec::new();
    put_words(&mut out, [0x0403_0201u32, 0x0807_0605].into_iter(), true);
    assert_eq!(out, [1, 5, 2, 6, 3, 7, 4, 8]);
}

#[test]
fn chunk_round_trips_every_row_kind() {
    let n = 5;
    let rows = vec![
        Row {
            index: 3,
            values: RowValues::Sparse {
                cols: vec![0, 2, 4],
                vals: vec![0.5, 0.25, 1e-30],
            },
            dropped: 0.125,
            links: Vec::new(),
            link_error: None,
        },
        Row::skipped(1),
        Row {
            index: 0,
            values: RowValues::Sparse {
                cols: vec![],
                vals: vec![],
            },
            dropped: 0.0,
            links: Vec::new(),
            link_error: None,
        },
    ];
    let layout = Layout::TopK { k: 3 };
    let c = encode_chunk(&rows, layout, n, 3).unwrap();
    assert_eq!(c.row_ids, vec![3, 1, 0]);
    assert_eq!(c.skipped, vec![1]);
    let (h, len) = check_record(&c.bytes).unwrap();
    assert_eq!(len as usize, c.bytes.len());
    let d = decode_record(h, &c.bytes, n, layout).unwrap();
    let back: Vec<Row> = d.entries().iter().map(|e| d.row(e, n).unwrap()).collect();
    assert_eq!(back, rows);
}

#[test]
fn encoder_rejects_rows_that_do_not_fit() {
    let dense = Layout::Dense;
    let topk = Layout::TopK { k: 2 };
    let sparse = |cols: Vec<u32>| Row {
        index: 0,
        values: RowValues::Sparse {
            vals: vec![1.0; cols.len()],
            cols,
        },
        dropped: 0.0,
        links: Vec::new(),
        link_error: None,
    };
    let cases: Vec<(Row, Layout)> = vec![
        (Row::dense(0, vec![1.0; 3]), dense),
        (Row::dense(9, vec![1.0; 4]), dense),
        (Row::dense(0, vec![1.0; 4]), topk),
        (sparse(vec![1]), dense),
        (sparse(vec![2, 1]), topk),
        (sparse(vec![1, 1]), topk),
        (sparse(vec![4]), topk),
        (sparse(vec![0, 1, 2]), topk),
        (
            Row {
                dropped: f32::NAN,
                links: Vec::new(),
                ..Row::skipped(0)
            },
            dense,
        ),
    ];
    for (row, layout) in cases {
        let e = encode_chunk(std::slice::from_ref(&row), layout, 4, 1);
        assert!(
            matches!(e, Err(FfzError::InvalidRow { .. })),
            "{row:?} accepted"
        );
    }
    let twice = [Row::skipped(1), Row::skipped(1)];
    assert!(matches!(
        encode_chunk(&twice, dense, 4, 1),
        Err(FfzError::InvalidRow { row: 1, .. })
    ));
}

/// Rows with links round-trip with their slopes, shuffled or not; a row written
/// before slopes (no SLOPES flag, 12 bytes a link, spec §5.7) reads with slopes of
/// zero; SLOPES without LINKS is refused.
#[test]
fn linked_rows_round_trip_with_slopes_and_read_without_them() {
    let (n, layout) = (8, Layout::TopK { k: 1 });
    let link = |start, len, value, slope| Link {
        start,
        len,
        value,
        slope,
    };
    let row = Row {
        index: 2,
        values: RowValues::Sparse {
            cols: vec![5],
            vals: vec![0.5],
        },
        dropped: 0.375,
        links: vec![
            link(0, 3, 0.25, [0.5, -0.25, 0.0]),
            link(4, 4, 0.125, [0.0, 0.0, 1.5]),
        ],
        link_error: None,
    };
    let decode = |bytes: &[u8]| decode_one(bytes, n, layout);
    assert_round_trips(&row, n, layout);
    let enc = ChunkEncoding {
        zstd_level: 1,
        shuffle: false,
    };
    let raw = encode_raw(std::slice::from_ref(&row), layout, n, false)
        .unwrap()
        .bytes;
    let flags = u32::from_le_bytes(raw[4..8].try_into().unwrap());
    assert_eq!(flags & spec::ROW_FLAG_SLOPES, spec::ROW_FLAG_SLOPES);
    let mut old = raw.clone();
    old.truncate(raw.len() - 3 * 4 * row.links.len());
    old[4..8].copy_from_slice(&(flags & !spec::ROW_FLAG_SLOPES).to_le_bytes());
    let mut want = row.clone();
    for l in &mut want.links {
        l.slope = [0.0; 3];
    }
    assert_eq!(decode(&record(&old, 1, enc).unwrap()).unwrap(), want);
    let mut bad = old;
    bad[4..8].copy_from_slice(&(spec::ROW_FLAG_SPARSE | spec::ROW_FLAG_SLOPES).to_le_bytes());
    let e = decode(&record(&bad, 1, enc).unwrap()).unwrap_err();
    assert!(e.contains("slopes"), "{e}");
}

/// A row's link error (spec §5.7, LINK_ERROR) round-trips, shuffled or not, after
/// its links; a row without one carries no flag and no bytes; the encoder refuses
/// one that is not finite and ≥ 0, or one without links, and the decoder a stored
/// one that is negative or NaN, or the flag on a row without links.
#[test]
fn a_link_error_round_trips_after_the_links_and_bad_ones_are_refused() {
    let (n, layout) = (8, Layout::TopK { k: 1 });
    let row = Row {
        index: 2,
        values: RowValues::Sparse {
            cols: vec![5],
            vals: vec![0.5],
        },
        dropped: 0.25,
        links: vec![Link {
            start: 0,
            len: 3,
            value: 0.25,
            slope: [0.5, 0.0, 0.0],
        }],
        link_error: Some(0.0625),
    };
    let decode = |bytes: &[u8]| decode_one(bytes, n, layout);
    assert_round_trips(&row, n, layout);
    let raw = |r: &Row| encode_raw(std::slice::from_ref(r), layout, n, false).map(|p| p.bytes);
    let with = raw(&row).unwrap();
    let without = raw(&Row {
        link_error: None,
        ..row.clone()
    })
    .unwrap();
    assert_eq!(with.len(), without.len() + 4);
    assert_eq!(&with[with.len() - 4..], &0.0625f32.to_le_bytes());
    let flags = |b: &[u8]| u32::from_le_bytes(b[4..8].try_into().unwrap());
    assert_eq!(
        flags(&with) & spec::ROW_FLAG_LINK_ERROR,
        spec::ROW_FLAG_LINK_ERROR
    );
    assert_eq!(flags(&without) & spec::ROW_FLAG_LINK_ERROR, 0);
    for bad in [f32::NAN, -1.0, f32::INFINITY] {
        let r = Row {
            link_error: Some(bad),
            ..row.clone()
        };
        assert!(raw(&r).is_err(), "{bad} accepted");
    }
    let unlinked = Row {
        links: Vec::new(),
        dropped: 0.0,
        ..row.clone()
    };
    assert!(
        raw(&unlinked).is_err(),
        "a link error without links accepted"
    );
    let enc = ChunkEncoding {
        zstd_level: 1,
        shuffle: false,
    };
    for bad in [-1.0f32, f32::NAN] {
        let mut b = with.clone();
        let at = b.len() - 4;
        b[at..].copy_from_slice(&bad.to_le_bytes());
        let e = decode(&record(&b, 1, enc).unwrap()).unwrap_err();
        assert!(e.contains("link error"), "{e}");
    }
    // The flag on a row without links: the chunk is refused.
    let mut b = raw(&Row {
        link_error: None,
        ..unlinked
    })
    .unwrap();
    let f = flags(&b) | spec::ROW_FLAG_LINK_ERROR;
    b[4..8].copy_from_slice(&f.to_le_bytes());
    let (h, _) = check_record(&record(&b, 1, enc).unwrap()).unwrap();
    assert!(decode_record(h, &record(&b, 1, enc).unwrap(), n, layout).is_err());
}
