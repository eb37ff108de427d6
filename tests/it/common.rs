//! Helpers shared by the integration tests: run the `ffstream` binary, with or without
//! mpirun, in a temporary directory.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary under test (built by cargo for the integration tests).
pub fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_ffstream"))
}

/// `ffstream ARGS...` with stdin closed; panics with the output if it cannot start.
pub fn ffstream(args: &[&str]) -> Output {
    Command::new(exe())
        .args(args)
        .env_remove("FFSTREAM_FAIL_ROW")
        .output()
        .expect("cannot start ffstream")
}

/// Like [`ffstream`] but asserts success and returns stderr.
pub fn ok(args: &[&str]) -> String {
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
pub fn mpirun(ranks: usize, args: &[&str]) -> Command {
    let mut c = Command::new("mpirun");
    c.args(["-n", &ranks.to_string(), "--oversubscribe"])
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        // Shared-memory transport only: no network interfaces needed.
        .env("OMPI_MCA_btl", "self,vader")
        .env_remove("FFSTREAM_FAIL_ROW")
        .arg(exe())
        .args(args);
    c
}

/// True when mpirun is on PATH and the binary was built with MPI.
pub fn mpi_available() -> bool {
    let has_mpirun = Command::new("mpirun")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    has_mpirun && cfg!(feature = "mpi")
}

pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}
