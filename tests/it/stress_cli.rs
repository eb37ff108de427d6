//! Stress, bad input through the command line: every file of the corpus in
//! `tests/data/bad/` (whose first line says what it breaks) given to `ffstream compute`
//! and `ffstream run`, and impossible sizes. Each must end with exit code 1 and exactly
//! one `ffstream: error: ...` line naming the file (and the line, where there is one),
//! or load with the documented warning; never a panic (exit 101, "panicked at") or an
//! abort. The library-level checks of the same corpus (error kinds) are in `scene.rs`.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::{ffstream, path_str};

pub(crate) fn bad(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/bad")
        .join(name)
}

/// No panic, no abort, no signal: the process ended through `main`.
pub(crate) fn assert_no_panic(out: &Output, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("panicked at") && !stderr.contains("RUST_BACKTRACE"),
        "{what}: panic\n{stderr}"
    );
    let code = out.status.code();
    assert!(
        matches!(code, Some(0..=3)),
        "{what}: exit status {:?} (101 = panic, none = signal)\n{stderr}",
        out.status
    );
}

/// Exit code 1 and exactly one error line, which contains every string in `names`.
/// Returns the error line.
pub(crate) fn assert_one_error(out: &Output, what: &str, names: &[&str]) -> String {
    assert_no_panic(out, what);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{what}: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("ffstream: error: "))
        .collect();
    assert_eq!(errors.len(), 1, "{what}: one error line wanted:\n{stderr}");
    for n in names {
        assert!(
            errors[0].contains(n),
            "{what}: `{n}` not named in {}",
            errors[0]
        );
    }
    errors[0].to_string()
}

