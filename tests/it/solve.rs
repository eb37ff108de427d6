//! Out-of-core radiosity solver against known answers: the unit cube's exact form
//! factors, a synthetic sphere-like enclosure (F_ij = A_j / A) with a closed-form
//! solution, a banded closed ring for top-k, an independent dense LU solve, linearity,
//! conservation of power, and round trips of the CSV and PLY outputs.

use std::path::Path;

use ffstream::formfactor::sampling::SplitMix64;
use ffstream::patch::{Patch, PatchSet};
use ffstream::render::{write_ply_with, PlyEncoding, PlyOptions};
use ffstream::rows::{Row, RowValues};
use ffstream::solve::{
    case_path, format_group_table, group_table, parse_emission_cases, read_radiosity_csv, solve,
    write_csv, DroppedMass, MemoryRows, RowSource, Solution, SolveConfig, SolveError, SolveMethod,
    CSV_HEADER,
};
use glam::DVec3;

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

/// A row source that poisons the rows of patches that neither reflect nor emit: the
/// scan hands them over as NaN (or Skipped) and random access to them is an error. A
/// solve that used them would fail or produce NaN.
struct Poisoned {
    inner: MemoryRows,
    inert: Vec<bool>,
    skipped: bool,
}

impl RowSource for Poisoned {
    fn patches(&self) -> &PatchSet {
        self.inner.patches()
    }
    fn scan(&self, f: &mut dyn FnMut(&Row) -> Result<(), SolveError>) -> Result<(), SolveError> {
        let n = self.inert.len();
        self.inner.scan(&mut |r| {
            if self.inert[r.index as usize] {
                let poison = if self.skipped {
                    Row::skipped(r.index)
                } else {
                    Row::dense(r.index, vec![f32::NAN; n])
                };
                f(&poison)
            } else {
                f(r)
            }
        })
    }
    fn has_row(&self, i: u32) -> bool {
        self.inner.has_row(i)
    }
    fn row(&self, i: u32) -> Result<Option<Row>, SolveError> {
        if self.inert[i as usize] {
            return Err(SolveError::InvalidInput(format!(
                "row {i} of an inert patch must not be read"
            )));
        }
        self.inner.row(i)
    }
}

/// Non-reflecting patches: rows never read (counted as skipped), B = E, and their
/// irradiance (a black sensor) obtained by reciprocity equals the closed form.
#[test]
fn non_reflecting_rows_are_skipped_and_never_read() {
    let mut rng = SplitMix64::new(0xda4c);
    let n = 200;
    let areas = sphere_areas(n, 512, &mut rng);
    let total: f64 = areas.iter().sum();
    let mut rho = vec![[0.7f32, 0.6, 0.5]; n];
    let mut e = vec![[0.0f32; 3]; n];
    let mut inert = vec![false; n];
    // 40 black sensors (inert), one black emitter (row needed to shoot, and for the
    // sensors' H), one reflecting emitter.
    for i in 0..40 {
        rho[i] = [0.0; 3];
        inert[i] = true;
    }
    rho[40] = [0.0; 3];
    e[40] = [5.0, 5.0, 5.0];
    e[100] = [1.0, 0.0, 2.0];
    let exact_h: [f64; 3] = std::array::from_fn(|c| {
        let phi = emitted(&areas, &e, c);
        let a_rho: f64 = areas.iter().zip(&rho).map(|(a, r)| a * r[c] as f64).sum();
        phi / (total - a_rho)
    });
    let tol = 1e-10;
    for skipped in [false, true] {
        let src = Poisoned {
            inner: source(&areas, sphere_rows(&areas)),
            inert: inert.clone(),
            skipped,
        };
        for method in SolveMethod::ALL {
            let s = solve(&src, &[e.clone()], &rho, &cfg(method, tol)).unwrap();
            assert_finite(&s);
            assert_eq!(s.rows_skipped, 41, "{method}");
            assert!(s.warnings.is_empty(), "{:?}", s.warnings);
            // Errors relative to ‖B‖∞ (see sphere_closed_form_every_method).
            let b_max = (0..n)
                .flat_map(|i| (0..3).map(move |c| (i, c)))
                .map(|(i, c)| e[i][c] as f64 + rho[i][c] as f64 * exact_h[c])
                .fold(0.0f64, f64::max);
            for i in 0..n {
                for c in 0..3 {
                    let b_exact = e[i][c] as f64 + rho[i][c] as f64 * exact_h[c];
                    let err = (s.b[0][i][c] - b_exact).abs() / b_max;
                    assert!(err < error_bound(tol, 0.7), "{method} B[{i}][{c}]: {err:e}");
                    let err = (s.h[0][i][c] - exact_h[c]).abs() / b_max;
                    assert!(err < error_bound(tol, 0.7), "{method} H[{i}][{c}]: {err:e}");
                }
                if rho[i] == [0.0; 3] {
                    assert_eq!(s.b[0][i], e[i].map(f64::from), "dark patches keep B = E");
                }
            }
        }
    }
}

