//! Stress, faults during `compute`: SIGKILL of a worker rank or of rank 0 (the I/O
//! master) at seeded random points of an `mpirun -n 3` job, and a full disk (file-size
//! limit) embedded and under MPI. After each, `compute --resume` must give a file whose
//! rows equal an uninterrupted run's (`ffstream verify A --against B`, exit 0). Killing
//! mpirun itself and a worker failing on one row are in `mpi.rs` / `service.rs`.
//!
//! Ranks are found as mpirun's children (read from /proc, Open MPI's local launch), each
//! rank read from its OMPI_COMM_WORLD_RANK in /proc/PID/environ: no product code needed.
//! 3 seeds per victim by default, 10 with FFSTREAM_STRESS_LONG=1.

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::common::{
    children, ffstream, kill_tree_and_wait, mpirun, need_mpi, need_tool, ok, output_of_within,
    path_str, resumed_counts, runs, sigkill, wait_within, Within,
};
use crate::stress_cli::assert_one_error;

pub(crate) const SCENE: &[&str] = &[
    "builtin:cornell",
    "--patches",
    "600",
    "--quiet",
    "--threads",
    "1",
    "--samples",
    "8",
    "--chunk-kib",
    "16",
    "--flush-seconds",
    "0.05",
];

pub(crate) fn compute_args<'a>(out: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec!["compute"];
    a.extend_from_slice(SCENE);
    a.extend_from_slice(&["-o", path_str(out)]);
    a.extend_from_slice(extra);
    a
}

fn seeds() -> u64 {
    if std::env::var_os("FFSTREAM_STRESS_LONG").is_some() {
        10
    } else {
        3
    }
}

