//! The files other people's tools read, read by those tools (issue 47):
//! - `export --udales` read by the reading loop of uDALES's `src/initfac.f90`, as a
//!   Fortran program compiled with gfortran (`tests/fortran/read_vfsparse.f90`), on a
//!   city scene as an STL, one patch per facet; the count and the values compared with
//!   the `.ffz` file, and a `#` line must stop that reader (so the test can fail);
//! - the `.vtu` grids of `solve --vtu` and `export --vtu` read by Python's meshio
//!   (`tests/python/vtu_meshio.py`), every cell array against `radiosity.csv` and the
//!   patch table.
//!
//! Without gfortran, or python3 with meshio, the tests fail naming what is missing
//! (`make test` installs both), unless FFSTREAM_SKIP_FORTRAN=1 or
//! FFSTREAM_SKIP_PYTHON=1 is set.

use crate::common::{ffstream, need_tool, ok, path_str, runs};
use ffstream::ffz::FfzReader;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The built-in city with `blocks` per side as an ASCII STL, every quad as the two
/// triangles of ffstream's own fan (0-1-2, 0-2-3), in face order.
fn city_stl(dir: &Path, blocks: u32) -> PathBuf {
    let scene = ffstream::scene::open_scene(&format!("builtin:city:{blocks}")).unwrap();
    let mut text = String::from("solid city\n");
    for (_, t) in scene.triangles() {
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        writeln!(text, "facet normal {} {} {}\nouter loop", n.x, n.y, n.z).unwrap();
        for v in t {
            writeln!(text, "vertex {} {} {}", v.x, v.y, v.z).unwrap();
        }
        text.push_str("endloop\nendfacet\n");
    }
    text.push_str("endsolid city\n");
    let path = dir.join("city.stl");
    std::fs::write(&path, text).unwrap();
    path
}

/// `ffstream compute SCENE HOW... --quiet -o OUT`.
fn compute(scene: &str, how: &[&str], out: &Path) {
    let mut args = vec!["compute", scene];
    args.extend(how);
    args.extend(["--quiet", "-o", path_str(out)]);
    ok(&args);
}

