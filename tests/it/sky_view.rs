//! Open scenes: the sky view factor (1 − row sum) against known answers, and the two
//! `verify` checks that catch rows a visibility fault pushed too high (rows above
//! 1 + tolerance, entries above their unoccluded form factor).

use std::path::Path;

use crate::common::{ffstream, ok, path_str};
use crate::ffz_common::write;
use crate::stress_geom::howell_c14;
use ffstream::ffz::FfzReader;
use ffstream::rows::{Row, RowValues};

/// `export --patches-csv` of `ffz`: (group, area, sky_view) per patch.
fn sky_views(ffz: &Path) -> Vec<(String, f64, f64)> {
    let csv = ffz.with_extension("csv");
    ok(&["export", path_str(ffz), "--patches-csv", path_str(&csv)]);
    let mut table = ::csv::Reader::from_path(&csv).unwrap();
    let head = table.headers().unwrap().clone();
    let col = |name: &str| head.iter().position(|h| h == name).unwrap();
    let (g, a, s) = (col("group"), col("area"), col("sky_view"));
    table
        .records()
        .map(|r| {
            let r = r.unwrap();
            (
                r[g].to_string(),
                r[a].parse().unwrap(),
                r[s].parse().unwrap(),
            )
        })
        .collect()
}

/// `m.mtl` in `dir`: one grey emitting material `lit`.
fn write_mtl(dir: &Path) {
    std::fs::write(dir.join("m.mtl"), "newmtl lit\nKd 0.5 0.5 0.5\nKe 1 1 1\n").unwrap();
}

/// `verify` of `ffz` with `extra` options: (exit code, stdout).
fn verify(ffz: &Path, extra: &[&str]) -> (i32, String) {
    let mut args = vec!["verify", path_str(ffz)];
    args.extend(extra);
    let out = ffstream(&args);
    (
        out.status.code().unwrap(),
        String::from_utf8(out.stdout).unwrap(),
    )
}

/// The numbers of `verify`'s `sky view:` line: min, max, mean.
fn sky_line(report: &str) -> [f64; 3] {
    let line = report
        .lines()
        .find(|l| l.starts_with("sky view:"))
        .unwrap_or_else(|| panic!("no sky view line:\n{report}"));
    let w: Vec<&str> = line.split_whitespace().collect();
    let at = |key: &str| -> f64 {
        let k = w.iter().position(|x| *x == key).unwrap();
        w[k + 1].parse().unwrap()
    };
    [at("min"), at("max"), at("mean")]
}

#[test]
fn an_open_square_sees_only_sky_and_a_closed_box_none() {
    let dir = tempfile::tempdir().unwrap();
    // One horizontal square facing up, cut into 16 patches: no patch sees another.
    let obj = dir.path().join("square.obj");
    write_mtl(dir.path());
    std::fs::write(
        &obj,
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng ground\nusemtl lit\nf 1 2 3 4\n",
    )
    .unwrap();
    let square = dir.path().join("square.ffz");
    ok(&[
        "compute",
        path_str(&obj),
        "--max-edge",
        "0.25",
        "-q",
        "-o",
        path_str(&square),
    ]);
    let s = sky_views(&square);
    assert_eq!(s.len(), 16);
    assert!(s.iter().all(|p| p.2 == 1.0), "{s:?}");
    let (code, report) = verify(&square, &[]);
    assert_eq!(code, 0, "{report}");
    assert_eq!(sky_line(&report), [1.0, 1.0, 1.0], "{report}");

    // The inside of the closed unit cube: every patch sees only walls. The rows are
    // exact (no occluders in a convex room), so 1 − row sum is 0 up to the float32
    // rounding of the entries.
    let cube = dir.path().join("cube.ffz");
    ok(&[
        "compute",
        "builtin:cube",
        "--patches",
        "600",
        "-q",
        "-o",
        path_str(&cube),
    ]);
    let s = sky_views(&cube);
    assert!(s.len() >= 600);
    let worst = s.iter().map(|p| p.2.abs()).fold(0.0, f64::max);
    assert!(
        worst < 1e-6,
        "largest |sky view| in the closed cube: {worst:e}"
    );
    let (code, report) = verify(&cube, &[]);
    assert_eq!(code, 0, "{report}");
    assert!(sky_line(&report).iter().all(|x| x.abs() < 1e-6), "{report}");
    // `info` prints the same line from its own pass over the rows.
    let info = String::from_utf8(ffstream(&["info", path_str(&cube)]).stdout).unwrap();
    assert_eq!(sky_line(&info), sky_line(&report), "{info}");
}

