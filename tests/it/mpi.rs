//! The MPI service under a real `mpirun` (Open MPI, as root with --oversubscribe on a
//! small machine): rank-count invariance, the folded schedule, the gather baseline, a
//! worker failure, a rank that sees a different scene, and kill + resume.
//!
//! These tests need mpirun and a binary built with the `mpi` feature; `make test`
//! installs Open MPI. Without them each test prints why it did nothing (only when
//! FFSTREAM_SKIP_MPI=1 is set; otherwise a missing mpirun is a failure).

use std::path::Path;
use std::time::{Duration, Instant};

use ffstream::ffz::FfzReader;

use crate::common::{kill_tree_and_wait, mpirun, need_mpi, ok, path_str, resumed_counts, Within};
use crate::service::assert_same_rows;

const CUBE: &[&str] = &[
    "builtin:cube",
    "--max-edge",
    "0.25",
    "--quiet",
    "--threads",
    "1",
];

fn mpi_compute(ranks: usize, out: &Path, extra: &[&str]) -> std::process::Output {
    mpi_compute_scene(ranks, CUBE, out, extra)
}

fn assert_ok(out: &std::process::Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed: {}\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn embedded_reference(dir: &Path) -> std::path::PathBuf {
    embedded_reference_with(dir, CUBE, &[])
}

/// Occluders and unequal patch areas, so that half rows (`--symmetric on`, merged by
/// rank 0 from pieces of every worker) differ from full rows.
const CORNELL: &[&str] = &[
    "builtin:cornell",
    "--patches",
    "300",
    "--quiet",
    "--threads",
    "1",
];

fn embedded_reference_with(dir: &Path, scene: &[&str], extra: &[&str]) -> std::path::PathBuf {
    let reference = dir.join(format!("embedded{}.ffz", extra.join("")));
    let mut args = vec!["compute"];
    args.extend_from_slice(scene);
    args.extend_from_slice(&["-o", path_str(&reference)]);
    args.extend_from_slice(extra);
    ok(&args);
    reference
}

fn mpi_compute_scene(
    ranks: usize,
    scene: &[&str],
    out: &Path,
    extra: &[&str],
) -> std::process::Output {
    let mut args = vec!["compute"];
    args.extend_from_slice(scene);
    args.extend_from_slice(&["-o", path_str(out)]);
    args.extend_from_slice(extra);
    mpirun(ranks, &args).output_within(&format!("mpirun -n {ranks}"))
}

#[test]
fn rows_are_identical_for_2_3_5_ranks_and_embedded() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for mode in ["on", "off"] {
        let sym = ["--symmetric", mode];
        let reference = embedded_reference_with(dir.path(), CORNELL, &sym);
        for ranks in [2, 3, 5] {
            let f = dir.path().join(format!("n{ranks}{mode}.ffz"));
            let out = mpi_compute_scene(
                ranks,
                CORNELL,
                &f,
                &[&sym[..], &["--chunk-kib", "8"]].concat(),
            );
            assert_ok(&out, &format!("mpirun -n {ranks} --symmetric {mode}"));
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(
                stderr.contains("worker rank"),
                "rank 0 reports each worker: {stderr}"
            );
            assert_same_rows(&reference, &f);
            // The index keeps the workers' pair counts (formats/ffz-v1.md §6.1): each
            // pair is evaluated once whichever rank has it.
            let routes = |p: &Path| FfzReader::open(p).unwrap().routes().copied();
            assert_eq!(
                routes(&f),
                routes(&reference),
                "-n {ranks} --symmetric {mode}"
            );
            assert!(routes(&f).is_some_and(|r| r.rows == 297 && r.pairs.evaluated > 0));
        }
    }
}

/// Under mpirun rank 0 builds no engine: the first worker says which convex solids it
/// found, once, and the set-up lines of the ranks come out whole (each is one write:
/// `eprintln!` wrote the plan line in pieces, and another rank's line landed inside).
#[test]
fn the_first_worker_names_the_solids_and_set_up_lines_stay_whole() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let exact = ["--visibility", "exact", "--patches", "150"];
    let embedded = dir.path().join("e.ffz");
    let mut args = vec![
        "compute",
        "builtin:cornell",
        "-q",
        "-o",
        path_str(&embedded),
    ];
    args.extend_from_slice(&exact);
    let said = ok(&args);
    let line = "exact visibility: 3 convex solids (30 occluder triangles) cast their shadows whole";
    assert!(said.contains(&format!("ffstream: {line}")), "{said}");
    for round in 0..3 {
        let f = dir.path().join(format!("m{round}.ffz"));
        let out = mpi_compute_scene(3, &["builtin:cornell", "-q"], &f, &exact);
        assert_ok(&out, "mpirun -n 3 --visibility exact");
        let stderr = String::from_utf8_lossy(&out.stderr);
        let solids: Vec<&str> = stderr.lines().filter(|l| l.contains(line)).collect();
        assert_eq!(solids, [format!("ffstream: rank 1: {line}")], "{stderr}");
        for l in stderr.lines() {
            assert!(
                l.matches("ffstream:").count() <= 1,
                "two lines ran into each other: {l}"
            );
        }
    }
}