/// What each corpus file must give: an error naming (file, line), or a warning (the
/// file loads; the text the warning must contain).
enum Want {
    Error(&'static str, Option<u32>),
    Warning(&'static str),
}

fn expected(file: &str) -> Want {
    use Want::*;
    match file {
        "all_degenerate.obj" => Error("all_degenerate.obj", None),
        "big_index.obj" => Error("big_index.obj", Some(8)),
        "collinear.obj" => Error("collinear.obj", None),
        "degenerate.obj" => Warning("dropped 3 degenerate"),
        "duplicate_faces.obj" => Warning("1 face(s) repeat another face exactly (same corners, same facing; first line 25 repeats line 23), in group(s) y0_copy"),
        "empty.obj" => Error("empty.obj", None),
        "empty_file.obj" => Error("empty_file.obj", None),
        "huge_coords.obj" => Error("huge_coords.obj", Some(4)),
        "huge_coord_vertex.obj" => Error("huge_coord_vertex.obj", Some(5)),
        "index_negative.obj" => Error("index_negative.obj", Some(16)),
        "index_out_of_range.obj" => Error("index_out_of_range.obj", Some(16)),
        "index_zero.obj" => Error("index_zero.obj", Some(16)),
        "inf.obj" => Error("inf.obj", Some(9)),
        "kd_high.obj" => Error("kd_high.mtl", Some(3)),
        "latin1.obj" => Warning("line 13 is not UTF-8: read as Latin-1"),
        "not_text.obj" => Error("not_text.obj", None),
        "kd_negative.obj" => Error("kd_negative.mtl", Some(6)),
        "kd_short.obj" => Error("kd_short.mtl", Some(3)),
        "ke_negative.obj" => Error("ke_negative.mtl", Some(6)),
        "line_element.obj" => Warning("ignored 1 line element"),
        "malformed.obj" => Error("malformed.obj", Some(5)),
        "malformed_face.obj" => Error("malformed_face.obj", Some(13)),
        "missing_material.obj" => Error("missing_material.obj", Some(15)),
        "missing_mtl.obj" => Error("missing_mtl.obj", Some(2)),
        "mtl_unreadable.obj" => Error("mtl_unreadable.obj", Some(2)),
        "nan.obj" => Error("nan.obj", Some(7)),
        "no_emitter.obj" => Warning("no face uses an emitting material"),
        "no_material.obj" => Error("no_material.obj", Some(12)),
        "nonplanar.obj" => Warning("non-planar"),
        "overflow.obj" => Error("overflow.obj", Some(10)),
        "short_face.obj" => Error("short_face.obj", Some(16)),
        "short_vertex.obj" => Error("short_vertex.obj", Some(4)),
        "tiny_coords.obj" => Error("tiny_coords.obj", None),
        other => panic!("{other}: new corpus file, say here what it must give"),
    }
}

/// Files whose only faces are dropped as degenerate: the error points at the first one.
fn dropped_line(file: &str) -> Option<u32> {
    match file {
        "all_degenerate.obj" | "collinear.obj" | "tiny_coords.obj" => {
            let text = std::fs::read_to_string(bad(file)).unwrap();
            text.lines()
                .position(|l| l.starts_with("f "))
                .map(|i| i as u32 + 1)
        }
        _ => None,
    }
}

#[test]
fn every_corpus_file_gives_one_error_line_or_a_warning_through_compute_and_run() {
    let dir = tempfile::tempdir().unwrap();
    let mut files: Vec<String> = std::fs::read_dir(bad(""))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".obj"))
        .collect();
    files.sort();
    assert!(files.len() >= 29, "corpus shrank: {files:?}");
    for file in &files {
        let path = bad(file);
        let out_ffz = dir.path().join("x.ffz");
        let out_dir = dir.path().join("run");
        let compute_with = |extra: &[&str]| {
            let mut a = vec!["compute", path_str(&path), "-o", path_str(&out_ffz)];
            a.extend_from_slice(&["--patches", "40", "--quiet", "--force"]);
            a.extend_from_slice(extra);
            ffstream(&a)
        };
        let compute = compute_with(&[]);
        let run = ffstream(&[
            "run",
            path_str(&path),
            "--out-dir",
            path_str(&out_dir),
            "--patches",
            "40",
            "--quiet",
        ]);
        match expected(file) {
            Want::Error(named, line) => {
                for (cmd, out) in [("compute", &compute), ("run", &run)] {
                    let what = format!("{cmd} {file}");
                    let mut names = vec![named.to_string()];
                    match (line, dropped_line(file)) {
                        (Some(l), _) => names.push(format!(":{l}:")),
                        (None, Some(l)) => names.push(format!("first at line {l}")),
                        (None, None) => {}
                    }
                    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
                    assert_one_error(out, &what, &refs);
                    // A load error stops everything before any output.
                    assert_eq!(
                        String::from_utf8_lossy(&out.stderr).lines().count(),
                        1,
                        "{what}: {}",
                        String::from_utf8_lossy(&out.stderr)
                    );
                }
            }
            Want::Warning(text) => {
                assert_no_panic(&compute, file);
                let stderr = String::from_utf8_lossy(&compute.stderr);
                assert!(compute.status.success(), "compute {file}: {stderr}");
                let warning = stderr
                    .lines()
                    .find(|l| l.starts_with("ffstream: warning: "))
                    .unwrap_or_else(|| panic!("{file}: no warning: {stderr}"));
                assert!(
                    warning.contains(text) && warning.contains(file),
                    "{warning}"
                );
                // --strict makes the warning an error (exit 1), naming the same.
                let strict = compute_with(&["--strict"]);
                assert_one_error(
                    &strict,
                    &format!("--strict {file}"),
                    &[text, file, "--strict"],
                );
                if file == "duplicate_faces.obj" {
                    // The solve says that light was created (it used to print a
                    // negative escaped power without a word).
                    let all = format!(
                        "{}{}",
                        String::from_utf8_lossy(&run.stdout),
                        String::from_utf8_lossy(&run.stderr)
                    );
                    assert!(all.contains("escaped power is negative"), "{all}");
                }
                if file == "no_emitter.obj" {
                    // The solve must say that nothing emits.
                    assert_one_error(&run, "run no_emitter.obj", &["nothing emits"]);
                } else {
                    assert_no_panic(&run, file);
                    assert!(run.status.success(), "run {file}");
                }
            }
        }
    }
}

