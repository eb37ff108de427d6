//! Crash safety: a writer process SIGKILLed mid-stream leaves a file from which every
//! chunk completed before the kill is recovered, and `resume` completes it. Also a
//! write that fails (file-size limit = disk full) names the path and keeps what was
//! written recoverable.
//!
//! The child is this test binary itself, run on the ignored test `child_writer` with
//! `FFZ_CHILD_PATH` set.

use crate::ffz_common::*;
use ffstream::ffz::{encode_chunk, FfzReader, FfzWriter, Layout, WriterOptions};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

const N: u32 = 400;
const SEED: u64 = 0xC0FFEE;
const LAYOUT: Layout = Layout::Dense;

/// The child: append chunks of 3 rows through the I/O-master path, print the ids after
/// each append returns, sleep a little so the parent can kill it mid-stream.
#[test]
#[ignore = "helper run by kill_mid_stream_then_resume in a child process"]
fn child_writer() {
    let Ok(path) = std::env::var("FFZ_CHILD_PATH") else {
        return;
    };
    let pause: u64 = std::env::var("FFZ_CHILD_PAUSE_MS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let m = meta(LAYOUT, patches(N, SEED));
    let mut ids: Vec<u32> = (0..N).collect();
    SplitMix64::new(SEED).shuffle(&mut ids);
    let opts = WriterOptions {
        fsync: false,
        ..Default::default()
    };
    let mut w = FfzWriter::create(&path, &m, opts).unwrap();
    for batch in ids.chunks(3) {
        let rows: Vec<_> = batch.iter().map(|&i| row(SEED, i, N, LAYOUT)).collect();
        let c = encode_chunk(&rows, LAYOUT, N, 1).unwrap();
        if let Err(e) = w.append_chunk(c) {
            println!("FFZ-ERROR {e}");
            return;
        }
        println!(
            "FFZ-DONE {}",
            batch
                .iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        );
        std::thread::sleep(std::time::Duration::from_millis(pause));
    }
    w.finish().unwrap();
    println!("FFZ-FINISHED");
}

fn child(path: &std::path::Path, pause_ms: u64) -> Command {
    let mut c = Command::new(std::env::current_exe().unwrap());
    c.args([
        "ffz_kill::child_writer",
        "--exact",
        "--ignored",
        "--nocapture",
        "--test-threads=1",
    ])
    .env("FFZ_CHILD_PATH", path)
    .env("FFZ_CHILD_PAUSE_MS", pause_ms.to_string())
    .stdout(Stdio::piped())
    .stderr(Stdio::null());
    c
}

fn done_rows(line: &str) -> Vec<u32> {
    line.trim_start_matches("FFZ-DONE ")
        .split_whitespace()
        .map(|s| s.parse().unwrap())
        .collect()
}

#[test]
fn kill_mid_stream_then_resume() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.ffz");
    let mut ch = child(&path, 5).spawn().unwrap();
    let out = BufReader::new(ch.stdout.take().unwrap());
    let mut reported = Vec::new();
    let mut appends = 0;
    for line in out.lines() {
        let line = line.unwrap();
        if line.starts_with("FFZ-DONE") {
            reported.extend(done_rows(&line));
            appends += 1;
            if appends == 20 {
                ch.kill().unwrap(); // SIGKILL on Unix
                break;
            }
        }
        assert!(
            !line.starts_with("FFZ-FINISHED"),
            "child finished before the kill"
        );
    }
    ch.wait().unwrap();

    let rd = FfzReader::open(&path).unwrap();
    assert!(
        !rd.warnings().is_empty(),
        "an unfinished file must come with a warning"
    );
    assert!(
        rd.warnings()[0].contains("recovered"),
        "{:?}",
        rd.warnings()
    );
    // Every reported chunk is back; rows the reader holds are exact.
    for &i in &reported {
        assert_ne!(
            rd.presence().get(i),
            ffstream::ffz::RowState::Missing,
            "row {i} lost"
        );
    }
    let held = check_against(&rd, &|i| row(SEED, i, N, LAYOUT));
    assert!(
        held >= reported.len() as u64 && held < N as u64,
        "held {held}"
    );
    assert_eq!(rd.presence().missing_count(), N as u64 - held);
    drop(rd);

    let m = meta(LAYOUT, patches(N, SEED));
    let (mut w, presence) = FfzWriter::resume(&path, &m, WriterOptions::default()).unwrap();
    assert_eq!(presence.missing_count(), N as u64 - held);
    for i in presence.missing() {
        w.push_row(row(SEED, i, N, LAYOUT)).unwrap();
    }
    w.finish().unwrap();
    let rd = FfzReader::open(&path).unwrap();
    assert!(rd.warnings().is_empty(), "{:?}", rd.warnings());
    assert_eq!(check_against(&rd, &|i| row(SEED, i, N, LAYOUT)), N as u64);
    assert!(rd.verify().ok());
}

