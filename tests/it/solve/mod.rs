//! Out-of-core radiosity solver against known answers: the unit cube's exact form
//! factors, a synthetic sphere-like enclosure (F_ij = A_j / A) with a closed-form
//! solution, a banded closed ring for top-k, an independent dense LU solve, linearity,
//! conservation of power, and round trips of the CSV and PLY outputs.
//!
//! This file holds the scene builders, the reference solver and the checks the others
//! share, and the solves against known answers; `skipped`: rows the solver skips or
//! lacks; `top_k`: top-k rows and the pooled solve; `outputs`: the energy report, the
//! CSV, emission cases, PLY and the summary.

use ffstream::formfactor::sampling::SplitMix64;
use ffstream::patch::{Patch, PatchSet};
use ffstream::rows::{Row, RowValues};
use ffstream::solve::{
    solve, DroppedMass, MemoryRows, RowSource, Solution, SolveConfig, SolveMethod,
};
use glam::DVec3;

mod outputs;
mod skipped;
mod top_k;

// ---------------------------------------------------------------- scene builders

/// Unit cube, inward faces (docs/known-answers.md §5, Howell C-11 and C-14).
const CUBE_OPPOSITE: f64 = 0.19982489570;
const CUBE_ADJACENT: f64 = 0.20004377608;

/// A patch whose geometry is irrelevant to the solver (only `area` counts).
fn patch(area: f64, group: u32) -> Patch {
    Patch {
        corners: [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::ZERO],
        n_corners: 3,
        normal: DVec3::Z,
        area,
        group,
        face: 0,
        rho: [0.0; 3],
        emission: [0.0; 3],
    }
}

fn patch_set(areas: &[f64]) -> PatchSet {
    PatchSet {
        patches: areas.iter().map(|&a| patch(a, 0)).collect(),
        groups: vec!["all".into()],
    }
}

/// The 6 faces of the unit cube; face i is opposite face i ^ 1.
fn cube_rows() -> Vec<Row> {
    (0..6u32)
        .map(|i| {
            let vals = (0..6u32)
                .map(|j| {
                    if j == i {
                        0.0
                    } else if j == i ^ 1 {
                        CUBE_OPPOSITE as f32
                    } else {
                        CUBE_ADJACENT as f32
                    }
                })
                .collect();
            Row::dense(i, vals)
        })
        .collect()
}

/// Areas: integers in [1, 4] summing to `total` (a power of two), so that every
/// F_ij = A_j / A is exact in f32 and reciprocity A_i F_ij = A_j F_ji holds exactly.
fn sphere_areas(n: usize, total: u32, rng: &mut SplitMix64) -> Vec<f64> {
    let mut a: Vec<u32> = (0..n).map(|_| 1 + rng.below(3) as u32).collect();
    let mut sum: u32 = a.iter().sum();
    while sum != total {
        let i = rng.below(n);
        if sum < total && a[i] < 4 {
            a[i] += 1;
            sum += 1;
        } else if sum > total && a[i] > 1 {
            a[i] -= 1;
            sum -= 1;
        }
    }
    a.into_iter().map(f64::from).collect()
}

/// The sphere property F_ij = A_j / A for every i (docs/known-answers.md §5): a closed
/// enclosure whose rows sum to 1.
fn sphere_rows(areas: &[f64]) -> Vec<Row> {
    let total: f64 = areas.iter().sum();
    let row: Vec<f32> = areas.iter().map(|&a| (a / total) as f32).collect();
    (0..areas.len() as u32)
        .map(|i| Row::dense(i, row.clone()))
        .collect()
}

