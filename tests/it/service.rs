//! The compute service in embedded mode, end to end through the binary: determinism
//! across thread counts, the gather baseline, failure injection, kill + resume, and the
//! Cornell box acceptance case.

use std::path::Path;
use std::time::{Duration, Instant};

use ffstream::ffz::FfzReader;
use ffstream::rows::RowValues;

use crate::common::{ffstream, ok, path_str};

/// Rows of two files, decompressed, must be bitwise identical.
pub fn assert_same_rows(a: &Path, b: &Path) {
    let ra = FfzReader::open(a).expect("open a");
    let rb = FfzReader::open(b).expect("open b");
    assert_eq!(ra.n(), rb.n(), "n differs");
    for i in 0..ra.n() {
        let x = ra
            .row(i)
            .expect("read a")
            .unwrap_or_else(|| panic!("{}: row {i} missing", a.display()));
        let y = rb
            .row(i)
            .expect("read b")
            .unwrap_or_else(|| panic!("{}: row {i} missing", b.display()));
        assert_eq!(
            x.values,
            y.values,
            "row {i} differs between {} and {}",
            a.display(),
            b.display()
        );
        assert_eq!(
            x.dropped.to_bits(),
            y.dropped.to_bits(),
            "dropped mass of row {i} differs"
        );
    }
    let out = ffstream(&["verify", path_str(a), "--against", path_str(b)]);
    assert!(
        out.status.success(),
        "verify --against disagrees: {}",
        String::from_utf8_lossy(&out.stdout)
    );
}

const CUBE: &[&str] = &["builtin:cube", "--max-edge", "0.25", "--quiet"];

fn compute(scene: &[&str], out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["compute"];
    args.extend_from_slice(scene);
    args.extend_from_slice(&["-o", path_str(out)]);
    args.extend_from_slice(extra);
    ok(&args)
}

#[test]
fn rows_are_bitwise_identical_for_one_and_two_threads_and_both_schedules() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("t1.ffz");
    let b = dir.path().join("t2.ffz");
    let c = dir.path().join("folded.ffz");
    compute(CUBE, &a, &["--threads", "1"]);
    compute(CUBE, &b, &["--threads", "2", "--chunk-kib", "4"]);
    compute(CUBE, &c, &["--threads", "2", "--schedule", "folded"]);
    assert_same_rows(&a, &b);
    assert_same_rows(&a, &c);
}

#[test]
fn gather_baseline_gives_the_streamed_rows() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("stream.ffz");
    let b = dir.path().join("gather.ffz");
    compute(CUBE, &a, &["--threads", "2"]);
    compute(CUBE, &b, &["--threads", "2", "--gather"]);
    // The gather path converts f32 rows to f64 and back: exact, so bitwise equal.
    assert_same_rows(&a, &b);
}

#[test]
fn injected_worker_failure_names_the_row_keeps_the_file_and_resume_completes_it() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    let part = dir.path().join("part.ffz");
    compute(CUBE, &full, &["--threads", "2"]);
    let out = std::process::Command::new(crate::common::exe())
        .args([
            "compute",
            CUBE[0],
            CUBE[1],
            CUBE[2],
            "--quiet",
            "-o",
            path_str(&part),
            "--threads",
            "2",
            "--chunk-kib",
            "8",
        ])
        .env("FFSTREAM_FAIL_ROW", "40")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "an injected failure must fail the run"
    );
    assert!(
        stderr.contains("row 40"),
        "the error must name the row: {stderr}"
    );
    assert_eq!(
        stderr.lines().filter(|l| l.contains("error")).count(),
        1,
        "one-line cause expected: {stderr}"
    );
    let r = FfzReader::open(&part).expect("a failed run leaves a readable file");
    assert!(
        r.row(40).unwrap().is_none(),
        "the failed row cannot be present"
    );
    drop(r);
    compute(CUBE, &part, &["--threads", "2", "--resume"]);
    assert_same_rows(&full, &part);
}