/// The ranks mpirun started: (pid, rank), once all `ranks` are up. Gives up after 30 s,
/// killing the job first (a panic alone would leave it running past the test).
pub(crate) fn rank_pids(mpirun_pid: u32, ranks: usize) -> Vec<(u32, usize)> {
    let t0 = Instant::now();
    loop {
        let mut found = Vec::new();
        for pid in children(mpirun_pid) {
            let Ok(env) = std::fs::read(format!("/proc/{pid}/environ")) else {
                continue;
            };
            let rank = env
                .split(|&b| b == 0)
                .filter_map(|kv| std::str::from_utf8(kv).ok())
                .find_map(|kv| kv.strip_prefix("OMPI_COMM_WORLD_RANK="))
                .and_then(|r| r.parse().ok());
            if let Some(rank) = rank {
                found.push((pid, rank));
            }
        }
        if found.len() == ranks {
            return found;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            kill_tree_and_wait(mpirun_pid);
            panic!(
                "{ranks} ranks not found under mpirun {mpirun_pid} in 30 s: {found:?}; job killed"
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// `verify A --against B` exits 0: every row present and bitwise identical.
pub(crate) fn assert_same(a: &Path, b: &Path, what: &str) {
    let v = ffstream(&["verify", path_str(a), "--against", path_str(b)]);
    assert_eq!(
        v.status.code(),
        Some(0),
        "{what}: files differ\n{}\n{}",
        String::from_utf8_lossy(&v.stdout),
        String::from_utf8_lossy(&v.stderr)
    );
}

pub(crate) fn output_text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn kill_and_resume(victim_rank: usize, seed: u64, full: &Path, dir: &Path) -> (f64, u64, u64) {
    let part = dir.join(format!("kill{victim_rank}_{seed}.ffz"));
    let full_len = std::fs::metadata(full).unwrap().len() as f64;
    // Kill once the file holds 10 %…70 % of the full file's rows (its chunks start at
    // meta_len, bytes 40..48 of the header, formats/ffz-v1.md §3.1).
    let bytes = std::fs::read(full).unwrap();
    let meta_len = u64::from_le_bytes(bytes[40..48].try_into().unwrap()) as f64;
    let r =
        ffstream::formfactor::sampling::SplitMix64::new(seed * 31 + victim_rank as u64).next_u64();
    let fraction = 0.1 + 0.6 * (r % 1000) as f64 / 1000.0;
    let target = meta_len + fraction * (full_len - meta_len);
    let mut child = mpirun(3, &compute_args(&part, &[]))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let ranks = rank_pids(child.id(), 3);
    let victim = ranks.iter().find(|(_, k)| *k == victim_rank).unwrap().0;
    let t0 = Instant::now();
    while std::fs::metadata(&part).map_or(0, |m| m.len()) < target as u64
        && t0.elapsed() < Duration::from_secs(60)
        && child.try_wait().unwrap().is_none()
    {
        std::thread::sleep(Duration::from_millis(2));
    }
    sigkill(victim);
    let status = wait_within(&mut child, "a job with a killed rank");
    assert!(
        !status.success(),
        "rank {victim_rank} seed {seed}: the job finished before the kill (fraction {fraction:.2})"
    );
    // Resume under MPI with a different rank count, then compare.
    let args = compute_args(&part, &["--resume"]);
    let out = mpirun(2, &args).output_within("resume under mpirun -n 2");
    assert!(out.status.success(), "resume: {}", output_text(&out));
    let (computed, present) = resumed_counts(&String::from_utf8_lossy(&out.stderr));
    assert_same(&part, full, &format!("kill rank {victim_rank} seed {seed}"));
    (fraction, computed, present)
}

#[test]
fn sigkill_of_a_worker_or_rank_0_then_resume_gives_the_uninterrupted_rows() {
    if !need_mpi() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    ok(&compute_args(&full, &[]));
    for victim in [1, 0, 2] {
        for seed in 0..seeds() {
            let (f, computed, present) = kill_and_resume(victim, seed, &full, dir.path());
            println!(
                "SIGKILL rank {victim} at {:.0}% of the rows written: resume computed {computed} rows, kept {present}",
                100.0 * f
            );
            // The kill landed mid-run: some rows were kept, some recomputed.
            assert!(
                present > 0 && computed > 0,
                "kept {present}, computed {computed}"
            );
        }
    }
}

/// `sh -c 'trap "" XFSZ; exec prlimit --fsize=N CMD'`: writes past N bytes fail with
/// EFBIG (as on a full disk) instead of killing the process with SIGXFSZ.
fn with_file_limit(limit: u64, cmd: &Command) -> Output {
    let mut c = Command::new("sh");
    c.arg("-c")
        .arg(format!("trap '' XFSZ; exec prlimit --fsize={limit} \"$@\""))
        .arg("sh")
        .arg(cmd.get_program())
        .args(cmd.get_args());
    for (k, v) in cmd.get_envs() {
        match v {
            Some(v) => c.env(k, v),
            None => c.env_remove(k),
        };
    }
    c.output_within("a run with a file size limit")
}

#[test]
fn full_disk_gives_one_clear_error_and_resume_completes_the_file() {
    if !need_tool(
        "prlimit (util-linux)",
        runs("prlimit"),
        "FFSTREAM_SKIP_PRLIMIT",
    ) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    ok(&compute_args(&full, &[]));
    let full_len = std::fs::metadata(&full).unwrap().len();
    let limit = full_len * 2 / 5;
    // Embedded.
    let part = dir.path().join("part.ffz");
    let mut cmd = Command::new(crate::common::exe());
    cmd.args(compute_args(&part, &[]))
        .env_remove("FFSTREAM_FAIL_ROW");
    let out = with_file_limit(limit, &cmd);
    let line = assert_one_error(&out, "disk full, embedded", &["part.ffz"]);
    println!("disk full (limit {limit} of {full_len} bytes), embedded: {line}");
    assert!(
        line.contains("File too large") || line.contains("No space"),
        "{line}"
    );
    assert!(std::fs::metadata(&part).unwrap().len() <= limit);
    let resumed = ok(&compute_args(&part, &["--resume"]));
    let (computed, present) = resumed_counts(&resumed);
    assert!(
        present > 0 && computed > 0,
        "kept {present}, computed {computed}"
    );
    assert_same(&part, &full, "disk full, embedded");
    // Under MPI: only rank 0 writes, so only rank 0 gets the limit, set with
    // `prlimit --pid` once it is writing (a limit from the start would also break Open
    // MPI's own shared-memory files). Every rank ignores SIGXFSZ (`trap` + exec).
    if !need_mpi() {
        return;
    }
    let part = dir.path().join("mpi_part.ffz");
    let mut c = Command::new("mpirun");
    c.args(["-n", "3", "--oversubscribe"])
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_btl", "self,vader")
        .env_remove("FFSTREAM_FAIL_ROW")
        .args(["sh", "-c", "trap '' XFSZ; exec \"$0\" \"$@\""])
        .arg(crate::common::exe())
        .args(compute_args(&part, &[]))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let child = c.spawn().unwrap();
    let rank0 = rank_pids(child.id(), 3)
        .into_iter()
        .find(|r| r.1 == 0)
        .unwrap()
        .0;
    let t0 = Instant::now();
    while std::fs::metadata(&part).map_or(0, |m| m.len()) == 0
        && t0.elapsed() < Duration::from_secs(30)
    {
        std::thread::sleep(Duration::from_millis(1));
    }
    let set = Command::new("prlimit")
        .args([
            "--pid",
            &rank0.to_string(),
            &format!("--fsize={limit}:{limit}"),
        ])
        .status()
        .unwrap();
    assert!(set.success());
    let out = output_of_within(child, "a job whose rank 0 meets a full disk");
    assert!(!out.status.success());
    let text = output_text(&out);
    assert!(!text.contains("panicked at"), "{text}");
    let errors: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("ffstream: error: "))
        .collect();
    assert!(
        errors.len() == 1
            && errors[0].contains("mpi_part.ffz")
            && errors[0].contains("File too large"),
        "one error line naming the file: {text}"
    );
    println!("disk full under mpirun -n 3: {}", errors[0]);
    let out =
        mpirun(3, &compute_args(&part, &["--resume"])).output_within("resume after a full disk");
    assert!(out.status.success(), "{}", output_text(&out));
    assert_same(&part, &full, "disk full, mpi");
}