/// A black emitter whose row the file skipped: gathering still solves B (its B = E)
/// but warns that the sensors' H misses its direct light; shooting cannot shoot from
/// it and says which row.
#[test]
fn skipped_row_of_a_black_emitter() {
    let areas = [1.0; 6];
    let mut rows = cube_rows();
    rows[0] = Row::skipped(0);
    let src = source(&areas, rows);
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0; 3];
    let mut rho = vec![[0.5f32; 3]; 6];
    rho[0] = [0.0; 3];
    rho[1] = [0.0; 3]; // a black sensor opposite the emitter
    for method in [SolveMethod::Jacobi, SolveMethod::GaussSeidel] {
        let s = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap();
        assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
        assert!(s.warnings[0].contains("row 0"), "{}", s.warnings[0]);
    }
    let err = solve(&src, &[e], &rho, &cfg(SolveMethod::Shooting, 1e-9)).unwrap_err();
    assert!(
        matches!(err, SolveError::SkippedRow { row: 0, .. }),
        "{err}"
    );
}

/// Needed rows that are missing or Skipped are errors naming the row, and every solver
/// counts all the needed rows that are missing (shooting, which reads rows at random,
/// said "1 needed rows missing" when 427 were).
#[test]
fn missing_or_skipped_needed_rows_are_errors() {
    let areas = [1.0; 6];
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0; 3];
    let rho = vec![[0.5f32; 3]; 6];
    let missing: Vec<Row> = cube_rows()
        .into_iter()
        .filter(|r| ![1, 3, 4].contains(&r.index))
        .collect();
    let src = source(&areas, missing);
    for method in SolveMethod::ALL {
        let err = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap_err();
        assert!(
            matches!(err, SolveError::MissingRow { missing: 3, .. }),
            "{method}: {err}"
        );
        assert!(err.to_string().contains("3 needed rows missing"), "{err}");
    }
    let missing: Vec<Row> = cube_rows().into_iter().filter(|r| r.index != 3).collect();
    let src = source(&areas, missing);
    for method in SolveMethod::ALL {
        let err = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap_err();
        assert!(
            matches!(err, SolveError::MissingRow { row: 3, .. }),
            "{method}: {err}"
        );
        assert!(err.to_string().contains("row 3"), "{err}");
    }
    let mut rows = cube_rows();
    rows[2] = Row::skipped(2);
    let src = source(&areas, rows);
    for method in SolveMethod::ALL {
        let err = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap_err();
        assert!(
            matches!(err, SolveError::SkippedRow { row: 2, .. }),
            "{method}: {err}"
        );
    }
    // Inputs that cannot be solved.
    let src = source(&areas, cube_rows());
    let bad_rho = vec![[1.0f32; 3]; 6];
    assert!(matches!(
        solve(&src, &[e.clone()], &bad_rho, &SolveConfig::default()),
        Err(SolveError::InvalidInput(_))
    ));
    assert!(matches!(
        solve(&src, &[vec![[0.0; 3]; 5]], &rho, &SolveConfig::default()),
        Err(SolveError::InvalidInput(_))
    ));
}

