//! Half rows (`--symmetric`): each pair computed once, the rows assembled by
//! reciprocity equal the full rows, also from a partial run.

use super::*;

/// `RowEngine::half_row` (the compute side of `--symmetric`): rows assembled from
/// upper halves and mirrored entries are exactly reciprocal, evaluate half of the
/// pairs of the dense rows, keep the upper entries of the dense rows bitwise, and in
/// the closed unoccluded cube sum to 1 like the dense rows.
#[test]
fn half_rows_assemble_reciprocal_rows_with_half_the_pairs() {
    let b = cube(4, false);
    let e = b.engine(FormFactorConfig::accurate());
    let n = e.n();
    let mut s = Scratch::new();
    let full = assemble_half_rows(&e, &vec![true; n], &mut s);
    let half = s.counters();
    let mut d = Scratch::new();
    let mut row = Vec::new();
    for (i, full_row) in full.iter().enumerate() {
        e.row_values(i as u32, &mut d, &mut row);
        for j in i + 1..n {
            assert_eq!(full_row[j], row[j], "upper entry ({i}, {j})");
        }
        let sum: f64 = full_row.iter().sum();
        let dense: f64 = row.iter().sum();
        assert!((sum - 1.0).abs() < TARGET, "row {i}: {sum}");
        assert!((sum - dense).abs() < 1e-7, "row {i}: {sum} vs {dense}");
    }
    let dense = d.counters();
    assert_eq!(2 * half.pairs_evaluated, dense.pairs_evaluated);
    let area = |k: usize| b.patches.patches[k].area;
    for (i, full_row) in full.iter().enumerate() {
        for (j, &fij) in full_row.iter().enumerate() {
            let (a, c) = (area(i) * fij, area(j) * full[j][i]);
            assert!((a - c).abs() <= 1e-15 * a.max(c), "({i}, {j}): {a} vs {c}");
        }
    }
}

/// Rows assembled from `RowEngine::half_row` over the rows with `in_run[i]` (others
/// stay 0): row i gets its own entries and the mirrored entries of the rows before it.
fn assemble_half_rows(e: &RowEngine, in_run: &[bool], s: &mut Scratch) -> Vec<Vec<f64>> {
    let n = e.n();
    let mut full = vec![vec![0.0f64; n]; n];
    let (mut own, mut mirrored) = (Vec::new(), Vec::new());
    for i in (0..n as u32).filter(|&i| in_run[i as usize]) {
        e.half_row(i, in_run, s, &mut own, &mut mirrored);
        for &(j, f) in &own {
            full[i as usize][j as usize] = f;
        }
        for &(j, f) in &mirrored {
            assert!(j > i && in_run[j as usize], "mirrored entry ({j}, {i})");
            full[j as usize][i as usize] = f;
        }
    }
    full
}

/// A run that computes only some rows (a resume, or `--rows needed`) gives those rows
/// bitwise equal to a run that computes all of them: a pair's value never depends on
/// which of its rows are in the run. And it evaluates every pair it needs once.
#[test]
fn half_rows_of_a_partial_run_equal_those_of_a_full_run() {
    // A blocker inside, so that visibility rays (seeded by the pair) matter.
    let mut b = cube(4, true);
    let (lo, s) = (dvec3(0.3, 0.3, 0.3), 0.4);
    let (x, y, z) = (dvec3(s, 0.0, 0.0), dvec3(0.0, s, 0.0), dvec3(0.0, 0.0, s));
    b.blocker(lo, y, x);
    b.blocker(lo + z, x, y);
    let e = b.engine(FormFactorConfig::accurate());
    let n = e.n();
    let all = assemble_half_rows(&e, &vec![true; n], &mut Scratch::new());
    let in_run: Vec<bool> = (0..n).map(|i| i % 3 != 1 && i % 7 != 0).collect();
    let mut s = Scratch::new();
    let part = assemble_half_rows(&e, &in_run, &mut s);
    let mut needed = 0u64;
    for i in 0..n {
        if in_run[i] {
            assert_eq!(part[i], all[i], "row {i}");
            assert!(part[i].iter().any(|&f| f > 0.0), "row {i} is empty");
        } else {
            assert!(
                part[i].iter().all(|&f| f == 0.0),
                "row {i} is not in the run"
            );
        }
        for j in 0..n {
            // Pairs with at least one row in the run, counted once each.
            if j > i && (in_run[i] || in_run[j]) && all[i][j] > 0.0 {
                needed += 1;
            }
        }
    }
    let c = s.counters();
    assert!(
        c.pairs_evaluated >= needed,
        "{} < {needed}",
        c.pairs_evaluated
    );
    let pairs_with_a_row_in_run = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter(|&(i, j)| in_run[i] || in_run[j])
        .count() as u64;
    assert!(c.pairs_evaluated <= pairs_with_a_row_in_run);
}