/// A closed ring of n equal patches: F_ij = w(d) / Z with d the circular distance,
/// w(d) = 1/d², F_ii = 0. Symmetric, rows sum to 1. With `keep = Some(r)` rows keep
/// only d ≤ r (a symmetric top-k pattern) and record the dropped mass.
fn ring_rows(n: usize, keep: Option<usize>) -> (Vec<Row>, f64) {
    let w = |d: usize| if d == 0 { 0.0 } else { 1.0 / (d * d) as f64 };
    let dist = |i: usize, j: usize| {
        let d = i.abs_diff(j);
        d.min(n - d)
    };
    let z: f64 = (0..n).map(|j| w(dist(0, j))).sum();
    let mut dropped_frac = 0.0;
    let rows = (0..n)
        .map(|i| {
            let mut cols = Vec::new();
            let mut vals = Vec::new();
            let mut dropped = 0.0;
            for j in 0..n {
                let f = w(dist(i, j)) / z;
                if f == 0.0 {
                    continue;
                }
                match keep {
                    Some(r) if dist(i, j) > r => dropped += f,
                    _ => {
                        cols.push(j as u32);
                        vals.push(f as f32);
                    }
                }
            }
            dropped_frac = dropped;
            Row {
                index: i as u32,
                values: RowValues::Sparse { cols, vals },
                dropped: dropped as f32,
                links: Vec::new(),
                link_error: None,
            }
        })
        .collect();
    (rows, dropped_frac)
}

fn source(areas: &[f64], rows: Vec<Row>) -> MemoryRows {
    MemoryRows::new(patch_set(areas), rows).unwrap()
}

fn cfg(method: SolveMethod, tolerance: f64) -> SolveConfig {
    SolveConfig {
        method,
        tolerance,
        max_iterations: 200_000,
        ..SolveConfig::default()
    }
}

// ---------------------------------------------------------------- reference solver

/// The matrix F̃ the solver documents for `how`, built densely from the stored rows:
/// as stored (absorb); rows scaled to their true sums (scale); or as stored plus the
/// pool's rank-one term F̃_ji += D_j s_i / W over reflecting rows j, with
/// s_i = max(0, A_i (R_i − K_i) − Σ_{j reflecting} A_j F_ji), K_i row i's stored part to
/// non-reflecting columns and W = Σ_{j reflecting} A_j D_j (pool).
fn documented_matrix(src: &MemoryRows, rho: &[[f32; 3]], how: DroppedMass) -> Vec<Vec<f64>> {
    let n = src.patches().len();
    let area: Vec<f64> = src.patches().patches.iter().map(|p| p.area).collect();
    let reflects = |i: usize| rho[i].iter().any(|&x| x > 0.0);
    let mut f = vec![vec![0.0f64; n]; n];
    let mut dropped = vec![0.0f64; n];
    let mut true_sum = vec![None; n];
    for r in src.rows() {
        let s = if how == DroppedMass::Scale && r.dropped > 0.0 {
            r.true_sum() / r.stored_sum()
        } else {
            1.0
        };
        for (j, x) in r.to_dense(n).into_iter().enumerate() {
            f[r.index as usize][j] = x as f64 * s;
        }
        dropped[r.index as usize] = r.dropped as f64;
        true_sum[r.index as usize] = Some(r.true_sum());
    }
    if how == DroppedMass::Pool {
        let w: f64 = (0..n)
            .filter(|&j| reflects(j))
            .map(|j| area[j] * dropped[j])
            .sum();
        let send: Vec<f64> = (0..n)
            .map(|i| match true_sum[i] {
                None => 0.0,
                Some(total) => {
                    let to_dark: f64 = (0..n).filter(|&x| !reflects(x)).map(|x| f[i][x]).sum();
                    let carried: f64 = (0..n)
                        .filter(|&j| reflects(j))
                        .map(|j| area[j] * f[j][i])
                        .sum();
                    (area[i] * (total - to_dark) - carried).max(0.0)
                }
            })
            .collect();
        if w > 0.0 {
            for j in (0..n).filter(|&j| reflects(j)) {
                for i in 0..n {
                    f[j][i] += dropped[j] * send[i] / w;
                }
            }
        }
    }
    f
}

/// Independent answer: dense Gaussian elimination with partial pivoting on
/// (I − diag(ρ_c) F̃) B_c = E_c per channel, F̃ from [`documented_matrix`].
fn dense_reference(
    src: &MemoryRows,
    e: &[[f32; 3]],
    rho: &[[f32; 3]],
    how: DroppedMass,
) -> Vec<[f64; 3]> {
    let n = src.patches().len();
    let f = documented_matrix(src, rho, how);
    let mut out = vec![[0.0; 3]; n];
    for c in 0..3 {
        let mut a: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let mut row: Vec<f64> = f[i].iter().map(|x| -(rho[i][c] as f64) * x).collect();
                row[i] += 1.0;
                row.push(e[i][c] as f64);
                row
            })
            .collect();
        for k in 0..n {
            let p = (k..n)
                .max_by(|&x, &y| a[x][k].abs().total_cmp(&a[y][k].abs()))
                .unwrap();
            a.swap(k, p);
            let pivot = a[k].clone();
            for row in a.iter_mut().skip(k + 1) {
                let m = row[k] / pivot[k];
                if m != 0.0 {
                    for (x, p) in row[k..].iter_mut().zip(&pivot[k..]) {
                        *x -= m * p;
                    }
                }
            }
        }
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| a[i][j] * out[j][c]).sum();
            out[i][c] = (a[i][n] - s) / a[i][i];
        }
    }
    out
}

