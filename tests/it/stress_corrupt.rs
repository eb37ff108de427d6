//! Stress, corrupt `.ffz` files through the command line: truncated, bit-flipped in
//! several chunks, wrong version, wrong n, an index pointing past the end of the file,
//! and a file given to `solve --scene` with another scene. Each is detected with one
//! clear error line (exit 1), or by `ffstream verify` listing every bad chunk (exit 3);
//! a truncated file is completed by `compute --resume` to the same rows as an intact
//! run (`verify --against`, exit 0). Byte offsets from formats/ffz-v1.md §3, §6, §7.
//! (Library-level byte sweeps are in `ffz_corrupt.rs`.)

use std::path::{Path, PathBuf};

use ffstream::ffz::FfzReader;

use crate::common::{ffstream, ok, path_str};
use crate::stress_cli::{assert_no_panic, assert_one_error};

const SCENE: &[&str] = &[
    "builtin:cube",
    "--max-edge",
    "0.25",
    "--quiet",
    "--threads",
    "2",
    "--chunk-kib",
    "1",
];

fn compute(out: &Path, extra: &[&str]) -> String {
    let mut a = vec!["compute"];
    a.extend_from_slice(SCENE);
    a.extend_from_slice(&["-o", path_str(out)]);
    a.extend_from_slice(extra);
    ok(&a)
}

