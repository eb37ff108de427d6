//! `verify` (row sums, reciprocity with a known answer, block passes), `compare`, and
//! the CLI library functions `info`, `verify`, `export`.

use crate::ffz_common::*;
use ffstream::ffz::{compare, FfzReader, Layout, VerifyOptions};
use ffstream::report::tools;
use ffstream::rows::{Row, RowValues};

/// S_ij of [`reciprocal_rows`]: symmetric, 0 on the diagonal.
fn exchange(i: u32, j: u32) -> f64 {
    let (a, b) = (i.min(j) as f64, i.max(j) as f64);
    if i == j {
        0.0
    } else {
        1e-4 * (1.0 + ((a * 7.0 + b * 3.0) % 11.0))
    }
}

/// A dense matrix that is exactly reciprocal (A_i F_ij = A_j F_ji = S_ij, S symmetric)
/// except pair (2, 5), where F_25 is raised by 30 %: the reciprocity error is then
/// |1.3 S − S| / (1.3 S) = 0.3 / 1.3 for that pair and 0 (up to f32 rounding) elsewhere.
fn reciprocal_rows(n: u32, areas: &[f64]) -> Vec<Row> {
    let s = exchange;
    (0..n)
        .map(|i| {
            let v = (0..n)
                .map(|j| {
                    let f = s(i, j) / areas[i as usize];
                    (if (i, j) == (2, 5) { f * 1.3 } else { f }) as f32
                })
                .collect();
            Row::dense(i, v)
        })
        .collect()
}

#[test]
fn reciprocity_and_row_sums_have_the_known_values() {
    let n = 40;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.ffz");
    let m = meta(Layout::Dense, patches(n, 5));
    let areas: Vec<f64> = m.patches.patches.iter().map(|p| p.area).collect();
    let mut rows = reciprocal_rows(n, &areas);
    SplitMix64::new(3).shuffle(&mut rows);
    write(&path, &m, &rows, 2000);
    let rd = FfzReader::open(&path).unwrap();
    let want = 0.3 / 1.3;
    // One block, and blocks of 3 rows (14 blocks, 15 passes): the same answer.
    for block_bytes in [256 << 20, 3 * (64 + 4 * n as usize)] {
        let rep = rd.verify_with(VerifyOptions {
            block_bytes,
            reciprocity: true,
            // A synthetic reciprocal matrix, not form factors: its row sums are not
            // judged here.
            row_sum_tol: f64::INFINITY,
        });
        assert!(rep.ok());
        let rc = rep.reciprocity.unwrap();
        assert_eq!(
            rc.pairs,
            (n * (n - 1) / 2) as u64,
            "every off-diagonal pair once"
        );
        assert!(
            (rc.max_rel_error - want).abs() < 1e-6,
            "{} vs {want}",
            rc.max_rel_error
        );
        assert_eq!(rc.worst, Some((2, 5)));
        // Weighted: 0.3 S_25 over Σ_{i<j} S_ij with S_25 counted as 1.3 S_25.
        let total: f64 = (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| exchange(i, j)))
            .sum();
        let s25 = exchange(2, 5);
        let weighted = 0.3 * s25 / (total + 0.3 * s25);
        assert!(
            (rc.weighted_rel_error - weighted).abs() < 1e-6,
            "{} vs {weighted}",
            rc.weighted_rel_error
        );
        if block_bytes < 1 << 20 {
            assert_eq!(rc.passes, 15);
        }
        // Row sums: Σ_j F_ij in f64 of the stored f32 values.
        let sums: Vec<f64> = rows.iter().map(|r| r.true_sum()).collect();
        let min = sums.iter().cloned().fold(f64::INFINITY, f64::min);
        let max = sums.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        assert_eq!((rep.row_sum_min, rep.row_sum_max), (min, max));
    }
}

#[test]
fn sparse_reciprocity_uses_only_pairs_stored_both_ways() {
    let n = 4;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sp.ffz");
    let mut ps = patches(n, 6);
    for (i, p) in ps.patches.iter_mut().enumerate() {
        p.area = [1.0, 2.0, 4.0, 8.0][i];
    }
    let m = meta(Layout::TopK { k: 2 }, ps);
    let sp = |i, cols: Vec<u32>, vals: Vec<f32>| Row {
        index: i,
        values: RowValues::Sparse { cols, vals },
        dropped: 0.0,
        links: Vec::new(),
        link_error: None,
    };
    // A_0 F_01 = 0.4, A_1 F_10 = 2 · 0.25 = 0.5 → error 0.1 / 0.5 = 0.2.
    // F_03 = 0.1 but row 3 does not store column 0: not a stored pair.
    let rows = vec![
        sp(0, vec![1, 3], vec![0.4, 0.1]),
        sp(1, vec![0], vec![0.25]),
        sp(2, vec![3], vec![0.5]),
        sp(3, vec![2], vec![0.25]), // A_2 F_23 = 2 = A_3 F_32: exact
    ];
    write(&path, &m, &rows, 1);
    let rc = FfzReader::open(&path)
        .unwrap()
        .verify()
        .reciprocity
        .unwrap();
    assert_eq!(rc.pairs, 2);
    assert!(
        (rc.max_rel_error - 0.2).abs() < 1e-7,
        "{}",
        rc.max_rel_error
    );
    // Weighted: (0.1 + 0) / (0.5 + 2).
    assert!(
        (rc.weighted_rel_error - 0.04).abs() < 1e-7,
        "{}",
        rc.weighted_rel_error
    );
    assert_eq!(rc.worst, Some((0, 1)));
}