// ---------------------------------------------------------------- checks

fn total_power(areas: &[f64], b: &[[f64; 3]], c: usize) -> f64 {
    areas.iter().zip(b).map(|(a, b)| a * b[c]).sum()
}

fn emitted(areas: &[f64], e: &[[f32; 3]], c: usize) -> f64 {
    areas.iter().zip(e).map(|(a, e)| a * e[c] as f64).sum()
}

/// max_i |x_i − y_i| / max_i |y_i| over all channels.
fn rel_diff(x: &[[f64; 3]], y: &[[f64; 3]]) -> f64 {
    let scale = y.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let d = x
        .iter()
        .zip(y)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f64, f64::max);
    d / scale
}

fn assert_finite(s: &Solution) {
    for v in s.b.iter().chain(&s.h).flatten().flatten() {
        assert!(
            v.is_finite(),
            "{}: non-finite value in the solution",
            s.method
        );
    }
    assert!(s.residual.is_finite());
}

/// Bound on the relative error of B (∞-norm) when the solve stopped at relative
/// residual `tol`: ‖e‖ ≤ ‖r‖ / (1 − ρ_max · max row sum) for the gathering methods; for
/// shooting in these closed, uniformly lit scenes, the unshot fraction bounds the
/// relative error of every patch (same derivation, unshot power instead of residual).
/// Factor 2 for the gap between ‖B‖ and ‖B_exact‖ and rounding.
fn error_bound(tol: f64, rho_max: f64) -> f64 {
    2.0 * tol / (1.0 - rho_max) + 1e-12
}

// ---------------------------------------------------------------- tests

/// Unit cube, one emitting face: conservation Σ A B = Φ / (1 − ρ) within 1e-4 for
/// every method at ρ = 0.5, 0.9, 0.99, and agreement with a dense LU solve.
#[test]
fn cube_conservation_and_dense_reference() {
    let areas = [1.0; 6];
    let src = source(&areas, cube_rows());
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0, 0.5, 0.25];
    for rho in [0.5f32, 0.9, 0.99] {
        let r = vec![[rho; 3]; 6];
        let reference = dense_reference(&src, &e, &r, DroppedMass::Pool);
        let tol = 1e-10;
        for method in SolveMethod::ALL {
            let s = solve(&src, &[e.clone()], &r, &cfg(method, tol)).unwrap();
            assert!(s.converged, "{method} at ρ = {rho}");
            assert_finite(&s);
            for c in 0..3 {
                let want = emitted(&areas, &e, c) / (1.0 - rho as f64);
                let got = total_power(&areas, &s.b[0], c);
                assert!(
                    ((got - want) / want).abs() < 1e-4,
                    "{method} ρ = {rho} channel {c}: Σ A B = {got}, Φ/(1-ρ) = {want}"
                );
            }
            let d = rel_diff(&s.b[0], &reference);
            assert!(
                d < error_bound(tol, rho as f64),
                "{method} ρ = {rho}: differs from dense LU by {d:e}"
            );
            if method != SolveMethod::Shooting {
                assert!(s.residual <= tol, "{method}: residual {}", s.residual);
            }
        }
    }
}