/// The intact file (n = 96, one chunk per 2-3 rows) and its bytes.
fn good(dir: &Path) -> (PathBuf, Vec<u8>) {
    let p = dir.join("good.ffz");
    compute(&p, &[]);
    let bytes = std::fs::read(&p).unwrap();
    (p, bytes)
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}
fn put_u64(b: &mut [u8], at: usize, v: u64) {
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

/// Recompute the fixed header's CRC (§3.1) so only the semantic damage remains.
fn fix_header_crc(b: &mut [u8]) {
    let c = crc32c::crc32c(&b[..60]);
    put_u32(b, 60, c);
}

/// Recompute index and footer CRCs (§7) after editing the index.
fn fix_index_crcs(b: &mut [u8]) {
    let f = b.len() - 32;
    let (off, len) = (u64_at(b, f) as usize, u64_at(b, f + 8) as usize);
    let c = crc32c::crc32c(&b[off..off + len]);
    put_u32(b, f + 16, c);
    let c = crc32c::crc32c(&b[f..f + 20]);
    put_u32(b, f + 20, c);
}

fn verify(p: &Path, against: Option<&Path>) -> std::process::Output {
    let mut a = vec!["verify", path_str(p)];
    if let Some(o) = against {
        a.extend_from_slice(&["--against", path_str(o)]);
    }
    ffstream(&a)
}

fn solve(p: &Path, dir: &Path) -> std::process::Output {
    ffstream(&["solve", path_str(p), "-o", path_str(&dir.join("r.csv"))])
}

#[test]
fn truncated_files_are_detected_and_resume_completes_them() {
    let dir = tempfile::tempdir().unwrap();
    let (good_path, bytes) = good(dir.path());
    let meta_len = u64_at(&bytes, 40) as usize;
    let len = bytes.len();
    let index_offset = u64_at(&bytes, len - 32) as usize;
    let rd = FfzReader::open(&good_path).unwrap();
    let offs = rd.chunk_offsets().to_vec();
    assert!(offs.len() >= 20, "{} chunks", offs.len());
    drop(rd);
    let cuts = [
        0,
        7,
        40,
        64,
        meta_len - 1,
        meta_len,
        offs[1] as usize + 17,
        offs[offs.len() / 2] as usize + 45,
        index_offset - 1,
        index_offset + 10,
        len - 33,
        len - 1,
    ];
    for cut in cuts {
        let what = format!("cut at {cut} of {len}");
        let p = dir.path().join(format!("cut{cut}.ffz"));
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let v = verify(&p, None);
        assert_no_panic(&v, &what);
        assert_ne!(v.status.code(), Some(0), "{what}: verify passed");
        if v.status.code() == Some(1) {
            // Header unreadable: one line naming the file.
            assert!(cut < meta_len, "{what}: header error past the header");
            assert_one_error(&v, &what, &[&format!("cut{cut}.ffz")]);
        } else {
            assert_eq!(v.status.code(), Some(3), "{what}");
        }
        // Solving a cut file: one error line naming the file, or the missing row.
        let s = solve(&p, dir.path());
        if cut < index_offset {
            let line = assert_one_error(&s, &format!("solve {what}"), &[]);
            assert!(
                line.contains(&format!("cut{cut}.ffz")) || line.contains("row"),
                "{what}: {line}"
            );
        } else {
            // Only index or footer cut: every chunk is recovered by the scan, with a
            // warning that says so, and the solve goes through.
            assert_no_panic(&s, &what);
            assert!(s.status.success(), "{what}");
            let stderr = String::from_utf8_lossy(&s.stderr);
            assert!(
                stderr.contains("recovered") && stderr.contains("96 rows present"),
                "{stderr}"
            );
        }
        // And resume completes it to exactly the intact rows, saying what it cut off
        // (every cut past the header lands inside a chunk, the index or the footer).
        let resumed = compute(&p, &["--resume"]);
        if cut > meta_len {
            assert!(
                resumed.contains("ffstream: warning: ") && resumed.contains("dropped"),
                "{what}: resume did not say what it dropped:\n{resumed}"
            );
        }
        let v = verify(&p, Some(&good_path));
        assert_eq!(
            v.status.code(),
            Some(0),
            "{what}: resumed file differs\n{}",
            String::from_utf8_lossy(&v.stdout)
        );
    }
}

#[test]
fn verify_names_every_bad_chunk_and_solve_names_the_first() {
    let dir = tempfile::tempdir().unwrap();
    let (_, bytes) = good(dir.path());
    let rd = FfzReader::open(dir.path().join("good.ffz")).unwrap();
    let offs = rd.chunk_offsets().to_vec();
    drop(rd);
    let hit = [1usize, offs.len() / 2, offs.len() - 1];
    let mut b = bytes.clone();
    for &k in &hit {
        // A byte inside the compressed payload (after the 40-byte chunk header).
        b[offs[k] as usize + 40 + 3] ^= 0x20;
    }
    let p = dir.path().join("flipped.ffz");
    std::fs::write(&p, &b).unwrap();
    let v = verify(&p, None);
    assert_no_panic(&v, "verify flipped");
    assert_eq!(v.status.code(), Some(3));
    let stdout = String::from_utf8_lossy(&v.stdout);
    let fails: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("FAIL: chunk"))
        .collect();
    assert_eq!(fails.len(), hit.len(), "{stdout}");
    for (&k, line) in hit.iter().zip(&fails) {
        assert!(
            line.contains(&format!("chunk {k} at byte {}", offs[k])),
            "{line}"
        );
    }
    let s = solve(&p, dir.path());
    assert_one_error(
        &s,
        "solve flipped",
        &["flipped.ffz", &format!("chunk {}", hit[0]), "checksum"],
    );
}

#[test]
fn wrong_version_and_wrong_n_are_header_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (_, bytes) = good(dir.path());
    assert_eq!(u32_at(&bytes, 16), 96);
    let cases: [(&str, usize, u32, &str); 4] = [
        ("version2", 8, 2, "version 2"),
        ("version0", 8, 0, "version 0"),
        ("n97", 16, 97, "byte"),
        ("n0", 16, 0, "byte"),
    ];
    for (name, at, value, says) in cases {
        let mut b = bytes.clone();
        put_u32(&mut b, at, value);
        fix_header_crc(&mut b);
        let p = dir.path().join(format!("{name}.ffz"));
        std::fs::write(&p, &b).unwrap();
        for cmd in ["info", "verify", "solve"] {
            let out = if cmd == "solve" {
                solve(&p, dir.path())
            } else {
                ffstream(&[cmd, path_str(&p)])
            };
            assert_one_error(
                &out,
                &format!("{cmd} {name}"),
                &[&format!("{name}.ffz"), says],
            );
        }
    }
}

