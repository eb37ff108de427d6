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

/// Inputs that are no files (issue 48): a FIFO as `mtllib` blocked the load forever in
/// `open`, `/dev/zero` as `mtllib` or as a glTF buffer read until memory ran out. Each
/// is refused before it is opened, naming it (one error line, exit 1), within seconds.
#[test]
fn devices_and_fifos_as_inputs_are_refused_at_once() {
    use crate::common::Within;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fifo = d.join("fifo.mtl");
    let c = std::ffi::CString::new(path_str(&fifo)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let obj = |name: &str, lib: &str| {
        let p = d.join(name);
        std::fs::write(
            &p,
            format!("mtllib {lib}\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl white\nf 1 2 3\n"),
        )
        .unwrap();
        p
    };
    let gltf = d.join("zero.gltf");
    std::fs::write(
        &gltf,
        r#"{"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36, "uri": "/dev/zero"}]}"#,
    )
    .unwrap();
    for (scene, names) in [
        (obj("fifo.obj", "fifo.mtl"), ["fifo.obj", "a FIFO"]),
        (obj("zero.obj", "/dev/zero"), ["zero.obj", "a device"]),
        (gltf, ["zero.gltf", "a device"]),
    ] {
        let o = std::process::Command::new(crate::common::exe())
            .args(["compute", path_str(&scene), "-o", "/dev/null", "--quiet"])
            .output_within(path_str(&scene));
        crate::stress_cli::assert_one_error(&o, path_str(&scene), &names);
    }
}

/// Issue 48, item 16 for the CSV inputs: `solve --emission` and `render --radiosity`
/// read their file whatever it was, so `/dev/zero` was read until memory ran out and
/// a FIFO blocked the command in `open` for good. Both are refused at once (exit 1),
/// naming the option, the path and what it is; so is a FIFO as the `.ffz` FILE.
#[test]
fn devices_and_fifos_as_csv_inputs_are_refused_at_once() {
    use std::process::{Command, Stdio};
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ffz = d.join("c.ffz");
    let csv = d.join("b.csv");
    crate::common::ok(&["compute", "builtin:cube", "-o", path_str(&ffz), "--quiet"]);
    crate::common::ok(&["solve", path_str(&ffz), "-o", path_str(&csv), "--quiet"]);
    let fifo = d.join("fifo.csv");
    let c = std::ffi::CString::new(path_str(&fifo)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let out_csv = d.join("o.csv");
    let png = d.join("o.png");
    let (f, o, p, r) = (
        path_str(&ffz),
        path_str(&out_csv),
        path_str(&png),
        path_str(&csv),
    );
    for (input, what) in [(path_str(&fifo), "a FIFO"), ("/dev/zero", "a device")] {
        for (args, option) in [
            (vec!["solve", f, "-o", o, "--emission", input], "--emission"),
            (
                vec!["render", f, "--radiosity", input, "-o", p],
                "--radiosity",
            ),
            (vec!["render", input, "--radiosity", r, "-o", p], "FILE"),
        ] {
            let child = Command::new(crate::common::exe())
                .args(&args)
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap();
            let said = args.join(" ");
            let out = crate::common::output_before(child, Duration::from_secs(30))
                .unwrap_or_else(|| panic!("{said}: still reading after 30 s (killed)"));
            crate::stress_cli::assert_one_error(&out, &said, &[option, input, what]);
        }
    }
}
