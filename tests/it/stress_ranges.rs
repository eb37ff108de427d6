//! Stress, the ends of every documented range (issue 48, acceptance): each numeric
//! option of `compute`, `run`, `solve`, `render`, `export`, `verify` and `annual` at
//! the least and the greatest value its help text allows, and just inside where the
//! range is open, each run under a time limit; `compute` also under `mpirun -n 3` for
//! the options the service uses (threads, flush, stall, chunk size, zstd level).
//!
//! The property: no panic, abort or hang for a value the help text documents. A run
//! may finish (exit 0) or refuse the value for what it would cost (exit 1, a message
//! saying why: too many patches for memory, a grid with too many points), never exit
//! 2 (the value is inside the range, so no usage error), 101 (a panic) or end by a
//! signal (an abort), never print a panic, and never run past its time limit.
//! Found by it: see `docs/faults-round3.md`, "The acceptance property test".

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{exe, mpirun, need_mpi, ok, output_before, path_str};

/// Smallest positive f64 (a subnormal): the least value of every range open at 0.
const TINY: &str = "5e-324";
/// Greatest f64 below 1: the greatest value of every range open at 1.
const BELOW_ONE: &str = "0.9999999999999999";
/// Greatest finite f64.
const HUGE: &str = "1.7976931348623157e308";

/// A limit for one run: generous, since a hang is what it catches (each case takes
/// well under a second but `annual`, about 4 s).
const LIMIT: Duration = Duration::from_secs(40);

/// Runs `cmd` (stdout and stderr piped) under [`LIMIT`] and says what went wrong:
/// None when it ended with 0 or 1 and printed no panic.
fn fault_of(mut cmd: Command, what: &str) -> Option<String> {
    let child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot start ffstream");
    let t0 = Instant::now();
    let Some(out) = output_before(child, LIMIT) else {
        return Some(format!("{what}: still running after {LIMIT:?} (killed)"));
    };
    let err = String::from_utf8_lossy(&out.stderr);
    let tail: String = {
        let lines: Vec<&str> = err.lines().collect();
        lines[lines.len().saturating_sub(4)..].join(" | ")
    };
    let digits = err
        .split(|c: char| !c.is_ascii_digit())
        .map(str::len)
        .max()
        .unwrap_or(0);
    let verdict = match (out.status.code(), out.status.signal()) {
        // A message must stay readable: a value printed in full (1e300 is 301
        // digits) is not.
        _ if digits > 40 => Some(format!("a number of {digits} digits in its message")),
        (_, Some(sig)) => Some(format!("ended by signal {sig}")),
        (Some(0 | 1), _) if !err.contains("panicked") => None,
        // `verify`'s verdict that the file fails the check asked for (a row sum above
        // 1 + 0 by rounding): an answer, not a fault.
        (Some(3), _) if what.starts_with("verify") && !err.contains("panicked") => None,
        (Some(code), _) => Some(format!("exit {code}")),
        (None, None) => Some("no exit status".into()),
    };
    let secs = t0.elapsed().as_secs_f64();
    if std::env::var_os("FFSTREAM_RANGES_TIMES").is_some() {
        eprintln!("{secs:6.2} s  {what}");
    }
    verdict.map(|v| format!("{what}: {v} after {secs:.1} s: {tail}"))
}

fn ffstream_cmd(args: &[String]) -> Command {
    let mut c = Command::new(exe());
    c.args(args).env_remove("FFSTREAM_FAIL_ROW");
    c
}

fn strings(a: &[&str]) -> Vec<String> {
    a.iter().map(|s| (*s).to_string()).collect()
}

/// (option, values) pairs of `compute` (and `run`): the ends of each range, with the
/// options a value needs to matter (`--top-k` for the tail, exact visibility for its
/// tolerance).
fn compute_cases() -> Vec<(Vec<&'static str>, Vec<&'static str>)> {
    let u32_max = "4294967295";
    vec![
        (vec!["--patches"], vec!["1", "67108864"]),
        (vec!["--max-edge"], vec![TINY, "1e-300", HUGE]),
        (
            vec!["--shadow-tol"],
            vec![TINY, "0.1"], // with --visibility exact below
        ),
        (vec!["--quad-tol"], vec![TINY, "0.1"]),
        (vec!["--samples"], vec!["1", "65536"]),
        (vec!["--first-batch"], vec!["1", "65536"]),
        (vec!["--top-k"], vec!["1", u32_max]),
        (vec!["--min-ff"], vec![TINY, BELOW_ONE]),
        (vec!["--top-k", "5", "--top-k-tail"], vec!["1", "65536"]),
        (
            vec!["--top-k", "5", "--symmetric", "off", "--links"],
            vec!["1", u32_max],
        ),
        (
            vec![
                "--top-k",
                "5",
                "--symmetric",
                "off",
                "--links",
                "64",
                "--link-tol",
            ],
            vec![TINY, BELOW_ONE],
        ),
        (vec!["--threads"], vec!["1", "4096"]),
        (vec!["--seed"], vec!["0", "18446744073709551615"]),
        (vec!["--zstd-level"], vec!["1", "22"]),
        (vec!["--chunk-kib"], vec!["1", "1048576"]),
        (vec!["--flush-seconds"], vec!["0", "1e9"]),
        (vec!["--stall-seconds"], vec![TINY, "1e9"]),
    ]
}