#[test]
fn compare_reports_identity_differences_and_rows_in_one_file() {
    let n = 30;
    let layout = Layout::TopK { k: 6 };
    let dir = tempfile::tempdir().unwrap();
    let m = meta(layout, patches(n, 7));
    let rows: Vec<Row> = (0..n).map(|i| row(4, i, n, layout)).collect();
    let a = dir.path().join("a.ffz");
    write(&a, &m, &rows, 100);
    // Same rows, other order and chunking: identical.
    let b = dir.path().join("b.ffz");
    let mut shuffled = rows.clone();
    SplitMix64::new(1).shuffle(&mut shuffled);
    write(&b, &m, &shuffled, 1 << 20);
    let (ra, rb) = (FfzReader::open(&a).unwrap(), FfzReader::open(&b).unwrap());
    let opts = VerifyOptions {
        block_bytes: 500, // several blocks
        reciprocity: false,
        ..VerifyOptions::default()
    };
    let c = compare(&ra, &rb, opts).unwrap();
    assert!(c.identical(), "{c:?}");
    assert_eq!(c.identical_rows, n as u64);
    // One value changed by 0.25, row 29 left out.
    let target = (0..n)
        .find(|&i| matches!(&rows[i as usize].values, RowValues::Sparse { cols, .. } if !cols.is_empty()))
        .unwrap();
    let mut changed = rows.clone();
    if let RowValues::Sparse { vals, .. } = &mut changed[target as usize].values {
        vals[0] += 0.25;
    }
    changed.pop();
    let d = dir.path().join("d.ffz");
    write(&d, &m, &changed, 100);
    let rd = FfzReader::open(&d).unwrap();
    let c = compare(&ra, &rd, opts).unwrap();
    assert!(!c.identical());
    assert_eq!((c.differing_rows, c.only_in_a, c.only_in_b), (1, 1, 0));
    assert_eq!(c.first_only_in_a, vec![29]);
    assert_eq!(c.worst_row, Some(target));
    assert!((c.max_abs_diff - 0.25).abs() < 1e-6, "{}", c.max_abs_diff);

    // tools::print_verify --against: true for the identical pair, false for the other.
    let mut out = Vec::new();
    assert!(tools::print_verify(&a, Some(&b), &mut out).unwrap());
    let text = String::from_utf8(out).unwrap();
    assert!(text.ends_with("OK\n"), "{text}");
    let mut out = Vec::new();
    assert!(!tools::print_verify(&a, Some(&d), &mut out).unwrap());
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.contains("FAIL: the files differ") && text.contains("only in the other 0"),
        "{text}"
    );
}

