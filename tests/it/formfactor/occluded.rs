//! Exact visibility (`--visibility exact`) against references computed by an
//! independent route: `tests/reference/occluded_ff.py` (Python, shapely) cuts the
//! receiver at the lines where a shadow changes shape and integrates the
//! point-to-visible-polygon form factor with an adaptive degree-9 rule on each piece,
//! and for the centred square blocker also by a closed form. The cases and values are
//! in `tests/data/occluded_refs.json`; docs/known-answers.md §8 describes them.

use ffstream::formfactor::{FormFactorConfig, Scratch, Visibility};
use glam::DVec3;
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
        pair_routes(&ok(&args))
    };
    let [n, none, exact, rays, fallback] = run("x1.ffz", &["--visibility", "exact", "--seed", "1"]);
    assert!(
        exact > 0 && rays == 0 && fallback == 0 && none + exact == n,
        "{n} {none} {exact} {rays}"
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
    let [n2, none2, exact2, rays2, _] = run("r.ffz", &[]);
    assert!(
        exact2 == 0 && rays2 == exact && none2 == none && n2 == n && none2 + rays2 == n2,
        "rays run: {n2} {none2} {exact2} {rays2}"
    );
}
