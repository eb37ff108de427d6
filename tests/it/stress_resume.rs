//! Stress, a file rewritten while it is read, and what a resume keeps (issue 20):
//! readers in a loop beside `compute --force` and `--resume` on the same file never die
//! of a signal (the writer never cuts a file in place: it writes a new one and renames
//! it over the old one); a resume after one damaged chunk in the middle recomputes
//! that chunk's rows only; a resume compares what determines the rows, not how the
//! scene's path was typed.

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::common::{exe, ffstream, need_tool, ok, path_str, resumed_counts};

const SCENE: &[&str] = &[
    "--patches",
    "300",
    "--quiet",
    "--threads",
    "1",
    "--samples",
    "4",
    "--chunk-kib",
    "16",
];

fn compute(scene: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut a = vec!["compute", scene];
    a.extend_from_slice(SCENE);
    a.extend_from_slice(&["-o", path_str(out)]);
    a.extend_from_slice(extra);
    ffstream(&a)
}

fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// One reader command, run again and again until `stop`: each run must end with an
/// exit code (0; 1, an error it printed; 3, `verify` found problems and listed them),
/// never by a signal. Returns the runs made.
fn read_in_a_loop(cmd: Vec<String>, stop: Arc<AtomicBool>) -> u32 {
    let mut runs = 0;
    while !stop.load(Ordering::Relaxed) {
        let out = Command::new(&cmd[0])
            .args(&cmd[1..])
            .stdin(Stdio::null())
            .output()
            .expect("reader starts");
        runs += 1;
        assert!(
            out.status.signal().is_none() && matches!(out.status.code(), Some(0 | 1 | 3)),
            "`{}` ended with {:?} beside a writer: {}",
            cmd.join(" "),
            out.status,
            text(&out)
        );
        if out.status.code() != Some(0) {
            // Not a crash: it must have said why, naming the file.
            let said = text(&out);
            assert!(
                said.contains("f.ffz"),
                "`{}` failed silently: {said}",
                cmd.join(" ")
            );
        }
    }
    runs
}

#[test]
fn readers_never_die_of_a_signal_beside_force_and_resume() {
    let python = need_tool(
        "python3 with numpy, scipy and zstandard",
        Command::new("python3")
            .args(["-c", "import numpy, scipy.sparse, zstandard"])
            .status()
            .is_ok_and(|s| s.success()),
        "FFSTREAM_SKIP_PYTHON",
    );
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("f.ffz");
    let out = compute("builtin:cornell", &f, &[]);
    assert!(out.status.success(), "{}", text(&out));
    let file = path_str(&f).to_string();
    let exe = exe().to_string_lossy().into_owned();
    let mut readers = vec![
        vec![exe.clone(), "verify".into(), file.clone()],
        vec![
            exe.clone(),
            "solve".into(),
            file.clone(),
            "-q".into(),
            "-o".into(),
            path_str(&dir.path().join("b.csv")).into(),
        ],
        vec![
            exe.clone(),
            "export".into(),
            file.clone(),
            "--matrix".into(),
            path_str(&dir.path().join("f.mtx")).into(),
        ],
    ];
    if python {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("formats/ffz.py");
        readers.push(vec![
            "python3".into(),
            script.to_string_lossy().into(),
            file.clone(),
        ]);
    }
    let stop = Arc::new(AtomicBool::new(false));
    let threads: Vec<_> = readers
        .into_iter()
        .map(|cmd| {
            let stop = stop.clone();
            std::thread::spawn(move || read_in_a_loop(cmd, stop))
        })
        .collect();
    // 20 of each: --force replaces the file, --resume of a finished file drops its
    // index and footer (both cut the file in place before).
    for round in 0..20 {
        for extra in [&["--force"][..], &["--resume"][..]] {
            let out = compute("builtin:cornell", &f, extra);
            assert!(
                out.status.success(),
                "round {round} {extra:?}: {}",
                text(&out)
            );
        }
    }
    stop.store(true, Ordering::Relaxed);
    let runs: Vec<u32> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    assert!(
        runs.iter().all(|&r| r >= 2),
        "every reader ran beside the writers: {runs:?}"
    );
    assert!(
        !dir.path().join("f.ffz.new").exists(),
        "no staging file left behind"
    );
}

