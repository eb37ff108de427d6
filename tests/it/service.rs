//! The compute service in embedded mode, end to end through the binary: determinism
//! across thread counts, the gather baseline, failure injection, kill + resume, and the
//! Cornell box acceptance case.

use std::path::Path;
use std::time::{Duration, Instant};

use ffstream::ffz::FfzReader;
use ffstream::rows::RowValues;

use crate::common::{ffstream, ok, path_str};

/// Rows of two files, decompressed, must be bitwise identical, and `verify --against`
/// must agree (which also compares the headers: same scene, same settings).
pub(crate) fn assert_same_rows(a: &Path, b: &Path) {
    assert_same_row_values(a, b);
    let out = ffstream(&["verify", path_str(a), "--against", path_str(b)]);
    assert!(
        out.status.success(),
        "verify --against disagrees: {}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// Rows of two files, decompressed, must be bitwise identical (values and dropped
/// mass); the headers may differ.
pub(crate) fn assert_same_row_values(a: &Path, b: &Path) {
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
}

const CUBE: &[&str] = &["builtin:cube", "--max-edge", "0.25", "--quiet"];
/// Occluders and unequal patch areas: half rows (`--symmetric on`) differ from full
/// rows here, so a test that mixes them up fails.
const CORNELL: &[&str] = &["builtin:cornell", "--patches", "300", "--quiet"];

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
    for mode in ["on", "off"] {
        let a = dir.path().join(format!("t1_{mode}.ffz"));
        let b = dir.path().join(format!("t2_{mode}.ffz"));
        let c = dir.path().join(format!("folded_{mode}.ffz"));
        let sym = ["--symmetric", mode];
        compute(CORNELL, &a, &[&sym[..], &["--threads", "1"]].concat());
        compute(
            CORNELL,
            &b,
            &[&sym[..], &["--threads", "2", "--chunk-kib", "4"]].concat(),
        );
        compute(
            CORNELL,
            &c,
            &[&sym[..], &["--threads", "2", "--schedule", "folded"]].concat(),
        );
        assert_same_rows(&a, &b);
        assert_same_rows(&a, &c);
    }
}

/// Largest |A_i F_ij - A_j F_ji| / max(A_i F_ij, A_j F_ji) over the pairs of a file,
/// and the largest entry difference against another file of the same scene.
fn reciprocity_and_difference(a: &Path, b: &Path) -> (f64, f64) {
    let ra = FfzReader::open(a).unwrap();
    let rb = FfzReader::open(b).unwrap();
    let n = ra.n() as usize;
    let dense = |r: &FfzReader, i: u32| -> Vec<f64> {
        let mut v = vec![0.0; n];
        r.row(i)
            .unwrap()
            .unwrap()
            .for_each_nonzero(|j, f| v[j as usize] = f64::from(f));
        v
    };
    let fa: Vec<Vec<f64>> = (0..n as u32).map(|i| dense(&ra, i)).collect();
    let area: Vec<f64> = ra.meta().patches.patches.iter().map(|p| p.area).collect();
    let (mut recip, mut diff) = (0.0f64, 0.0f64);
    for i in 0..n {
        let fb = dense(&rb, i as u32);
        for j in 0..n {
            diff = diff.max((fa[i][j] - fb[j]).abs());
            let (x, y) = (area[i] * fa[i][j], area[j] * fa[j][i]);
            if x.max(y) > 0.0 {
                recip = recip.max((x - y).abs() / x.max(y));
            }
        }
    }
    (recip, diff)
}

/// `--symmetric on` computes each pair once: its rows are reciprocal to f32 rounding
/// (A_i F_ij and A_j F_ji come from one f64 value), and where the kernel is exact
/// (no occluders: the contour integral to 1e-8) they equal the full rows to that
/// accuracy, even with unequal patch areas.
#[test]
fn symmetric_rows_are_reciprocal_and_equal_full_rows_where_the_kernel_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    // Perpendicular 1 x 2 rectangles at max edge 0.3: patches of 0.25 x 0.25 and
    // 0.25 x 0.2857, no occluder between them.
    let open = ["builtin:perpendicular:2", "--max-edge", "0.3", "--quiet"];
    let (half, full) = (dir.path().join("half.ffz"), dir.path().join("full.ffz"));
    compute(&open, &half, &["--symmetric", "on"]);
    compute(&open, &full, &["--symmetric", "off"]);
    let (recip, diff) = reciprocity_and_difference(&half, &full);
    assert!(recip <= 2.5e-7, "half rows: reciprocity error {recip}");
    assert!(diff <= 1e-7, "half vs full rows, exact kernel: {diff}");
    let params = FfzReader::open(&half).unwrap().meta().params.clone();
    assert!(
        params.contains("pairs=half"),
        "the header says how: {params}"
    );

    // With occluders (Cornell box) the full rows carry the visibility estimate of both
    // directions and are reciprocal only to its noise; the half rows stay exact.
    let (half, full) = (dir.path().join("ch.ffz"), dir.path().join("cf.ffz"));
    compute(CORNELL, &half, &["--symmetric", "on"]);
    compute(CORNELL, &full, &["--symmetric", "off"]);
    let (recip_half, diff) = reciprocity_and_difference(&half, &full);
    let (recip_full, _) = reciprocity_and_difference(&full, &half);
    assert!(
        recip_half <= 2.5e-7,
        "half rows: reciprocity error {recip_half}"
    );
    assert!(
        recip_full > 1e-3,
        "full rows are not exactly reciprocal: {recip_full}"
    );
    assert!(
        diff > 0.0 && diff < 0.05,
        "half vs full, visibility noise only: {diff}"
    );
}

