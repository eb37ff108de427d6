//! Helpers shared by the `ffz_*` tests: a seeded generator, random patch sets and
//! random rows (deterministic in (seed, row), so a child process and its parent agree).

use ffstream::ffz::{FfzReader, FfzWriter, FileMeta, Layout, RowState, WriterOptions};
use ffstream::patch::{Patch, PatchSet};
use ffstream::rows::{Row, RowValues};
use glam::DVec3;
use std::path::Path;

/// The project's seeded generator, for test data.
pub(crate) use ffstream::formfactor::sampling::SplitMix64;

/// n random patches in 3 groups.
pub(crate) fn patches(n: u32, seed: u64) -> PatchSet {
    let mut r = SplitMix64::new(seed);
    let mut ps = Vec::with_capacity(n as usize);
    for i in 0..n {
        let o = DVec3::new(
            r.next_f32() as f64,
            r.next_f32() as f64,
            r.next_f32() as f64,
        );
        let quad = r.below(2) == 0;
        let corners = [
            o,
            o + DVec3::X * 0.1,
            o + DVec3::new(0.1, 0.1, 0.0),
            if quad {
                o + DVec3::Y * 0.1
            } else {
                DVec3::ZERO
            },
        ];
        ps.push(Patch {
            corners,
            n_corners: if quad { 4 } else { 3 },
            normal: DVec3::Z,
            area: if quad { 0.01 } else { 0.005 } + r.next_f32() as f64 * 1e-3,
            group: i % 3,
            face: i / 2,
            rho: [r.next_f32() * 0.9, 0.5, 0.25],
            emission: [if i == 0 { 10.0 } else { 0.0 }, 0.0, 1.5],
        });
    }
    PatchSet {
        patches: ps,
        groups: vec!["floor".into(), "walls, and \"more\"".into(), "light".into()],
    }
}

pub(crate) fn meta(layout: Layout, patches: PatchSet) -> FileMeta {
    FileMeta {
        layout,
        method: "mc".into(),
        params: "samples=4 seed=1".into(),
        scene_hash: patches.content_hash(),
        created: "test".into(),
        patches,
        clusters: None,
    }
}

/// Row i of a random matrix, deterministic in (seed, i): about 1 row in 11 skipped,
/// 1 in 13 empty (sparse) or all-zero (dense), the rest with random values, each below
/// 1 / n (dense) or 0.9 / min(k, n) (sparse) so a row sums below 1 as form factors do.
pub(crate) fn row(seed: u64, i: u32, n: u32, layout: Layout) -> Row {
    let mut r = SplitMix64::new(seed ^ (i as u64).wrapping_mul(0x2545_F491_4F6C_DD1D));
    if r.below(11) == 0 {
        return Row::skipped(i);
    }
    let empty = r.below(13) == 0;
    match layout {
        Layout::Dense => {
            let v = (0..n)
                .map(|j| {
                    if empty || j == i || r.below(4) == 0 {
                        0.0
                    } else {
                        r.next_f32() / n as f32
                    }
                })
                .collect();
            Row::dense(i, v)
        }
        Layout::TopK { k } => {
            let want = if empty {
                0
            } else {
                r.below(k.min(n) as usize + 1)
            };
            let mut cols: Vec<u32> = Vec::with_capacity(want);
            // Random distinct columns: sample, then sort and dedupe.
            for _ in 0..want {
                cols.push(r.below(n as usize) as u32);
            }
            cols.sort_unstable();
            cols.dedup();
            let top = 0.9 / k.min(n).max(1) as f32;
            let vals = cols.iter().map(|_| r.next_f32() * top).collect();
            Row {
                index: i,
                values: RowValues::Sparse { cols, vals },
                dropped: if empty { 0.0 } else { r.next_f32() * 1e-3 },
                links: Vec::new(),
                link_error: None,
            }
        }
    }
}

/// Write rows `ids` (in that order) with `push_row`, then finish.
pub(crate) fn write(path: &Path, meta: &FileMeta, rows: &[Row], chunk_bytes: usize) {
    let opts = WriterOptions {
        chunk_bytes,
        fsync: false,
        ..Default::default()
    };
    let mut w = FfzWriter::create(path, meta, opts).unwrap();
    for r in rows {
        w.push_row(r.clone()).unwrap();
    }
    w.finish().unwrap();
}

/// Bitwise equality of two rows (NaN-safe, distinguishes -0.0).
pub(crate) fn same(a: &Row, b: &Row) -> bool {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    a.index == b.index
        && a.dropped.to_bits() == b.dropped.to_bits()
        && match (&a.values, &b.values) {
            (RowValues::Dense(x), RowValues::Dense(y)) => bits(x) == bits(y),
            (
                RowValues::Sparse { cols: c1, vals: v1 },
                RowValues::Sparse { cols: c2, vals: v2 },
            ) => c1 == c2 && bits(v1) == bits(v2),
            (RowValues::Skipped, RowValues::Skipped) => true,
            _ => false,
        }
}

/// Check that every row the reader returns is bitwise the expected one, and that the
/// rows it lacks are exactly those reported missing. Returns the number of rows held.
pub(crate) fn check_against(rd: &FfzReader, expect: &dyn Fn(u32) -> Row) -> u64 {
    let mut held = 0;
    // Random access in row order on a shuffled file decodes one chunk per row: sample
    // the rows of a big file (the scan below checks all of them).
    let step = if rd.n() > 5000 { 97 } else { 1 };
    for i in (0..rd.n()).step_by(step) {
        match rd.row(i).unwrap() {
            Some(got) => {
                held += 1;
                assert!(same(&got, &expect(i)), "row {i} differs");
                assert_ne!(rd.presence().get(i), RowState::Missing);
            }
            None => assert_eq!(rd.presence().get(i), RowState::Missing),
        }
    }
    let mut scanned = 0;
    rd.scan(|r| {
        scanned += 1;
        assert!(same(r, &expect(r.index)), "scan row {} differs", r.index);
    })
    .unwrap();
    if step == 1 {
        assert_eq!(scanned, held);
    }
    let p = rd.presence();
    assert_eq!(scanned, p.present_count() + p.skipped_count());
    scanned
}