#[test]
fn an_index_pointing_past_the_end_is_not_trusted() {
    let dir = tempfile::tempdir().unwrap();
    let (good_path, bytes) = good(dir.path());
    let f = bytes.len() - 32;
    let index = u64_at(&bytes, f) as usize;
    let n_chunks = u64_at(&bytes, index + 8) as usize;
    let n = u64_at(&bytes, index + 16) as usize;
    assert_eq!(n, 96);
    // (a) the last chunk offset far past the end of the file;
    // (b) row 5's chunk number past the chunk count.
    let mut a = bytes.clone();
    put_u64(&mut a, index + 24 + 8 * (n_chunks - 1), 1 << 40);
    fix_index_crcs(&mut a);
    let mut b = bytes.clone();
    put_u32(
        &mut b,
        index + 24 + 8 * n_chunks + 8 * 5,
        n_chunks as u32 + 7,
    );
    fix_index_crcs(&mut b);
    for (name, data) in [("offset_past_end", a), ("chunk_past_count", b)] {
        let p = dir.path().join(format!("{name}.ffz"));
        std::fs::write(&p, &data).unwrap();
        // The reader must not follow the index: it recovers by scanning, says so, and
        // hands out the exact rows.
        let rd = FfzReader::open(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!rd.is_indexed(), "{name}: bad index trusted");
        assert!(!rd.warnings().is_empty(), "{name}: no warning");
        let gd = FfzReader::open(&good_path).unwrap();
        for i in 0..96 {
            assert_eq!(rd.row(i).unwrap(), gd.row(i).unwrap(), "{name}: row {i}");
        }
        let v = verify(&p, None);
        assert_no_panic(&v, name);
        assert_eq!(v.status.code(), Some(3), "{name}: a bad index fails verify");
        let all = format!(
            "{}{}",
            String::from_utf8_lossy(&v.stdout),
            String::from_utf8_lossy(&v.stderr)
        );
        assert!(all.contains("index"), "{name}: {all}");
    }
}

#[test]
fn a_file_from_another_scene_is_refused_by_solve_and_verify() {
    let dir = tempfile::tempdir().unwrap();
    let (good_path, _) = good(dir.path());
    let plates_obj = dir.path().join("plates.obj");
    let cube_obj = dir.path().join("cube.obj");
    ok(&["scene", "plates", "-o", path_str(&plates_obj)]);
    ok(&["scene", "cube", "-o", path_str(&cube_obj)]);
    let out = ffstream(&[
        "solve",
        path_str(&good_path),
        "--scene",
        path_str(&plates_obj),
        "-o",
        path_str(&dir.path().join("r.csv")),
    ]);
    assert_one_error(
        &out,
        "solve --scene plates",
        &["plates.obj", "not the scene"],
    );
    // The cube itself but cut differently (other max edge): also another patch set.
    let coarse = dir.path().join("coarse.ffz");
    ok(&[
        "compute",
        "builtin:cube",
        "--max-edge",
        "0.5",
        "--quiet",
        "-o",
        path_str(&coarse),
    ]);
    let out = ffstream(&[
        "solve",
        path_str(&coarse),
        "--scene",
        path_str(&cube_obj),
        "-o",
        path_str(&dir.path().join("r.csv")),
    ]);
    assert_no_panic(&out, "solve --scene cube.obj");
    let v = verify(&good_path, Some(&coarse));
    assert_eq!(v.status.code(), Some(3));
    let stdout = String::from_utf8_lossy(&v.stdout);
    assert!(stdout.contains("n 96 vs 24"), "{stdout}");
}