#[test]
fn folded_schedule_and_gather_baseline_give_the_same_rows() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let reference = embedded_reference_with(dir.path(), CORNELL, &[]);
    let folded = dir.path().join("folded.ffz");
    assert_ok(
        &mpi_compute_scene(3, CORNELL, &folded, &["--schedule", "folded"]),
        "folded",
    );
    assert_same_rows(&reference, &folded);
    // The paper's design computes full rows.
    let full = embedded_reference_with(dir.path(), CORNELL, &["--symmetric", "off"]);
    let gather = dir.path().join("gather.ffz");
    assert_ok(
        &mpi_compute_scene(3, CORNELL, &gather, &["--gather"]),
        "gather",
    );
    assert_same_rows(&full, &gather);
}

/// A 3-rank job on the cube made to break by the test hook `hook` = `row`, with
/// `extra` options; the caller checks what it said. Then: the file written so far is
/// readable without `row`, and `--resume` completes it to the rows of an uninterrupted
/// embedded run. `check` gets the broken job's stderr and how long it took.
fn broken_job_resumes(hook: &str, row: u32, extra: &[&str], check: impl Fn(&str, Duration)) {
    let dir = tempfile::tempdir().unwrap();
    let reference = embedded_reference(dir.path());
    let f = dir.path().join("broken.ffz");
    let mut args = vec!["compute"];
    args.extend_from_slice(CUBE);
    args.extend_from_slice(&["-o", path_str(&f), "--chunk-kib", "4"]);
    args.extend_from_slice(extra);
    let t0 = Instant::now();
    let out = mpirun(3, &args)
        .env(hook, row.to_string())
        .output_within(hook);
    let took = t0.elapsed();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the job must fail: {stderr}");
    check(&stderr, took);
    let r = FfzReader::open(&f).expect("the file written so far is readable");
    assert!(
        r.row(row).unwrap().is_none(),
        "row {row} is not in the file"
    );
    drop(r);
    assert_ok(&mpi_compute(3, &f, &["--resume"]), "resume");
    assert_same_rows(&reference, &f);
}

#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn worker_failure_is_named_file_stays_readable_and_resume_completes_it() {
    if !need_mpi() {
        return;
    }
    broken_job_resumes("FFSTREAM_FAIL_ROW", 50, &[], |stderr, _| {
        assert!(
            stderr.contains("row 50") && stderr.contains("rank "),
            "rank and row named: {stderr}"
        );
    });
}

/// Issue 20 item 9: a worker stopped with SIGSTOP used to stall the job for ever.
/// With a liveness limit rank 0 names the silent rank, keeps the rows written so far
/// and ends the job; `--resume` then completes the file to the uninterrupted rows.
#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn a_stopped_worker_is_named_after_the_stall_limit_and_resume_completes_the_file() {
    if !need_mpi() {
        return;
    }
    let limit = ["--stall-seconds", "3"];
    broken_job_resumes("FFSTREAM_TEST_STOP_ROW", 60, &limit, |stderr, took| {
        let named = ["rank 1 has sent nothing", "rank 2 has sent nothing"]
            .iter()
            .any(|m| stderr.contains(m));
        assert!(named, "the silent rank is named: {stderr}");
        assert!(stderr.contains("--resume"), "the way on is said: {stderr}");
        assert!(
            took >= Duration::from_secs(3),
            "ended only after the limit: {took:?}"
        );
    });
}

#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn a_rank_with_a_different_scene_is_named_before_computing() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("x.ffz");
    let mut args = vec!["compute"];
    args.extend_from_slice(CUBE);
    args.extend_from_slice(&["-o", path_str(&f)]);
    let out = mpirun(3, &args)
        .env("FFSTREAM_TEST_SCENE_RANK", "2:builtin:plates")
        .output_within("a rank with another scene");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("rank 2") && stderr.contains("scene differs"),
        "{stderr}"
    );
    let out = mpirun(3, &args)
        .env("FFSTREAM_TEST_SCENE_RANK", "1:/nonexistent/scene.obj")
        .output_within("a rank without its scene");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("rank 1") && stderr.contains("nonexistent"),
        "{stderr}"
    );
}