/// The scene every `compute` case cuts: the Cornell box (occluded pairs) in about 40
/// patches.
const SCENE: &[&str] = &["builtin:cornell", "--patches", "40", "--quiet"];

/// For `--shadow-tol`: two plates and a blocker, one partly shadowed pair. The outer
/// rule's work on a pair is capped (`MAX_POINTS` in `src/formfactor/shadow/integral.rs`), about
/// 0.5 s a pair at the smallest tolerance: bounded, but 25 s for the 68 exact pairs of
/// the Cornell box in 12 patches.
const SHADOWED: &[&str] = &["builtin:obstructed", "--patches", "4", "--quiet"];

fn compute_args(out: &Path, opt: &[&str], value: &str) -> Vec<String> {
    let mut a = strings(&["compute"]);
    match opt {
        ["--patches"] => a.extend(strings(&["builtin:cornell", "--quiet"])),
        ["--shadow-tol"] => a.extend(strings(SHADOWED)),
        _ => a.extend(strings(SCENE)),
    }
    a.extend(strings(&["--force", "-o", path_str(out)]));
    if opt == ["--shadow-tol"] {
        a.extend(strings(&["--visibility", "exact"]));
    }
    if !opt.contains(&"--threads") {
        a.extend(strings(&["--threads", "2"]));
    }
    a.extend(strings(opt));
    a.push(value.to_string());
    a
}

