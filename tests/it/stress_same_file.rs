//! Stress, outputs that are inputs or each other (issue 48): `export F.ffz --matrix
//! F.ffz` died with a bus error and left F.ffz at 0 bytes, `solve F.ffz -o F.ffz`,
//! `render -o`, `--ply`, `--npz` and `--patches-csv` onto the input replaced the
//! matrix and exited 0, `--matrix X --sparse X` wrote one broken file and exited 0.
//! Each such command line must be a usage error (exit 2) naming the option, whatever
//! the spelling of the path (`./F`, `dir/../F`, a hard link, a symbolic link), and
//! leave every file as it was.

use std::path::Path;

use crate::common::{ffstream, ok, path_str};
use crate::stress_cli::assert_no_panic;

/// Exit 2, one error line naming `option`.
fn refused(args: &[&str], option: &str) {
    let out = ffstream(args);
    assert_no_panic(&out, &format!("{args:?}"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("ffstream: error: "))
        .collect();
    assert_eq!(errors.len(), 1, "{args:?}: {stderr}");
    assert!(errors[0].contains(option), "{args:?}: {}", errors[0]);
}

fn small_file(dir: &Path) -> (String, Vec<u8>) {
    let f = dir.join("F.ffz");
    ok(&[
        "compute",
        "builtin:cube",
        "--max-edge",
        "0.5",
        "--threads",
        "1",
        "--quiet",
        "-o",
        path_str(&f),
    ]);
    let bytes = std::fs::read(&f).unwrap();
    (path_str(&f).to_string(), bytes)
}

#[test]
fn an_output_onto_an_input_or_another_output_is_refused_by_identity() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (f, bytes) = small_file(d);
    std::fs::create_dir(d.join("sub")).unwrap();
    std::fs::hard_link(&f, d.join("hard.ffz")).unwrap();
    std::os::unix::fs::symlink(&f, d.join("soft.ffz")).unwrap();
    let p = |name: &str| path_str(&d.join(name)).to_string();
    let (dotted, hard, soft) = (p("sub/../F.ffz"), p("hard.ffz"), p("soft.ffz"));
    let (x, x2, csv) = (p("X.txt"), p("sub/../X.txt"), p("r.csv"));
    ok(&["solve", &f, "-o", &csv]);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["export", &f, "--matrix", &f], "--matrix"),
        (vec!["export", &f, "--matrix", &dotted], "--matrix"),
        (vec!["export", &f, "--sparse", &hard], "--sparse"),
        (vec!["export", &f, "--npz", &soft], "--npz"),
        (vec!["export", &f, "--patches-csv", &f], "--patches-csv"),
        (
            vec!["export", &f, "--matrix", &x, "--sparse", &x2],
            "--sparse",
        ),
        (vec!["solve", &f, "-o", &f], "-o"),
        (vec!["solve", &f, "-o", &csv, "--ply", &dotted], "--ply"),
        (vec!["solve", &f, "-o", &x, "--ply", &x2], "--ply"),
        (vec!["render", &f, "--radiosity", &csv, "-o", &f], "-o"),
        (vec!["render", &f, "--radiosity", &csv, "-o", &csv], "-o"),
    ];
    let csv_bytes = std::fs::read(&csv).unwrap();
    for (args, option) in &cases {
        refused(args, option);
        assert_eq!(std::fs::read(&f).unwrap(), bytes, "{args:?} changed F.ffz");
        assert_eq!(
            std::fs::read(&csv).unwrap(),
            csv_bytes,
            "{args:?} changed r.csv"
        );
        assert!(!Path::new(&x).exists(), "{args:?} wrote X.txt");
    }
    // Devices are no files an output could destroy: both outputs to /dev/null work.
    ok(&[
        "export",
        &f,
        "--matrix",
        "/dev/null",
        "--sparse",
        "/dev/null",
    ]);
}

#[test]
fn compute_and_run_refuse_to_write_over_their_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = d.join("s.obj");
    ok(&["scene", "cube", "-o", path_str(&obj)]);
    let bytes = std::fs::read(&obj).unwrap();
    refused(
        &["compute", path_str(&obj), "-o", path_str(&obj), "--force"],
        "-o",
    );
    assert_eq!(std::fs::read(&obj).unwrap(), bytes);
    // `run` writes image.png into its directory: --ply onto it is two outputs in one.
    let out = d.join("out");
    let ply = out.join("image.png");
    refused(
        &[
            "run",
            "builtin:cube",
            "--out-dir",
            path_str(&out),
            "--ply",
            path_str(&ply),
        ],
        "--ply",
    );
}
