//! Helpers shared by the integration tests: run the `ffstream` binary, with or without
//! mpirun, in a temporary directory.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

/// The binary under test (built by cargo for the integration tests).
pub(crate) fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_ffstream"))
}

/// `ffstream ARGS...` with stdin closed; panics with the output if it cannot start.
pub(crate) fn ffstream(args: &[&str]) -> Output {
    Command::new(exe())
        .args(args)
        .env_remove("FFSTREAM_FAIL_ROW")
        .output()
        .expect("cannot start ffstream")
}

/// Like [`ffstream`] but asserts success and returns stderr.
pub(crate) fn ok(args: &[&str]) -> String {
    let out = ffstream(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "ffstream {args:?} failed: {}\nstderr:\n{stderr}",
        out.status
    );
    stderr
}

/// An `mpirun -n P ffstream ...` command, with Open MPI's flags for running as root and
/// for more ranks than cores (CI runs as root on 2 cores).
pub(crate) fn mpirun(ranks: usize, args: &[&str]) -> Command {
    let mut c = Command::new("mpirun");
    c.args(["-n", &ranks.to_string(), "--oversubscribe"])
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        // Shared-memory transport only: no network interfaces needed.
        .env("OMPI_MCA_btl", "self,vader")
        .env_remove("FFSTREAM_FAIL_ROW")
        .env_remove("FFSTREAM_TEST_STOP_ROW")
        .arg(exe())
        .args(args);
    c
}

/// True when mpirun is on PATH and the binary was built with MPI.
pub(crate) fn mpi_available() -> bool {
    let has_mpirun = Command::new("mpirun")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    has_mpirun && cfg!(feature = "mpi")
}

pub(crate) fn path_str(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

/// "rows: X computed, Y skipped (not needed), Z already present" → (X, Z).
pub(crate) fn resumed_counts(stderr: &str) -> (u64, u64) {
    let line = stderr
        .lines()
        .find(|l| l.starts_with("rows: "))
        .unwrap_or_else(|| panic!("no rows line: {stderr}"));
    let num = |after: &str| -> u64 {
        let w: Vec<&str> = line.split_whitespace().collect();
        let k = w.iter().position(|x| *x == after).unwrap();
        w[k - 1].trim_end_matches(',').parse().unwrap()
    };
    (num("computed,"), num("already"))
}

/// The processes whose parent is `pid`, read from `/proc/*/stat` (a minimal Debian has
/// no procps, so no `pgrep`).
pub(crate) fn children(pid: u32) -> Vec<u32> {
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    dir.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&p| {
            // "PID (COMM) STATE PPID ...": COMM may hold spaces and parentheses, so the
            // fields are counted from the last ") ".
            std::fs::read_to_string(format!("/proc/{p}/stat")).is_ok_and(|st| {
                st.rsplit_once(") ")
                    .and_then(|(_, rest)| rest.split_whitespace().nth(1))
                    .and_then(|ppid| ppid.parse::<u32>().ok())
                    == Some(pid)
            })
        })
        .collect()
}

/// `pid` and all its descendants (Open MPI may put ranks in process groups of their own,
/// so a group kill does not reach them).
pub(crate) fn process_tree(pid: u32) -> Vec<u32> {
    let mut all = vec![pid];
    let mut k = 0;
    while k < all.len() {
        let below = children(all[k]);
        all.extend(below);
        k += 1;
    }
    all
}

/// SIGKILL to `pid` (no `kill` command needed: it is procps' on Debian). A process that
/// is already gone is not an error.
pub(crate) fn sigkill(pid: u32) {
    let pid = libc::pid_t::try_from(pid).expect("a pid fits pid_t");
    // SAFETY: kill(2) takes plain integers and touches no memory of ours.
    unsafe {
        libc::kill(pid, libc::SIGKILL);
    }
}

