//! Exact visibility (`--visibility exact`) against references computed by an
//! independent route: `tests/reference/occluded_ff.py` (Python, shapely) cuts the
//! receiver at the lines where a shadow changes shape and integrates the
//! point-to-visible-polygon form factor with an adaptive degree-9 rule on each piece,
//! and for the centred square blocker also by a closed form. The cases and values are
//! in `tests/data/occluded_refs.json`; docs/known-answers.md §8 describes them.

use ffstream::formfactor::{FormFactorConfig, Scratch, Visibility};
use glam::{dvec3, DVec3};
use serde_json::Value;

use super::scenes::{all_rows, group_ff, Built};

/// One case of the JSON file: two parallelograms (corners counter-clockwise seen from
/// the front), the occluder triangles, the reference group factors.
struct Case {
    name: String,
    i: [DVec3; 4],
    j: [DVec3; 4],
    occluders: Vec<[DVec3; 3]>,
    f_ij: f64,
    f_ji: f64,
}

fn point(v: &Value) -> DVec3 {
    let c: Vec<f64> = v
        .as_array()
        .expect("a point is an array")
        .iter()
        .map(|x| x.as_f64().expect("a coordinate is a number"))
        .collect();
    DVec3::new(c[0], c[1], c[2])
}

fn points<const N: usize>(v: &Value) -> [DVec3; N] {
    let ps: Vec<DVec3> = v.as_array().expect("a polygon").iter().map(point).collect();
    ps.try_into().expect("corner count")
}

fn cases() -> Vec<Case> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/occluded_refs.json");
    let text = std::fs::read_to_string(path).expect("tests/data/occluded_refs.json");
    let all: Value = serde_json::from_str(&text).expect("valid JSON");
    all.as_array()
        .expect("a list of cases")
        .iter()
        .map(|c| Case {
            name: c["name"].as_str().expect("name").to_string(),
            i: points(&c["i"]),
            j: points(&c["j"]),
            occluders: c["occluders"]
                .as_array()
                .expect("occluders")
                .iter()
                .map(points)
                .collect(),
            f_ij: c["F_ij"].as_f64().expect("F_ij"),
            f_ji: c["F_ji"].as_f64().expect("F_ji"),
        })
        .collect()
}

/// The case as a scene: i (group 0) and j (group 1) cut m × m, the occluders as
/// triangles that are no patches.
fn scene(c: &Case, m: usize) -> Built {
    let mut b = Built::default();
    for (name, q) in [("i", &c.i), ("j", &c.j)] {
        // Parallelograms: the fourth corner is q0 + (q1 − q0) + (q3 − q0).
        assert!((q[0] + (q[1] - q[0]) + (q[3] - q[0]) - q[2]).length() < 1e-12);
        b.cells(name, q[0], q[1] - q[0], q[3] - q[0], (m, m), false);
    }
    for (k, t) in c.occluders.iter().enumerate() {
        b.tris.push((1000 + k as u32, *t));
    }
    b
}

/// Exact visibility to 1e-6 of each entry's F⁰ (the `reference` preset's shadow
/// tolerance, tighter than `--visibility exact` alone gets from `accurate`).
fn exact_cfg() -> FormFactorConfig {
    let mut cfg = FormFactorConfig::accurate();
    cfg.visibility = Visibility::Exact;
    cfg.shadow_tol = 1e-6;
    cfg
}

#[test]
fn exact_visibility_matches_the_independent_references() {
    // Acceptance of the exact route: group factors within 1e-6 of the reference (the
    // shadow tolerance is 1e-6 of each entry's F⁰; f32 storage adds ~1e-8).
    let mut worst = 0.0f64;
    for c in cases() {
        for m in [1, 3] {
            let b = scene(&c, m);
            let e = b.engine(exact_cfg());
            let mut s = Scratch::new();
            let rows: Vec<_> = (0..e.n() as u32)
                .map(|i| e.compute_row(i, &mut s))
                .collect();
            let counters = s.counters();
            let (f_ij, f_ji) = (
                group_ff(&b.patches, &rows, 0, 1),
                group_ff(&b.patches, &rows, 1, 0),
            );
            let (e_ij, e_ji) = (f_ij - c.f_ij, f_ji - c.f_ji);
            println!(
                "{} m={m}: F_ij {f_ij:.10} (ref {:.10}, err {e_ij:+.1e}), F_ji {f_ji:.10} (ref {:.10}, err {e_ji:+.1e}); {} pairs exact, {} fell back to rays",
                c.name, c.f_ij, c.f_ji, counters.pairs_exact, counters.pairs_exact_fallback
            );
            worst = worst.max(e_ij.abs()).max(e_ji.abs());
            assert!(
                e_ij.abs() <= 1e-6 && e_ji.abs() <= 1e-6,
                "{} m={m}: F_ij {f_ij} vs {}, F_ji {f_ji} vs {}",
                c.name,
                c.f_ij,
                c.f_ji
            );
        }
    }
    println!("worst error {worst:.1e}");
}

