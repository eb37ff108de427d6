//! Stress, numerical stability of the form factors and the solve, against known answers
//! only (Howell's formulas, conservation, reciprocity, exact zeros):
//! - whole-scene scaling 1e-4 … 1e4 (Cornell box with occluders, a closed box);
//! - patches touching along an edge, at a vertex, coplanar neighbours, nearly touching
//!   (gap 1e-6 of their size), slivers (aspect 1e4), a tiny patch next to a huge one;
//! - f32 storage against the f64 values;
//! - closed scenes with ρ → 1 (0.9, 0.99, 0.999): convergence, energy balance
//!   Σ A_i B_i = Φ_E / (1 − ρ) within the bound the measured row sums and reciprocity
//!   allow, iteration counts, no NaN/Inf.
//!
//! Figures are printed (`cargo test --test it stress_numeric -- --nocapture`) and
//! collected in tests/README.md.

use std::path::Path;
use std::sync::Arc;

use ffstream::formfactor::{FormFactorConfig, RowEngine, Scratch};
use ffstream::geometry::occluders::Occluders;
use ffstream::geometry::subdivide::{default_max_edge, subdivide};
use ffstream::rows::{Row, RowValues};
use ffstream::scene::load_obj;
use ffstream::solve::{solve, MemoryRows, SolveConfig, SolveMethod};
use glam::{dvec3, DQuat, DVec3};

use crate::stress_geom::*;

fn cornell_engine(scale: f64, target: usize) -> RowEngine {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/cornell_box.obj");
    let scene = load_obj(&path).unwrap();
    let max_edge = default_max_edge(&scene, target);
    let scene = scene.scaled(scale);
    let patches = subdivide(&scene, max_edge * scale);
    RowEngine::new(
        &patches,
        Arc::new(Occluders::new(scene.triangles().collect())),
        FormFactorConfig::accurate(),
    )
}

/// (Largest |a − b| / max(a, b) over entries ≥ 1e-6, largest |a − b| over all.)
/// Entries below 1e-6 come from nearly coplanar patches (the measured Cornell walls are
/// not quite planar), where the double contour integral cancels to a few 1e-15
/// absolute; their relative change says nothing about the scaling.
fn changes(a: &[f64], b: &[f64]) -> (f64, f64) {
    assert_eq!(a.len(), b.len(), "patch count changed");
    let (mut rel, mut abs) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        abs = abs.max((x - y).abs());
        if x.max(*y) >= 1e-6 {
            rel = rel.max((x - y).abs() / x.max(*y));
        }
    }
    (rel, abs)
}

fn assert_sane(f: &[f64], what: &str) {
    for (k, v) in f.iter().enumerate() {
        assert!(v.is_finite() && *v >= 0.0, "{what}: entry {k} = {v}");
    }
}

/// Row sums and the worst reciprocity error max |A_i F_ij − A_j F_ji| / max(A_i F_ij, A_j F_ji).
fn sums_and_reciprocity(g: &Geo, f: &[f64]) -> (Vec<f64>, f64) {
    let n = g.n();
    let sums = (0..n).map(|i| f[i * n..(i + 1) * n].iter().sum()).collect();
    let mut worst = 0.0f64;
    for i in 0..n {
        for j in i + 1..n {
            let (x, y) = (g.area(i) * f[i * n + j], g.area(j) * f[j * n + i]);
            if x.max(y) > 0.0 {
                worst = worst.max((x - y).abs() / x.max(y));
            }
        }
    }
    (sums, worst)
}

#[test]
fn scaling_the_whole_scene_1e_minus4_to_1e4_changes_nothing() {
    // Cornell box (occluded: the blocks), ~150 patches.
    let reference = matrix(&cornell_engine(1.0, 150));
    assert_sane(&reference, "cornell");
    for s in [1e-4, 1e-3, 1e-2, 1e2, 1e4] {
        let f = matrix(&cornell_engine(s, 150));
        assert_sane(&f, &format!("cornell × {s:e}"));
        let (rel, abs) = changes(&reference, &f);
        println!("cornell box scaled by {s:e}: max relative change of F_ij ≥ 1e-6 {rel:.2e}, max absolute change {abs:.2e}");
        assert!(rel <= 1e-8 && abs <= 1e-13, "scale {s}: {rel} {abs}");
    }
    // The patch count chosen for --patches does not depend on the units either.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scenes/cornell_box.obj");
    let scene = load_obj(&path).unwrap();
    for target in [150, 500, 2000] {
        let counts: Vec<usize> = [1e-4, 1e-3, 1.0, 1e3, 1e4]
            .iter()
            .map(|&s| {
                let sc = scene.scaled(s);
                subdivide(&sc, default_max_edge(&sc, target)).len()
            })
            .collect();
        assert!(
            counts.iter().all(|&c| c == counts[0]),
            "target {target}: {counts:?}"
        );
    }
    // A closed, rotated, shifted box: row sums stay 1 at every scale.
    let base = Geo::closed_box(1.0, 2.0, 0.5, 3);
    let r = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
    for s in [1e-4, 1.0, 1e4] {
        let g = base.transformed(s, r, dvec3(3.0, -7.0, 11.0) * s);
        let f = matrix(&g.engine(FormFactorConfig::accurate()));
        assert_sane(&f, "box");
        let (sums, recip) = sums_and_reciprocity(&g, &f);
        let dev = sums.iter().map(|x| (x - 1.0).abs()).fold(0.0, f64::max);
        println!(
            "closed box scaled by {s:e}: max |row sum − 1| {dev:.2e}, reciprocity {recip:.2e}"
        );
        assert!(dev <= 1e-5, "scale {s}: row sum off by {dev}");
        assert!(recip <= 1e-6, "scale {s}: reciprocity {recip}");
    }
}

