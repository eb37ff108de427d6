//! Stress, properties over random small scenes (proptest): closed boxes (rotated,
//! shifted, scaled 1e-2 … 1e2, optionally with a box standing inside as an occluder) and
//! open scenes of a few randomly oriented quads. For every matrix: F_ij finite and ≥ 0,
//! F_ii = 0, row sums = 1 ± 1e-5 in an empty closed box, ≤ 1 + 1e-5 in open scenes
//! (≤ 1 + sampling error where visibility is sampled), reciprocity
//! |A_i F_ij − A_j F_ji| small, and rows bitwise identical when computed in other orders
//! on other threads. 12 cases per property by default, 200 with FFSTREAM_STRESS_LONG=1.

use std::sync::Arc;

use ffstream::formfactor::{FormFactorConfig, RowEngine, Scratch, Visibility};
use ffstream::rows::Row;
use glam::{dvec3, DQuat, DVec3, EulerRot};
use proptest::prelude::*;

use crate::stress_geom::*;

fn cases() -> u32 {
    if std::env::var_os("FFSTREAM_STRESS_LONG").is_some() {
        200
    } else {
        12
    }
}

fn rotation(a: (f64, f64, f64)) -> DQuat {
    DQuat::from_euler(EulerRot::XYZ, a.0, a.1, a.2)
}

/// Row sums, and the worst reciprocity error relative to the larger side, over pairs
/// whose larger side is above `floor` (exact zeros and cancellation noise excluded).
/// Σ |A_i F_ij − A_j F_ji| / Σ max(A_i F_ij, A_j F_ji) over i < j: the share of the
/// exchanged flux that is not reciprocal (`ffstream verify`'s weighted error).
fn weighted_reciprocity(g: &Geo, f: &[f64]) -> f64 {
    let n = g.n();
    let (mut diff, mut flux) = (0.0, 0.0);
    for i in 0..n {
        for j in i + 1..n {
            let (x, y) = (g.area(i) * f[i * n + j], g.area(j) * f[j * n + i]);
            diff += (x - y).abs();
            flux += x.max(y);
        }
    }
    diff / flux
}

fn check_matrix(g: &Geo, f: &[f64], floor: f64) -> (Vec<f64>, f64) {
    let n = g.n();
    for (k, v) in f.iter().enumerate() {
        assert!(v.is_finite() && *v >= 0.0, "F[{}][{}] = {v}", k / n, k % n);
    }
    for i in 0..n {
        assert_eq!(f[i * n + i], 0.0, "F_ii of a planar patch");
    }
    let sums: Vec<f64> = (0..n).map(|i| f[i * n..(i + 1) * n].iter().sum()).collect();
    let mut worst = 0.0f64;
    for i in 0..n {
        for j in i + 1..n {
            let (x, y) = (g.area(i) * f[i * n + j], g.area(j) * f[j * n + i]);
            if x.max(y) > floor {
                worst = worst.max((x - y).abs() / x.max(y));
            }
        }
    }
    (sums, worst)
}