/// The cube's rows are exactly symmetric (equal areas, equal f32 values), so shooting
/// (which reads columns through reciprocity) and Jacobi solve the same system and must
/// agree within their tolerances.
#[test]
fn shooting_agrees_with_jacobi_and_gauss_seidel() {
    let areas = [1.0; 6];
    let src = source(&areas, cube_rows());
    let mut e = vec![[0.0f32; 3]; 6];
    e[2] = [3.0, 2.0, 1.0];
    e[5] = [0.5, 0.5, 0.5];
    let r: Vec<[f32; 3]> = (0..6).map(|i| [0.3 + 0.1 * i as f32, 0.8, 0.5]).collect();
    let tol = 1e-9;
    let j = solve(&src, &[e.clone()], &r, &cfg(SolveMethod::Jacobi, tol)).unwrap();
    let g = solve(&src, &[e.clone()], &r, &cfg(SolveMethod::GaussSeidel, tol)).unwrap();
    let s = solve(&src, &[e.clone()], &r, &cfg(SolveMethod::Shooting, tol)).unwrap();
    let bound = 2.0 * error_bound(tol, 0.8);
    assert!(
        rel_diff(&s.b[0], &j.b[0]) < bound,
        "{:e}",
        rel_diff(&s.b[0], &j.b[0])
    );
    assert!(
        rel_diff(&g.b[0], &j.b[0]) < bound,
        "{:e}",
        rel_diff(&g.b[0], &j.b[0])
    );
    // B = E + ρ H holds for the returned H within the reported residual.
    for sol in [&j, &g, &s] {
        for i in 0..6 {
            for c in 0..3 {
                let lhs = sol.b[0][i][c];
                let rhs = e[i][c] as f64 + r[i][c] as f64 * sol.h[0][i][c];
                assert!((lhs - rhs).abs() <= sol.residual * 10.0 + 1e-12);
            }
        }
    }
    // Gauss–Seidel needs fewer sweeps than Jacobi on this diagonally dominant system.
    assert!(
        g.iterations < j.iterations,
        "{} vs {}",
        g.iterations,
        j.iterations
    );
}

/// Sphere property F_ij = A_j / A with n = 500 random areas. Closed form (derived in
/// the test body): H_i = Φ / (A − Σ_j A_j ρ_j) for every i, B_i = E_i + ρ_i H_i; with
/// uniform ρ that is B_i = E_i + ρ Φ / (A (1 − ρ)), the integrating sphere.
#[test]
fn sphere_closed_form_every_method() {
    // Derivation: every row is the same vector a_j = A_j / A, so H_i = Σ_j a_j B_j = h
    // for all i. Then B_j = E_j + ρ_j h and h = Σ_j a_j E_j + h Σ_j a_j ρ_j, i.e.
    // h = (Φ / A) / (1 − Σ_j A_j ρ_j / A) = Φ / (A − Σ_j A_j ρ_j).
    // n = 500 random areas; 200 at ρ = 0.99, where shooting needs ~1000 rounds of n
    // shots. `None`: random ρ per patch and channel in [0.1, 0.9).
    let cases: [(usize, u32, Option<f32>, f64); 4] = [
        (500, 1024, Some(0.5), 0.5),
        (500, 1024, Some(0.9), 0.9),
        (200, 512, Some(0.99), 0.99),
        (500, 1024, None, 0.9),
    ];
    for (n, total_area, uniform, rho_max) in cases {
        let mut rng = SplitMix64::new(0x5eed_0001);
        let areas = sphere_areas(n, total_area, &mut rng);
        let total: f64 = areas.iter().sum();
        let src = source(&areas, sphere_rows(&areas));
        let mut e = vec![[0.0f32; 3]; n];
        for _ in 0..20 {
            let i = rng.below(n);
            e[i] = [1.0, 2.0, 0.5];
        }
        let rho: Vec<[f32; 3]> = match uniform {
            Some(r) => vec![[r; 3]; n],
            None => (0..n)
                .map(|_| std::array::from_fn(|_| (0.1 + 0.8 * rng.next_f64()) as f32))
                .collect(),
        };
        let (rho, rho_max) = (&rho, &rho_max);
        let mut exact_h = [0.0; 3];
        for (c, h) in exact_h.iter_mut().enumerate() {
            let phi = emitted(&areas, &e, c);
            let a_rho: f64 = areas.iter().zip(rho).map(|(a, r)| a * r[c] as f64).sum();
            *h = phi / (total - a_rho);
        }
        let exact_b: Vec<[f64; 3]> = (0..n)
            .map(|i| std::array::from_fn(|c| e[i][c] as f64 + rho[i][c] as f64 * exact_h[c]))
            .collect();
        let tol = 1e-9;
        for method in SolveMethod::ALL {
            let t0 = std::time::Instant::now();
            let s = solve(&src, &[e.clone()], rho, &cfg(method, tol)).unwrap();
            let elapsed = t0.elapsed();
            assert!(s.converged);
            if method == SolveMethod::GaussSeidel {
                // The residual bound of gauss_seidel.rs is rigorous: the first check
                // pass confirms convergence, so exactly one extra pass.
                assert_eq!(s.passes, s.iterations + 1);
            }
            let d = rel_diff(&s.b[0], &exact_b);
            assert!(
                d < error_bound(tol, *rho_max),
                "{method} ρmax {rho_max}: B off by {d:e}"
            );
            // H = F B with row sums 1: its absolute error is at most B's, which is
            // bounded relative to ‖B‖∞ (not to H, which can be much smaller).
            let b_max = exact_b.iter().flatten().fold(0.0f64, |m, x| m.max(*x));
            for (i, h) in s.h[0].iter().enumerate() {
                for c in 0..3 {
                    let err = (h[c] - exact_h[c]).abs() / b_max;
                    assert!(
                        err < error_bound(tol, *rho_max),
                        "{method}: H[{i}][{c}] = {} vs {}",
                        h[c],
                        exact_h[c]
                    );
                }
            }
            if rho.iter().all(|r| *r == rho[0]) {
                let rho = rho[0][0] as f64;
                for c in 0..3 {
                    let phi = emitted(&areas, &e, c);
                    let got = total_power(&areas, &s.b[0], c);
                    assert!(((got - phi / (1.0 - rho)) / got).abs() < 1e-4);
                    let rep = &s.energy[0];
                    assert!((rep.emitted[c] - phi).abs() < 1e-9 * phi);
                    // Closed scene: nothing escapes, all emitted power is absorbed.
                    assert!(rep.escaped[c].abs() < 1e-6 * rep.total[c], "{rep}");
                    assert!(rep.imbalance()[c].abs() < 1e-6, "{rep}");
                }
            }
            eprintln!(
                "sphere n={n} ρmax={rho_max} {method}: {} iterations, {} passes, residual {:.2e}, {:.2?}",
                s.iterations, s.passes, s.residual, elapsed
            );
        }
    }
}