/// (offset, row_count) of every chunk of a finished file, from its index (spec §6, §7).
fn chunks_of(bytes: &[u8]) -> Vec<(usize, u32)> {
    let footer = &bytes[bytes.len() - 32..];
    let ix = u64::from_le_bytes(footer[0..8].try_into().unwrap()) as usize;
    let count = u64::from_le_bytes(bytes[ix + 8..ix + 16].try_into().unwrap()) as usize;
    (0..count)
        .map(|c| {
            let at = ix + 24 + 8 * c;
            let o = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
            (
                o,
                u32::from_le_bytes(bytes[o + 24..o + 28].try_into().unwrap()),
            )
        })
        .collect()
}

/// A finished file of the test scene, damaged by `damage` (given its bytes and its
/// chunks; it returns the rows it destroyed), then resumed: the resume must compute
/// exactly those rows and give the rows of the undamaged file. Returns what it printed.
fn damage_and_resume(damage: impl FnOnce(&mut Vec<u8>, &[(usize, u32)]) -> u64) -> String {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    let f = dir.path().join("f.ffz");
    assert!(compute("builtin:cornell", &full, &[]).status.success());
    let mut bytes = std::fs::read(&full).unwrap();
    let chunks = chunks_of(&bytes);
    assert!(chunks.len() >= 5, "several chunks: {}", chunks.len());
    let lost = damage(&mut bytes, &chunks);
    std::fs::write(&f, &bytes).unwrap();
    let out = compute("builtin:cornell", &f, &["--resume"]);
    let err = text(&out);
    assert!(out.status.success(), "{err}");
    let n = chunks.iter().map(|c| u64::from(c.1)).sum::<u64>();
    assert_eq!(
        resumed_counts(&err),
        (lost, n - lost),
        "only the {lost} rows of the damaged chunks are computed again: {err}"
    );
    let v = ffstream(&["verify", path_str(&f), "--against", path_str(&full)]);
    assert_eq!(
        v.status.code(),
        Some(0),
        "rows equal an uninterrupted run: {}",
        text(&v)
    );
    err
}

#[test]
fn resume_after_a_flipped_byte_in_a_middle_chunk_recomputes_only_its_rows() {
    let mut at = 0;
    let err = damage_and_resume(|bytes, chunks| {
        let rows;
        (at, rows) = chunks[chunks.len() / 2];
        // A byte of the compressed payload (after the 40-byte chunk header).
        bytes[at + 40 + 7] ^= 0x20;
        u64::from(rows)
    });
    assert!(
        err.contains(&format!("bytes {at}..")),
        "the dropped region is named: {err}"
    );
}

#[test]
fn resume_of_a_killed_run_keeps_the_chunks_after_a_damaged_one() {
    // No index (a killed run): the scan finds the chunks on both sides of the damage.
    damage_and_resume(|bytes, chunks| {
        let (at, rows) = chunks[1];
        let (last, last_rows) = *chunks.last().unwrap();
        bytes[at + 3] ^= 0xff; // the chunk's magic
                               // Cut inside the last chunk: a torn write, and no index or footer.
        bytes.truncate(last + 50);
        u64::from(rows) + u64::from(last_rows)
    });
}

#[test]
fn resume_accepts_the_scene_under_another_path_and_names_a_differing_key() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("box.obj");
    ok(&["scene", "cornell", "-o", path_str(&obj)]);
    let full = dir.path().join("full.ffz");
    let f = dir.path().join("f.ffz");
    assert!(compute(path_str(&obj), &full, &[]).status.success());
    let bytes = std::fs::read(&full).unwrap();
    // A killed run: the file up to the middle of its chunks.
    let chunks = chunks_of(&bytes);
    std::fs::write(&f, &bytes[..chunks[chunks.len() / 2].0 + 10]).unwrap();
    // The same scene, typed relative to another directory.
    let out = Command::new(exe())
        .current_dir(dir.path())
        .args(["compute", "./box.obj"])
        .args(SCENE)
        .args(["-o", "f.ffz", "--resume", "--seed", "1"])
        .output()
        .unwrap();
    let err = text(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("seed differs: the file was computed with seed=0, this run has seed=1")
            && !err.contains("scene_path"),
        "names the one setting that differs: {err}"
    );
    let out = Command::new(exe())
        .current_dir(dir.path())
        .args(["compute", "./box.obj"])
        .args(SCENE)
        .args(["-o", "f.ffz", "--resume"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "same scene, other path: {}",
        text(&out)
    );
    let v = ffstream(&["verify", path_str(&f), "--against", path_str(&full)]);
    assert_eq!(v.status.code(), Some(0), "{}", text(&v));
}