/// A floor strip 1 long and 0.25 deep at the foot of a wall 1 × 1 (groups `floor` and
/// `wall`), with its MTL, in `dir`: the OBJ's path.
fn write_wall_foot(dir: &Path) -> std::path::PathBuf {
    write_mtl(dir);
    let obj = dir.join("foot.obj");
    std::fs::write(
        &obj,
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 0.25 0\nv 0 0.25 0\nv 0 0 1\nv 1 0 1\n\
         usemtl lit\ng floor\nf 1 2 3 4\ng wall\nf 1 5 6 2\n",
    )
    .unwrap();
    obj
}

#[test]
fn the_sky_view_at_the_foot_of_a_wall_is_one_minus_howell_c14() {
    // A floor strip 1 long (along the wall) and 0.25 deep at the foot of a wall 1 × 1,
    // both facing into the open quarter space in front of the wall: the floor's sky
    // view is 1 − F(floor → wall), Howell C-14 with W = 0.25, H = 1; the wall's is
    // 1 − (A_floor / A_wall) F(floor → wall) by reciprocity.
    let dir = tempfile::tempdir().unwrap();
    let obj = write_wall_foot(dir.path());
    let f = howell_c14(0.25, 1.0);
    let want_floor = 1.0 - f;
    let want_wall = 1.0 - 0.25 * f;
    for (edge, name) in [("2", "whole"), ("0.125", "cut")] {
        let ffz = dir.path().join(format!("{name}.ffz"));
        ok(&[
            "compute",
            path_str(&obj),
            "--max-edge",
            edge,
            "-q",
            "-o",
            path_str(&ffz),
        ]);
        let s = sky_views(&ffz);
        // Area-weighted mean over each face's patches (one patch each when whole).
        let mean = |group: &str| {
            let (a, sa) = s
                .iter()
                .filter(|p| p.0 == group)
                .fold((0.0, 0.0), |(a, sa), p| (a + p.1, sa + p.1 * p.2));
            sa / a
        };
        let (floor, wall) = (mean("floor"), mean("wall"));
        println!(
            "{name}: floor {floor:.9} (C-14 {want_floor:.9}), wall {wall:.9} (want {want_wall:.9})"
        );
        assert!(
            (floor - want_floor).abs() < 1e-7,
            "{name}: floor {floor} vs {want_floor}"
        );
        assert!(
            (wall - want_wall).abs() < 1e-7,
            "{name}: wall {wall} vs {want_wall}"
        );
    }
}

/// Top-k rows of an open scene get their dropped mass from hemisphere rays (the header
/// says so): the floor at the foot of the wall, with the rays' row totals, still has
/// the sky view 1 − C-14 within their statistical error; with an `--occluders` mesh the
/// header names the tree walk instead.
#[test]
fn top_k_row_totals_from_hemisphere_rays_give_the_sky_view_of_an_open_scene() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write_wall_foot(dir.path());
    let want_floor = 1.0 - howell_c14(0.25, 1.0);
    // 1,024 rays a row; the tail (about 3,100 patches) is above twice that, so it is
    // not evaluated in full.
    let common = [
        path_str(&obj),
        "--max-edge",
        "0.02",
        "--top-k",
        "2",
        "--top-k-tail",
        "1024",
        "-q",
        "-o",
    ];
    let ffz = dir.path().join("topk.ffz");
    ok(&[&["compute"], &common[..], &[path_str(&ffz)]].concat());
    let info = String::from_utf8(ffstream(&["info", path_str(&ffz)]).stdout).unwrap();
    assert!(info.contains("dropped_mass=hemisphere:1024"), "{info}");
    let s = sky_views(&ffz);
    let (a, sa) = s
        .iter()
        .filter(|p| p.0 == "floor")
        .fold((0.0, 0.0), |(a, sa), p| (a + p.1, sa + p.1 * p.2));
    let floor = sa / a;
    // About 650 floor patches × 1,024 rays: a standard error near 6e-4 at most.
    println!("floor sky view {floor:.5} (1 − C-14: {want_floor:.5})");
    assert!((floor - want_floor).abs() < 3e-3, "{floor} vs {want_floor}");

    let other = dir.path().join("other.ffz");
    ok(&[
        &["compute"],
        &common[..],
        &[path_str(&other), "--occluders", path_str(&obj)],
    ]
    .concat());
    let info = String::from_utf8(ffstream(&["info", path_str(&other)]).stdout).unwrap();
    assert!(info.contains("dropped_mass=tree-walk:1024"), "{info}");
}

/// Every row of `from`, in file order.
fn rows_of(from: &Path) -> (FfzReader, Vec<Row>) {
    let r = FfzReader::open(from).unwrap();
    let mut rows = Vec::new();
    r.scan(|row| rows.push(row.clone())).unwrap();
    (r, rows)
}