/// Top-k rows: with a symmetric kept pattern (the ring, keep d ≤ 4) the renormalised
/// matrix is reciprocal with row sums 1, so Σ A B = Φ / (1 − ρ) again, and so is the
/// pooled one; absorbed, the dropped mass D is lost and Σ A B = Φ / (1 − ρ (1 − D)).
#[test]
fn top_k_renormalisation_restores_conservation() {
    let n = 64;
    let (rows, dropped) = ring_rows(n, Some(4));
    assert!(
        dropped > 0.04,
        "the test needs a visible dropped mass, got {dropped}"
    );
    let areas = vec![1.0; n];
    let src = source(&areas, rows);
    let mut e = vec![[0.0f32; 3]; n];
    e[10] = [1.0, 0.5, 2.0];
    e[11] = [1.0, 0.5, 2.0];
    let tol = 1e-10;
    for rho in [0.5f32, 0.9, 0.99] {
        let r = vec![[rho; 3]; n];
        let rho = rho as f64;
        for method in SolveMethod::ALL {
            let with = |dropped| SolveConfig {
                dropped,
                ..cfg(method, tol)
            };
            let off = solve(&src, &[e.clone()], &r, &with(DroppedMass::Absorb)).unwrap();
            for c in 0..3 {
                let phi = emitted(&areas, &e, c);
                let conserved = phi / (1.0 - rho);
                let lossy = phi / (1.0 - rho * (1.0 - dropped));
                for how in [DroppedMass::Scale, DroppedMass::Pool] {
                    let on = solve(&src, &[e.clone()], &r, &with(how)).unwrap();
                    let got_on = total_power(&areas, &on.b[0], c);
                    assert!(
                        ((got_on - conserved) / conserved).abs() < 1e-4,
                        "{method} ρ={rho} {how}: Σ A B = {got_on}, want {conserved}"
                    );
                }
                let got_off = total_power(&areas, &off.b[0], c);
                assert!(
                    ((got_off - lossy) / lossy).abs() < 1e-4,
                    "{method} ρ={rho}: raw Σ A B = {got_off}, want {lossy}"
                );
                assert!(
                    (conserved - lossy) / conserved > 0.02,
                    "the two must differ"
                );
            }
        }
    }
}

/// n patches of random areas inside a sphere (F_ij = A_j / A, A the total area), every
/// row keeping the same 50 largest columns: the areas, the patches from largest to
/// smallest, the rows.
fn sphere_top_50(n: usize, seed: u64) -> (Vec<f64>, Vec<usize>, MemoryRows) {
    let mut rng = SplitMix64::new(seed);
    let areas = sphere_areas(n, 512, &mut rng);
    let total: f64 = areas.iter().sum();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| areas[b].total_cmp(&areas[a]).then(a.cmp(&b)));
    let mut kept: Vec<u32> = order[..50].iter().map(|&j| j as u32).collect();
    kept.sort_unstable();
    let dropped: f64 = order[50..].iter().map(|&j| areas[j] / total).sum();
    let rows: Vec<Row> = (0..n as u32)
        .map(|i| Row {
            index: i,
            values: RowValues::Sparse {
                cols: kept.clone(),
                vals: kept
                    .iter()
                    .map(|&j| (areas[j as usize] / total) as f32)
                    .collect(),
            },
            dropped: dropped as f32,
            links: Vec::new(),
            link_error: None,
        })
        .collect();
    let src = source(&areas, rows);
    (areas, order, src)
}

