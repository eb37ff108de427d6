//! Stress, signals during an embedded `compute`: the first SIGTERM or SIGINT (a batch
//! system's time limit, Ctrl-C) stops the run cleanly: the rows finished are in the
//! file, which is closed with its index (no scan needed), the exit code is 128 + the
//! signal, and `--resume` completes the file with the rows of a run never stopped. A
//! second signal stops the process at once, and the file stays readable by a scan.
//!
//! Deterministic: the run stops itself (SIGSTOP) at a chosen row through the test hook
//! `FFSTREAM_TEST_STOP_ROW`; the signals are sent while it is stopped, then SIGCONT.
//! The scene and settings are those of `stress_faults` (Cornell box, 612 patches).

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{
    exe, ffstream, kill_tree_and_wait, mpirun, need_mpi, ok, output_of_within, path_str,
    resumed_counts, Within,
};
use crate::stress_faults::{
    assert_same, compute_args as args, output_text as text, rank_pids, SCENE,
};

/// `compute` with `args(out, extra)`, stopped by itself (SIGSTOP) at row 300.
fn stopped_run(out: &Path, extra: &[&str]) -> Child {
    stopped_at_row_300(&args(out, extra))
}

/// `ffstream ARGS` once it has stopped itself (SIGSTOP) at row 300.
fn stopped_at_row_300(args: &[&str]) -> Child {
    let mut child = Command::new(exe())
        .args(args)
        .env_remove("FFSTREAM_FAIL_ROW")
        .env("FFSTREAM_TEST_STOP_ROW", "300")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot start ffstream");
    let pid = child.id();
    await_stop(&mut child, &[pid]);
    child
}

/// Waits until one of `pids` (`child` or processes under it) has stopped itself at row
/// 300; past 60 s, or when `child` ends first, kills it and everything under it and
/// fails.
fn await_stop(child: &mut Child, pids: &[u32]) {
    let t0 = Instant::now();
    while !pids.iter().any(|&pid| is_stopped(pid)) {
        if t0.elapsed() > Duration::from_secs(60) || child.try_wait().unwrap().is_some() {
            kill_tree_and_wait(child.id());
            panic!("nothing stopped itself at row 300 within 60 s");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Whether process `pid` is stopped (state T in /proc/PID/stat).
fn is_stopped(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        // The state follows the command name in parentheses.
        stat.rsplit(')')
            .next()
            .and_then(|r| r.split_whitespace().next())
            == Some("T")
    })
}

fn send(child: &Child, signal: libc::c_int) {
    kill(child.id(), signal);
}

fn kill(pid: u32, signal: libc::c_int) {
    let pid = libc::pid_t::try_from(pid).unwrap();
    // SAFETY: kill(2) takes plain integers and touches no memory of ours.
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0, "kill {signal}");
}

/// Resumes `part` and checks it against `full` ([`assert_resumed`]).
fn resume_and_compare(part: &Path, full: &Path, extra: &[&str]) {
    let mut a = args(part, extra);
    a.push("--resume");
    assert_resumed(&ok(&a), part, full);
}

/// A resume (its stderr `said`) kept rows and computed others, and `part` now has the
/// rows of `full` (`verify --against`, exit 0: every row present, bitwise the same, and
/// the file sound, its route record included).
fn assert_resumed(said: &str, part: &Path, full: &Path) {
    let (computed, present) = resumed_counts(said);
    assert!(
        computed > 0 && present > 0,
        "computed {computed}, kept {present}"
    );
    assert_same(part, full, "resumed after a stop");
}

/// `part` was closed with its index: verify reads it without a scan, and names the
/// rows still to do.
fn assert_closed_and_indexed(part: &Path) {
    let v = text(&ffstream(&["verify", path_str(part)]));
    assert!(!v.contains("unusable") && !v.contains("scanning"), "{v}");
    assert!(
        v.contains("missing (finish them with compute --resume)"),
        "{v}"
    );
}