#[test]
fn killed_run_resumes_to_the_same_rows() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    let part = dir.path().join("part.ffz");
    // Enough work (occluded pairs cast rays) to be killed mid-way; small chunks
    // flushed often.
    let scene = ["builtin:cornell", "--patches", "800", "--quiet"];
    let extra = ["--threads", "2", "--samples", "8"];
    compute(&scene, &full, &extra);
    let mut child = std::process::Command::new(crate::common::exe())
        .args([
            "compute",
            scene[0],
            scene[1],
            scene[2],
            "--quiet",
            "-o",
            path_str(&part),
        ])
        .args(extra)
        .args(["--chunk-kib", "16", "--flush-seconds", "0.05"])
        .spawn()
        .unwrap();
    // Kill once about a third of the file is on disk (the header and patch table come
    // first, then chunks).
    let t0 = Instant::now();
    let target = std::fs::metadata(&full).unwrap().len() / 3;
    while std::fs::metadata(&part).map_or(0, |m| m.len()) < target
        && t0.elapsed() < Duration::from_secs(60)
    {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL
    let status = child.wait().unwrap();
    let r = FfzReader::open(&part).expect("a killed run's file can be opened (scan)");
    let presence = r.presence();
    let missing = presence.missing().len();
    drop(r);
    if status.success() {
        eprintln!("note: the run finished before the kill; resume is then a no-op");
    } else {
        assert!(missing > 0, "a killed run should have missing rows");
    }
    let stderr = compute(
        &scene,
        &part,
        &[extra[0], extra[1], extra[2], extra[3], "--resume"],
    );
    eprintln!("{stderr}");
    assert_same_rows(&full, &part);
}

#[test]
fn rows_needed_skips_inert_patches_and_says_so_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    // A closed unit cube, inward faces, whose x0 face is black (rho = 0) and dark.
    let obj = dir.path().join("black.obj");
    std::fs::write(dir.path().join("black.mtl"), BLACK_CUBE_MTL).unwrap();
    std::fs::write(&obj, BLACK_CUBE_OBJ).unwrap();
    let f = dir.path().join("needed.ffz");
    let all = dir.path().join("all.ffz");
    compute(&[path_str(&obj), "--max-edge", "0.5", "--quiet"], &all, &[]);
    compute(
        &[path_str(&obj), "--max-edge", "0.5", "--quiet"],
        &f,
        &["--rows", "needed"],
    );
    let ra = FfzReader::open(&all).unwrap();
    let rn = FfzReader::open(&f).unwrap();
    let patches = &rn.meta().patches;
    let mut skipped = 0;
    for i in 0..rn.n() {
        let row = rn.row(i).unwrap().expect("every row is present or skipped");
        if patches.patches[i as usize].is_inert() {
            assert_eq!(
                row.values,
                RowValues::Skipped,
                "inert patch {i} must be skipped"
            );
            skipped += 1;
        } else {
            assert_eq!(
                Some(row),
                ra.row(i).unwrap(),
                "needed row {i} must equal the full run's"
            );
        }
    }
    // Face x0 at --max-edge 0.5 is 2 x 2 patches.
    assert_eq!(skipped, 4, "the black face's patches are skipped");
}

const BLACK_CUBE_MTL: &str = "newmtl white\nKd 0.5 0.5 0.5\nnewmtl black\nKd 0 0 0\nnewmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n";
const BLACK_CUBE_OBJ: &str = "mtllib black.mtl
v 0 0 0
v 0 1 0
v 0 1 1
v 0 0 1
v 1 0 0
v 1 0 1
v 1 1 1
v 1 1 0
g x0
usemtl black
f 1 2 3 4
g x1
usemtl white
f 5 6 7 8
g y0
f 1 4 6 5
g y1
usemtl light
f 2 8 7 3
g z0
usemtl white
f 1 5 8 2
g z1
f 4 3 7 6
";