/// The inside of a sphere, F_ij = A_j / A (A the total area), truncated the same way in
/// every row (the 50 largest columns kept) with a small emitter among the dropped: the
/// pool restores the exact answer B_i = E_i + ρ Φ / ((1 − ρ) A) for every method, while
/// scaled rows place the light wrongly (and absorbed rows lose it).
#[test]
fn the_pool_is_exact_where_form_factors_are_uniform() {
    let n = 200;
    let (areas, order, src) = sphere_top_50(n, 4242);
    let total: f64 = areas.iter().sum();
    let mut e = vec![[0.0f32; 3]; n];
    e[order[n - 1]] = [10.0, 5.0, 1.0];
    let rho = 0.8f32;
    let r = vec![[rho; 3]; n];
    let want = |i: usize, c: usize| {
        e[i][c] as f64 + rho as f64 * emitted(&areas, &e, c) / ((1.0 - rho as f64) * total)
    };
    let worst = |s: &Solution| {
        (0..n)
            .flat_map(|i| (0..3).map(move |c| (i, c)))
            .map(|(i, c)| ((s.b[0][i][c] - want(i, c)) / want(i, c)).abs())
            .fold(0.0, f64::max)
    };
    for method in SolveMethod::ALL {
        let with = |dropped| SolveConfig {
            dropped,
            ..cfg(method, 1e-10)
        };
        let pooled = solve(&src, &[e.clone()], &r, &with(DroppedMass::Pool)).unwrap();
        // f32 storage of the entries: about 1e-7 relative.
        assert!(
            worst(&pooled) < 1e-5,
            "{method}: pooled {:e}",
            worst(&pooled)
        );
        let escaped = pooled.energy[0].escaped[0] / pooled.energy[0].total[0];
        assert!(escaped.abs() < 1e-6, "{method}: escaped {escaped:e}");
        let scaled = solve(&src, &[e.clone()], &r, &with(DroppedMass::Scale)).unwrap();
        assert!(
            worst(&scaled) > 1e-2,
            "{method}: scaled {:e}",
            worst(&scaled)
        );
    }
}

/// A random closed reciprocal matrix (A_i F_ij = G_ij = G_ji, rows summing to 1)
/// truncated to each row's 8 largest entries, with patches that reflect nothing (one
/// of them emits): every gathering method's pooled answer is the dense solution of the
/// matrix the pool documents (built independently in [`documented_matrix`]), and no
/// power escapes; with uniform ρ every method gives Σ A B = Φ / (1 − ρ).
#[test]
fn the_pooled_solve_solves_the_documented_matrix_and_conserves_power() {
    let mut rng = SplitMix64::new(99);
    let n = 40;
    let mut g = vec![vec![0.0f64; n]; n];
    for (i, j) in (0..n).flat_map(|i| (i + 1..n).map(move |j| (i, j))) {
        let x = rng.next_f64().powi(4);
        g[i][j] = x;
        g[j][i] = x;
    }
    let areas: Vec<f64> = g.iter().map(|r| r.iter().sum()).collect();
    let rows: Vec<Row> = (0..n)
        .map(|i| {
            let f: Vec<f64> = g[i].iter().map(|x| x / areas[i]).collect();
            let mut order: Vec<usize> = (0..n).collect();
            order.sort_by(|&a, &b| f[b].total_cmp(&f[a]).then(a.cmp(&b)));
            let mut cols: Vec<u32> = order[..8].iter().map(|&j| j as u32).collect();
            cols.sort_unstable();
            let vals: Vec<f32> = cols.iter().map(|&j| f[j as usize] as f32).collect();
            let stored: f64 = vals.iter().map(|&v| v as f64).sum();
            Row {
                index: i as u32,
                values: RowValues::Sparse { cols, vals },
                dropped: (1.0 - stored) as f32,
                links: Vec::new(),
                link_error: None,
            }
        })
        .collect();
    let src = source(&areas, rows);
    let mut rho: Vec<[f32; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| (0.3 + 0.6 * rng.next_f64()) as f32))
        .collect();
    for i in [3, 17, 29] {
        rho[i] = [0.0; 3];
    }
    let mut e = vec![[0.0f32; 3]; n];
    e[3] = [5.0, 1.0, 0.5];
    e[10] = [0.0, 2.0, 1.0];
    let tol = 1e-11;
    let reference = dense_reference(&src, &e, &rho, DroppedMass::Pool);
    for method in [SolveMethod::Jacobi, SolveMethod::GaussSeidel] {
        let s = solve(&src, &[e.clone()], &rho, &cfg(method, tol)).unwrap();
        let d = rel_diff(&s.b[0], &reference);
        assert!(d < 2.0 * error_bound(tol, 0.9), "{method}: vs dense {d:e}");
        for c in 0..3 {
            let r = &s.energy[0];
            assert!(
                (r.escaped[c] / r.total[c]).abs() < 1e-6,
                "{method} channel {c}: escaped {:e} of {:e}",
                r.escaped[c],
                r.total[c]
            );
        }
    }
    // Shooting solves the pool's other form (rows read from the shooter's side); with
    // uniform ρ conservation fixes Σ A B for it too.
    let uniform = vec![[0.7f32; 3]; n];
    for method in SolveMethod::ALL {
        let s = solve(&src, &[e.clone()], &uniform, &cfg(method, 1e-11)).unwrap();
        for c in 0..3 {
            let want = emitted(&areas, &e, c) / (1.0 - 0.7f32 as f64);
            let got = total_power(&areas, &s.b[0], c);
            assert!(
                ((got - want) / want).abs() < 1e-6,
                "{method}: Σ A B {got} vs {want}"
            );
        }
    }
}