/// Perpendicular w × 1 (emitter, z = 0, facing +z) and 1 × h (receiver, y = `gap`,
/// facing +y) sharing the edge x ∈ [0, 1] when gap = 0 … or lifted by `lift` in z.
fn perpendicular(w: f64, h: f64, m: usize, lift: f64) -> Geo {
    let mut g = Geo::default();
    g.para(DVec3::ZERO, DVec3::X, DVec3::Y * w, m, m).para(
        DVec3::Z * lift,
        DVec3::Z * h,
        DVec3::X,
        m,
        m,
    );
    g
}

#[test]
fn touching_along_an_edge_at_a_vertex_and_nearly_touching() {
    let cfg = FormFactorConfig::accurate();
    // Along an edge: Howell C-14, one patch per face and cut 4 × 4.
    for m in [1, 4] {
        let g = perpendicular(1.0, 1.0, m, 0.0);
        let f = matrix(&g.engine(cfg.clone()));
        assert_sane(&f, "edge");
        let v = group_ff(&g, &f, 0, 1);
        let err = (v - howell_c14(1.0, 1.0)).abs();
        println!("shared edge, {m}×{m}: F = {v:.9}, error {err:.2e}");
        assert!(err < 1e-5, "edge m={m}: {v}");
    }
    // At a vertex: a 2 × 1 pair sharing a 2-long edge, cut in halves: the halves that
    // touch only at (1, 0, 0) have, by superposition and symmetry,
    // F = F_C14(l=2; W=H=0.5) − F_C14(l=1; W=H=1).
    let mut g = Geo::default();
    g.para(DVec3::ZERO, DVec3::X * 2.0, DVec3::Y, 2, 1).para(
        DVec3::ZERO,
        DVec3::Z,
        DVec3::X * 2.0,
        1,
        2,
    );
    // Patches: 0 = emitter x∈[0,1], 1 = emitter x∈[1,2]; 2 = receiver x∈[0,1], 3 = x∈[1,2].
    let f = matrix(&g.engine(cfg.clone()));
    assert_sane(&f, "vertex");
    let want = howell_c14(0.5, 0.5) - howell_c14(1.0, 1.0);
    for (i, j) in [(0, 3), (1, 2), (3, 0), (2, 1)] {
        let err = (f[i * 4 + j] - want).abs();
        println!(
            "touching at a vertex ({i},{j}): F = {:.9}, exact {want:.9}, error {err:.2e}",
            f[i * 4 + j]
        );
        assert!(err < 1e-5, "vertex ({i},{j})");
    }
    // Coplanar neighbours (sharing an edge, and overlapping in projection only along
    // it): exactly zero both ways.
    let mut g = Geo::default();
    g.para(DVec3::ZERO, DVec3::X, DVec3::Y, 3, 3)
        .para(DVec3::X, DVec3::X, DVec3::Y, 3, 3);
    let f = matrix(&g.engine(cfg.clone()));
    assert!(
        f.iter().all(|&v| v == 0.0),
        "coplanar patches see each other"
    );
    // Nearly touching: the receiver lifted off the shared edge by 1e-6 of its size. The
    // factor is continuous in the gap, so it must stay within the gap's effect
    // (≈ gap·|ln gap| ≈ 1.4e-5 here) of C-14, and reciprocity must hold.
    for m in [1, 3] {
        let g = perpendicular(1.0, 1.0, m, 1e-6);
        let f = matrix(&g.engine(cfg.clone()));
        assert_sane(&f, "gap");
        let v = group_ff(&g, &f, 0, 1);
        let (_, recip) = sums_and_reciprocity(&g, &f);
        let err = (v - howell_c14(1.0, 1.0)).abs();
        println!("gap 1e-6, {m}×{m}: F = {v:.9}, |F − C-14| {err:.2e}, reciprocity {recip:.2e}");
        assert!(err < 5e-5 && v < howell_c14(1.0, 1.0), "gap m={m}: {v}");
        assert!(recip < 1e-6, "gap m={m}: reciprocity {recip}");
    }
}