#[test]
fn killed_mpi_run_resumes_to_the_same_rows() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = [
        "builtin:cornell",
        "--patches",
        "800",
        "--quiet",
        "--threads",
        "1",
        "--samples",
        "8",
    ];
    let full = dir.path().join("full.ffz");
    let mut args = vec!["compute"];
    args.extend_from_slice(&scene);
    args.extend_from_slice(&["-o", path_str(&full)]);
    ok(&args);
    let part = dir.path().join("part.ffz");
    let mut args = vec!["compute"];
    args.extend_from_slice(&scene);
    args.extend_from_slice(&[
        "-o",
        path_str(&part),
        "--chunk-kib",
        "16",
        "--flush-seconds",
        "0.05",
    ]);
    let mut child = mpirun(3, &args).spawn().unwrap();
    let target = std::fs::metadata(&full).unwrap().len() / 3;
    let t0 = Instant::now();
    while std::fs::metadata(&part).map_or(0, |m| m.len()) < target
        && t0.elapsed() < Duration::from_secs(60)
    {
        std::thread::sleep(Duration::from_millis(5));
    }
    // SIGKILL the whole job (a SIGKILLed mpirun alone can leave ranks running: the
    // file's writer lock would then, rightly, refuse the resume).
    let finished_first = child.try_wait().expect("poll mpirun").is_some();
    kill_tree_and_wait(child.id());
    let _ = child.wait();
    let r = FfzReader::open(&part).expect("a killed run's file opens (by scan)");
    let missing = r.presence().missing().len();
    drop(r);
    // The kill must have landed mid-run, or the resume below would test nothing.
    assert!(
        !finished_first && missing > 0,
        "the job was not interrupted (ended before the kill: {finished_first}, {missing} rows missing)"
    );
    args.push("--resume");
    let out = mpirun(2, &args).output_within("resume under mpirun -n 2");
    assert_ok(&out, "resume under mpirun -n 2");
    let (computed, present) = resumed_counts(&String::from_utf8_lossy(&out.stderr));
    assert!(
        computed as usize == missing && present > 0,
        "resume computed {computed} rows and kept {present}; {missing} were missing"
    );
    assert_same_rows(&full, &part);
}

/// A pair whose outer rule runs out of points before meeting `--shadow-tol` (1e-16 is
/// below rounding) is counted in the report, embedded and under mpirun alike (the
/// count crosses from the workers to rank 0 in their DONE messages), and in the file
/// (`info` prints it); at the default tolerance no pair is short and the report says
/// nothing of it.
#[test]
fn pairs_short_of_the_shadow_tolerance_are_reported_embedded_and_under_mpirun() {
    let dir = tempfile::tempdir().unwrap();
    let scene: &[&str] = &[
        "builtin:obstructed",
        "--patches",
        "4",
        "--symmetric",
        "off",
        "--visibility",
        "exact",
        "--quiet",
    ];
    let short = |stderr: &str| -> Option<u64> {
        let clause = stderr.split("; ").find(|c| c.contains("did not reach"))?;
        clause.split_whitespace().next()?.parse().ok()
    };
    let run = |extra: &[&str]| {
        let out = dir.path().join("x.ffz");
        let mut args = vec!["compute"];
        args.extend_from_slice(scene);
        args.extend_from_slice(&["-o", path_str(&out), "--force"]);
        args.extend_from_slice(extra);
        ok(&args)
    };
    let normal = run(&[]);
    assert!(
        normal.contains("partly shadowed") && short(&normal).is_none(),
        "{normal}"
    );
    let tight = run(&["--shadow-tol", "1e-16"]);
    let embedded = short(&tight).unwrap_or_else(|| panic!("no count in\n{tight}"));
    assert!(embedded >= 1, "{tight}");
    // The file keeps the count (spec §6.1's tenth), and `info` prints it.
    let info = crate::common::ffstream(&["info", path_str(&dir.path().join("x.ffz"))]);
    let info = String::from_utf8_lossy(&info.stdout);
    assert_eq!(short(&info), Some(embedded), "{info}");
    if !need_mpi() {
        return;
    }
    let f = dir.path().join("mpi.ffz");
    let out = mpi_compute_scene(3, scene, &f, &["--shadow-tol", "1e-16"]);
    assert_ok(&out, "mpirun -n 3 at 1e-16");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(short(&stderr), Some(embedded), "{stderr}");
}