#[test]
fn every_numeric_option_at_the_ends_of_its_range_neither_panics_nor_hangs() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Instant::now();
    let mut faults = Vec::new();
    let mut note = |f: Option<String>| faults.extend(f);

    // compute, embedded.
    let out = dir.path().join("c.ffz");
    for (opt, values) in compute_cases() {
        for v in values {
            let a = compute_args(&out, &opt, v);
            note(fault_of(ffstream_cmd(&a), &a[1..].join(" ")));
        }
    }

    // run: the compute options are those above (one code path); its own are the
    // solver's and the picture's, at both ends together.
    let run_dir = dir.path().join("run");
    for extra in [
        &["--tolerance", TINY, "--max-iterations", "1"][..],
        &[
            "--tolerance",
            BELOW_ONE,
            "--max-iterations",
            "18446744073709551615",
        ][..],
        &[
            "--width",
            "1",
            "--height",
            "1",
            "--spp",
            "1",
            "--exposure",
            "1e-45",
        ][..],
        &[
            "--width",
            "16384",
            "--height",
            "1",
            "--spp",
            "256",
            "--exposure",
            "3.4028235e38",
        ][..],
    ] {
        let mut a = strings(&["run"]);
        a.extend(strings(SCENE));
        a.extend(strings(&[
            "--threads",
            "2",
            "--out-dir",
            path_str(&run_dir),
        ]));
        a.extend(strings(extra));
        note(fault_of(ffstream_cmd(&a), &a.join(" ")));
    }

    // solve, render, export, verify on one file and its radiosity.
    let ffz = dir.path().join("base.ffz");
    let csv = dir.path().join("b.csv");
    let mut base = strings(&["compute"]);
    base.extend(strings(SCENE));
    base.extend(strings(&["--threads", "2", "-o", path_str(&ffz)]));
    ok(&base.iter().map(String::as_str).collect::<Vec<_>>());
    ok(&["solve", path_str(&ffz), "-o", path_str(&csv), "--quiet"]);
    let solved = dir.path().join("s.csv");
    for solver in ["jacobi", "gauss-seidel", "shooting"] {
        for (opt, v) in [
            ("--tolerance", TINY),
            ("--tolerance", BELOW_ONE),
            ("--max-iterations", "1"),
            ("--max-iterations", "18446744073709551615"),
            ("--cache-mib", "0"),
            ("--cache-mib", "1048576"),
        ] {
            let a = strings(&[
                "solve",
                path_str(&ffz),
                "-o",
                path_str(&solved),
                "--solver",
                solver,
                opt,
                v,
            ]);
            note(fault_of(ffstream_cmd(&a), &a.join(" ")));
        }
    }
    let png = dir.path().join("r.png");
    let camera_far = format!("{HUGE},0,0,0,0,0,0,0,1,90");
    for extra in [
        vec!["--width", "1", "--height", "1", "--spp", "1"],
        vec!["--width", "16384", "--height", "1", "--spp", "256"],
        vec!["--width", "1", "--height", "16384"],
        vec!["--exposure", "1e-45"],
        vec!["--exposure", "1.1754944e-38"],
        vec!["--exposure", "3.4028235e38"],
        vec!["--camera", "278,273,-800,278,273,0,0,1,0,1e-300"],
        vec!["--camera", "278,273,-800,278,273,0,0,1,0,179.99999999"],
        vec!["--camera", camera_far.as_str()],
    ] {
        let mut a = strings(&[
            "render",
            path_str(&ffz),
            "--radiosity",
            path_str(&csv),
            "-o",
            path_str(&png),
        ]);
        a.extend(strings(&extra));
        note(fault_of(ffstream_cmd(&a), &a.join(" ")));
    }
    let mtx = dir.path().join("m.mtx");
    for v in ["0", TINY, HUGE] {
        let a = strings(&[
            "export",
            path_str(&ffz),
            "--matrix",
            path_str(&mtx),
            "--min-ff",
            v,
        ]);
        note(fault_of(ffstream_cmd(&a), &a.join(" ")));
    }
    for (opt, v) in [
        ("--row-sum-tol", "0"),
        ("--row-sum-tol", HUGE),
        ("--unoccluded", "0"),
        ("--unoccluded", HUGE),
    ] {
        let a = strings(&["verify", path_str(&ffz), opt, v]);
        note(fault_of(ffstream_cmd(&a), &a.join(" ")));
    }

    // annual: about 4 s a run (a year of skies), so every option at its least value in
    // one run and at its greatest in another, on form factors computed once.
    let office = dir.path().join("office.ffz");
    ok(&[
        "compute",
        "builtin:office",
        "--patches",
        "10",
        "--quiet",
        "--threads",
        "2",
        "-o",
        path_str(&office),
    ]);
    let ann = dir.path().join("annual");
    let neg_huge = format!("-{HUGE}");
    for (location, ends) in [
        (
            format!("-90,-180,-14,{neg_huge}"),
            vec![
                "--year",
                "-2000",
                "--linke-turbidity",
                "1",
                "--ground-reflectance",
                TINY,
                "--occupied",
                "0-1",
                "--da-threshold",
                TINY,
                "--rotate",
                neg_huge.as_str(),
                "--glazing",
                "wall_south:5e-324",
                "--grid",
                "floor:5:-1e300",
            ],
        ),
        (
            format!("90,180,14,{HUGE}"),
            vec![
                "--year",
                "6000",
                "--linke-turbidity",
                HUGE,
                "--ground-reflectance",
                BELOW_ONE,
                "--occupied",
                "23-24",
                "--da-threshold",
                HUGE,
                "--rotate",
                HUGE,
                "--glazing",
                "wall_south:1",
                "--grid",
                "floor:5:1e300",
            ],
        ),
        // The greatest spacing: no grid point on the floor, refused (exit 1) naming
        // the spacing briefly (it was printed as 301 digits).
        (
            "36,-80,-5".to_string(),
            vec!["--grid", "floor:1.7976931348623157e308"],
        ),
    ] {
        let mut a = strings(&["annual", "builtin:office", "--patches", "10", "--quiet"]);
        a.extend(strings(&["--threads", "2", "--ffz", path_str(&office)]));
        a.extend(strings(&["-o", path_str(&ann), "--location", &location]));
        a.extend(strings(&ends));
        note(fault_of(ffstream_cmd(&a), &a.join(" ")));
    }

    // compute under mpirun -n 3: the options the transport and the I/O master use.
    if need_mpi() {
        let out = dir.path().join("mpi.ffz");
        for (opt, v) in [
            ("--threads", "1"),
            ("--threads", "4096"),
            ("--flush-seconds", "0"),
            ("--flush-seconds", "1e9"),
            ("--stall-seconds", TINY),
            ("--stall-seconds", "1e9"),
            ("--chunk-kib", "1"),
            ("--chunk-kib", "1048576"),
        ] {
            let a = compute_args(&out, &[opt], v);
            let refs: Vec<&str> = a.iter().map(String::as_str).collect();
            note(fault_of(
                mpirun(3, &refs),
                &format!("mpirun -n 3 {}", a[1..].join(" ")),
            ));
        }
    }
    eprintln!(
        "stress_ranges: every case ran in {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    assert!(
        faults.is_empty(),
        "{} run(s) at the ends of documented ranges failed:\n{}",
        faults.len(),
        faults.join("\n")
    );
}
