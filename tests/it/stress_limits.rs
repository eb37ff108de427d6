//! Stress, values inside or at the edge of an option's documented range that used to
//! break the run (issue 48): each must either work or be a usage error (exit 2) naming
//! the option and its range, never a panic (exit 101) or an abort.

use crate::common::{ffstream, path_str};
use crate::stress_cli::assert_no_panic;

/// `--threads 257` to `4096` are inside the documented range 1..=4096, but a dynamic
/// batch's floor (one row per thread) then exceeded its cap of 256 and the master
/// panicked in `clamp` ("min > max", exit 101). The run must complete.
#[test]
fn more_than_256_threads_complete_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.ffz");
    let o = ffstream(&[
        "compute",
        "builtin:cube",
        "-o",
        path_str(&out),
        "--threads",
        "300",
        "--quiet",
    ]);
    assert_no_panic(&o, "--threads 300");
    assert!(
        o.status.success(),
        "--threads 300: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v = ffstream(&["verify", path_str(&out)]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
}

/// `--stall-seconds 1e300` and `--flush-seconds 1e20` passed the old checks (finite
/// and positive) and then panicked turning the number into a `Duration` (limit about 1.8e19 s).
/// Every duration option is now bounded where it is read: a usage error naming it.
#[test]
fn durations_beyond_what_a_timer_holds_are_usage_errors() {
    for arg in [
        "--stall-seconds=1e300",
        "--stall-seconds=2e19",
        "--stall-seconds=inf",
        "--flush-seconds=1e20",
        "--flush-seconds=1e300",
    ] {
        let o = ffstream(&["compute", "builtin:cube", "-o", "/dev/null", arg]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{arg}: {stderr}");
        let option = arg.split('=').next().unwrap();
        assert!(
            stderr.contains(option) && stderr.contains("1e9"),
            "{arg}: should name the option and its range: {stderr}"
        );
    }
}