#[test]
fn slivers_of_aspect_1e4_and_a_tiny_patch_next_to_a_huge_one() {
    let cfg = FormFactorConfig::accurate();
    // Parallel opposed slivers 1 × 1e-4 at distance 1 (C-11, X = 1, Y = 1e-4), and the
    // same pair cut lengthwise into 4 slivers of 1 × 2.5e-5 each.
    for m in [1, 4] {
        let mut g = Geo::default();
        let (a, b) = (1.0, 1e-4);
        g.para(DVec3::ZERO, DVec3::X * a, DVec3::Y * b, 1, m).para(
            dvec3(0.0, 0.0, 1.0),
            DVec3::Y * b,
            DVec3::X * a,
            m,
            1,
        );
        let f = matrix(&g.engine(cfg.clone()));
        assert_sane(&f, "sliver");
        let v = group_ff(&g, &f, 0, 1);
        let exact = howell_c11(a, b);
        let rel = (v - exact).abs() / exact;
        println!("parallel slivers 1 × 1e-4 ({m} pieces): F = {v:.6e}, exact {exact:.6e}, relative error {rel:.2e}");
        assert!(rel < 1e-6, "sliver {m}: {v} vs {exact}");
    }
    // A sliver standing on the edge of a square (C-14 with W = 1, H = 1e-4) and the
    // other way round (W = 1e-4, H = 1): both ends of the aspect range.
    for (w, h) in [(1.0, 1e-4), (1e-4, 1.0)] {
        let g = perpendicular(w, h, 1, 0.0);
        let f = matrix(&g.engine(cfg.clone()));
        assert_sane(&f, "sliver edge");
        let v = f[1];
        let exact = howell_c14(w, h);
        let rel = (v - exact).abs() / exact;
        let (_, recip) = sums_and_reciprocity(&g, &f);
        println!("sliver sharing an edge W={w:e} H={h:e}: F = {v:.6e}, exact {exact:.6e}, relative error {rel:.2e}, reciprocity {recip:.2e}");
        assert!(rel < 1e-5, "W={w} H={h}: {v} vs {exact}");
        assert!(recip < 1e-6);
    }
    // Tiny next to huge: a square of side t at height 1 facing down over a 2e3 square
    // facing up, centred: F_tiny→huge = 4 · corner(1e3, 1e3), up to the tiny patch's
    // own extent (< 1e-8 here). Size ratio 2e5 meets the 1e-5 target; at 2e6 the double
    // contour integral loses digits to cancellation (terms ~ t·L·ln L cancel to t²):
    // a known limit, pinned at the error measured (README).
    for (t, tol) in [(1e-2, 1e-5), (1e-3, 1e-4)] {
        let mut g = Geo::default();
        let big = 2e3;
        g.para(
            dvec3(-t / 2.0, -t / 2.0, 1.0),
            DVec3::Y * t,
            DVec3::X * t,
            1,
            1,
        )
        .para(
            dvec3(-big / 2.0, -big / 2.0, 0.0),
            DVec3::X * big,
            DVec3::Y * big,
            1,
            1,
        );
        let f = matrix(&g.engine(cfg.clone()));
        assert_sane(&f, "tiny/huge");
        let exact = 4.0 * howell_point_to_corner_rectangle(big / 2.0, big / 2.0);
        let err = (f[1] - exact).abs();
        let recip = (g.area(0) * f[1] - g.area(1) * f[2]).abs() / (g.area(0) * f[1]);
        println!("tiny ({t:e}) over huge (2e3), ratio {:.0e}: F = {:.12}, exact {exact:.12}, error {err:.2e}; F back {:.3e}, reciprocity {recip:.2e}", big / t, f[1], f[2]);
        assert!(err < tol, "t={t}: {} vs {exact}", f[1]);
        assert!(
            f[2] > 0.0 && recip < 10.0 * tol,
            "t={t}: huge → tiny {}",
            f[2]
        );
    }
}