#[test]
fn invalid_utf8_and_binary_garbage_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("garbage.obj");
    // A fixed pseudo-random byte string, every byte ≥ 0x80: not valid UTF-8.
    let mut rng = ffstream::formfactor::sampling::SplitMix64::new(1);
    let bytes: Vec<u8> = (0..4096)
        .map(|_| (rng.next_u64() >> 24) as u8 | 0x80)
        .collect();
    std::fs::write(&f, &bytes).unwrap();
    let out = ffstream(&["compute", path_str(&f), "-o", "/dev/null", "--quiet"]);
    assert_one_error(&out, "garbage.obj", &["garbage.obj", "UTF-8"]);
    // A byte that is no Latin-1 text either is refused naming its line (a Latin-1 byte
    // outside a comment is read, with a warning: corpus latin1.obj).
    let out = ffstream(&[
        "compute",
        path_str(&bad("not_text.obj")),
        "-o",
        "/dev/null",
        "-q",
    ]);
    assert_one_error(
        &out,
        "not_text.obj",
        &["not_text.obj", "line 3", "0x9d", "Latin-1"],
    );
    // The same bytes as an .ffz file.
    let out = ffstream(&["solve", path_str(&f), "-o", "/dev/null"]);
    assert_one_error(&out, "solve garbage", &["garbage.obj", "not an .ffz file"]);
}

#[test]
fn impossible_sizes_are_refused_before_allocating() {
    // Too many patches for this scene: known once it is loaded (exit 1, naming it).
    for args in [&["--max-edge", "1e-7"][..], &["--max-edge", "1e-300"]] {
        let mut a = vec!["compute", "builtin:cube", "-o", "/dev/null", "--quiet"];
        a.extend_from_slice(args);
        let out = ffstream(&a);
        let line = assert_one_error(
            &out,
            &format!("{args:?}"),
            &["builtin:cube", "patches", "supported"],
        );
        assert!(line.contains("--max-edge"), "{line}");
    }
}

