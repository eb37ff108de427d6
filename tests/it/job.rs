//! The job layer through the library alone (`ffstream::job`, no binary): a dense job,
//! the resume of a partial file and a top-k job, each built with [`build_job`] and run
//! by the embedded service, give the file `ffstream compute` gives with the same
//! options: the same rows, bitwise, and the same run parameters in the header (the
//! creation time and host may differ).

use std::path::Path;

use ffstream::ffz::{FfzReader, FfzWriter};
use ffstream::formfactor::Scratch;
use ffstream::job::{build_job, HalfRows, JobSettings, PatchBudget, RowMode, RunParams};
use ffstream::scene::SceneSpec;
use ffstream::service::embedded::run_embedded;
use ffstream::service::{ComputeJob, Role};

use crate::common::{ok, path_str};
use crate::service::assert_same_rows;

/// The settings of `ffstream compute SCENE --patches N --threads 2 -q -o OUT`.
fn settings(scene: &str, patches: usize, out: &Path) -> JobSettings {
    let mut s = JobSettings::new(SceneSpec::parse(scene).expect("a scene name"), out);
    s.budget = PatchBudget::Target(patches);
    s.threads = Some(2);
    s.progress = false;
    s
}

/// The job of `s`, built as the process that runs alone builds it, saying nothing.
fn job(s: &JobSettings) -> ComputeJob {
    build_job(s, Role::Alone, &|_| {}).expect("the job builds")
}

/// `ffstream compute` with `args` into `out`; then the library's file `lib` must hold
/// the same rows and the same run parameters.
fn same_as_the_command_line(lib: &Path, out: &Path, args: &[&str]) {
    let mut all = vec!["compute", "-q", "--threads", "2", "-o", path_str(out)];
    all.extend_from_slice(args);
    ok(&all);
    assert_same_rows(lib, out);
    let (a, b) = (FfzReader::open(lib).unwrap(), FfzReader::open(out).unwrap());
    assert_eq!(a.meta().params, b.meta().params);
    // The header's params read back into the typed structure and write the same string.
    let params = RunParams::parse(&a.meta().params).unwrap();
    assert_eq!(params.to_string(), a.meta().params);
    assert_eq!(params.difference_from_file(&b.meta().params), None);
}

/// Dense rows of the Cornell box (half rows, the default for them): 300 patches.
#[test]
fn a_dense_job_built_by_the_library_writes_the_file_the_command_line_writes() {
    let dir = tempfile::tempdir().unwrap();
    let (lib, cli) = (dir.path().join("lib.ffz"), dir.path().join("cli.ffz"));
    let s = settings("builtin:cornell", 300, &lib);
    let report = run_embedded(&job(&s)).expect("the job runs");
    assert!(report.summary().contains("rows:"), "{}", report.summary());
    same_as_the_command_line(&lib, &cli, &["builtin:cornell", "--patches", "300"]);
}

/// A partial file (the first half of the rows, written by the job's own engine and
/// header, then finished with the rest missing, spec §9.1) is completed by the
/// library's resume into the command line's file.
#[test]
fn a_partial_file_resumed_by_the_library_is_the_command_lines_file() {
    let dir = tempfile::tempdir().unwrap();
    let (lib, cli) = (dir.path().join("lib.ffz"), dir.path().join("cli.ffz"));
    let mut s = settings("builtin:cornell", 300, &lib);
    s.half_rows = HalfRows::Off;
    let first = job(&s);
    let engine = first.engine.as_ref().expect("an engine");
    let n = first.patches.len() as u32;
    let mut w = FfzWriter::create(&lib, &first.meta, first.writer).unwrap();
    let mut scratch = Scratch::new();
    for i in 0..n / 2 {
        w.push_row(engine.compute_row(i, &mut scratch)).unwrap();
    }
    w.finish().unwrap();
    assert_eq!(
        FfzReader::open(&lib).unwrap().presence().missing().len(),
        (n - n / 2) as usize
    );
    s.resume = true;
    let report = run_embedded(&job(&s)).expect("the resume runs");
    let summary = report.summary();
    assert!(
        summary.contains(&format!("{} already present", n / 2)),
        "{summary}"
    );
    same_as_the_command_line(
        &lib,
        &cli,
        &["builtin:cornell", "--patches", "300", "--symmetric", "off"],
    );
}

/// Top-k rows with the tree search and links (the accurate preset's) in the room.
#[test]
fn a_top_k_job_built_by_the_library_writes_the_file_the_command_line_writes() {
    let dir = tempfile::tempdir().unwrap();
    let (lib, cli) = (dir.path().join("lib.ffz"), dir.path().join("cli.ffz"));
    let mut s = settings("builtin:room", 400, &lib);
    s.form.rows = RowMode::TopK(32);
    run_embedded(&job(&s)).expect("the job runs");
    same_as_the_command_line(
        &lib,
        &cli,
        &["builtin:room", "--patches", "400", "--top-k", "32"],
    );
}

/// The library refuses what the command line refuses, with the same words, before
/// reading the scene.
#[test]
fn the_library_refuses_settings_that_do_not_go_together() {
    let mut s = settings("builtin:no-such-scene", 100, Path::new("/dev/null"));
    s.gather = true;
    s.resume = true;
    let e = build_job(&s, Role::Alone, &|_| {}).err().unwrap();
    assert_eq!(
        e.to_string(),
        "--gather writes the file at the end only: it cannot resume"
    );
    let mut s = settings("builtin:cornell", 100, Path::new("/dev/null"));
    s.form.shadow_tol = Some(1e-4);
    let e = build_job(&s, Role::Alone, &|_| {}).err().unwrap();
    assert!(
        e.to_string()
            .starts_with("--shadow-tol applies to exact visibility"),
        "{e}"
    );
}