#[test]
fn f32_storage_stays_within_rounding_of_the_f64_values() {
    let e = cornell_engine(1.0, 300);
    let (mut s, mut v64) = (Scratch::new(), Vec::new());
    let (mut worst_rel, mut worst_sum) = (0.0f64, 0.0f64);
    for i in 0..e.n() as u32 {
        e.row_values(i, &mut s, &mut v64);
        let row = e.compute_row(i, &mut s);
        let RowValues::Dense(v32) = &row.values else {
            panic!("dense expected")
        };
        for (a, b) in v64.iter().zip(v32) {
            if *a != 0.0 {
                worst_rel = worst_rel.max((*b as f64 - a).abs() / a);
            } else {
                assert_eq!(*b, 0.0);
            }
        }
        let s64: f64 = v64.iter().sum();
        worst_sum = worst_sum.max((row.stored_sum() - s64).abs());
    }
    println!(
        "f32 vs f64 ({} rows): max relative entry error {worst_rel:.2e} (bound 2^-24 = {:.2e}), max row-sum difference {worst_sum:.2e}",
        e.n(),
        2f64.powi(-24)
    );
    // Round to nearest: at most half an ulp of the f32, 2^-24 relative.
    assert!(worst_rel <= 2f64.powi(-24) * (1.0 + 1e-12), "{worst_rel}");
    assert!(worst_sum <= e.n() as f64 * 2f64.powi(-24), "{worst_sum}");
}

/// Closed box, rows through f32 as stored; uniform ρ; one face (group 0) emits 1.
fn closed_system(rho: f32) -> (Geo, Vec<Row>) {
    let mut g = Geo::closed_box(1.0, 1.0, 1.0, 4);
    for p in &mut g.patches.patches {
        p.rho = [rho; 3];
        p.emission = if p.group == 0 { [1.0; 3] } else { [0.0; 3] };
    }
    let e = g.engine(FormFactorConfig::accurate());
    let mut s = Scratch::new();
    let rows = (0..g.n() as u32)
        .map(|i| e.compute_row(i, &mut s))
        .collect();
    (g, rows)
}

#[test]
fn closed_scene_with_rho_near_one_converges_and_conserves_energy() {
    for rho in [0.9f32, 0.99, 0.999] {
        let (g, rows) = closed_system(rho);
        let n = g.n();
        // What the stored rows allow: δ = max |row sum − 1| + max relative reciprocity
        // error; then Σ A B lies in Φ / (1 − ρ(1 ± δ)) (docs/known-answers.md §6 enclosure law,
        // with A_i F_ij = A_j F_ji (1 ± δ_r) and Σ_j F_ij = 1 ± δ_s).
        let f: Vec<f64> = rows
            .iter()
            .flat_map(|r| r.to_dense(n).into_iter().map(f64::from))
            .collect();
        let (sums, recip) = sums_and_reciprocity(&g, &f);
        let ds = sums.iter().map(|x| (x - 1.0).abs()).fold(0.0, f64::max);
        let delta = ds + recip + ds * recip;
        let phi: f64 = (0..n)
            .map(|i| g.area(i) * g.patches.patches[i].emission[0] as f64)
            .sum();
        let r = rho as f64;
        let src = MemoryRows::new(g.patches.clone(), rows).unwrap();
        let emission: Vec<[f32; 3]> = g.patches.patches.iter().map(|p| p.emission).collect();
        let refl: Vec<[f32; 3]> = g.patches.patches.iter().map(|p| p.rho).collect();
        for method in SolveMethod::ALL {
            let cfg = SolveConfig {
                method,
                tolerance: 1e-9,
                max_iterations: 200_000,
                ..SolveConfig::default()
            };
            let sol = solve(&src, std::slice::from_ref(&emission), &refl, &cfg).unwrap();
            assert!(
                sol.converged,
                "{method} ρ={rho}: not converged ({})",
                sol.residual
            );
            for (b, h) in sol.b[0].iter().zip(&sol.h[0]) {
                assert!(
                    b.iter().chain(h).all(|x| x.is_finite() && *x >= 0.0),
                    "{method} ρ={rho}: {b:?} {h:?}"
                );
            }
            let total: f64 = (0..n).map(|i| g.area(i) * sol.b[0][i][0]).sum();
            let law = phi / (1.0 - r);
            // The solve's own error: residual tolerance on B amplified by 1/(1 − ρ).
            let slack = 2.0 * cfg.tolerance / (1.0 - r);
            let (lo, hi) = (
                phi / (1.0 - r * (1.0 - delta)),
                phi / (1.0 - r * (1.0 + delta)),
            );
            let rel = (total - law).abs() / law;
            println!(
                "ρ = {rho}: {method}: {} iterations, Σ A B = {total:.6} vs Φ/(1−ρ) = {law:.6} (relative {rel:.2e}; rows allow [{:.2e}, {:.2e}], δ = {delta:.2e})",
                sol.iterations,
                lo / law - 1.0,
                hi / law - 1.0
            );
            assert!(
                total >= lo * (1.0 - slack) && total <= hi * (1.0 + slack),
                "{method} ρ={rho}: Σ A B = {total} outside [{lo}, {hi}]"
            );
        }
    }
}