/// Each triangle cut into 4^levels by its edge midpoints (shared edges are cut at
/// bit-identical points: (a + b) / 2 does not depend on the order).
fn split(t: [DVec3; 3], levels: u32) -> Vec<[DVec3; 3]> {
    let mut tris = vec![t];
    for _ in 0..levels {
        tris = tris
            .into_iter()
            .flat_map(|[a, b, c]| {
                let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
    }
    tris
}

#[test]
fn split_occluders_merged_again_are_handled_exactly() {
    // The occluders of every case given as a mesh already split into facets (64 per
    // triangle, as a mesher would deliver them): more candidates than the exact route
    // takes, so without the merge pairs get rays; merged, every pair is exact again
    // and the group factors are within 1e-6 of the independent references.
    use ffstream::formfactor::RowEngine;
    use ffstream::geometry::merge::merge_coplanar;
    use ffstream::geometry::occluders::Occluders;
    use std::sync::Arc;
    let mut split_rays = 0;
    for c in cases() {
        let mut b = scene(&c, 2);
        let unsplit = b.tris.len();
        b.tris = b
            .tris
            .iter()
            .flat_map(|&(f, t)| split(t, 3).into_iter().map(move |s| (f, s)))
            .collect();
        let run = |occ: Occluders| {
            let e = RowEngine::new(&b.patches, Arc::new(occ), exact_cfg());
            let mut s = Scratch::new();
            let rows: Vec<_> = (0..e.n() as u32)
                .map(|i| e.compute_row(i, &mut s))
                .collect();
            (rows, s.counters())
        };
        if c.name == "obstructed" {
            // (Once: the split occluders are slow to clip where they are few enough.)
            let (_, split_counters) = run(Occluders::new(b.tris.clone()));
            split_rays += split_counters.rays_cast;
        }
        let merged = merge_coplanar(b.tris.iter().map(|t| t.1));
        assert!(
            merged.triangles.len() <= unsplit,
            "{}: {} triangles merged into {}, the case has {unsplit} unsplit",
            c.name,
            b.tris.len(),
            merged.triangles.len(),
        );
        let foreign: Vec<_> = (0u32..).zip(merged.triangles).collect();
        let (rows, counters) = run(Occluders::new_foreign(foreign));
        assert_eq!(counters.pairs_exact_fallback, 0, "{}: {counters:?}", c.name);
        assert_eq!(counters.rays_cast, 0, "{}: {counters:?}", c.name);
        let (f_ij, f_ji) = (
            group_ff(&b.patches, &rows, 0, 1),
            group_ff(&b.patches, &rows, 1, 0),
        );
        assert!(
            (f_ij - c.f_ij).abs() <= 1e-6 && (f_ji - c.f_ji).abs() <= 1e-6,
            "{}: F_ij {f_ij} vs {}, F_ji {f_ji} vs {}",
            c.name,
            c.f_ij,
            c.f_ji
        );
    }
    assert!(split_rays > 0, "the split occluders never needed rays");
}

/// A pair that shows less than 1 % of itself keeps it at `--shadow-tol 1e-2`: only a
/// small share of the tolerance counts as nothing. (The snap was the whole tolerance
/// once, and this pair came out 0.)
#[test]
fn a_small_visible_remainder_survives_a_loose_tolerance() {
    // Unit squares 1 apart (y = 0 facing +y, y = 1 facing −y); a wall midway hides
    // every segment whose ends' heights sum to less than 1.9: P_i sees only a corner of
    // P_j, from near its own top edge.
    let (o, x, y, z) = (DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z);
    let wall = [
        dvec3(-3.0, 0.5, -3.0),
        dvec3(4.0, 0.5, -3.0),
        dvec3(4.0, 0.5, 0.95),
        dvec3(-3.0, 0.5, 0.95),
    ];
    let c = Case {
        name: "sliver".into(),
        i: [o, z, x + z, x],
        j: [y, y + x, y + x + z, y + z],
        occluders: vec![[wall[0], wall[1], wall[2]], [wall[0], wall[2], wall[3]]],
        f_ij: 0.0,
        f_ji: 0.0,
    };
    let b = scene(&c, 1);
    let entry = |tol: f64| {
        let mut cfg = exact_cfg();
        cfg.shadow_tol = tol;
        let e = b.engine(cfg);
        let mut s = Scratch::new();
        let rows: Vec<_> = (0..e.n() as u32)
            .map(|i| e.compute_row(i, &mut s))
            .collect();
        assert_eq!(s.counters().pairs_exact, 2, "{:?}", s.counters());
        group_ff(&b.patches, &rows, 0, 1)
    };
    // F⁰ of two unit squares 1 apart (Howell C-11).
    let f0 = 0.199_824_895_7;
    let (tight, loose) = (entry(1e-6), entry(1e-2));
    assert!(
        tight > 1e-3 * f0 && tight < 1e-2 * f0,
        "the case shows {:.2e} of F0, meant between 0.1 % and 1 %",
        tight / f0
    );
    assert!(loose > 0.0, "snapped to 0 (tight {tight:.3e})");
    assert!(
        (loose - tight).abs() <= 1e-2 * f0,
        "{loose:.3e} vs {tight:.3e}"
    );
}

#[test]
fn exactly_handled_pairs_use_no_random_numbers() {
    // Every pair of these cases is handled exactly (no fallback to rays), so the rows
    // are the same for any seed, bitwise.
    for c in cases() {
        let b = scene(&c, 2);
        let a = all_rows(&b.engine(exact_cfg().with_seed(1)));
        let e = b.engine(exact_cfg().with_seed(987_654_321));
        let mut s = Scratch::new();
        let z: Vec<_> = (0..e.n() as u32)
            .map(|i| e.compute_row(i, &mut s))
            .collect();
        let counters = s.counters();
        assert_eq!(counters.pairs_exact_fallback, 0, "{}", c.name);
        assert_eq!(counters.rays_cast, 0, "{}: {counters:?}", c.name);
        assert_eq!(a, z, "{}: rows depend on the seed", c.name);
    }
}

/// The counts of the report line `pairs: N evaluated; visibility: A (..%) need none,
/// B (..%) exact, C (..%) by rays (D of them fell back from exact)`.
fn pair_routes(stderr: &str) -> [u64; 5] {
    let line = stderr
        .lines()
        .find(|l| l.starts_with("pairs: "))
        .unwrap_or_else(|| panic!("no pairs line in\n{stderr}"));
    let numbers: Vec<u64> = line
        .split(|c: char| !c.is_ascii_digit() && c != '.')
        .filter(|w| !w.is_empty() && !w.contains('.'))
        .map(|w| w.parse().expect("a count"))
        .collect();
    // N, A, B, C, D (the percentages hold a '.').
    [numbers[0], numbers[1], numbers[2], numbers[3], numbers[4]]
}

#[test]
fn compute_reports_the_pairs_handled_each_way_and_exact_rows_ignore_the_seed() {
    use crate::common::{ok, path_str};
    let dir = tempfile::tempdir().expect("tempdir");
    let file = |name: &str| dir.path().join(name);
    let run = |out: &str, extra: &[&str]| {
        let out = file(out);
        let mut args = vec![
            "compute",
            "builtin:obstructed",
            "--max-edge",
            "0.25",
            "--symmetric",
            "off",
            "-q",
            "-o",
            path_str(&out),
        ];
        args.extend_from_slice(extra);
        ok(&args)
    };
    let said = run("x1.ffz", &["--visibility", "exact", "--seed", "1"]);
    let [n, none, exact, rays, fallback] = pair_routes(&said);
    assert!(
        exact > 0 && rays == 0 && fallback == 0 && none + exact == n,
        "{n} {none} {exact} {rays}"
    );
    // The exact pairs split into the shortcuts and the partly shadowed ones, which
    // took outer points (the blocker hides part of the receiver from some patches).
    let tail = said
        .split("of the exact: ")
        .nth(1)
        .unwrap_or_else(|| panic!("no breakdown of the exact pairs in\n{said}"));
    let counts: Vec<f64> = tail
        .split(|c: char| !c.is_ascii_digit() && c != '.')
        .filter(|w| !w.is_empty() && *w != ".")
        .map(|w| w.parse().expect("a number"))
        .collect();
    let (visible, hidden, partly, mean) = (counts[0], counts[1], counts[2], counts[3]);
    assert!(
        visible + hidden + partly == exact as f64 && partly > 0.0 && mean >= 1.0,
        "{tail}"
    );
    run("x2.ffz", &["--visibility", "exact", "--seed", "2"]);
    let out = crate::common::ffstream(&[
        "verify",
        path_str(&file("x1.ffz")),
        "--against",
        path_str(&file("x2.ffz")),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.contains(" 0 differ"),
        "rows depend on --seed:\n{stdout}"
    );
    // Rays are counted where they are cast: in dense rows every pair that may be
    // occluded gets them.
    let [n2, none2, exact2, rays2, _] = pair_routes(&run("r.ffz", &[]));
    assert!(
        exact2 == 0 && rays2 == exact && none2 == none && n2 == n && none2 + rays2 == n2,
        "rays run: {n2} {none2} {exact2} {rays2}"
    );
    // The file keeps what the run printed, and `info` prints it (formats/ffz-v1.md
    // §6.1): the same line, over all the rows.
    let printed = said
        .lines()
        .find(|l| l.starts_with("pairs: "))
        .expect("the pairs line");
    let info = |name: &str| {
        let out = crate::common::ffstream(&["info", path_str(&file(name))]);
        assert!(out.status.success(), "{out:?}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let shown = info("x1.ffz");
    let rows = ffstream::ffz::FfzReader::open(file("x1.ffz")).unwrap().n();
    let routes = shown
        .lines()
        .find(|l| l.starts_with("routes:"))
        .unwrap_or_else(|| panic!("no routes line in\n{shown}"));
    assert!(
        routes.contains(&format!("over the {rows} rows")) && routes.ends_with(printed),
        "{routes}\nvs what compute printed:\n{printed}"
    );
}

/// builtin:obstructed (unit squares 1 apart facing each other, a square blocker
/// midway seen from both sides) as a mesher would deliver it: the plates in 2 × 2
/// facets, the blocker in 6 × 6 on each side, one face per facet.
fn presplit_obstructed(dir: &std::path::Path) -> std::path::PathBuf {
    use std::fmt::Write;
    let mut obj = String::from("mtllib split.mtl\n");
    let mut nv = 0;
    // Facets of origin + [0,1]·u + [0,1]·v in m × m, counter-clockwise about u × v.
    let mut grid = |obj: &mut String, o: [f64; 3], u: [f64; 3], v: [f64; 3], m: usize| {
        let p = |a: f64, b: f64| [0, 1, 2].map(|k| o[k] + a * u[k] + b * v[k]);
        for i in 0..m {
            for j in 0..m {
                let (a0, a1) = (i as f64 / m as f64, (i + 1) as f64 / m as f64);
                let (b0, b1) = (j as f64 / m as f64, (j + 1) as f64 / m as f64);
                for q in [p(a0, b0), p(a1, b0), p(a1, b1), p(a0, b1)] {
                    writeln!(obj, "v {} {} {}", q[0], q[1], q[2]).unwrap();
                }
                writeln!(obj, "f {} {} {} {}", nv + 1, nv + 2, nv + 3, nv + 4).unwrap();
                nv += 4;
            }
        }
    };
    obj.push_str("g bottom\nusemtl light\n");
    grid(&mut obj, [0.0; 3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 2);
    obj.push_str("g top\nusemtl white\n");
    grid(
        &mut obj,
        [0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        2,
    );
    obj.push_str("g blocker\nusemtl white\n");
    grid(
        &mut obj,
        [0.25, 0.5, 0.25],
        [0.5, 0.0, 0.0],
        [0.0, 0.0, 0.5],
        6,
    );
    grid(
        &mut obj,
        [0.25, 0.5, 0.25],
        [0.0, 0.0, 0.5],
        [0.5, 0.0, 0.0],
        6,
    );
    std::fs::write(
        dir.join("split.mtl"),
        "newmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\nnewmtl white\nKd 0.5 0.5 0.5\n",
    )
    .unwrap();
    let path = dir.join("split.obj");
    std::fs::write(&path, obj).unwrap();
    path
}

#[test]
fn compute_merges_a_presplit_mesh_and_a_resume_across_the_flag_is_refused() {
    use crate::common::{ffstream, path_str};
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = presplit_obstructed(dir.path());
    let file = |name: &str| dir.path().join(name);
    // `compute` of the pre-split scene into `out`, exact visibility.
    let compute = |out: &str, extra: &[&str]| {
        let out = file(out);
        let mut args = vec![
            "compute",
            path_str(&scene),
            "--max-edge",
            "0.5",
            "--visibility",
            "exact",
            "-q",
            "-o",
            path_str(&out),
        ];
        args.extend_from_slice(extra);
        ffstream(&args)
    };
    let run = |out: &str, extra: &[&str]| {
        let o = compute(out, extra);
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "compute {extra:?} failed:\n{stderr}");
        stderr
    };
    // 8 plate facets and 72 blocker facets, 160 triangles; merged: the two plates
    // and the blocker's plane, 2 triangles each.
    let merged = run("m.ffz", &[]);
    assert!(
        merged.contains("occluders: 160 triangles, those of 3 planes merged: 6 triangles"),
        "{merged}"
    );
    let [n, none, exact, rays, _] = pair_routes(&merged);
    assert!(
        exact > 0 && rays == 0 && none + exact == n,
        "merged: {merged}"
    );
    let given = run("g.ffz", &["--no-merge-occluders"]);
    assert!(!given.contains("merged"), "{given}");
    let [.., rays_given, _] = pair_routes(&given);
    assert!(
        rays_given > 0,
        "the facets as given should need rays:\n{given}"
    );
    // The header keeps the count as given and the merged one.
    let out = ffstream(&["info", path_str(&file("m.ffz"))]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("occluder_triangles=160 occluders_merged=6"),
        "{stdout}"
    );
    // The file computed without the merge does not resume with it, and says why.
    let out = compute("g.ffz", &["--resume"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("occluders_merged"),
        "{stderr}"
    );
}

/// The shadow tolerance is a promise per entry: |F_ij − exact| ≤ `--shadow-tol` × F⁰_ij,
/// checked at loose tolerances against the same cases at 1e-8 (whose group factors
/// match the independent references within 1e-6), with F⁰ from the same patches without
/// the occluders. Measured worst shares of the promise: 0.015 at 1e-1, 0.048 at 1e-2,
/// 0.15 at 1e-3 (bench/PERF.md §28).
#[test]
fn every_entry_keeps_the_shadow_tolerance() {
    for c in cases() {
        for m in [1, 3, 4] {
            let b = scene(&c, m);
            let rows = |t: f64| {
                let mut cfg = exact_cfg();
                cfg.shadow_tol = t;
                all_rows(&b.engine(cfg))
            };
            let tight = rows(1e-8);
            let mut open = scene(&c, m);
            open.tris.clear();
            let f0 = all_rows(&open.engine(exact_cfg()));
            let n = tight.len();
            for tol in [1e-1, 1e-2, 1e-3] {
                let loose = rows(tol);
                for i in 0..n {
                    let (t, l, z) = (
                        tight[i].to_dense(n),
                        loose[i].to_dense(n),
                        f0[i].to_dense(n),
                    );
                    for j in 0..n {
                        let err = (f64::from(l[j]) - f64::from(t[j])).abs();
                        // f32 storage: half an ulp of each stored value.
                        let slack = 1e-7 * f64::from(t[j]);
                        assert!(
                            err <= tol * f64::from(z[j]) + slack,
                            "{} m={m} tol {tol:e}: F({i},{j}) {} against {} (F0 {})",
                            c.name,
                            l[j],
                            t[j],
                            z[j]
                        );
                    }
                }
            }
        }
    }
}