/// Point strictly inside a convex polygon in the xz plane (counter-clockwise or not).
fn inside_xz(p: glam::DVec3, poly: &[(f64, f64)]) -> bool {
    let n = poly.len();
    let mut sign = 0.0;
    for k in 0..n {
        let (ax, az) = poly[k];
        let (bx, bz) = poly[(k + 1) % n];
        let c = (bx - ax) * (p.z - az) - (bz - az) * (p.x - ax);
        if c.abs() < 1e-9 {
            return false;
        }
        if sign == 0.0 {
            sign = c.signum();
        } else if c.signum() != sign {
            return false;
        }
    }
    true
}

#[test]
fn cornell_box_default_patch_count_end_to_end_and_floor_under_blocks_is_dark() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("cornell.ffz");
    let stderr = compute(&["builtin:cornell"], &f, &["--quiet"]);
    assert!(
        stderr.contains("patches"),
        "the chosen patch count is printed: {stderr}"
    );
    let r = FfzReader::open(&f).unwrap();
    let n = r.n();
    assert!(
        (1500..=2600).contains(&n),
        "default should give about 2000 patches, got {n}"
    );
    // Block footprints on the floor (from the published Cornell box data).
    let short = [(290.0, 114.0), (240.0, 272.0), (82.0, 225.0), (130.0, 65.0)];
    let tall = [
        (423.0, 247.0),
        (265.0, 296.0),
        (314.0, 456.0),
        (472.0, 406.0),
    ];
    let patches = &r.meta().patches;
    let mut under = 0;
    for (i, p) in patches.patches.iter().enumerate() {
        if patches.group_name(i) != "floor" {
            continue;
        }
        let c = p.corners();
        if c.iter().all(|&v| inside_xz(v, &short)) || c.iter().all(|&v| inside_xz(v, &tall)) {
            under += 1;
            let row = r.row(i as u32).unwrap().expect("row present");
            let mut nonzero = 0;
            row.for_each_nonzero(|_, _| nonzero += 1);
            assert_eq!(
                nonzero, 0,
                "floor patch {i} lies under a block: its row must be all zero"
            );
        }
    }
    assert!(
        under > 10,
        "expected floor patches under the blocks, found {under}"
    );
}

#[test]
fn an_existing_file_is_never_overwritten_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("keep.ffz");
    compute(CUBE, &f, &[]);
    let before = std::fs::read(&f).unwrap();
    let mut args = vec!["compute"];
    args.extend_from_slice(CUBE);
    args.extend_from_slice(&["-o", path_str(&f), "--seed", "7"]);
    let out = ffstream(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("already exists")
            && stderr.contains("--resume")
            && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(&f).unwrap(),
        before,
        "the existing file must be untouched"
    );
    args.push("--force");
    ok(&args);
    assert_ne!(std::fs::read(&f).unwrap(), before, "--force replaces it");
}

#[test]
fn a_second_writer_on_the_same_file_is_refused_and_does_not_clobber_it() {
    use ffstream::ffz::{FfzError, FfzWriter};
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("busy.ffz");
    compute(CUBE, &f, &[]);
    let meta = FfzReader::open(&f).unwrap().meta().clone();
    let before = std::fs::read(&f).unwrap();
    let (first, _) = FfzWriter::resume(&f, &meta, Default::default()).unwrap();
    // Both a resume and a create (--force) by a second writer are refused.
    assert!(matches!(
        FfzWriter::resume(&f, &meta, Default::default()),
        Err(FfzError::Locked { .. })
    ));
    assert!(matches!(
        FfzWriter::create(&f, &meta, Default::default()),
        Err(FfzError::Locked { .. })
    ));
    let out = ffstream(&[
        "compute",
        CUBE[0],
        CUBE[1],
        CUBE[2],
        "--quiet",
        "-o",
        path_str(&f),
        "--force",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("another process is writing"), "{stderr}");
    drop(first);
    // The first writer was dropped without finish: the rows are all still there.
    let r = FfzReader::open(&f).unwrap();
    assert!(r.presence().is_complete());
    let _ = before;
}