/// ρ = 0.999: slow convergence, but no NaN/Inf, and conservation still holds for the
/// stored matrix: the cube's rows all sum to S (f32 values), so Σ A B = Φ / (1 − ρ S).
#[test]
fn high_reflectance_stays_finite_and_conserves() {
    let areas = [1.0; 6];
    let rows = cube_rows();
    let s_row = rows[0].stored_sum();
    let src = source(&areas, rows);
    let mut e = vec![[0.0f32; 3]; 6];
    e[4] = [1.0, 1.0, 1.0];
    let rho = 0.999f32;
    let r = vec![[rho; 3]; 6];
    let tol = 1e-9;
    for method in SolveMethod::ALL {
        let s = solve(&src, &[e.clone()], &r, &cfg(method, tol)).unwrap();
        assert_finite(&s);
        assert!(s.converged, "{method}: {}", s.summary());
        let want = emitted(&areas, &e, 0) / (1.0 - rho as f64 * s_row);
        let got = total_power(&areas, &s.b[0], 0);
        assert!(
            ((got - want) / want).abs() < error_bound(tol, 0.999),
            "{got} vs {want}"
        );
        eprintln!(
            "cube ρ=0.999 {method}: {} iterations, residual {:.2e}",
            s.iterations, s.residual
        );
    }
    // The same on a 64-patch sphere (exact rows).
    let mut rng = SplitMix64::new(99);
    let areas = sphere_areas(64, 128, &mut rng);
    let src = source(&areas, sphere_rows(&areas));
    let mut e = vec![[0.0f32; 3]; 64];
    e[7] = [2.0, 1.0, 0.0];
    let r = vec![[rho; 3]; 64];
    for method in SolveMethod::ALL {
        let s = solve(&src, &[e.clone()], &r, &cfg(method, tol)).unwrap();
        assert_finite(&s);
        let want = emitted(&areas, &e, 0) / (1.0 - rho as f64);
        let got = total_power(&areas, &s.b[0], 0);
        assert!(
            ((got - want) / want).abs() < error_bound(tol, 0.999),
            "{method}"
        );
        assert_eq!(
            s.b[0].iter().map(|b| b[2]).sum::<f64>(),
            0.0,
            "blue emits nothing"
        );
        eprintln!(
            "sphere n=64 ρ=0.999 {method}: {} iterations, residual {:.2e}",
            s.iterations, s.residual
        );
    }
}