/// Non-reciprocal truncation (the sphere keeps its 50 largest columns in every row):
/// shooting distributes each shooter's whole power (kept entries and the pool), so it
/// conserves exactly whatever the truncation.
#[test]
fn shooting_conserves_power_with_asymmetric_top_k() {
    let n = 300;
    let (areas, order, src) = sphere_top_50(n, 31337);
    let mut e = vec![[0.0f32; 3]; n];
    e[order[n - 1]] = [10.0, 10.0, 10.0]; // a small emitter outside the kept columns
    e[order[0]] = [1.0, 0.0, 0.0];
    for rho in [0.5f32, 0.9, 0.99] {
        let r = vec![[rho; 3]; n];
        let s = solve(&src, &[e.clone()], &r, &cfg(SolveMethod::Shooting, 1e-8)).unwrap();
        for c in 0..2 {
            let want = emitted(&areas, &e, c) / (1.0 - rho as f64);
            let got = total_power(&areas, &s.b[0], c);
            assert!(
                ((got - want) / want).abs() < 1e-4,
                "ρ={rho} c={c}: {got} vs {want}"
            );
        }
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

/// An open scene: every row sums to 0.8 (20 % of the light leaves). With uniform ρ,
/// P = Σ A B = Φ / (1 − 0.8 ρ), incident = 0.8 P, escaped = 0.2 P.
#[test]
fn energy_report_of_an_open_scene() {
    let n = 32;
    let areas = vec![2.0; n];
    let rows: Vec<Row> = (0..n as u32)
        .map(|i| Row::dense(i, vec![0.8 / n as f32; n]))
        .collect();
    let src = source(&areas, rows);
    let mut e = vec![[0.0f32; 3]; n];
    e[3] = [1.0, 1.0, 1.0];
    let rho = 0.75;
    let s = solve(
        &src,
        &[e.clone()],
        &vec![[rho as f32; 3]; n],
        &cfg(SolveMethod::Jacobi, 1e-12),
    )
    .unwrap();
    let phi = 2.0;
    let p = phi / (1.0 - 0.8 * rho);
    let rep = &s.energy[0];
    for c in 0..3 {
        assert!((rep.total[c] - p).abs() < 1e-6 * p, "{rep}");
        assert!((rep.incident[c] - 0.8 * p).abs() < 1e-6 * p, "{rep}");
        assert!((rep.escaped[c] - 0.2 * p).abs() < 1e-6 * p, "{rep}");
        assert!((rep.reflected[c] - (p - phi)).abs() < 1e-6 * p, "{rep}");
        assert!(
            (rep.absorbed[c] - (1.0 - rho) * 0.8 * p).abs() < 1e-6 * p,
            "{rep}"
        );
        assert!(rep.imbalance()[c].abs() < 1e-6, "{rep}");
    }
}

// ---------------------------------------------------------------- outputs

/// CSV: exact header, one line per patch, values read back bit for bit; group table
/// gives area-weighted averages.
#[test]
fn csv_round_trip_and_group_table() {
    let dir = tempfile::tempdir().unwrap();
    let mut ps = patch_set(&[1.0, 3.0, 2.0, 2.0]);
    ps.groups = vec!["floor, east".into(), "lamp".into()];
    ps.patches[2].group = 1;
    ps.patches[3].group = 1;
    let rows: Vec<Row> = (0..4u32)
        .map(|i| Row::dense(i, vec![0.1, 0.2, 0.3, 0.1]))
        .collect();
    let src = MemoryRows::new(ps.clone(), rows).unwrap();
    let e = vec![[0.0; 3], [0.0; 3], [1.5, 0.1, 0.0], [0.0; 3]];
    let rho = vec![[0.5f32, 0.25, 0.125]; 4];
    let s = solve(
        &src,
        &[e.clone(), e.clone()],
        &rho,
        &cfg(SolveMethod::GaussSeidel, 1e-12),
    )
    .unwrap();
    let path = case_path(&dir.path().join("radiosity.csv"), 1, 2);
    assert!(path.ends_with("radiosity_case1.csv"));
    assert_eq!(case_path(Path::new("r.csv"), 0, 1), Path::new("r.csv"));
    write_csv(&path, &ps, &s, 1).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], CSV_HEADER);
    assert!(lines[0].starts_with("patch,group,area,B_r,B_g,B_b"));
    assert_eq!(lines.len(), 5);
    assert!(lines[1].starts_with("0,\"floor, east\",1,"), "{}", lines[1]);
    let back = read_radiosity_csv(&path, 4).unwrap();
    assert_eq!(back, s.radiosity_f32(1));
    // The other columns: E, rho and H read back exactly.
    let fields: Vec<&str> = lines[3].rsplitn(10, ',').collect();
    let tail: Vec<&str> = fields[..9].iter().rev().copied().collect();
    let as_f32 = |x: &str| x.parse::<f32>().unwrap();
    assert_eq!(
        tail[..3].iter().map(|x| as_f32(x)).collect::<Vec<_>>(),
        e[2]
    );
    assert_eq!(
        tail[3..6].iter().map(|x| as_f32(x)).collect::<Vec<_>>(),
        rho[2]
    );
    assert_eq!(tail[8].parse::<f64>().unwrap(), s.h[1][2][2]);
    // Group table: Σ A B / Σ A.
    let table = group_table(&ps, &s, 0).unwrap();
    assert_eq!(table.len(), 2);
    let b = &s.b[0];
    let want_floor = (1.0 * b[0][0] + 3.0 * b[1][0]) / 4.0;
    assert!((table[0].b[0] - want_floor).abs() < 1e-15 * want_floor);
    assert_eq!(table[1].area, 4.0);
    assert_eq!(table[1].patches, 2);
    let text = format_group_table(&table);
    assert!(text.lines().next().unwrap().starts_with("group"));
    assert!(text.contains("floor, east") && text.contains("lamp"));
    // A file with a patch missing is refused, naming the patch.
    std::fs::write(&path, format!("{CSV_HEADER}\n0,g,1,1,1,1\n")).unwrap();
    let err = read_radiosity_csv(&path, 2).unwrap_err();
    assert!(err.to_string().contains("patch 1"), "{err}");
}

