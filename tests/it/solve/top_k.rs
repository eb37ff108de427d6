//! Top-k rows: renormalised, pooled or absorbed, the dropped mass keeps power
//! conserved as documented; the pool is exact where form factors are uniform and the
//! pooled solve solves the documented matrix.

use super::*;

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