#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn a_signal_closes_the_file_with_its_index_and_resume_completes_it() {
    let dir = tempfile::tempdir().unwrap();
    for (signal, name, extra) in [
        (libc::SIGTERM, "SIGTERM", &[][..]),
        (libc::SIGINT, "SIGINT", &["--symmetric", "off"][..]),
    ] {
        let full = dir.path().join(format!("full-{name}.ffz"));
        ok(&args(&full, extra));
        let part = dir.path().join(format!("{name}.ffz"));
        let child = stopped_run(&part, extra);
        send(&child, signal);
        send(&child, libc::SIGCONT);
        let out = output_of_within(child, "a run stopped by a signal");
        assert_eq!(out.status.code(), Some(128 + signal), "{}", text(&out));
        let said = text(&out);
        assert!(
            said.contains(&format!("ffstream: stopped by {name}:"))
                && said.contains("--resume computes the rest"),
            "{said}"
        );
        assert_closed_and_indexed(&part);
        // The pair counts cover exactly the rows in the file (full rows), or none (half
        // rows: those of unmerged blocks are computed again by the resume).
        let info = text(&ffstream(&["info", path_str(&part)]));
        let number_after = |key: &str| -> Option<u64> {
            let rest = &info[info.find(key)? + key.len()..];
            rest.split_whitespace().next()?.parse().ok()
        };
        let present = number_after("rows:").expect("info names the rows present");
        match number_after("routes:        over the") {
            Some(counted) => {
                assert!(extra.contains(&"off"), "half rows counted: {info}");
                assert_eq!(counted, present, "{info}");
            }
            None => assert!(!extra.contains(&"off"), "full rows not counted: {info}"),
        }
        resume_and_compare(&part, &full, extra);
    }
}

#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn a_second_signal_stops_at_once_and_the_rows_written_are_kept() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    ok(&args(&full, &[]));
    let part = dir.path().join("twice.ffz");
    let child = stopped_run(&part, &[]);
    // Both pending while it is stopped: the first caught, the second its default action.
    send(&child, libc::SIGTERM);
    send(&child, libc::SIGINT);
    send(&child, libc::SIGCONT);
    let out = output_of_within(child, "a run given two signals");
    assert!(
        matches!(out.status.signal(), Some(libc::SIGINT | libc::SIGTERM)),
        "ended by {:?}, not by the second signal\n{}",
        out.status,
        text(&out)
    );
    // No index (the process was ended in the middle): a scan reads what is there.
    let v = text(&ffstream(&["verify", path_str(&part)]));
    assert!(v.contains("by scanning"), "{v}");
    resume_and_compare(&part, &full, &[]);
}

/// `run` stops before its solve: the same exit code and message, and its `--resume`
/// completes the file and goes on to the picture.
#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn a_signal_stops_run_before_the_solve_and_its_resume_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let run = |extra: &[&'static str]| {
        let mut a = vec!["run"];
        a.extend_from_slice(SCENE);
        a.extend_from_slice(&["--out-dir", path_str(&out)]);
        a.extend_from_slice(extra);
        a
    };
    let child = stopped_at_row_300(&run(&[]));
    send(&child, libc::SIGINT);
    send(&child, libc::SIGCONT);
    let stopped = output_of_within(child, "run stopped by SIGINT");
    assert_eq!(stopped.status.code(), Some(130), "{}", text(&stopped));
    assert!(text(&stopped).contains("ffstream: stopped by SIGINT:"));
    assert!(
        !out.join("image.png").exists(),
        "the solve ran after the stop"
    );
    let stderr = ok(&run(&["--resume"]));
    let (computed, present) = resumed_counts(&stderr);
    assert!(
        computed > 0 && present > 0,
        "computed {computed}, kept {present}"
    );
    assert!(out.join("image.png").exists(), "{stderr}");
}

/// Under mpirun with each rank signalled (as a batch system's direct launch does): the
/// ranks stop as in one process, rank 0 closes the file with its index and exits 143,
/// and a resume with another rank count gives the rows of a run never stopped.
#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn under_mpirun_sigterm_to_every_rank_closes_the_file_and_resume_completes_it() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    ok(&args(&full, &[]));
    let part = dir.path().join("mpi.ffz");
    let mut child = mpirun(3, &args(&part, &[]))
        .env("FFSTREAM_TEST_STOP_ROW", "300")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let ranks: Vec<u32> = rank_pids(child.id(), 3)
        .iter()
        .map(|&(pid, _)| pid)
        .collect();
    await_stop(&mut child, &ranks);
    for &pid in &ranks {
        kill(pid, libc::SIGTERM);
    }
    for &pid in &ranks {
        kill(pid, libc::SIGCONT);
    }
    let out = output_of_within(child, "mpirun, every rank given SIGTERM");
    let said = text(&out);
    assert_eq!(out.status.code(), Some(143), "{said}");
    assert!(said.contains("ffstream: stopped by SIGTERM:"), "{said}");
    assert_closed_and_indexed(&part);
    let mut a = args(&part, &[]);
    a.push("--resume");
    let resumed = mpirun(2, &a).output_within("resume under mpirun -n 2");
    assert!(resumed.status.success(), "{}", text(&resumed));
    assert_resumed(&String::from_utf8_lossy(&resumed.stderr), &part, &full);
}