/// Half rows are for `contour` only: `point` and `mc` clamp each direction to 1, so a
/// mirrored value can exceed 1 (row sums of 4.5 were seen). `auto` gives them full rows
/// and `on` is refused with the reason.
#[test]
fn symmetric_is_refused_for_the_clamping_baselines_and_auto_gives_them_full_rows() {
    let dir = tempfile::tempdir().unwrap();
    for method in ["point", "mc"] {
        let f = dir.path().join(format!("{method}.ffz"));
        let mut args = vec!["compute"];
        args.extend_from_slice(CORNELL);
        args.extend_from_slice(&["-o", path_str(&f), "--method", method, "--symmetric", "on"]);
        let out = ffstream(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains("needs --method contour"),
            "{method}: {stderr}"
        );
        compute(CORNELL, &f, &["--method", method]);
        let r = FfzReader::open(&f).unwrap();
        assert!(
            !r.meta().params.contains("pairs=half"),
            "{method}: auto gives full rows"
        );
        for i in 0..r.n() {
            let row = r.row(i).unwrap().unwrap();
            row.for_each_nonzero(|j, v| assert!(v <= 1.0, "{method}: F[{i}][{j}] = {v}"));
        }
    }
}

/// `--symmetric on --top-k K`: the master selects the K largest entries of each whole
/// merged row, so the rows equal the top-K of the dense half-row file bitwise and the
/// dropped mass is the rest of the row.
#[test]
fn symmetric_top_k_keeps_the_largest_entries_of_the_merged_rows() {
    let dir = tempfile::tempdir().unwrap();
    let (dense, topk) = (dir.path().join("d.ffz"), dir.path().join("k.ffz"));
    compute(CORNELL, &dense, &["--symmetric", "on"]);
    compute(CORNELL, &topk, &["--symmetric", "on", "--top-k", "20"]);
    let (rd, rk) = (
        FfzReader::open(&dense).unwrap(),
        FfzReader::open(&topk).unwrap(),
    );
    for i in 0..rd.n() {
        let d = rd.row(i).unwrap().unwrap();
        let k = rk.row(i).unwrap().unwrap();
        let RowValues::Sparse { cols, vals } = &k.values else {
            panic!("row {i}: top-k rows are sparse")
        };
        let RowValues::Dense(all) = &d.values else {
            panic!("row {i}: dense")
        };
        let positive = all.iter().filter(|&&v| v > 0.0).count();
        assert_eq!(cols.len(), positive.min(20), "row {i}");
        let smallest_kept = vals.iter().copied().fold(f32::INFINITY, f32::min);
        let mut dropped = 0.0f64;
        for (j, &v) in all.iter().enumerate() {
            match cols.binary_search(&(j as u32)) {
                Ok(p) => assert_eq!(vals[p], v, "row {i} column {j}"),
                Err(_) => {
                    assert!(
                        v <= smallest_kept,
                        "row {i}: dropped {v} > kept {smallest_kept}"
                    );
                    dropped += f64::from(v);
                }
            }
        }
        assert!(
            (f64::from(k.dropped) - dropped).abs() <= 1e-6 * dropped.max(1e-3),
            "row {i}: dropped {} vs {dropped}",
            k.dropped
        );
    }
}