/// Emission cases from a CSV drive a multi-case solve: a case lighting group "lamp"
/// equals the scene whose lamp emits the same.
#[test]
fn emission_cases_file_drives_a_multi_case_solve() {
    let areas = [1.0; 6];
    let mut ps = patch_set(&areas);
    ps.groups = vec!["walls".into(), "lamp".into()];
    ps.patches[5].group = 1;
    let src = MemoryRows::new(ps.clone(), cube_rows()).unwrap();
    let text = "case,group,e_r,e_g,e_b\nnight,lamp,2,2,2\nday,walls,0.5,0.5,0.5\n";
    let cases = parse_emission_cases(text, Path::new("cases.csv"), &ps).unwrap();
    assert_eq!(cases.names, ["night", "day"]);
    let rho = vec![[0.5f32; 3]; 6];
    let s = solve(&src, &cases.sets, &rho, &cfg(SolveMethod::Jacobi, 1e-12)).unwrap();
    // Night: only face 5 emits; Σ A B = 2 / (1 − 0.5 S) with S the stored row sum.
    let s_row = cube_rows()[0].stored_sum();
    let night = total_power(&areas, &s.b[0], 0);
    assert!((night - 2.0 / (1.0 - 0.5 * s_row)).abs() < 1e-9);
    // Day: five walls at 0.5: Σ A B = 2.5 / (1 − 0.5 S).
    let day = total_power(&areas, &s.b[1], 1);
    assert!((day - 2.5 / (1.0 - 0.5 * s_row)).abs() < 1e-9);
}