/// A full disk, simulated by a file-size limit (`prlimit --fsize`, SIGXFSZ ignored so
/// the write fails with EFBIG instead of killing the process).
#[test]
fn full_disk_error_names_the_path_and_keeps_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("full.ffz");
    let limit = 200_000; // meta block ~67 kB, then about 25 chunks of 4.8 kB raw
    let exe = std::env::current_exe().unwrap();
    let Some(out) = under_file_size_limit(
        limit,
        &exe,
        &[
            "ffz_kill::child_writer",
            "--exact",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ],
        &[("FFZ_CHILD_PATH", path.as_os_str())],
    ) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let err_line = stdout.lines().find(|l| l.starts_with("FFZ-ERROR"));
    let Some(err_line) = err_line else {
        panic!("the writer did not report a write error:\n{stdout}");
    };
    assert!(
        err_line.contains("full.ffz") && err_line.contains("write chunk"),
        "{err_line}"
    );
    let reported: Vec<u32> = stdout
        .lines()
        .filter(|l| l.starts_with("FFZ-DONE"))
        .flat_map(done_rows)
        .collect();
    assert!(!reported.is_empty());
    let rd = FfzReader::open(&path).unwrap();
    for &i in &reported {
        assert_ne!(
            rd.presence().get(i),
            ffstream::ffz::RowState::Missing,
            "row {i} lost"
        );
    }
    check_against(&rd, &|i| row(SEED, i, N, LAYOUT));
}

/// `DIR/c.ffz`: the Cornell box at about `patches` patches.
fn cornell_ffz(dir: &std::path::Path, patches: u32) -> std::path::PathBuf {
    use crate::common::{ok, path_str};
    let ffz = dir.join("c.ffz");
    let patches = patches.to_string();
    ok(&[
        "compute",
        "builtin:cornell",
        "--patches",
        &patches,
        "-q",
        "-o",
        path_str(&ffz),
    ]);
    ffz
}

/// `export --npz` onto a full disk (a file-size limit that the spill file fits under
/// and the archive does not; then `/dev/full`): one error line naming the archive, no
/// archive left that looks like one, no spill left, and a device is not removed. The
/// zip writer, dropped unfinished, used to print its own unterminated message first,
/// and the cut archive stayed.
#[test]
fn npz_export_onto_a_full_disk_is_one_error_and_leaves_no_archive() {
    use crate::common::{ffstream as run, path_str};
    let dir = tempfile::tempdir().unwrap();
    let ffz = cornell_ffz(dir.path(), 150);
    let r = FfzReader::open(&ffz).unwrap();
    let n = r.n() as usize;
    let nnz: usize = (0..r.n())
        .map(|i| {
            let row = r.row(i).unwrap().unwrap();
            row.to_dense(n).iter().filter(|&&v| v != 0.0).count()
        })
        .sum();
    // The spill holds 8 bytes an entry; the archive that and n + 1 offsets more.
    let limit = 8 * nnz + 64;
    let npz = dir.path().join("c.npz");
    let Some(out) = under_file_size_limit(
        limit,
        &crate::common::exe(),
        &["export", path_str(&ffz), "--npz", path_str(&npz)],
        &[],
    ) else {
        return;
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    assert!(!out.status.success(), "the export must fail: {stderr}");
    assert!(
        lines.len() == 1 && lines[0].starts_with("ffstream: error: ") && lines[0].contains("c.npz"),
        "one error line naming the archive expected:\n{stderr}"
    );
    assert!(!npz.exists(), "a cut archive was left behind");
    let spills: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".spill"))
        .collect();
    assert!(spills.is_empty(), "the spill was left: {spills:?}");
    // A device: written to, failing, and still there.
    let full = std::path::Path::new("/dev/full");
    let out = run(&["export", path_str(&ffz), "--npz", "/dev/full"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with("ffstream: error: /dev/full"), "{stderr}");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata(full)
        .unwrap()
        .file_type()
        .is_char_device());
}

/// `export --npz` onto a device that takes the bytes (`/dev/null`): it succeeds (the
/// device is not synced: `/dev/null` refuses), and the spill goes to TMPDIR and is
/// removed there, not created beside the device (it used to be `/dev/null.spill`).
#[test]
fn npz_export_onto_a_device_spills_into_tmpdir() {
    use crate::common::path_str;
    let dir = tempfile::tempdir().unwrap();
    let ffz = cornell_ffz(dir.path(), 60);
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let out = std::process::Command::new(crate::common::exe())
        .args(["export", path_str(&ffz), "--npz", "/dev/null"])
        .env("TMPDIR", &tmp)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!std::path::Path::new("/dev/null.spill").exists());
    assert_eq!(
        std::fs::read_dir(&tmp).unwrap().count(),
        0,
        "a spill was left"
    );
}

/// Runs `exe args` (with `env`) under a file-size limit of `limit` bytes, SIGXFSZ
/// ignored so that a write past it fails with EFBIG, as on a full disk. None when
/// prlimit or bash is missing and `FFSTREAM_SKIP_PRLIMIT` says to skip.
fn under_file_size_limit(
    limit: usize,
    exe: &std::path::Path,
    args: &[&str],
    env: &[(&str, &std::ffi::OsStr)],
) -> Option<std::process::Output> {
    use crate::common::{need_tool, runs};
    if !need_tool(
        "prlimit (util-linux) and bash",
        runs("prlimit") && runs("bash"),
        "FFSTREAM_SKIP_PRLIMIT",
    ) {
        return None;
    }
    let mut cmd = Command::new("bash");
    cmd.arg("-c")
        .arg(format!(
            "trap '' XFSZ; exec prlimit --fsize={limit} \"$0\" \"$@\""
        ))
        .arg(exe)
        .args(args);
    for (k, v) in env {
        cmd.env(k, v);
    }
    Some(cmd.output().unwrap())
}