/// `read_vfsparse` compiled with gfortran into `dir`, or None when gfortran is missing
/// and FFSTREAM_SKIP_FORTRAN is set.
fn fortran_reader(dir: &Path) -> Option<PathBuf> {
    if !need_tool("gfortran", runs("gfortran"), "FFSTREAM_SKIP_FORTRAN") {
        return None;
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fortran/read_vfsparse.f90");
    let exe = dir.join("read_vfsparse");
    let out = Command::new("gfortran")
        .args(["-std=f2008", "-fdefault-real-8", "-fdefault-double-8", "-o"])
        .arg(&exe)
        .arg(&src)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "gfortran failed on {}:\n{}",
        src.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(exe)
}

/// `name value` lines of the Fortran reader's output.
fn value(report: &str, name: &str) -> String {
    report
        .lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .unwrap_or_else(|| panic!("no `{name}` in the reader's output:\n{report}"))
        .trim()
        .to_string()
}

#[test]
fn udales_reading_loop_reads_the_exported_city_with_its_count_and_values() {
    let dir = tempfile::tempdir().unwrap();
    let Some(reader) = fortran_reader(dir.path()) else {
        return;
    };
    let stl = city_stl(dir.path(), 2);
    let ffz = dir.path().join("city.ffz");
    compute(path_str(&stl), &["--max-edge", "1e9"], &ffz);
    // The directory is made, and the experiment number written with three digits.
    let exp = dir.path().join("exp");
    let out = ffstream(&[
        "export",
        path_str(&ffz),
        "--udales",
        path_str(&exp),
        "--expnr",
        "42",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let nnz: u64 = value(&stdout.replace(" = ", " "), "nnz").parse().unwrap();

    // What the file holds: entries ≥ 5e-7 of every row, sky view max(0, 1 - row sum).
    let r = FfzReader::open(&ffz).unwrap();
    let n = r.n();
    assert_eq!(value(&stdout.replace(" = ", " "), "nfcts"), n.to_string());
    let (mut count, mut sum_f, mut sum_i, mut sum_j, mut sum_svf) = (0u64, 0f64, 0u64, 0u64, 0f64);
    r.scan(|row| {
        row.for_each_nonzero(|j, x| {
            if x >= 5e-7 {
                count += 1;
                sum_f += f64::from(x);
                sum_i += u64::from(row.index) + 1;
                sum_j += u64::from(j) + 1;
            }
        });
        sum_svf += (1.0 - row.true_sum()).max(0.0);
    })
    .unwrap();
    assert_eq!(nnz, count, "the printed nnz is the count of entries ≥ 5e-7");
    assert!(
        count > u64::from(n),
        "a city's rows see several facets each"
    );
    let vfsparse = exp.join("vfsparse.inp.042");
    let svf = exp.join("svf.inp.042");
    let lines = std::fs::read_to_string(&vfsparse).unwrap().lines().count() as u64;
    assert_eq!(lines, nnz, "one line per entry, no header");

    let run = |file: &Path, nnz: u64| {
        Command::new(&reader)
            .arg(file)
            .arg(nnz.to_string())
            .arg(n.to_string())
            .arg(&svf)
            .output()
            .unwrap()
    };
    let got = run(&vfsparse, nnz);
    let report = String::from_utf8_lossy(&got.stdout).into_owned();
    assert!(
        got.status.success(),
        "the Fortran reader failed on {}: {}",
        vfsparse.display(),
        String::from_utf8_lossy(&got.stderr)
    );
    assert_eq!(value(&report, "count"), nnz.to_string());
    assert_eq!(value(&report, "sum_i"), sum_i.to_string());
    assert_eq!(value(&report, "sum_j"), sum_j.to_string());
    // Each value is printed in the shortest decimal that reads back as the same f32;
    // read into a real(8), that decimal is within half an f32 ulp (2^-24 relative) of
    // the f32.
    let f: f64 = value(&report, "sum_f").parse().unwrap();
    assert!(
        (f - sum_f).abs() <= 2f64.powi(-24) * sum_f,
        "sum of F: Fortran {f}, file {sum_f}"
    );
    // And line by line, each value read as f32 is the stored entry, bit for bit.
    let mut stored = std::collections::HashMap::new();
    r.scan(|row| {
        row.for_each_nonzero(|j, x| {
            stored.insert((row.index + 1, j + 1), x);
        })
    })
    .unwrap();
    for line in std::fs::read_to_string(&vfsparse).unwrap().lines() {
        let w: Vec<&str> = line.split(' ').collect();
        let (i, j, x): (u32, u32, f32) = (
            w[0].parse().unwrap(),
            w[1].parse().unwrap(),
            w[2].parse().unwrap(),
        );
        assert_eq!(
            stored.get(&(i, j)),
            Some(&x),
            "line `{line}` of {}",
            vfsparse.display()
        );
    }
    // Sky view factors have 8 decimals, as uDALES writes them.
    let s: f64 = value(&report, "sum_svf").parse().unwrap();
    assert!(
        (s - sum_svf).abs() <= 5e-9 * f64::from(n) + 1e-12,
        "sum of svf: Fortran {s}, file {sum_svf}"
    );
    assert!(
        s > 0.1 * f64::from(n),
        "a city open to the sky has sky view: {s}"
    );

    // The reader must be able to fail: a `#` header line (ffstream's --sparse text)
    // stops uDALES's list-directed READ.
    let headed = dir.path().join("headed.inp");
    let text = std::fs::read_to_string(&vfsparse).unwrap();
    std::fs::write(&headed, format!("# ffstream form factors\n{text}")).unwrap();
    let bad = run(&headed, nnz);
    assert!(
        !bad.status.success(),
        "a `#` line must stop the Fortran reader: {}",
        String::from_utf8_lossy(&bad.stdout)
    );
}

#[test]
fn udales_export_refuses_what_is_not_the_stl_facets_one_patch_each() {
    let dir = tempfile::tempdir().unwrap();
    let stl = city_stl(dir.path(), 1);
    let exp = dir.path();
    let refused = |ffz: &Path, extra: &[&str]| {
        let mut args = vec!["export", path_str(ffz), "--udales", path_str(exp)];
        args.extend(extra);
        let out = ffstream(&args);
        assert!(
            !out.status.success(),
            "export --udales {} must be refused",
            ffz.display()
        );
        assert!(!exp.join("vfsparse.inp.001").exists(), "nothing written");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    // Subdivided: several patches per facet.
    let cut = dir.path().join("cut.ffz");
    compute(path_str(&stl), &["--patches", "300"], &cut);
    let why = refused(&cut, &[]);
    assert!(
        why.contains("cut.ffz") && why.contains("subdivision"),
        "{why}"
    );
    // A built-in scene: no STL numbering.
    let builtin = dir.path().join("builtin.ffz");
    compute("builtin:city:1", &["--max-edge", "1e9"], &builtin);
    let why = refused(&builtin, &[]);
    assert!(
        why.contains("built-in") && why.contains("not an STL"),
        "{why}"
    );
    // The right file, checked against another STL.
    let whole = dir.path().join("whole.ffz");
    compute(path_str(&stl), &["--max-edge", "1e9"], &whole);
    let other = dir.path().join("other");
    std::fs::create_dir(&other).unwrap();
    let other_stl = city_stl(&other, 2);
    let why = refused(&whole, &["--stl", path_str(&other_stl)]);
    assert!(why.contains("not the STL it was computed from"), "{why}");
    // A bad experiment number.
    let why = refused(&whole, &["--expnr", "1234"]);
    assert!(why.contains("1 to 3 digits"), "{why}");
}

fn meshio_or_skip() -> bool {
    let ready = Command::new("python3")
        .args(["-c", "import meshio, numpy"])
        .status()
        .is_ok_and(|s| s.success());
    need_tool(
        "python3 with meshio and numpy",
        ready,
        "FFSTREAM_SKIP_PYTHON",
    )
}

fn meshio_check(kind: &str, grid: &Path, tables: &[&Path]) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/vtu_meshio.py");
    let out = Command::new("python3")
        .arg(script)
        .args([kind, path_str(grid)])
        .args(tables.iter().map(|t| path_str(t)))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "meshio check of {} failed: {}{said}",
        grid.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(said.contains(" equal "), "{said}");
}

/// `export FFZ --patches-csv --vtu` beside it, the grid checked against the table.
fn export_checked(ffz: &Path) {
    let (csv, vtu) = (ffz.with_extension("csv"), ffz.with_extension("vtu"));
    ok(&[
        "export",
        path_str(ffz),
        "--patches-csv",
        path_str(&csv),
        "--vtu",
        path_str(&vtu),
    ]);
    meshio_check("export", &vtu, &[&csv]);
}

#[test]
fn meshio_reads_the_vtu_grids_with_every_cell_array_equal_to_the_tables() {
    if !meshio_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    // The Cornell box cut into quads and triangles, solved and exported.
    compute("builtin:cornell", &["--patches", "200"], &p("c.ffz"));
    ok(&[
        "solve",
        path_str(&p("c.ffz")),
        "-o",
        path_str(&p("r.csv")),
        "--vtu",
        path_str(&p("lit.vtu")),
    ]);
    export_checked(&p("c.ffz"));
    // The solve's grid: radiosity.csv's values, and the row sums of the patch table.
    meshio_check("solve", &p("lit.vtu"), &[&p("r.csv"), &p("c.csv")]);
    // A top-k file, whose rows have dropped mass.
    compute(
        "builtin:city:2",
        &["--patches", "300", "--top-k", "20"],
        &p("k.ffz"),
    );
    export_checked(&p("k.ffz"));
}