/// `annual` stopped by SIGTERM while it computes its form factors exited 1 (the stop
/// went out as an error); it exits 143 as `compute` and `run` do, and computes no year.
#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn a_signal_stops_annual_with_the_signal_exit_code() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("annual");
    let child = stopped_at_row_300(&[
        "annual",
        "builtin:office",
        "--location",
        "36,-80,-5",
        "--grid",
        "floor:1",
        "--patches",
        "1500",
        "--threads",
        "2",
        "--quiet",
        "-o",
        path_str(&out),
    ]);
    send(&child, libc::SIGTERM);
    send(&child, libc::SIGCONT);
    let stopped = output_of_within(child, "annual stopped by SIGTERM");
    assert_eq!(stopped.status.code(), Some(143), "{}", text(&stopped));
    assert!(text(&stopped).contains("ffstream: stopped by SIGTERM:"));
    assert!(
        !out.join("illuminance.csv").exists(),
        "the year ran after the stop"
    );
}

/// Issue 48, item 4: SIGTERM to one worker of a half-row run under `mpirun -n 3`. The
/// pair-count record said 2,831 rows with 748 present (the workers' counts took in half
/// rows of blocks never merged); `--resume` then exited 0 with a record of 5,077 rows
/// for n = 2,994, and every reader refused the index (`verify` exit 3). Now the
/// stopped run counts no rows it did not write (for half rows: none, as after a signal
/// to every rank), and the resumed file is sound, its record within the rows it holds,
/// and has the rows of a run never stopped.
#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn sigterm_to_one_worker_of_a_half_row_run_leaves_a_sound_route_record() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    ok(&args(&full, &["--symmetric", "on"]));
    let part = dir.path().join("one-worker.ffz");
    let mut child = mpirun(3, &args(&part, &["--symmetric", "on"]))
        .env("FFSTREAM_TEST_STOP_ROW", "300")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let ranks = rank_pids(child.id(), 3);
    let pids: Vec<u32> = ranks.iter().map(|&(pid, _)| pid).collect();
    await_stop(&mut child, &pids);
    let worker = ranks.iter().find(|&&(_, rank)| rank == 1).unwrap().0;
    kill(worker, libc::SIGTERM);
    for &pid in &pids {
        kill(pid, libc::SIGCONT);
    }
    let out = output_of_within(child, "mpirun, one worker given SIGTERM");
    assert!(!out.status.success(), "{}", text(&out));
    let counted_and_present = |what: &str| {
        let info = text(&ffstream(&["info", path_str(&part)]));
        assert!(!info.contains("unusable"), "{what}: {info}");
        let number_after = |key: &str| -> Option<u64> {
            let rest = &info[info.find(key)? + key.len()..];
            rest.split_whitespace().next()?.parse().ok()
        };
        let present = number_after("rows:").expect("info names the rows present");
        (number_after("routes:        over the"), present, info)
    };
    let (counted, present, info) = counted_and_present("stopped");
    assert!(present > 0, "{info}");
    assert_eq!(
        counted, None,
        "half rows of a run that did not finish: {info}"
    );
    let mut a = args(&part, &["--symmetric", "on"]);
    a.push("--resume");
    let resumed = mpirun(3, &a).output_within("resume under mpirun -n 3");
    assert!(resumed.status.success(), "{}", text(&resumed));
    let (computed, kept) = resumed_counts(&String::from_utf8_lossy(&resumed.stderr));
    let (counted, present, info) = counted_and_present("resumed");
    assert_eq!(counted, Some(computed), "{info}");
    assert!(kept > 0 && computed + kept == present, "{info}");
    assert_same(&part, &full, "resumed after one worker's SIGTERM");
}
