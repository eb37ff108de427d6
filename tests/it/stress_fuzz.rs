//! Stress, fuzzing on stable Rust: a seeded mutation loop over the `.ffz` golden files
//! (and a file written here, dense and top-k) and over the OBJ corpus, with the same
//! checks as the cargo-fuzz targets in `fuzz/` (which need a nightly compiler):
//! - `.ffz`: `FfzReader::open` on the mutated bytes, then `row` for every row, `scan`,
//!   `verify`: any result is fine, a panic (or an abort on a huge allocation) is not,
//!   and when the checksums were not touched by hand every row handed out must be
//!   exact (mutations mostly break a checksum; some recompute the header, index and
//!   footer CRCs so the semantic checks behind them get exercised too);
//! - OBJ: `load_obj` on mutated lines (deleted, duplicated, numbers replaced by extreme
//!   or malformed values, indices shifted, bytes cut): Ok or Err, never a panic; when
//!   Ok the scene passes `validate()` and subdivides.
//!
//! Default: 400 mutants per target (a few seconds). FFSTREAM_FUZZ_ITERS=N for more, or
//! FFSTREAM_STRESS_LONG=1 for 20 000. A failing mutant is written to
//! `target/fuzz-failures/` and named in the panic message, with its seed.

use ffstream::formfactor::sampling::SplitMix64;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use ffstream::ffz::{FfzReader, Layout};
use ffstream::geometry::subdivide::{default_max_edge, patch_count};
use ffstream::rows::Row;
use ffstream::scene::load_obj;

use crate::ffz_common::{meta, patches, row, write};

fn iterations() -> u64 {
    if let Some(n) = std::env::var("FFSTREAM_FUZZ_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        return n;
    }
    if std::env::var_os("FFSTREAM_STRESS_LONG").is_some() {
        20_000
    } else {
        400
    }
}

fn keep_failure(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures");
    let _ = std::fs::create_dir_all(&dir);
    let p = dir.join(name);
    let _ = std::fs::write(&p, bytes);
    p
}

// ---------------------------------------------------------------- .ffz reader

/// Values worth writing into a header or index field.
const EXTREMES: [u64; 9] = [
    0,
    1,
    2,
    3,
    0xFF,
    0xFFFF_FFFF,
    0x8000_0000,
    u64::MAX,
    1 << 40,
];

/// Recompute every CRC the reader checks before trusting the header and the index
/// (formats/ffz-v1.md §3.1, §3.3, §7), where the file is long enough to hold them.
fn fix_crcs(b: &mut [u8]) {
    if b.len() >= 64 {
        let c = crc32c::crc32c(&b[..60]);
        b[60..64].copy_from_slice(&c.to_le_bytes());
        let meta_len = u64::from_le_bytes(b[40..48].try_into().unwrap());
        if meta_len >= 68 && meta_len <= b.len() as u64 {
            let m = meta_len as usize;
            let c = crc32c::crc32c(&b[64..m - 4]);
            b[m - 4..m].copy_from_slice(&c.to_le_bytes());
        }
    }
    if b.len() >= 96 {
        let f = b.len() - 32;
        let off = u64::from_le_bytes(b[f..f + 8].try_into().unwrap());
        let len = u64::from_le_bytes(b[f + 8..f + 16].try_into().unwrap());
        if off.checked_add(len).is_some_and(|e| e <= f as u64) {
            let c = crc32c::crc32c(&b[off as usize..(off + len) as usize]);
            b[f + 16..f + 20].copy_from_slice(&c.to_le_bytes());
        }
        let c = crc32c::crc32c(&b[f..f + 20]);
        b[f + 20..f + 24].copy_from_slice(&c.to_le_bytes());
    }
}