/// Parse a PLY file written by `write_ply_with` (either encoding): vertices with
/// colours, faces.
type PlyMesh = (Vec<[f32; 3]>, Vec<[u8; 3]>, Vec<Vec<i32>>);

fn parse_ply(bytes: &[u8]) -> PlyMesh {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("end_header")
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let mut nv = 0;
    let mut nf = 0;
    let mut binary = false;
    for l in header.lines() {
        let w: Vec<&str> = l.split_whitespace().collect();
        match w.as_slice() {
            ["format", "ascii", "1.0"] => binary = false,
            ["format", "binary_little_endian", "1.0"] => binary = true,
            ["element", "vertex", k] => nv = k.parse().unwrap(),
            ["element", "face", k] => nf = k.parse().unwrap(),
            _ => {}
        }
    }
    assert_eq!(header.lines().next(), Some("ply"));
    let (mut pos, mut col, mut faces) = (Vec::new(), Vec::new(), Vec::new());
    let body = &bytes[end..];
    if binary {
        let mut at = 0;
        let f32_at = |at: usize| f32::from_le_bytes(body[at..at + 4].try_into().unwrap());
        for _ in 0..nv {
            pos.push([f32_at(at), f32_at(at + 4), f32_at(at + 8)]);
            col.push([body[at + 12], body[at + 13], body[at + 14]]);
            at += 15;
        }
        for _ in 0..nf {
            let k = body[at] as usize;
            at += 1;
            let f = (0..k)
                .map(|q| i32::from_le_bytes(body[at + 4 * q..at + 4 * q + 4].try_into().unwrap()))
                .collect();
            at += 4 * k;
            faces.push(f);
        }
        assert_eq!(at, body.len(), "trailing bytes");
    } else {
        let text = std::str::from_utf8(body).unwrap();
        let mut lines = text.lines();
        for _ in 0..nv {
            let w: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
            pos.push(std::array::from_fn(|c| w[c].parse().unwrap()));
            col.push(std::array::from_fn(|c| w[3 + c].parse().unwrap()));
        }
        for _ in 0..nf {
            let w: Vec<i32> = lines
                .next()
                .unwrap()
                .split_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            assert_eq!(w[0] as usize, w.len() - 1);
            faces.push(w[1..].to_vec());
        }
        assert!(lines.next().is_none(), "trailing lines");
    }
    (pos, col, faces)
}

/// A unit cube cut into 2 × 2 quads per face (24 patches), one group per face: 26
/// distinct points (8 corners, 12 edge midpoints, 6 face centres), 9 vertices per face
/// once faces are not smoothed into each other (groups, and 90° creases).
fn subdivided_cube() -> PatchSet {
    let mut patches = Vec::new();
    let mut groups = Vec::new();
    for axis in 0..3 {
        for side in [0.0, 1.0] {
            let g = groups.len() as u32;
            groups.push(format!("face{axis}{side}"));
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for a in 0..2 {
                for b in 0..2 {
                    let corner = |du: f64, dv: f64| {
                        let mut p = [0.0; 3];
                        p[axis] = side;
                        p[u] = (a as f64 + du) * 0.5;
                        p[v] = (b as f64 + dv) * 0.5;
                        DVec3::from_array(p)
                    };
                    let mut p = patch(0.25, g);
                    p.n_corners = 4;
                    p.corners = [
                        corner(0., 0.),
                        corner(1., 0.),
                        corner(1., 1.),
                        corner(0., 1.),
                    ];
                    patches.push(p);
                }
            }
        }
    }
    PatchSet { patches, groups }
}