#[test]
fn gather_baseline_gives_the_streamed_rows() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("stream.ffz");
    let b = dir.path().join("gather.ffz");
    compute(CORNELL, &a, &["--threads", "2", "--symmetric", "off"]);
    compute(CORNELL, &b, &["--threads", "2", "--gather"]);
    // The gather path converts f32 rows to f64 and back: exact, so bitwise equal.
    assert_same_rows(&a, &b);
}

#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
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
    assert!(
        !ffstream::service::symmetric::spill_path(&part).exists(),
        "the spill of the failed run is removed"
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
    killed_run_resumes_to_the_same_rows_with("off");
}

/// Half rows: the killed run keeps its merged row blocks (its spill is useless and
/// replaced); the resumed rows are bitwise those of an uninterrupted run.
#[test]
fn killed_symmetric_run_resumes_to_the_same_rows() {
    killed_run_resumes_to_the_same_rows_with("on");
}

fn killed_run_resumes_to_the_same_rows_with(symmetric: &str) {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    let part = dir.path().join("part.ffz");
    // Enough work (occluded pairs cast rays) to be killed mid-way; small chunks
    // flushed often.
    let scene = ["builtin:cornell", "--patches", "800", "--quiet"];
    let extra = ["--threads", "2", "--samples", "8", "--symmetric", symmetric];
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
    // The kill must have landed mid-run, or the resume below would test nothing.
    assert!(
        !status.success() && missing > 0,
        "the run was not interrupted ({status}, {missing} rows missing): it needs more work"
    );
    let stderr = compute(&scene, &part, &[&extra[..], &["--resume"]].concat());
    let (computed, present) = crate::common::resumed_counts(&stderr);
    assert!(
        computed as usize == missing && present > 0,
        "resume computed {computed} rows and kept {present}; {missing} were missing\n{stderr}"
    );
    assert_same_rows(&full, &part);
    assert!(!ffstream::service::symmetric::spill_path(&part).exists());
}

#[test]
fn rows_needed_skips_inert_patches_and_says_so_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    // A closed unit cube, inward faces, whose x0 face is black (rho = 0) and dark.
    let obj = dir.path().join("black.obj");
    std::fs::write(dir.path().join("black.mtl"), BLACK_CUBE_MTL).unwrap();
    std::fs::write(&obj, BLACK_CUBE_OBJ).unwrap();
    for mode in ["on", "off"] {
        rows_needed_equal_those_of_a_full_run(dir.path(), &obj, mode);
    }
}

fn rows_needed_equal_those_of_a_full_run(dir: &Path, obj: &Path, symmetric: &str) {
    let f = dir.join(format!("needed_{symmetric}.ffz"));
    let all = dir.join(format!("all_{symmetric}.ffz"));
    let scene = [path_str(obj), "--max-edge", "0.5", "--quiet"];
    compute(&scene, &all, &["--symmetric", symmetric]);
    compute(&scene, &f, &["--rows", "needed", "--symmetric", symmetric]);
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
                "needed row {i} must equal the full run's (--symmetric {symmetric})"
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