/// One mutant of `base`; true when the CRCs were recomputed afterwards.
fn mutate_ffz(base: &[u8], rng: &mut SplitMix64) -> (Vec<u8>, bool) {
    let mut b = base.to_vec();
    let rounds = 1 + rng.below(3);
    for _ in 0..rounds {
        let len = b.len().max(1);
        match rng.below(8) {
            0 => {
                let i = rng.below(len);
                if i < b.len() {
                    b[i] ^= 1 << rng.below(8);
                }
            }
            1 => {
                let i = rng.below(len);
                if i < b.len() {
                    b[i] = rng.next_u64() as u8;
                }
            }
            2 => b.truncate(rng.below(len)),
            3 => {
                // A header/index/footer-sized field (4 or 8 bytes, aligned) set to an
                // extreme value.
                let w = if rng.below(2) == 0 { 4 } else { 8 };
                let i = rng.below(len / w) * w;
                if i + w <= b.len() {
                    let v = EXTREMES[rng.below(EXTREMES.len())].to_le_bytes();
                    b[i..i + w].copy_from_slice(&v[..w]);
                }
            }
            4 => {
                // The same in the fixed header, field by field (§3.1).
                let i = [8, 12, 16, 20, 24, 28, 32, 40, 48, 52, 56][rng.below(11)];
                if i + 4 <= b.len() {
                    let v = EXTREMES[rng.below(EXTREMES.len())].to_le_bytes();
                    b[i..i + 4].copy_from_slice(&v[..4]);
                }
            }
            5 => {
                // Duplicate a slice somewhere else.
                let (i, j) = (rng.below(len), rng.below(len));
                let k = rng.below(64).min(b.len().saturating_sub(i.max(j)));
                let s = b[i..i + k].to_vec();
                b[j..j + k].copy_from_slice(&s);
            }
            6 => {
                let i = rng.below(len);
                let k = rng.below(16).min(b.len() - i.min(b.len()));
                b.drain(i..i + k);
            }
            _ => {
                let i = rng.below(len).min(b.len());
                let ins: Vec<u8> = (0..1 + rng.below(16))
                    .map(|_| rng.next_u64() as u8)
                    .collect();
                b.splice(i..i, ins);
            }
        }
    }
    let fixed = rng.below(2) == 0;
    if fixed {
        fix_crcs(&mut b);
    }
    (b, fixed)
}

/// Exercise the reader on one file: must return, whatever the bytes. Rows that come
/// out must equal `expect(i)` when given (it is given when the CRCs were not forged:
/// a wrong row would then be undetected damage).
pub(crate) fn exercise_reader(path: &Path, expect: Option<&dyn Fn(u32) -> Option<Row>>) {
    let Ok(rd) = FfzReader::open(path) else {
        return;
    };
    let n = rd.n();
    for i in 0..n.min(4096) {
        if let Ok(Some(r)) = rd.row(i) {
            if let Some(e) = expect.and_then(|f| f(i)) {
                assert_eq!(r, e, "row {i} came out wrong");
            }
        }
    }
    let _ = rd.scan(|r| {
        if let Some(e) = expect.and_then(|f| f(r.index)) {
            assert_eq!(*r, e, "scan: row {} came out wrong", r.index);
        }
    });
    let rep = rd.verify();
    let _ = rep.ok();
    let _ = ffstream::ffz::compare(&rd, &rd, Default::default());
}

fn golden(name: &str) -> Vec<u8> {
    std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("formats/golden")
            .join(name),
    )
    .unwrap()
}

/// A file to mutate: name, bytes, and (n, layout) when its rows are known.
type Base = (String, Vec<u8>, Option<(u32, Layout)>);