/// sRGB transfer function (IEC 61966-2-1) and 8-bit code, written out here.
fn srgb8(linear: f64) -> u8 {
    let x = linear.clamp(0.0, 1.0);
    let e = if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round() as u8
}

#[test]
fn ply_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let ps = subdivided_cube();
    let b = [0.2f32, 0.1, 0.05];
    let radiosity = vec![b; ps.len()];
    let mut decoded = Vec::new();
    for encoding in [PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian] {
        let path = dir.path().join(format!("lit-{encoding:?}.ply"));
        let opts = PlyOptions {
            encoding,
            exposure: None,
        };
        let exposure = write_ply_with(&path, &ps, &radiosity, &opts).unwrap();
        // The picture's automatic exposure: 0.8 over the luminance (BT.709) of the
        // (uniform) non-emitting patches.
        let y = 0.2126 * 0.2 + 0.7152 * 0.1 + 0.0722 * 0.05;
        assert!((f64::from(exposure) - 0.8 / y).abs() < 1e-5 * exposure as f64);
        let (pos, col, faces) = parse_ply(&std::fs::read(&path).unwrap());
        assert_eq!(pos.len(), 6 * 9, "9 vertices per face");
        assert_eq!(faces.len(), 24);
        for f in &faces {
            assert_eq!(f.len(), 4);
            assert!(f.iter().all(|&i| i >= 0 && (i as usize) < pos.len()));
        }
        // Every vertex lies on the half-unit lattice; 26 distinct points.
        let mut points: Vec<[f32; 3]> = Vec::new();
        for p in &pos {
            assert!(p.iter().all(|x| [0.0, 0.5, 1.0].contains(x)), "{p:?}");
            if !points.contains(p) {
                points.push(*p);
            }
        }
        assert_eq!(points.len(), 26);
        // No two vertices of one face's quads coincide: each face's 4 quads use 9.
        for face in faces.chunks(4) {
            let mut ids: Vec<i32> = face.iter().flatten().copied().collect();
            ids.sort_unstable();
            ids.dedup();
            assert_eq!(ids.len(), 9);
        }
        let want = b.map(|x| srgb8(f64::from(x) * 0.8 / y));
        assert!(col.iter().all(|c| *c == want), "{:?} vs {want:?}", col[0]);
        decoded.push((pos, col, faces));
    }
    assert_eq!(
        decoded[0], decoded[1],
        "ASCII and binary hold the same mesh"
    );
    // Explicit exposure 2.5: linear 0.5, 0.25, 0.125 → 188, 137, 99.
    let path = dir.path().join("exposed.ply");
    let opts = PlyOptions {
        encoding: PlyEncoding::Ascii,
        exposure: Some(2.5),
    };
    write_ply_with(&path, &ps, &radiosity, &opts).unwrap();
    let (_, col, _) = parse_ply(&std::fs::read(&path).unwrap());
    assert!(col.iter().all(|c| *c == [188, 137, 99]), "{:?}", col[0]);
    assert!(write_ply_with(&path, &ps, &radiosity[1..], &opts).is_err());
}

/// The summary names the method, the counts and every case's power balance.
#[test]
fn summary_reports_iterations_residual_and_energy() {
    let areas = [1.0; 6];
    let src = source(&areas, cube_rows());
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0; 3];
    let rho = vec![[0.5f32; 3]; 6];
    let mut c = cfg(SolveMethod::Jacobi, 1e-12);
    c.max_iterations = 3;
    let s = solve(&src, &[e.clone(), e], &rho, &c).unwrap();
    assert!(!s.converged);
    assert_eq!(s.iterations, 3);
    let text = s.summary();
    eprintln!("{text}");
    assert!(text.starts_with("jacobi: 3 sweeps"), "{text}");
    assert!(
        text.contains("NOT converged") && text.contains("case 1 power"),
        "{text}"
    );
    assert!(
        s.warnings[0].contains("iteration limit"),
        "{:?}",
        s.warnings
    );
}
