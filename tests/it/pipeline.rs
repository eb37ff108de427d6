//! The whole pipeline on known answers: computed form factors of a closed, subdivided
//! cube, written to an .ffz file and solved from it by every method, conserve power
//! exactly as the closed-enclosure law says: Σ A_i B_i = Φ_E / (1 − ρ).
//! And `solve --emission` through the command line: one pass, several cases, linear.

use std::sync::Arc;

use ffstream::ffz::{FfzReader, FfzWriter, FileMeta, Layout, WriterOptions};
use ffstream::formfactor::{FormFactorConfig, RowEngine, Scratch};
use ffstream::geometry::occluders::Occluders;
use ffstream::geometry::subdivide::subdivide;
use ffstream::scene::builtin;
use ffstream::solve::{self, SolveConfig, SolveMethod};

use crate::common::{ok, path_str};

/// The built-in cube (y1 emits), subdivided 4×4 per face, computed into `path`.
fn cube_file(path: &std::path::Path) -> ffstream::patch::PatchSet {
    let scene = builtin("cube", None).unwrap();
    let patches = Arc::new(subdivide(&scene, 0.25));
    let occluders = Arc::new(Occluders::new(scene.triangles().collect()));
    let engine = RowEngine::new(&patches, occluders, FormFactorConfig::accurate());
    let meta = FileMeta {
        layout: Layout::Dense,
        method: "contour".into(),
        params: ffstream::job::EngineParams::of_engine(&engine).to_string(),
        scene_hash: patches.content_hash(),
        created: "test".into(),
        patches: (*patches).clone(),
        clusters: None,
    };
    let mut w = FfzWriter::create(path, &meta, WriterOptions::default()).unwrap();
    let mut scratch = Scratch::default();
    // Rows in reverse order: the file order must not matter.
    for i in (0..patches.len() as u32).rev() {
        w.push_row(engine.compute_row(i, &mut scratch)).unwrap();
    }
    w.finish().unwrap();
    (*patches).clone()
}

#[test]
fn closed_cube_conserves_power_for_every_method_and_reflectance() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("cube.ffz");
    let patches = cube_file(&f);
    let reader = FfzReader::open(&f).unwrap();
    let emission = solve::scene_emission(&patches);
    let phi: f64 = patches.emitted_power()[0];
    assert!(phi > 0.0, "the built-in cube has an emitting face");
    for rho in [0.5f32, 0.9, 0.99] {
        let rhos = vec![[rho; 3]; patches.len()];
        let mut totals = Vec::new();
        for method in SolveMethod::ALL {
            let cfg = SolveConfig {
                method,
                tolerance: 1e-9,
                ..SolveConfig::default()
            };
            let s = solve::solve(&reader, std::slice::from_ref(&emission), &rhos, &cfg).unwrap();
            assert!(s.converged, "{method} at rho {rho} did not converge");
            let total: f64 = patches
                .patches
                .iter()
                .zip(&s.b[0])
                .map(|(p, b)| p.area * b[0])
                .sum();
            let expected = phi / (1.0 - rho as f64);
            let rel = (total - expected).abs() / expected;
            eprintln!(
                "rho {rho} {method}: Σ A B = {total:.9} expected {expected:.9} (rel {rel:.2e})"
            );
            assert!(
                rel < 1e-4,
                "{method} at rho {rho}: Σ A_i B_i = {total}, expected Φ/(1-ρ) = {expected}"
            );
            totals.push(s.b[0].clone());
        }
        // The methods agree patch by patch within the tolerance's effect.
        let scale = totals[0].iter().map(|b| b[0]).fold(0.0, f64::max);
        for other in &totals[1..] {
            for (a, b) in totals[0].iter().zip(other) {
                assert!(
                    (a[0] - b[0]).abs() <= 1e-6 * scale / (1.0 - rho as f64),
                    "methods disagree at rho {rho}"
                );
            }
        }
    }
}

#[test]
fn solve_emission_cases_from_the_command_line_are_linear() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("cube.ffz");
    cube_file(&f);
    let cases = dir.path().join("cases.csv");
    std::fs::write(
        &cases,
        "case,group,e_r,e_g,e_b\nfloor,y0,1,2,3\nwall,x0,4,0,1\nboth,y0,1,2,3\nboth,x0,4,0,1\n",
    )
    .unwrap();
    let out = dir.path().join("b.csv");
    ok(&[
        "solve",
        path_str(&f),
        "-o",
        path_str(&out),
        "--emission",
        path_str(&cases),
        "--tolerance",
        "1e-10",
    ]);
    let read = |k: usize| {
        let p = dir.path().join(format!("b_case{k}.csv"));
        solve::read_radiosity_csv(&p, 96).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let (a, b, both) = (read(0), read(1), read(2));
    for i in 0..96 {
        for c in 0..3 {
            let sum = a[i][c] + b[i][c];
            assert!(
                (both[i][c] - sum).abs() <= 1e-5 * sum.abs().max(1e-3),
                "patch {i} channel {c}: {} vs {sum}",
                both[i][c]
            );
        }
    }
}