#[test]
fn ffz_reader_survives_mutated_files() {
    let dir = tempfile::tempdir().unwrap();
    // A file written here, whose rows are known, dense and top-k, several chunks.
    let n = 7;
    let mut bases: Vec<Base> = Vec::new();
    for (name, layout) in [("dense", Layout::Dense), ("topk", Layout::TopK { k: 3 })] {
        let p = dir.path().join(format!("{name}.ffz"));
        let m = meta(layout, patches(n, 11));
        let rows: Vec<Row> = [3, 0, 6, 1, 5, 2, 4]
            .iter()
            .map(|&i| row(13, i, n, layout))
            .collect();
        write(&p, &m, &rows, 64);
        bases.push((name.into(), std::fs::read(&p).unwrap(), Some((n, layout))));
    }
    for g in ["tiny-v1.ffz", "tiny-dense-v1.ffz"] {
        bases.push((g.into(), golden(g), None));
    }
    let iters = iterations();
    let target = dir.path().join("mutant.ffz");
    let mut opened = 0u64;
    for seed in 0..iters {
        let (name, base, known) = &bases[(seed % bases.len() as u64) as usize];
        let mut rng = SplitMix64::new(seed);
        let (bytes, forged) = mutate_ffz(base, &mut rng);
        std::fs::write(&target, &bytes).unwrap();
        let expect = |i: u32| -> Option<Row> {
            let (n, layout) = (*known)?;
            (i < n).then(|| row(13, i, n, layout))
        };
        let exp: Option<&dyn Fn(u32) -> Option<Row>> = if forged || known.is_none() {
            None
        } else {
            Some(&expect)
        };
        let t0 = std::time::Instant::now();
        let res = catch_unwind(AssertUnwindSafe(|| exercise_reader(&target, exp)));
        let took = t0.elapsed().as_secs_f64();
        if took > 0.5 {
            let p = keep_failure(&format!("ffz-{name}-seed{seed}-slow.ffz"), &bytes);
            println!(
                "slow mutant of {name}, seed {seed}: {took:.1} s (kept at {})",
                p.display()
            );
        }
        if res.is_err() {
            let p = keep_failure(&format!("ffz-{name}-seed{seed}.ffz"), &bytes);
            panic!(
                "mutant of {name}, seed {seed} (forged CRCs: {forged}): panic; kept at {}",
                p.display()
            );
        }
        opened += FfzReader::open(&target).is_ok() as u64;
    }
    println!("ffz reader: {iters} mutants, {opened} opened, no panic");
}

// ---------------------------------------------------------------- OBJ loader

const NUMBERS: [&str; 14] = [
    "0",
    "-0",
    "1e308",
    "1e309",
    "-1e309",
    "nan",
    "inf",
    "1e-320",
    "0x10",
    "",
    "-1",
    "4294967296",
    "99999999999999999999",
    "1/2/3",
];

fn mutate_obj(text: &str, rng: &mut SplitMix64) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for _ in 0..1 + rng.below(3) {
        if lines.is_empty() {
            lines.push("f 1 2 3".into());
        }
        let k = rng.below(lines.len());
        match rng.below(7) {
            0 => {
                lines.remove(k);
            }
            1 => {
                let l = lines[k].clone();
                lines.insert(rng.below(lines.len() + 1), l);
            }
            2 | 3 => {
                // Replace one token by an extreme or malformed value.
                let mut t: Vec<String> = lines[k].split_whitespace().map(String::from).collect();
                if t.len() > 1 {
                    let i = 1 + rng.below(t.len() - 1);
                    t[i] = NUMBERS[rng.below(NUMBERS.len())].into();
                    lines[k] = t.join(" ");
                }
            }
            4 => {
                // Shift a face index (out of range, negative, zero).
                if lines[k].starts_with("f ") {
                    let d = rng.below(20) as i64 - 10;
                    lines[k] = lines[k]
                        .split_whitespace()
                        .map(|w| match w.parse::<i64>() {
                            Ok(v) => (v + d).to_string(),
                            Err(_) => w.to_string(),
                        })
                        .collect::<Vec<_>>()
                        .join(" ");
                }
            }
            5 => {
                let l = &lines[k];
                let cut = rng.below(l.len() + 1);
                let cut = (0..=cut)
                    .rev()
                    .find(|&c| l.is_char_boundary(c))
                    .unwrap_or(0);
                lines[k] = l[..cut].to_string();
            }
            _ => {
                // A face over random existing vertex numbers, 1 to 6 corners.
                let nv = lines.iter().filter(|l| l.starts_with("v ")).count().max(1);
                let c: Vec<String> = (0..1 + rng.below(6))
                    .map(|_| (1 + rng.below(nv)).to_string())
                    .collect();
                lines.insert(k, format!("f {}", c.join(" ")));
            }
        }
    }
    lines.join("\n") + "\n"
}