/// SIGKILL mpirun and every rank, then wait (up to 30 s) until all are gone: only then
/// may a resume open the file.
pub(crate) fn kill_tree_and_wait(pid: u32) {
    let pids = process_tree(pid);
    for &p in &pids {
        sigkill(p);
    }
    let t0 = Instant::now();
    let alive = |p: &u32| {
        std::fs::read_to_string(format!("/proc/{p}/stat")).is_ok_and(|st| {
            st.rsplit(") ")
                .next()
                .is_some_and(|rest| !rest.starts_with('Z'))
        })
    };
    while pids.iter().any(alive) {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "processes {pids:?} still alive 30 s after SIGKILL"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// True when a test may use `tool`; `found` says whether it is there. A missing tool
/// fails the test with a message that names it (`make test` installs every tool the
/// tests call), unless the variable `skip` is set, which turns the test into a no-op
/// that says so.
pub(crate) fn need_tool(tool: &str, found: bool, skip: &str) -> bool {
    if found {
        return true;
    }
    if std::env::var_os(skip).is_some() {
        eprintln!("skipped: {tool} is missing and {skip} is set");
        return false;
    }
    panic!("this test needs {tool}, which is missing: run `make test` (it installs it), or set {skip}=1 to skip the tests that need it");
}

/// True when `cmd --version` runs.
pub(crate) fn runs(cmd: &str) -> bool {
    Command::new(cmd)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
}

/// [`need_tool`] for MPI: mpirun on PATH and a binary built with the `mpi` feature
/// (`FFSTREAM_SKIP_MPI`).
pub(crate) fn need_mpi() -> bool {
    need_tool(
        "mpirun (Open MPI) and a binary built with the mpi feature",
        mpi_available(),
        "FFSTREAM_SKIP_MPI",
    )
}

/// Longest an mpirun job of these tests may take before it counts as hung (the longest
/// takes a few seconds).
pub(crate) const MPIRUN_LIMIT: Duration = Duration::from_secs(300);

/// Waits for an mpirun job for at most [`MPIRUN_LIMIT`]. Open MPI 4.1's mpirun was seen
/// here to hang for good after every rank of an aborted job had exited (the ranks left
/// as zombies, mpirun blocked on a futex); without a limit that hangs the whole test run
/// until CI's own limit. Past it, the job's processes are killed and the test fails,
/// naming the hang.
pub(crate) trait Within {
    /// `Command::output` under the limit (stdin closed).
    fn output_within(&mut self, what: &str) -> Output;
}

impl Within for Command {
    fn output_within(&mut self, what: &str) -> Output {
        let child = self
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
        output_of_within(child, what)
    }
}

/// `Child::wait_with_output` for a spawned mpirun job, under [`MPIRUN_LIMIT`]. Once
/// the job has ended its pipes must close within [`PIPE_LIMIT`]; a process that
/// outlived mpirun and still holds one fails the test, named, instead of hanging it.
pub(crate) fn output_of_within(child: Child, what: &str) -> Output {
    output_at_most(child, what, MPIRUN_LIMIT, PIPE_LIMIT)
}

/// [`output_of_within`] with its two limits given.
fn output_at_most(mut child: Child, what: &str, limit: Duration, pipe_limit: Duration) -> Output {
    let out = drain(child.stdout.take());
    let err = drain(child.stderr.take());
    let status = wait_at_most(&mut child, what, limit);
    let t0 = Instant::now();
    let rest = |pipe: &crossbeam::channel::Receiver<Vec<u8>>, name: &str| {
        pipe.recv_timeout(pipe_limit.saturating_sub(t0.elapsed()))
            .unwrap_or_else(|_| {
                panic!(
                    "{what}: ended ({status}) but its {name} stayed open for \
                     {pipe_limit:?}: a process outlived it"
                )
            })
    };
    Output {
        status,
        stdout: rest(&out, "stdout"),
        stderr: rest(&err, "stderr"),
    }
}

/// The output of `child` if it ends within `limit`; past it, None, once it and every
/// process under it are killed. For tests that report a hang among other faults they
/// collect instead of failing at the first (`stress_ranges.rs`).
pub(crate) fn output_before(mut child: Child, limit: Duration) -> Option<Output> {
    let out = drain(child.stdout.take());
    let err = drain(child.stderr.take());
    let t0 = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for a child") {
            break status;
        }
        if t0.elapsed() > limit {
            kill_tree_and_wait(child.id());
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let rest = |pipe: &crossbeam::channel::Receiver<Vec<u8>>| {
        pipe.recv_timeout(PIPE_LIMIT).unwrap_or_default()
    };
    Some(Output {
        status,
        stdout: rest(&out),
        stderr: rest(&err),
    })
}

/// How long the pipes of an ended mpirun job may stay open (see [`output_of_within`]).
const PIPE_LIMIT: Duration = Duration::from_secs(60);

/// Reads `pipe` to its end on a thread of its own (so that neither pipe of a child can
/// fill up and block it while the other is read); the bytes arrive on the channel.
fn drain(pipe: Option<impl Read + Send + 'static>) -> crossbeam::channel::Receiver<Vec<u8>> {
    let (tx, rx) = crossbeam::channel::bounded(1);
    std::thread::spawn(move || {
        let mut buf = Vec::new();
        if let Some(mut r) = pipe {
            let _ = r.read_to_end(&mut buf);
        }
        let _ = tx.send(buf);
    });
    rx
}

/// Waits for the spawned mpirun `child` for at most [`MPIRUN_LIMIT`] (see [`Within`]).
pub(crate) fn wait_within(child: &mut Child, what: &str) -> ExitStatus {
    wait_at_most(child, what, MPIRUN_LIMIT)
}

/// Waits for `child` for at most `limit`; past it, kills it and its descendants and
/// panics.
fn wait_at_most(child: &mut Child, what: &str, limit: Duration) -> ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait for mpirun") {
            return status;
        }
        if t0.elapsed() > limit {
            let pids = process_tree(child.id());
            kill_tree_and_wait(child.id());
            let _ = child.wait();
            panic!(
                "{what}: still running after {limit:?}; killed it and its processes \
                 {pids:?} (an mpirun hang, see common::Within)"
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_hung_job_is_killed_and_named() {
    // A shell that starts a child and waits: both must be gone after the limit.
    let mut child = Command::new("sh")
        .args(["-c", "sleep 30 & wait"])
        .spawn()
        .expect("sh");
    let pid = child.id();
    let hung = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        wait_at_most(&mut child, "sleeper", Duration::from_millis(200))
    }));
    let message = hung.expect_err("the wait must give up");
    let message = message
        .downcast_ref::<String>()
        .expect("a formatted panic message");
    assert!(
        message.starts_with("sleeper: still running after"),
        "{message}"
    );
    assert!(
        std::fs::metadata(format!("/proc/{pid}")).is_err(),
        "the hung process is reaped"
    );
}

#[test]
fn a_process_outliving_its_job_is_named() {
    // The shell ends at once; the sleep it leaves holds both pipes for eight seconds.
    // The wait must give up 200 ms after the shell's exit, long before the sleep ends
    // (measured 2.2 s from the spawn on the 2-core machine at load 6, where two seconds
    // of sleep were too few to tell giving up from waiting).
    let child = Command::new("sh")
        .args(["-c", "sleep 8 & exit 0"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("sh");
    let t0 = Instant::now();
    let held = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        output_at_most(
            child,
            "orphan",
            Duration::from_secs(10),
            Duration::from_millis(200),
        )
    }));
    let message = held.expect_err("the pipes' wait must give up");
    let message = message
        .downcast_ref::<String>()
        .expect("a formatted panic message");
    assert!(
        message.contains("orphan") && message.contains("outlived"),
        "{message}"
    );
    assert!(
        t0.elapsed() < Duration::from_secs(8),
        "gave up late (the orphan had ended): {:?}",
        t0.elapsed()
    );
}