/// K cases at once equal each case alone; case 3 = case 1 + case 2 gives B3 = B1 + B2;
/// the answers match a dense LU solve with per-patch, per-channel reflectance.
#[test]
fn multi_rhs_equals_single_solves_and_is_linear() {
    let n = 48;
    let (rows, _) = ring_rows(n, None);
    let areas = vec![1.0; n];
    let src = source(&areas, rows);
    let mut rng = SplitMix64::new(7);
    let rho: Vec<[f32; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| (0.2 + 0.7 * rng.next_f64()) as f32))
        .collect();
    let mut e1 = vec![[0.0f32; 3]; n];
    let mut e2 = vec![[0.0f32; 3]; n];
    e1[3] = [4.0, 1.0, 0.0];
    e1[4] = [4.0, 1.0, 0.0];
    e2[30] = [0.0, 2.0, 8.0];
    let e3: Vec<[f32; 3]> = e1
        .iter()
        .zip(&e2)
        .map(|(a, b)| std::array::from_fn(|c| a[c] + b[c]))
        .collect();
    let tol = 1e-10;
    let bound = 2.0 * error_bound(tol, 0.9);
    for method in SolveMethod::ALL {
        let joint = solve(
            &src,
            &[e1.clone(), e2.clone(), e3.clone()],
            &rho,
            &cfg(method, tol),
        )
        .unwrap();
        assert_eq!(joint.cases(), 3);
        for (k, e) in [&e1, &e2, &e3].into_iter().enumerate() {
            let alone = solve(&src, std::slice::from_ref(e), &rho, &cfg(method, tol)).unwrap();
            let d = rel_diff(&joint.b[k], &alone.b[0]);
            assert!(d < bound, "{method} case {k}: joint vs alone {d:e}");
            let reference = dense_reference(&src, e, &rho, DroppedMass::Pool);
            let d = rel_diff(&joint.b[k], &reference);
            assert!(d < bound, "{method} case {k}: vs dense LU {d:e}");
        }
        let sum: Vec<[f64; 3]> = joint.b[0]
            .iter()
            .zip(&joint.b[1])
            .map(|(a, b)| std::array::from_fn(|c| a[c] + b[c]))
            .collect();
        let d = rel_diff(&joint.b[2], &sum);
        assert!(d < bound, "{method}: B(E1 + E2) − (B(E1) + B(E2)) = {d:e}");
        // Red of case 2 and blue of case 1 emit nothing: their columns stay exactly 0.
        assert!(joint.b[1].iter().all(|b| b[0] == 0.0));
        assert!(joint.b[0].iter().all(|b| b[2] == 0.0));
    }
}

/// Gauss–Seidel's answer does not depend on the order rows are stored in (within
/// tolerance).
#[test]
fn gauss_seidel_is_order_independent() {
    let n = 40;
    let (mut rows, _) = ring_rows(n, None);
    let areas = vec![1.0; n];
    let mut e = vec![[0.0f32; 3]; n];
    e[0] = [1.0, 2.0, 3.0];
    let rho = vec![[0.8f32, 0.6, 0.95]; n];
    let tol = 1e-10;
    let forward = solve(
        &source(&areas, rows.clone()),
        &[e.clone()],
        &rho,
        &cfg(SolveMethod::GaussSeidel, tol),
    )
    .unwrap();
    rows.reverse();
    let mut rng = SplitMix64::new(5);
    for i in (1..n).rev() {
        rows.swap(i, rng.below(i + 1));
    }
    let shuffled = solve(
        &source(&areas, rows),
        &[e],
        &rho,
        &cfg(SolveMethod::GaussSeidel, tol),
    )
    .unwrap();
    let d = rel_diff(&shuffled.b[0], &forward.b[0]);
    assert!(d < 2.0 * error_bound(tol, 0.95), "{d:e}");
}
