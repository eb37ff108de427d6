//! Top-k rows: the K largest entries kept with the row sum preserved (kept plus
//! dropped mass), with the exact or the sampled tail, from few hemisphere rays, under
//! a box, and with occluders equal to the K largest of the dense row.

use ffstream::formfactor::TopKTail;

use super::*;

#[test]
fn top_k_keeps_largest_and_preserves_row_sum() {
    let b = cube(4, false);
    let dense = all_rows(&b.engine(FormFactorConfig::accurate()));
    let k = 10;
    let sparse = all_rows(&b.engine(FormFactorConfig::accurate().with_top_k(Some(k))));
    let n = b.n();
    for (d, s) in dense.iter().zip(&sparse) {
        let RowValues::Sparse { cols, vals } = &s.values else {
            panic!("expected sparse")
        };
        assert_eq!(cols.len(), k as usize);
        assert!(cols.windows(2).all(|w| w[0] < w[1]));
        let dv = d.to_dense(n);
        for (&c, &v) in cols.iter().zip(vals) {
            assert_eq!(v, dv[c as usize]);
        }
        let smallest_kept = vals.iter().cloned().fold(f32::INFINITY, f32::min);
        let largest_dropped = (0..n)
            .filter(|j| !cols.contains(&(*j as u32)))
            .map(|j| dv[j])
            .fold(0.0f32, f32::max);
        assert!(smallest_kept >= largest_dropped);
        assert!(
            (s.true_sum() - d.true_sum()).abs() < 1e-6,
            "row {}",
            s.index
        );
        assert!((s.true_sum() - 1.0).abs() < TARGET);
    }
}

#[test]
fn top_k_sampled_tail_keeps_the_same_entries_and_estimates_dropped_mass() {
    // Closed cube with an occluder-only box in the middle (not patches: light that
    // meets it reaches no patch, so rows sum to about 0.91); many pairs partly hidden.
    let mut b = cube(16, false);
    b.blocker_box(dvec3(0.35, 0.35, 0.35), 0.3);
    let k = 20;
    let t = 64;
    let base = FormFactorConfig::accurate().with_top_k(Some(k));
    let exact_cfg = FormFactorConfig {
        top_k_tail: TopKTail::Exact,
        ..base.clone()
    };
    let sampled_cfg = FormFactorConfig {
        top_k_tail: TopKTail::Sampled(t),
        ..base
    };
    let (exact_e, sampled_e) = (b.engine(exact_cfg), b.engine(sampled_cfg));
    let (mut se, mut ss) = (Scratch::new(), Scratch::new());
    let (mut sum_diff, mut sum_dropped, mut worst) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..b.n() as u32 {
        let re = exact_e.compute_row(i, &mut se);
        let rs = sampled_e.compute_row(i, &mut ss);
        assert_eq!(re.values, rs.values, "row {i}: kept entries differ");
        let d = rs.dropped as f64 - re.dropped as f64;
        sum_diff += d;
        sum_dropped += re.dropped as f64;
        worst = worst.max(d.abs());
    }
    let (ce, cs) = (se.counters(), ss.counters());
    println!(
        "sampled tail ({t} hemisphere rays a row): mean dropped bias {:.2e} of dropped mass, worst row {worst:.2e}; shadow rays exact {} sampled {} (+{} hemisphere rays)",
        sum_diff / sum_dropped,
        ce.rays_cast,
        cs.rays_cast,
        cs.closure_rays
    );
    // The tree search's tail: the row total from hemisphere rays (the cube is the
    // patches' own scene), no shadow rays for the tail's pairs.
    assert!(cs.closure_rays > 0 && cs.rays_cast < ce.rays_cast);
    // Unbiased: the errors of 1,536 rows average out (measured 7.5e-4 of the dropped
    // mass)...
    assert!(
        (sum_diff / sum_dropped).abs() < 0.01,
        "bias {}",
        sum_diff / sum_dropped
    );
    // ... and no row is off by more than five standard errors of a proportion
    // estimated from t rays (√(1/4t) at most).
    assert!(worst < 5.0 * (0.25 / t as f64).sqrt(), "worst row {worst}");

    // Without occluders between any pair the tail is exact: identical rows.
    let c = cube(4, false);
    let cfg = FormFactorConfig::accurate().with_top_k(Some(10));
    let a = all_rows(&c.engine(FormFactorConfig {
        top_k_tail: TopKTail::Sampled(4),
        ..cfg.clone()
    }));
    let e = all_rows(&c.engine(cfg));
    assert_eq!(a, e);
}

/// In a closed scene every hemisphere ray meets a patch's front, so the tree search's
/// row totals are exactly 1 (f32 rounding) even from 4 rays a row: the dropped mass is
/// 1 − the kept entries, with none of the sampling error of its tail.
#[test]
fn top_k_rows_of_a_closed_scene_sum_to_one_from_few_hemisphere_rays() {
    let c = cube(12, false);
    let cfg = FormFactorConfig {
        top_k_tail: TopKTail::Sampled(4),
        ..FormFactorConfig::accurate().with_top_k(Some(10))
    };
    let e = c.engine(cfg);
    let mut s = Scratch::new();
    for i in 0..c.n() as u32 {
        let r = e.compute_row(i, &mut s);
        assert!(
            (r.true_sum() - 1.0).abs() < 1e-5,
            "row {i}: {}",
            r.true_sum()
        );
    }
    assert_eq!(s.counters().closure_rays, 4 * c.n() as u64);
}