/// One crafted chunk header (its checksum recomputed) declaring 80 GB of raw rows for
/// its real payload of a few hundred kB: n = 100 000 lets a dense chunk of n rows
/// honestly hold 80 GB, so the old bound (rows × (directory + 8 n)) let `info`,
/// `verify`, `solve` and `export` allocate it and abort. The declared size is now
/// bounded by what the payload can decompress to before anything is allocated: every
/// command names the chunk (exit 1; `verify` exit 3), none aborts.
#[test]
fn a_chunk_header_declaring_more_than_its_payload_can_hold_is_refused_before_allocating() {
    use crate::ffz_common::{meta, patches, row, write};
    use ffstream::ffz::Layout;
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    let good = dir.path().join("big.ffz");
    let rows: Vec<_> = (0..3).map(|i| row(5, i, n, Layout::Dense)).collect();
    write(&good, &meta(Layout::Dense, patches(n, 3)), &rows, 1 << 20);
    let at = FfzReader::open(&good).unwrap().chunk_offsets()[0] as usize;
    let mut b = std::fs::read(&good).unwrap();
    put_u64(&mut b, at + 16, 80_000_000_000);
    put_u32(&mut b, at + 24, n);
    let c = crc32c::crc32c(&b[at..at + 36]);
    put_u32(&mut b, at + 36, c);
    let p = dir.path().join("forged.ffz");
    std::fs::write(&p, &b).unwrap();
    let o = ffstream(&["info", path_str(&p)]);
    assert_no_panic(&o, "info");
    let v = verify(&p, None);
    assert_no_panic(&v, "verify");
    assert_eq!(v.status.code(), Some(3));
    let stdout = String::from_utf8_lossy(&v.stdout);
    assert!(stdout.contains("FAIL: chunk 0"), "{stdout}");
    let s = solve(&p, dir.path());
    assert_one_error(&s, "solve", &["forged.ffz", "chunk 0", "raw length"]);
    let e = ffstream(&["export", path_str(&p), "--matrix", "/dev/null"]);
    assert_one_error(&e, "export", &["forged.ffz", "chunk 0", "raw length"]);
}

/// An export that fails halfway (here at a bit-flipped chunk in the middle of the
/// file) left a partial `--sparse` text that looked like a result, over any older
/// file of that name. Text outputs are now written under a temporary name and renamed
/// into place once complete: after the failure the older file is as it was and no
/// temporary file remains.
#[test]
fn a_failed_export_leaves_no_partial_text_and_an_older_file_intact() {
    let dir = tempfile::tempdir().unwrap();
    let (p, bytes) = good(dir.path());
    let offs = FfzReader::open(&p).unwrap().chunk_offsets().to_vec();
    let mut b = bytes.clone();
    b[offs[offs.len() / 2] as usize + 40 + 3] ^= 0x20;
    let bad = dir.path().join("flipped.ffz");
    std::fs::write(&bad, &b).unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let txt = out.join("F.txt");
    std::fs::write(&txt, "older export\n").unwrap();
    let e = ffstream(&["export", path_str(&bad), "--sparse", path_str(&txt)]);
    assert_one_error(&e, "export --sparse", &["flipped.ffz", "chunk"]);
    assert_eq!(std::fs::read_to_string(&txt).unwrap(), "older export\n");
    let left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("F.txt")], "{left:?}");
    // The intact file exports: the text replaces the older one.
    ok(&["export", path_str(&p), "--sparse", path_str(&txt)]);
    assert!(std::fs::read_to_string(&txt)
        .unwrap()
        .starts_with("# ffstream"));
}

/// Issue 48, item 18: an export of a partial file (a run that did not finish) exited 0
/// without a word; `--npz` has no header to name the missing rows, so nothing said
/// the matrix lacked them. Every export of such a file still succeeds (it is what the
/// run has so far) but warns, naming the count of missing rows.
#[test]
fn an_export_of_a_partial_file_warns_of_the_rows_missing() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.ffz");
    ok(&[
        "compute",
        "builtin:cornell",
        "--patches",
        "300",
        "--quiet",
        "--chunk-kib",
        "16",
        "-o",
        path_str(&full),
    ]);
    // Cut inside the chunks: the first ones stay, the index and footer are gone.
    let bytes = std::fs::read(&full).unwrap();
    let part = dir.path().join("part.ffz");
    std::fs::write(&part, &bytes[..bytes.len() * 2 / 3]).unwrap();
    for (option, out) in [("--npz", "p.npz"), ("--matrix", "p.mtx")] {
        let out = dir.path().join(out);
        let o = ffstream(&["export", path_str(&part), option, path_str(&out)]);
        assert_no_panic(&o, option);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{option}: {stderr}");
        assert!(
            stderr.contains("ffstream: warning: ")
                && stderr.contains("rows are missing")
                && stderr.contains("--resume"),
            "{option}: no warning of the missing rows: {stderr}"
        );
    }
    // A complete file exports without one.
    let o = ffstream(&[
        "export",
        path_str(&full),
        "--npz",
        path_str(&dir.path().join("f.npz")),
    ]);
    assert!(o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("warning"));
}