/// Rows computed forward on this thread, and in two other orders on two threads:
/// bitwise the same.
fn assert_thread_invariant(e: RowEngine, shuffle_seed: u64) {
    let e = Arc::new(e);
    let n = e.n() as u32;
    let mut s = Scratch::new();
    let forward: Vec<Row> = (0..n).map(|i| e.compute_row(i, &mut s)).collect();
    let mut order: Vec<u32> = (0..n).collect();
    // Any order will do, it only has to differ.
    ffstream::formfactor::sampling::SplitMix64::new(shuffle_seed).shuffle(&mut order);
    let handles: Vec<_> = [order.clone(), order.into_iter().rev().collect::<Vec<_>>()]
        .into_iter()
        .map(|o| {
            let e = Arc::clone(&e);
            std::thread::spawn(move || {
                let mut s = Scratch::new();
                let mut rows: Vec<Row> = o.into_iter().map(|i| e.compute_row(i, &mut s)).collect();
                rows.sort_by_key(|r| r.index);
                rows
            })
        })
        .collect();
    for h in handles {
        let rows = h.join().unwrap();
        for (a, b) in forward.iter().zip(&rows) {
            let bits = |r: &Row| {
                r.to_dense(n as usize)
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(
                bits(a),
                bits(b),
                "row {} differs between threads/orders",
                a.index
            );
        }
    }
}

proptest! {
    // Fixed RNG seed: the same cases on every run (CI reproducible; the sampled
    // visibility bounds below are empirical). PROPTEST_RNG_SEED does not override a
    // fixed seed; change it here to explore.
    #![proptest_config(ProptestConfig {
        cases: cases(),
        rng_seed: proptest::test_runner::RngSeed::Fixed(20261122),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_closed_boxes(
        dims in (0.3f64..3.0, 0.3f64..3.0, 0.3f64..3.0),
        m in 1usize..=3,
        angles in (-3.2f64..3.2, -3.2f64..3.2, -3.2f64..3.2),
        shift in (-10.0f64..10.0, -10.0f64..10.0, -10.0f64..10.0),
        log_scale in -2.0f64..2.0,
        inner in proptest::option::of((0.2f64..0.6, 0.2f64..0.6, 0.2f64..0.6)),
        seed in any::<u64>(),
    ) {
        let (a, b, c) = dims;
        // The scene with `m` × `m` patches per wall of the enclosure.
        let build = |m: usize| {
        let mut g = Geo::closed_box(a, b, c, m);
        if let Some((x, y, z)) = inner {
            // A box with six outward faces floating inside, touching nothing: the
            // enclosure stays closed (every ray ends on a front face).
            let (o, u, v, w) = (dvec3(0.2 * a, 0.2 * b, 0.2 * c), DVec3::X * x * a, DVec3::Y * y * b, DVec3::Z * z * c);
            g.para(o, v, u, 1, 1) // bottom, −z
                .para(o + w, u, v, 1, 1) // top, +z
                .para(o, u, w, 1, 1) // −y
                .para(o + v, w, u, 1, 1) // +y
                .para(o, w, v, 1, 1) // −x
                .para(o + u, v, w, 1, 1); // +x
        }
        let s = 10f64.powf(log_scale);
        g.transformed(s, rotation(angles), dvec3(shift.0, shift.1, shift.2) * s)
        };
        let g = build(m);
        let cfg = FormFactorConfig::accurate().with_seed(seed % 1000);
        let f = matrix(&g.engine(cfg.clone()));
        let total: f64 = (0..g.n()).map(|i| g.area(i)).sum();
        let (sums, recip) = check_matrix(&g, &f, 1e-12 * total);
        let dev = sums.iter().map(|x| (x - 1.0).abs()).fold(0.0, f64::max);
        let over = sums.iter().cloned().fold(0.0, f64::max) - 1.0;
        if inner.is_none() {
            // Convex enclosure: no occlusion, exact unoccluded integrals.
            prop_assert!(dev <= 1e-5, "closed box: row sum off by {dev}");
            prop_assert!(over <= 1e-5, "row sum exceeds 1 by {over}");
            prop_assert!(recip <= 1e-6, "closed box: reciprocity {recip}");
        } else {
            // Visibility is a sampled ratio estimate (16 rays per pair at most in
            // `accurate`): rows sum to 1 only within the sampling error, and may exceed
            // 1 by it (measured up to ~6e-2 with one patch per wall: the
            // "row sums ≤ 1" of docs/numerics.md §6 holds for occluded pairs only up to sampling error).
            // Pairs the occluder does not touch keep exact reciprocity; occluded pairs
            // only up to the sampling (the early stop after 4 agreeing rays can give 0
            // one way and > 0 the other: relative error 1, printed, not asserted).
            // `accurate` stops after 4 agreeing rays, a bias on coarse occluded pairs
            // (measured over 200 cases: rows off by up to 0.55 with one patch per wall,
            // 0.19 with 2-3; printed, not asserted); `reference` samples every pair
            // fully and converges as samples grow (one case, 1 patch per wall: 1.3e-2 at
            // 256 samples, 9e-3 at 4096; 4 × 4: 2.5e-3, 4.4e-4), so it must stay within
            // its sampling error: measured ≤ 0.125 (m = 1), ≤ 0.054 (m ≥ 2, a flat
            // 1.9 × 2.8 × 0.3 box). Bounds 0.2 / 0.1: a sanity check, not a rigorous one.
            assert_unoccluded_pairs_reciprocal(&g, &f, &cfg)?;
            // Exact visibility: the shadows of the floating box are clipped, not
            // sampled, so rows of the closed box sum to 1 and every pair is reciprocal,
            // to the quadrature's tolerance. At 1e-6 this costs about 2 minutes a case
            // with 2 × 2 patches per wall and 60-75 s with one (the outer rule refines
            // toward the shadow edges, where the integrand has kinks along curves): the
            // short run checks the first occluded case only, with one patch per wall
            // (the same box, scale and placement); the long run every case, with its
            // own m.
            let long = std::env::var_os("FFSTREAM_STRESS_LONG").is_some();
            static EXACT_CASES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
            if long || EXACT_CASES.fetch_add(1, std::sync::atomic::Ordering::Relaxed) == 0 {
            let mx = if long { m } else { 1 };
            let gx = build(mx);
            let totalx: f64 = (0..gx.n()).map(|i| gx.area(i)).sum();
            let mut xcfg = FormFactorConfig::accurate().with_seed(seed % 1000);
            xcfg.visibility = Visibility::Exact;
            xcfg.shadow_tol = 1e-6;
            let t = std::time::Instant::now();
            let fx = matrix(&gx.engine(xcfg.clone()));
            let (xs, xrecip) = check_matrix(&gx, &fx, 1e-12 * totalx);
            let xdev = xs.iter().map(|x| (x - 1.0).abs()).fold(0.0, f64::max);
            let xweighted = weighted_reciprocity(&gx, &fx);
            println!("occluded closed box, {m}×{m} per wall: max |row sum − 1| accurate {dev:.2e} (over 1: {over:.2e}, reciprocity {recip:.2e}); {mx}×{mx} per wall, exact {xdev:.2e} (reciprocity {xrecip:.2e}, weighted {xweighted:.2e}, {:.1} s)", t.elapsed().as_secs_f64());
            prop_assert!(xdev <= 1e-5, "occluded box, exact, m={mx}: row sum off by {xdev}");
            // Per pair the error is up to shadow_tol × F⁰_ij, large relative to a
            // mostly hidden F_ij; the share of the exchanged flux is what must be tiny.
            prop_assert!(xweighted <= 1e-5, "occluded box, exact, m={mx}: weighted reciprocity {xweighted}");
            }
        }
        assert_thread_invariant(g.engine(cfg), seed);
    }

    #[test]
    fn random_open_scenes(
        quads in proptest::collection::vec(
            ((0.2f64..0.9, 0.2f64..0.9), (-3.2f64..3.2, -3.2f64..3.2, -3.2f64..3.2), 1usize..=2),
            2..6,
        ),
        seed in any::<u64>(),
    ) {
        // Each quad in its own unit cell of a 2 × 2 × 2 grid (so none intersect), any
        // orientation: some face each other, some are occluded, some face away.
        let mut g = Geo::default();
        for (k, ((w, h), angles, m)) in quads.iter().enumerate() {
            let cell = dvec3((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64) * 1.2;
            let r = rotation(*angles);
            let (u, v) = (r * DVec3::X * *w, r * DVec3::Y * *h);
            let centre = cell + DVec3::splat(0.6);
            g.para(centre - (u + v) * 0.5, u, v, *m, *m);
        }
        let cfg = FormFactorConfig::accurate().with_seed(seed % 1000);
        let f = matrix(&g.engine(cfg.clone()));
        let (sums, _) = check_matrix(&g, &f, 0.0);
        let over = sums.iter().cloned().fold(0.0, f64::max) - 1.0;
        prop_assert!(over <= 1e-5, "row sum exceeds 1 by {over}");
        assert_unoccluded_pairs_reciprocal(&g, &f, &cfg)?;
        assert_thread_invariant(g.engine(cfg), seed);
    }
}

/// Reciprocity for pairs no occluder touched (their entries equal the engine's without
/// occluders) is exact up to quadrature; occlusion never adds light.
fn assert_unoccluded_pairs_reciprocal(
    g: &Geo,
    f: &[f64],
    cfg: &FormFactorConfig,
) -> Result<(), TestCaseError> {
    {
        let mut bare = g.clone();
        bare.tris.clear();
        let f0 = matrix(&bare.engine(cfg.clone()));
        let n = g.n();
        for i in 0..n {
            for j in i + 1..n {
                let (k, l) = (i * n + j, j * n + i);
                if f[k] == f0[k] && f[l] == f0[l] {
                    let (x, y) = (g.area(i) * f[k], g.area(j) * f[l]);
                    // On the scale of F (divide by the larger area): 1e-7, two orders
                    // below the accuracy target. (Relative to A_i F_ij itself the
                    // `accurate` preset can be off by ~1e-6 on small partly clipped
                    // pairs; `reference` agrees to 1e-11.)
                    prop_assert!(
                        (x - y).abs() <= 1e-7 * g.area(i).max(g.area(j)),
                        "({i},{j}): {x} vs {y}"
                    );
                }
                // Occlusion only removes light.
                prop_assert!(
                    f[k] <= f0[k] * (1.0 + 1e-9) + 1e-15,
                    "({i},{j}) gained light"
                );
            }
        }
    }
    Ok(())
}