pub(crate) fn exercise_loader(path: &Path) {
    if let Ok(s) = load_obj(path) {
        assert_eq!(s.validate(), Ok(()), "a loaded scene must be valid");
        assert!(!s.faces.is_empty());
        let e = default_max_edge(&s, 50);
        assert!(patch_count(&s, e) >= s.faces.len());
    }
}

#[test]
fn obj_loader_survives_mutated_files() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut bases: Vec<(String, String)> = Vec::new();
    for sub in ["bad", "scenes"] {
        for e in std::fs::read_dir(root.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "obj") {
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                // (Lossy: two corpus files hold bytes that are not UTF-8 on purpose.)
                let text = String::from_utf8_lossy(&std::fs::read(&p).unwrap()).into_owned();
                bases.push((name, text));
            }
        }
    }
    bases.sort();
    // Mutants go next to the MTL files they name.
    let dir = tempfile::tempdir().unwrap();
    for sub in ["bad", "scenes"] {
        for e in std::fs::read_dir(root.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "mtl") {
                std::fs::copy(&p, dir.path().join(p.file_name().unwrap())).unwrap();
            }
        }
    }
    let iters = iterations();
    let target = dir.path().join("mutant.obj");
    let mut loaded = 0u64;
    for seed in 0..iters {
        let (name, base) = &bases[(seed % bases.len() as u64) as usize];
        let mut rng = SplitMix64::new(seed ^ 0x0B1);
        let text = mutate_obj(base, &mut rng);
        std::fs::write(&target, &text).unwrap();
        if let Some(trace) = std::env::var_os("FFSTREAM_FUZZ_TRACE") {
            // Which mutant is running, for one that never returns.
            let _ = std::fs::write(trace, format!("{name} seed {seed}\n{text}"));
        }
        let t0 = std::time::Instant::now();
        let res = catch_unwind(AssertUnwindSafe(|| exercise_loader(&target)));
        let took = t0.elapsed().as_secs_f64();
        if took > 0.5 {
            let p = keep_failure(&format!("obj-{name}-seed{seed}-slow.obj"), text.as_bytes());
            println!(
                "slow mutant of {name}, seed {seed}: {took:.1} s (kept at {})",
                p.display()
            );
        }
        if res.is_err() {
            let p = keep_failure(&format!("obj-{name}-seed{seed}.obj"), text.as_bytes());
            panic!(
                "mutant of {name}, seed {seed}: panic; kept at {}",
                p.display()
            );
        }
        loaded += load_obj(&target).is_ok() as u64;
    }
    println!("OBJ loader: {iters} mutants, {loaded} loaded, no panic");
}

// ---------------------------------------------------------------- regressions

/// Found by the `.ffz` mutation loop (seed 1859 of tiny-dense-v1.ffz, CRCs forged): an
/// index chunk offset near u64::MAX overflowed `offset + chunk header length` in
/// `read_index` (a panic with overflow checks, a wrapped bound without).
#[test]
fn index_chunk_offset_near_u64_max_is_rejected_not_overflowed() {
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad/ffz_chunk_offset_overflow.ffz");
    exercise_reader(&p, None);
    let rd = FfzReader::open(&p).expect("recovered by scan");
    assert!(!rd.is_indexed(), "the damaged index must not be used");
}

/// Found by the OBJ mutation loop (seed 15100 of cornell_box.obj): a finite coordinate
/// 1e308 gave an edge of infinite length, and `default_max_edge` halved infinity
/// forever. The loader now refuses such coordinates (file and line), and
/// `default_max_edge` returns on a non-finite edge.
#[test]
fn huge_finite_coordinate_is_refused_and_default_max_edge_returns() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad/huge_coord_vertex.obj");
    let e = load_obj(&p).unwrap_err();
    assert_eq!(e.line(), Some(5), "{e}");
    let mut s = ffstream::scene::builtin("plates", None).unwrap();
    s.faces[0].corners[2].z = 1e308;
    let m = default_max_edge(&s, 100);
    assert!(m > 0.0, "{m}");
}