#[test]
fn top_k_row_totals_of_patches_partly_under_a_box_are_their_uncovered_share() {
    // A closed unit room, floor 5 × 5 (cells of 0.2), with a bottomless box standing on
    // [0.27, 0.72] × [0.31, 0.68] × [0, 0.4]: the box's walls cross floor cells, off the
    // lines of any grid of start points. A point of the floor
    // beside the box sees the closed room (Σ_j F = 1), a point beneath it sees only
    // the inside of the box (backs of faces: 0), so a cell's row total is the share
    // of its area outside the footprint. The
    // hemisphere estimate cuts such a cell along the walls standing on it and samples
    // each part (engine/closure.rs): exact here. Without the cut, its 4 rays over the
    // whole cell leave errors of up to 0.25 (0.5 for 0.7075 measured).
    let (x, y, z) = (
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
        dvec3(0.0, 0.0, 1.0),
    );
    let mut b = Built::default();
    b.face("floor", DVec3::ZERO, x, y, 5, false);
    b.face("ceiling", z, y, x, 5, false);
    b.face("x0", DVec3::ZERO, y, z, 5, false);
    b.face("x1", x, z, y, 5, false);
    b.face("y0", DVec3::ZERO, z, x, 5, false);
    b.face("y1", y, x, z, 5, false);
    let (lo, hi) = (dvec3(0.27, 0.31, 0.0), dvec3(0.72, 0.68, 0.4));
    b.bottomless_box(lo, hi, 2);
    let cfg = FormFactorConfig {
        top_k_tail: TopKTail::Sampled(4),
        ..FormFactorConfig::accurate().with_top_k(Some(8))
    };
    let e = b.engine(cfg);
    let mut s = Scratch::new();
    let mut partial = 0;
    for (i, p) in b.patches.patches.iter().enumerate() {
        let c = p.corners();
        let (plo, phi) = (c[0].min(c[2]), c[0].max(c[2]));
        let overlap = |a: f64, b: f64, l: f64, h: f64| (b.min(h) - a.max(l)).max(0.0);
        let covered = match p.group {
            0 => overlap(plo.x, phi.x, lo.x, hi.x) * overlap(plo.y, phi.y, lo.y, hi.y) / p.area,
            _ => 0.0,
        };
        let want = 1.0 - covered;
        partial += (covered > 0.0 && covered < 1.0) as usize;
        let got = e.compute_row(i as u32, &mut s).true_sum();
        assert!(
            (got - want).abs() < 1e-6,
            "patch {i} (group {}): row total {got}, uncovered share {want}",
            p.group
        );
    }
    assert_eq!(partial, 8, "floor cells the box's walls cross");
}

/// Top-k with occluders, both tails: each kept entry equals the dense row's entry
/// bitwise (same (i, j)-seeded rays), the kept set is the K largest of the dense row
/// (ties aside: nothing dropped is larger than anything kept), and the true row sum
/// (kept + dropped) equals the dense row sum (exactly up to f32 rounding for the exact
/// tail; for the sampled tail, unbiased over the rows).
#[test]
fn top_k_with_occluders_equals_k_largest_of_dense_row() {
    let mut b = cube(6, false);
    b.blocker_box(dvec3(0.3, 0.3, 0.3), 0.4);
    let k = 24u32;
    let n = b.n();
    let dense = all_rows(&b.engine(FormFactorConfig::accurate()));
    for tail in [TopKTail::Exact, TopKTail::Sampled(16)] {
        let cfg = FormFactorConfig {
            top_k_tail: tail,
            ..FormFactorConfig::accurate().with_top_k(Some(k))
        };
        let e = b.engine(cfg);
        let mut scratch = Scratch::new();
        let (mut sum_diff, mut sum_true) = (0.0f64, 0.0f64);
        for d in &dense {
            let r = e.compute_row(d.index, &mut scratch);
            let RowValues::Sparse { cols, vals } = &r.values else {
                panic!("expected a sparse row")
            };
            let dv = d.to_dense(n);
            let nonzero = dv.iter().filter(|&&v| v > 0.0).count();
            assert_eq!(cols.len(), nonzero.min(k as usize), "row {}", d.index);
            for (&c, &v) in cols.iter().zip(vals) {
                assert_eq!(v, dv[c as usize], "{tail} row {} col {c}", d.index);
            }
            let smallest_kept = vals.iter().cloned().fold(f32::INFINITY, f32::min);
            let largest_dropped = (0..n)
                .filter(|j| cols.binary_search(&(*j as u32)).is_err())
                .map(|j| dv[j])
                .fold(0.0f32, f32::max);
            assert!(smallest_kept >= largest_dropped, "{tail} row {}", d.index);
            let diff = r.true_sum() - d.true_sum();
            if tail == TopKTail::Exact {
                assert!(diff.abs() < 1e-6, "row {}: {diff}", d.index);
            }
            sum_diff += diff;
            sum_true += d.true_sum();
        }
        let c = scratch.counters();
        println!(
            "top-{k} {tail}: mean row-sum deviation {:.2e}, rays cast {}, rays skipped {} ({:.1}% of budget), tail pairs skipped {}",
            sum_diff / dense.len() as f64,
            c.rays_cast,
            c.rays_skipped,
            100.0 * c.rays_skipped as f64 / (c.rays_cast + c.rays_skipped) as f64,
            c.pairs_topk_tail_skipped
        );
        // The sampled tail is unbiased: the mean deviation is far below one row's
        // tail mass.
        assert!((sum_diff / sum_true).abs() < 2e-3, "{tail}: {sum_diff}");
    }
}