#[test]
fn info_verify_export_outputs() {
    let n = 12;
    let layout = Layout::Dense;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.ffz");
    let m = meta(layout, patches(n, 8));
    let rows: Vec<Row> = (0..n - 2).map(|i| row(6, i, n, layout)).collect();
    write(&path, &m, &rows, 200);

    let mut out = Vec::new();
    tools::info(&path, &mut out).unwrap();
    let info = String::from_utf8(out).unwrap();
    let skipped = rows
        .iter()
        .filter(|r| matches!(r.values, RowValues::Skipped))
        .count();
    for want in [
        "n:             12 patches in 3 groups".to_string(),
        "layout:        dense".to_string(),
        format!(
            "rows:          {} present, {skipped} skipped, 2 missing (of 12)",
            10 - skipped
        ),
        "index:         ok".to_string(),
        "compression:".to_string(),
        format!("dense f32 matrix would be {}", 12 * 12 * 4),
    ] {
        assert!(info.contains(&want), "info lacks {want:?}:\n{info}");
    }

    // Missing rows make verify fail and say so.
    let mut out = Vec::new();
    assert!(!tools::print_verify(&path, None, &mut out).unwrap());
    let text = String::from_utf8(out).unwrap();
    assert!(text.contains("FAIL: 2 rows missing"), "{text}");

    // Export: Matrix Market header, size line, 1-based entries equal to the rows.
    let mtx = dir.path().join("f.mtx");
    let csv = dir.path().join("p.csv");
    let txt = dir.path().join("f.txt");
    let all = tools::ExportTargets {
        matrix: Some(&mtx),
        sparse: Some(&txt),
        min_ff: 0.0,
        patches_csv: Some(&csv),
        npz: None,
        vtu: None,
    };
    tools::export(&path, all).unwrap();
    let text = std::fs::read_to_string(&mtx).unwrap();
    let mut lines = text
        .lines()
        .filter(|l| !l.starts_with('%') || l.starts_with("%%"));
    assert_eq!(
        lines.next(),
        Some("%%MatrixMarket matrix coordinate real general")
    );
    let mut want = Vec::new();
    for r in &rows {
        r.for_each_nonzero(|j, x| want.push((r.index + 1, j + 1, x.to_bits())));
    }
    assert_eq!(lines.next(), Some(format!("12 12 {}", want.len()).as_str()));
    let entries = |lines: &mut dyn Iterator<Item = &str>| {
        let mut got: Vec<(u32, u32, u32)> = lines
            .map(|l| {
                let t: Vec<&str> = l.split_whitespace().collect();
                assert_eq!(t.len(), 3, "{l}");
                (
                    t[0].parse().unwrap(),
                    t[1].parse().unwrap(),
                    t[2].parse::<f32>().unwrap().to_bits(),
                )
            })
            .collect();
        got.sort_unstable();
        got
    };
    want.sort_unstable();
    assert_eq!(entries(&mut lines), want);

    // Sparse text: `#` header lines, then the same entries; with --min-ff exactly
    // those at or above it.
    let sparse = std::fs::read_to_string(&txt).unwrap();
    assert!(
        sparse.starts_with("# ffstream form factors from "),
        "{sparse}"
    );
    assert!(sparse.contains("# n = 12; one line per entry: i j F_ij (1-based"));
    let body = |t: &str| {
        t.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(entries(&mut body(&sparse).lines()), want);
    let mut values: Vec<f32> = want.iter().map(|w| f32::from_bits(w.2)).collect();
    values.sort_by(f32::total_cmp);
    let eps = values[values.len() / 2];
    let above = tools::ExportTargets {
        sparse: Some(&txt),
        min_ff: eps,
        ..Default::default()
    };
    tools::export(&path, above).unwrap();
    let kept: Vec<_> = want
        .iter()
        .copied()
        .filter(|w| f32::from_bits(w.2) >= eps)
        .collect();
    assert!(!kept.is_empty() && kept.len() < want.len());
    let sparse = std::fs::read_to_string(&txt).unwrap();
    assert_eq!(entries(&mut body(&sparse).lines()), kept);
    let csv = std::fs::read_to_string(&csv).unwrap();
    let mut l = csv.lines();
    assert_eq!(
        l.next(),
        Some("patch,group,area,cx,cy,cz,nx,ny,nz,rho_r,rho_g,rho_b,e_r,e_g,e_b,row_sum,sky_view")
    );
    let first = l.next().unwrap();
    assert!(first.starts_with("0,floor,"), "{first}");
    let second = l.next().unwrap();
    assert!(
        second.starts_with("1,\"walls, and \"\"more\"\"\","),
        "{second}"
    );
    assert_eq!(csv.lines().count(), 13);
    // row_sum = stored + dropped of the row, sky_view = 1 - row_sum; empty where the
    // file has no row (missing or skipped).
    let mut table = ::csv::Reader::from_reader(csv.as_bytes());
    let mut seen = 0;
    for (i, rec) in table.records().enumerate() {
        let rec = rec.unwrap();
        let (sum, sky) = (&rec[15], &rec[16]);
        match rows.iter().find(|r| r.index as usize == i) {
            Some(r) if !matches!(r.values, RowValues::Skipped) => {
                let want = r.true_sum();
                assert_eq!(sum.parse::<f64>().unwrap(), want, "row {i}");
                assert_eq!(sky.parse::<f64>().unwrap(), 1.0 - want, "row {i}");
                seen += 1;
            }
            _ => assert_eq!((sum, sky), ("", ""), "row {i} has no sum"),
        }
    }
    assert_eq!(seen, 10 - skipped);
}

#[test]
fn verify_fails_on_a_cut_file_and_names_the_recovery() {
    let n = 10;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.ffz");
    let m = meta(Layout::Dense, patches(n, 2));
    let rows: Vec<Row> = (0..n).map(|i| row(2, i, n, Layout::Dense)).collect();
    write(&path, &m, &rows, 100);
    let b = std::fs::read(&path).unwrap();
    std::fs::write(&path, &b[..b.len() - 40]).unwrap(); // footer and part of the index
    let mut out = Vec::new();
    assert!(!tools::print_verify(&path, None, &mut out).unwrap());
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.contains("FAIL:") && text.contains("recovered 5 chunks") && text.contains("0 missing"),
        "{text}"
    );
    // The rows themselves are all there and exact.
    let rd = FfzReader::open(&path).unwrap();
    assert_eq!(
        check_against(&rd, &|i| row(2, i, n, Layout::Dense)),
        n as u64
    );
}