/// Log output to a file or a pipe (a batch system's capture, not a terminal) has no
/// ANSI colour codes (a worker failure used to print them into the job's log), and a
/// worker failure is said once: the `ffstream: error:` line (it used to come with a
/// coloured `ERROR worker failed` log line saying the same; that is now at debug level).
#[test]
#[cfg_attr(
    not(feature = "test-hooks"),
    ignore = "needs the test-hooks feature (make test)"
)]
fn log_lines_to_a_pipe_carry_no_colour_codes() {
    let dir = tempfile::tempdir().unwrap();
    let run = |verbose: &[&str]| {
        let out = std::process::Command::new(crate::common::exe())
            .args(verbose)
            .args([
                "compute",
                "builtin:cube",
                "--patches",
                "20",
                "-q",
                "--force",
                "-o",
            ])
            .arg(dir.path().join("c.ffz"))
            .env("FFSTREAM_FAIL_ROW", "3")
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{out:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = run(&["-vv"]);
    assert!(
        err.contains("DEBUG") && err.contains("worker failed"),
        "the worker's log line: {err}"
    );
    assert!(!err.contains('\u{1b}'), "no escape codes: {err:?}");
    let err = run(&[]);
    let said: Vec<_> = err.lines().filter(|l| l.contains("row 3")).collect();
    assert_eq!(said.len(), 1, "the failed row is said once: {err}");
    assert!(said[0].starts_with("ffstream: error: "), "{err}");
}

/// Every number an option takes has a range, checked when the command line is read:
/// a value outside it exits 2 at once (the scene, which does not exist here, is never
/// opened), and the message names the option and the range. Before, `--threads 100000`
/// aborted after starting 16k threads, `--samples 4294967295` died allocating 51 GB,
/// and `--patches 0` or `--flush-seconds=-1` were silently accepted.
#[test]
fn option_values_out_of_range_are_refused_at_once_naming_the_range() {
    let compute = ["compute", "no.obj", "-o", "x.ffz"];
    let cases: &[(&[&str], &str, &str)] = &[
        (&compute, "--samples=4294967295", "1..=65536"),
        (&compute, "--samples=0", "1..=65536"),
        (&compute, "--first-batch=0", "1..=65536"),
        (&compute, "--threads=100000", "1..=4096"),
        (&compute, "--threads=0", "1..=4096"),
        (&compute, "--patches=0", "1..=67108864"),
        (&compute, "--patches=4000000000", "1..=67108864"),
        (&compute, "--top-k=0", "1..="),
        (&compute, "--min-ff=0", "(0, 1)"),
        (&compute, "--min-ff=1", "(0, 1)"),
        (
            &compute,
            "--top-k-tail=0",
            "neither `exact` nor a sample count",
        ),
        (
            &compute,
            "--top-k-tail=sometimes",
            "neither `exact` nor a sample count",
        ),
        (&compute, "--top-k-search=greedy", "exhaustive"),
        (&compute, "--chunk-kib=0", "1..=1048576"),
        (&compute, "--zstd-level=30", "1..=22"),
        (&compute, "--flush-seconds=nan", "duration from 0 to 1e9"),
        (&compute, "--flush-seconds=-1", "duration from 0 to 1e9"),
        (&compute, "--max-edge=0", "finite number > 0"),
        (&compute, "--max-edge=inf", "finite number > 0"),
        (&compute, "--max-edge=-inf", "finite number > 0"),
        (&compute, "--max-edge=nan", "finite number > 0"),
        (&compute, "--shadow-tol=1", "(0, 0.1]"),
        (&compute, "--quad-tol=0", "(0, 0.1]"),
        (&["run", "no.obj"], "--samples=0", "1..=65536"),
        (
            &["solve", "no.ffz", "-o", "r.csv"],
            "--tolerance=0",
            "(0, 1)",
        ),
        (
            &["solve", "no.ffz", "-o", "r.csv"],
            "--max-iterations=0",
            "1..",
        ),
        (
            &["solve", "no.ffz", "-o", "r.csv"],
            "--cache-mib=1048577",
            "0..=1048576",
        ),
        (
            &["render", "no.ffz", "-o", "i.png"],
            "--width=0",
            "1..=16384",
        ),
        (
            &["render", "no.ffz", "-o", "i.png"],
            "--spp=8",
            "perfect square from 1 to 256",
        ),
        (
            &["render", "no.ffz", "-o", "i.png"],
            "--exposure=nan",
            "finite number > 0",
        ),
        (
            &["scene", "plates", "-o", "x.obj"],
            "--param=inf",
            "finite number",
        ),
    ];
    for (cmd, arg, range) in cases {
        let mut a = cmd.to_vec();
        a.push(arg);
        let out = ffstream(&a);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{a:?}: {stderr}");
        let option = arg.split('=').next().unwrap();
        assert!(
            stderr.contains(option) && stderr.contains(range),
            "{a:?}: the message should name {option} and {range}: {stderr}"
        );
    }
}

#[test]
fn unreadable_and_unwritable_paths_name_the_path_once() {
    let out = ffstream(&["compute", "/nonexistent/scene.obj", "-o", "/dev/null"]);
    let line = assert_one_error(&out, "missing scene", &["/nonexistent/scene.obj"]);
    // The OS message once, not repeated by the error chain.
    assert_eq!(line.matches("No such file").count(), 1, "{line}");
    let out = ffstream(&[
        "compute",
        "builtin:cube",
        "--patches",
        "20",
        "-o",
        "/nonexistent/dir/x.ffz",
        "--quiet",
    ]);
    let line = assert_one_error(&out, "unwritable output", &["/nonexistent/dir/x.ffz"]);
    assert_eq!(line.matches("No such file").count(), 1, "{line}");
    // A directory where a file is wanted (it used to say "mmap: No such device").
    let dir = tempfile::tempdir().unwrap();
    for cmd in ["info", "verify"] {
        let out = ffstream(&[cmd, path_str(dir.path())]);
        assert_one_error(
            &out,
            cmd,
            &[path_str(dir.path()), "is a directory, not an .ffz file"],
        );
    }
}

/// Every fixed choice of every command: a misspelt value exits 2 at once (before the
/// scene, which does not exist here, is opened) with the list of possible values.
#[test]
fn every_fixed_choice_is_checked_before_any_work_and_lists_its_values() {
    let cases: &[(&[&str], &[&str])] = &[
        (
            &["compute", "no.obj", "-o", "x.ffz", "--method", "bogus"],
            &["point", "mc", "contour"],
        ),
        (
            &["compute", "no.obj", "-o", "x.ffz", "--preset", "bogus"],
            &["fast", "accurate", "reference"],
        ),
        (
            &["compute", "no.obj", "-o", "x.ffz", "--schedule", "bogus"],
            &["dynamic", "folded"],
        ),
        (
            &["compute", "no.obj", "-o", "x.ffz", "--rows", "bogus"],
            &["all", "needed"],
        ),
        (
            &["compute", "no.obj", "-o", "x.ffz", "--symmetric", "bogus"],
            &["auto", "on", "off"],
        ),
        (
            &["compute", "builtin:bogus", "-o", "x.ffz"],
            &["cornell", "cube", "room"],
        ),
        (
            &["compute", "builtin:room:many", "-o", "x.ffz"],
            &["not a number"],
        ),
        (
            &["run", "no.obj", "--method", "bogus"],
            &["point", "mc", "contour"],
        ),
        (
            &["run", "no.obj", "--solver", "bogus"],
            &["gauss-seidel", "jacobi", "shooting"],
        ),
        (
            &["run", "no.obj", "--preset", "bogus"],
            &["fast", "accurate", "reference"],
        ),
        (
            &["solve", "no.ffz", "-o", "r.csv", "--solver", "bogus"],
            &["gauss-seidel", "jacobi", "shooting"],
        ),
        (
            &[
                "render",
                "no.ffz",
                "--radiosity",
                "r.csv",
                "-o",
                "i.png",
                "--camera",
                "1,2",
            ],
            &["expected 10"],
        ),
        (
            &["scene", "bogus", "-o", "x.obj"],
            &[
                "cornell",
                "cube",
                "plates",
                "perpendicular",
                "obstructed",
                "room",
            ],
        ),
    ];
    for (args, values) in cases {
        let out = ffstream(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        for v in *values {
            assert!(stderr.contains(v), "{args:?} should list {v}: {stderr}");
        }
        assert!(
            !stderr.contains("no.obj: ") && !stderr.contains("no.ffz: "),
            "{args:?} opened its input: {stderr}"
        );
    }
}

/// The old spellings of renamed options still work, hidden, for one release:
/// `solve --method`, `export --patches`, `run -o DIR`.
#[test]
fn old_spellings_of_renamed_options_still_work() {
    let dir = tempfile::tempdir().unwrap();
    let ffz = dir.path().join("c.ffz");
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    crate::common::ok(&[
        "compute",
        "builtin:cube",
        "--max-edge",
        "0.5",
        "-q",
        "-o",
        &p("c.ffz"),
    ]);
    crate::common::ok(&[
        "solve",
        path_str(&ffz),
        "-o",
        &p("r.csv"),
        "--method",
        "jacobi",
    ]);
    crate::common::ok(&["export", path_str(&ffz), "--patches", &p("p.csv")]);
    assert!(dir.path().join("p.csv").is_file());
    crate::common::ok(&[
        "run",
        "builtin:cube",
        "--max-edge",
        "0.5",
        "-q",
        "-o",
        &p("run"),
    ]);
    assert!(dir.path().join("run/image.png").is_file());
    let help = ffstream(&["solve", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(
        help.contains("--solver") && !help.contains("--method <"),
        "{help}"
    );
}

/// An explicit `--samples` casts all its rays: with the default preset (whose first
/// batch is 16) `--samples 64` used to keep a first batch of 16, so a pair whose first
/// 16 rays agreed stopped there (issue 23). The early stop only when asked for.
#[test]
fn explicit_samples_never_inherit_an_early_stop() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, want) in [
        (&["--samples", "64"][..], "samples=64 first_batch=64"),
        (
            &["--samples", "64", "--first-batch", "8"][..],
            "samples=64 first_batch=8",
        ),
        (&[][..], "samples=16 first_batch=16"),
    ] {
        let out = dir.path().join("s.ffz");
        let mut args = vec![
            "compute",
            "builtin:cube",
            "--max-edge",
            "0.5",
            "-q",
            "--force",
        ];
        args.extend_from_slice(&["-o", path_str(&out)]);
        args.extend_from_slice(extra);
        crate::common::ok(&args);
        let info = ffstream(&["info", path_str(&out)]);
        let text = String::from_utf8_lossy(&info.stdout);
        assert!(text.contains(want), "{extra:?}: {text}");
    }
}

/// Options that would change nothing are refused, not dropped: a shadow tolerance
/// without exact visibility, a visibility mode for a kernel that casts its own rays,
/// a quadrature tolerance for a kernel without quadrature.
#[test]
fn visibility_options_that_would_do_nothing_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v.ffz");
    for (extra, says) in [
        (
            &["--shadow-tol", "1e-4"][..],
            "--shadow-tol applies to exact visibility",
        ),
        (
            &["--method", "mc", "--visibility", "exact"][..],
            "--visibility applies to --method contour",
        ),
        (
            &["--method", "point", "--quad-tol", "1e-3"][..],
            "--quad-tol applies to --method contour",
        ),
    ] {
        let mut args = vec!["compute", "builtin:obstructed", "-q", "-o", path_str(&out)];
        args.extend_from_slice(extra);
        let o = ffstream(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && stderr.contains(says),
            "{extra:?}: {stderr}"
        );
        assert!(!out.exists(), "{extra:?}: a file was written");
    }
    // With exact visibility (asked for, or the reference preset's) the tolerance is
    // taken, and so is --quad-tol; the header records them (a resume compares them).
    for (extra, want) in [
        (
            &["--visibility", "exact", "--shadow-tol", "1e-4"][..],
            "visibility=exact shadow_tol=1e-4",
        ),
        (
            &["--preset", "reference", "--shadow-tol", "1e-4"][..],
            "visibility=exact shadow_tol=1e-4",
        ),
        (&["--quad-tol", "1e-3"][..], "quad_tol=1e-3"),
    ] {
        let mut args = vec![
            "compute",
            "builtin:obstructed",
            "-q",
            "--force",
            "--max-edge",
            "0.5",
            "-o",
            path_str(&out),
        ];
        args.extend_from_slice(extra);
        crate::common::ok(&args);
        let info = ffstream(&["info", path_str(&out)]);
        let text = String::from_utf8_lossy(&info.stdout);
        assert!(text.contains(want), "{extra:?}: {text}");
    }
}

/// Issue 20 item 5: a mesh far too fine for its file used to be subdivided (seconds,
/// gigabytes) and then started with an ETA of days for a file of terabytes. The plan
/// comes first and a file the disk cannot hold is refused before any subdivision,
/// naming the sizes and the ways on; nothing is created.
#[test]
fn a_file_the_disk_cannot_hold_is_refused_before_subdividing() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("huge.ffz");
    // 6 faces at edge 1e-3: 1.2e7 patches, a dense file of about 5.8e14 bytes.
    let out = ffstream(&[
        "compute",
        "builtin:cube",
        "--max-edge",
        "0.001",
        "-q",
        "-o",
        path_str(&f),
    ]);
    let line = assert_one_error(
        &out,
        "huge dense file",
        &["huge.ffz", "needs up to", "TB", "free", "--no-space-check"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("ffstream: plan: "),
        "the plan is printed: {err}"
    );
    assert!(!err.contains("patches (max edge"), "no subdivision: {err}");
    assert!(!f.exists(), "nothing created: {line}");
}

/// Issue 20 item 5: a scene with more faces than `--patches` gets far more patches than
/// asked for (each face is at least one patch); that used to pass without a word.
#[test]
fn a_patch_count_far_above_the_target_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let args = |target: &'static str| {
        let f = dir.path().join(format!("room{target}.ffz"));
        let out = ffstream(&[
            "compute",
            "builtin:room:0",
            "--patches",
            target,
            "--top-k",
            "4",
            "-q",
            "-o",
            path_str(&f),
        ]);
        assert!(out.status.success(), "{out:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = args("2");
    let warning = err
        .lines()
        .find(|l| l.starts_with("ffstream: warning: ") && l.contains("--patches target 2"))
        .unwrap_or_else(|| panic!("warned: {err}"));
    assert!(warning.contains("faces"), "{warning}");
    let err = args("200");
    assert!(
        !err.contains("--patches target"),
        "no warning near the target: {err}"
    );
}

/// The plan's file size is the most the file can take: files written in both layouts
/// stay under it, and it is not far above their uncompressed size.
#[test]
fn written_files_stay_under_the_planned_size() {
    use ffstream::ffz::size::file_bytes_bound;
    use ffstream::ffz::{FfzReader, Layout};
    let dir = tempfile::tempdir().unwrap();
    for (extra, layout) in [
        (&[][..], Layout::Dense),
        (&["--top-k", "8"][..], Layout::TopK { k: 8 }),
    ] {
        let f = dir.path().join(format!("c{}.ffz", extra.len()));
        let mut a = vec!["compute", "builtin:cornell", "--patches", "400", "-q"];
        a.extend_from_slice(&["--chunk-kib", "16", "-o", path_str(&f)]);
        a.extend_from_slice(extra);
        let out = ffstream(&a);
        assert!(out.status.success(), "{out:?}");
        let n = FfzReader::open(&f).unwrap().n() as u64;
        let len = std::fs::metadata(&f).unwrap().len();
        let bound = file_bytes_bound(n, layout, 16 * 1024);
        assert!(len <= bound, "{layout:?}: {len} > {bound}");
        let values = match layout {
            Layout::Dense => 4 * n * n,
            Layout::TopK { k } => 8 * u64::from(k) * n,
        };
        // Header slack (1 MiB) plus 3 % of the values and the patch table.
        let not_far = values + values * 3 / 100 + 168 * n + (1 << 20) + 64 * n;
        assert!(
            bound <= not_far,
            "{layout:?}: bound {bound} far above {values}"
        );
    }
}

/// Issue 19 item 4: `--min-ff EPS` writes threshold rows (every entry ≥ EPS, at most n a
/// row, the rest dropped mass) that verify accepts; the choices that cannot go with it
/// are refused with the reason before any work.
#[test]
fn threshold_rows_hold_the_entries_at_or_above_the_threshold() {
    use ffstream::ffz::{FfzReader, Layout};
    use ffstream::rows::RowValues;
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("t.ffz");
    let base = [
        "compute",
        "builtin:cornell",
        "--patches",
        "300",
        "-q",
        "-o",
        path_str(&f),
    ];
    let run = |extra: &[&str]| {
        let mut a = base.to_vec();
        a.extend_from_slice(extra);
        a.push("--force");
        ffstream(&a)
    };
    let out = run(&["--min-ff", "1e-3"]);
    assert!(out.status.success(), "{out:?}");
    let r = FfzReader::open(&f).unwrap();
    let n = r.n() as usize;
    assert_eq!(r.layout(), Layout::TopK { k: n as u32 });
    assert!(
        r.meta().params.contains("min_ff=1e-3"),
        "{}",
        r.meta().params
    );
    let (mut kept, mut rows_with_dropped) = (0usize, 0usize);
    r.scan(|row| {
        let RowValues::Sparse { vals, .. } = &row.values else {
            panic!("sparse rows")
        };
        assert!(vals.iter().all(|&v| v >= 1e-3), "row {}", row.index);
        kept += vals.len();
        rows_with_dropped += usize::from(row.dropped > 0.0);
    })
    .unwrap();
    assert!(
        kept > 10 * n && kept < n * n / 2,
        "{kept} entries of {n} rows"
    );
    assert!(rows_with_dropped > n / 2, "{rows_with_dropped}");
    let out = ffstream(&["verify", path_str(&f)]);
    assert!(out.status.success(), "{out:?}");
    for (extra, says) in [
        (
            &["--min-ff", "1e-3", "--symmetric", "on"][..],
            "--symmetric on cannot",
        ),
        (&["--min-ff", "1e-3", "--gather"][..], "--gather"),
        (&["--top-k-search", "tree"][..], "apply to sparse rows"),
        (
            &["--top-k", "8", "--top-k-tail", "exact"][..],
            "--top-k-search exhaustive",
        ),
    ] {
        let out = run(extra);
        assert_eq!(out.status.code(), Some(1), "{extra:?}: {out:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{extra:?}: {err}");
    }
    let out = run(&[
        "--top-k",
        "8",
        "--top-k-tail",
        "exact",
        "--top-k-search",
        "exhaustive",
    ]);
    assert!(out.status.success(), "{out:?}");
}