#[test]
fn verify_fails_rows_above_one_and_entries_above_their_unoccluded_value() {
    let dir = tempfile::tempdir().unwrap();
    // Perpendicular plates: nothing occludes, so every entry is its own unoccluded
    // value and passes; so do the obstructed plates, whose blocker lowers entries.
    for scene in ["perpendicular", "obstructed"] {
        let ffz = dir.path().join(format!("{scene}.ffz"));
        ok(&[
            "compute",
            &format!("builtin:{scene}"),
            "--patches",
            "300",
            "-q",
            "-o",
            path_str(&ffz),
        ]);
        let (code, report) = verify(&ffz, &["--unoccluded"]);
        assert_eq!(code, 0, "{scene}:\n{report}");
        assert!(report.contains("unoccluded:  0 of "), "{report}");
    }

    // One entry of the perpendicular plates raised by 1 %: above its unoccluded value,
    // a fault only the unoccluded check sees (the row still sums below 1).
    let (r, mut rows) = rows_of(&dir.path().join("perpendicular.ffz"));
    let (mut at, mut best) = ((0, 0), 0.0f32);
    for row in &rows {
        row.for_each_nonzero(|j, x| {
            if x > best {
                (at, best) = ((row.index, j), x);
            }
        });
    }
    let raise = |rows: &mut Vec<Row>, by: f32| {
        for row in rows.iter_mut().filter(|r| r.index == at.0) {
            if let RowValues::Dense(v) = &mut row.values {
                v[at.1 as usize] *= by;
            }
        }
    };
    raise(&mut rows, 1.01);
    let raised = dir.path().join("raised.ffz");
    write(&raised, r.meta(), &rows, 1 << 16);
    let (code, report) = verify(&raised, &[]);
    assert_eq!(
        code, 0,
        "without --unoccluded the raised entry passes:\n{report}"
    );
    let (code, report) = verify(&raised, &["--unoccluded"]);
    assert_eq!(code, 3, "{report}");
    assert!(report.contains("unoccluded:  1 of "), "{report}");
    assert!(
        report.contains(&format!("FAIL: entry ({}, {})", at.0, at.1)),
        "{report}"
    );
    // A tolerance above the raise lets it pass.
    let (code, report) = verify(&raised, &["--unoccluded", "0.02"]);
    assert_eq!(code, 0, "{report}");

    // The same entry raised until its row sums above 1 + 1e-2: verify fails it by
    // default, naming the row; a looser --row-sum-tol lets it pass.
    let (_, mut rows) = rows_of(&dir.path().join("perpendicular.ffz"));
    let sum = rows.iter().find(|r| r.index == at.0).unwrap().true_sum();
    let by = ((1.02 - sum) / f64::from(best) + 1.0) as f32;
    raise(&mut rows, by);
    let over = dir.path().join("over.ffz");
    write(&over, r.meta(), &rows, 1 << 16);
    let (code, report) = verify(&over, &[]);
    assert_eq!(code, 3, "{report}");
    assert!(
        report.contains(&format!(
            "FAIL: 1 rows sum above 1 + 1e-2 (largest: row {}, 1.02",
            at.0
        )),
        "{report}"
    );
    let (code, report) = verify(&over, &["--row-sum-tol", "0.05"]);
    assert_eq!(code, 0, "{report}");
}

#[test]
fn a_top_k_row_above_one_only_by_its_dropped_mass_is_reported_not_failed() {
    use crate::ffz_common::{meta, patches};
    use ffstream::ffz::Layout;
    let dir = tempfile::tempdir().unwrap();
    let layout = Layout::TopK { k: 4 };
    let m = meta(layout, patches(3, 5));
    let sparse = |index: u32, vals: Vec<f32>, dropped: f32| Row {
        index,
        values: RowValues::Sparse {
            cols: (0..vals.len() as u32)
                .map(|c| (index + 1 + c) % 3)
                .collect(),
            vals,
        },
        dropped,
        links: Vec::new(),
        link_error: None,
    };
    // Row 0: stored 0.5, dropped 0.6 (an overestimated tail): a warning.
    let tail = dir.path().join("tail.ffz");
    let rows = vec![
        sparse(0, vec![0.5], 0.6),
        sparse(1, vec![0.25], 0.0),
        sparse(2, vec![0.25], 0.0),
    ];
    write(&tail, &m, &rows, 1 << 16);
    let (code, report) = verify(&tail, &[]);
    assert_eq!(code, 0, "{report}");
    assert!(
        report.contains("warning:     1 top-k rows sum above 1 + 1e-2 only with their dropped mass (largest: row 0, 1.1"),
        "{report}"
    );
    // Row 0 stores 1.05 itself: a fault.
    let over = dir.path().join("over.ffz");
    let rows = vec![
        sparse(0, vec![1.05], 0.0),
        sparse(1, vec![0.25], 0.0),
        sparse(2, vec![0.25], 0.0),
    ];
    write(&over, &m, &rows, 1 << 16);
    let (code, report) = verify(&over, &[]);
    assert_eq!(code, 3, "{report}");
    assert!(
        report.contains("FAIL: 1 rows sum above 1 + 1e-2 (largest: row 0, 1.05"),
        "{report}"
    );
}
