//! The Python reader (`formats/ffz.py`) against the Rust reader on real random files
//! written with rows in shuffled order: the CSR matrix, dropped mass, presence and
//! patch areas must agree bit for bit. Then the Python test
//! `test_matches_rust_export` checks `tools::export` output against the Python reader.
//! Without python3 and those packages the test fails naming them (`make test` installs
//! them), unless FFSTREAM_SKIP_PYTHON=1 is set.

use crate::ffz_common::*;
use ffstream::ffz::{FfzReader, Layout, RowState};
use ffstream::report::tools;
use ffstream::rows::Row;
use std::path::{Path, PathBuf};
use std::process::Command;

fn formats_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("formats")
}

fn python_ready() -> Result<(), String> {
    let out = Command::new("python3")
        .args(["-c", "import numpy, scipy.sparse, zstandard, pytest"])
        .output()
        .map_err(|e| format!("python3 not runnable: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "python3 lacks numpy/scipy/zstandard/pytest: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// True when python3 has the packages; otherwise fails the test naming them, or
/// (with FFSTREAM_SKIP_PYTHON=1) says it skips and returns false.
fn python_or_skip() -> bool {
    let ready = python_ready();
    if let Err(why) = &ready {
        eprintln!("{why}");
    }
    crate::common::need_tool(
        "python3 with numpy, scipy, zstandard and pytest",
        ready.is_ok(),
        "FFSTREAM_SKIP_PYTHON",
    )
}

fn read_vec<T: Copy>(path: &Path, conv: fn(&[u8]) -> T, size: usize) -> Vec<T> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(size)
        .map(conv)
        .collect()
}

fn check_file(path: &Path, dump: &Path) {
    let out = Command::new("python3")
        .arg(formats_dir().join("ffz.py"))
        .arg(path)
        .arg("--dump")
        .arg(dump)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ffz.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let indptr = read_vec(
        &dump.join("indptr.i64"),
        |b| i64::from_le_bytes(b.try_into().unwrap()),
        8,
    );
    let indices = read_vec(
        &dump.join("indices.u32"),
        |b| u32::from_le_bytes(b.try_into().unwrap()),
        4,
    );
    let data = read_vec(
        &dump.join("data.f32"),
        |b| u32::from_le_bytes(b.try_into().unwrap()),
        4,
    );
    let dropped = read_vec(
        &dump.join("dropped.f32"),
        |b| u32::from_le_bytes(b.try_into().unwrap()),
        4,
    );
    let presence = std::fs::read(dump.join("presence.u8")).unwrap();
    let area = read_vec(
        &dump.join("area.f64"),
        |b| u64::from_le_bytes(b.try_into().unwrap()),
        8,
    );

    let rd = FfzReader::open(path).unwrap();
    let n = rd.n() as usize;
    for (i, p) in rd.meta().patches.patches.iter().enumerate() {
        assert_eq!(area[i], p.area.to_bits(), "area {i}");
    }
    let rows = assert_csr_is_rows(&rd, &indptr, &indices, &data, 0.0);
    for i in 0..n {
        let state = match rd.presence().get(i as u32) {
            RowState::Missing => 0,
            RowState::Present => 1,
            RowState::Skipped => 2,
        };
        assert_eq!(presence[i], state, "presence of row {i}");
        if let (Some(r), 1) = (&rows[i], state) {
            assert_eq!(dropped[i], r.dropped.to_bits(), "dropped of row {i}");
        }
    }
}

/// The CSR arrays (`data` as f32 bits) hold exactly the non-zero entries ≥ `min_ff` of
/// the rows of `rd`, bit for bit, rows in order; returns the rows.
fn assert_csr_is_rows(
    rd: &FfzReader,
    indptr: &[i64],
    indices: &[u32],
    data: &[u32],
    min_ff: f32,
) -> Vec<Option<Row>> {
    let n = rd.n() as usize;
    assert_eq!(indptr.len(), n + 1);
    assert_eq!(indices.len(), data.len());
    let mut rows: Vec<Option<Row>> = vec![None; n];
    rd.scan(|r| rows[r.index as usize] = Some(r.clone()))
        .unwrap();
    for i in 0..n {
        let (a, b) = (indptr[i] as usize, indptr[i + 1] as usize);
        let mut want = Vec::new();
        if let Some(r) = &rows[i] {
            r.for_each_nonzero(|j, x| {
                if x >= min_ff {
                    want.push((j, x.to_bits()))
                }
            });
        }
        let got: Vec<(u32, u32)> = indices[a..b]
            .iter()
            .copied()
            .zip(data[a..b].iter().copied())
            .collect();
        assert_eq!(got, want, "row {i}");
    }
    rows
}

#[test]
fn python_reader_agrees_with_rust() {
    if !python_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (name, n, layout) in [
        ("dense.ffz", 150u32, Layout::Dense),
        ("topk.ffz", 700, Layout::TopK { k: 12 }),
    ] {
        let path = dir.path().join(name);
        let m = meta(layout, patches(n, 21));
        let mut ids: Vec<u32> = (0..n).collect();
        SplitMix64::new(99).shuffle(&mut ids);
        ids.truncate(n as usize - 7); // a few rows missing too
        let rows: Vec<Row> = ids.iter().map(|&i| row(13, i, n, layout)).collect();
        write(&path, &m, &rows, 8 << 10);
        check_file(&path, &dir.path().join(format!("{name}.dump")));

        // The export, checked by the Python test when pytest is there.
        let mtx = dir.path().join(format!("{name}.mtx"));
        let csv = dir.path().join(format!("{name}.csv"));
        let targets = tools::ExportTargets {
            matrix: Some(&mtx),
            patches_csv: Some(&csv),
            ..Default::default()
        };
        tools::export(&path, targets).unwrap();
        let out = Command::new("python3")
            .args([
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                "test_ffz.py",
                "-k",
                "rust_export",
            ])
            .current_dir(formats_dir())
            .env("FFZ_FILE", &path)
            .env("FFZ_MTX", &mtx)
            .env("FFZ_CSV", &csv)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && text.contains("1 passed"),
            "pytest export check failed:\n{text}"
        );
    }
}

#[test]
fn scipy_load_npz_opens_the_exported_npz_as_the_same_matrix() {
    if !python_or_skip() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // scipy alone (not our reader) opens the archive and writes its arrays raw.
    let script = "import sys, numpy as np, scipy.sparse as sp\n\
        m = sp.load_npz(sys.argv[1])\n\
        assert isinstance(m, sp.csr_matrix), type(m)\n\
        assert m.dtype == np.float32, m.dtype\n\
        m.indptr.astype('<i8').tofile(sys.argv[2] + '.indptr')\n\
        m.indices.astype('<u4').tofile(sys.argv[2] + '.indices')\n\
        m.data.astype('<f4').tofile(sys.argv[2] + '.data')\n\
        print(m.shape[0], m.shape[1], m.indptr.dtype)\n";
    for (name, n, layout, min_ff) in [
        ("dense.ffz", 150u32, Layout::Dense, 0.0f32),
        ("dense_cut.ffz", 150, Layout::Dense, 0.5 / 150.0), // entries are below 1 / n
        ("topk.ffz", 700, Layout::TopK { k: 12 }, 0.0),
    ] {
        let path = dir.path().join(name);
        let m = meta(layout, patches(n, 21));
        let mut ids: Vec<u32> = (0..n).collect();
        SplitMix64::new(7).shuffle(&mut ids);
        ids.truncate(n as usize - 5); // rows missing, the rest in shuffled order
        let rows: Vec<Row> = ids.iter().map(|&i| row(17, i, n, layout)).collect();
        write(&path, &m, &rows, 8 << 10);
        let npz = dir.path().join(format!("{name}.npz"));
        let targets = tools::ExportTargets {
            npz: Some(&npz),
            min_ff,
            ..Default::default()
        };
        tools::export(&path, targets).unwrap();
        let spilt = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .any(|e| e.file_name().to_string_lossy().ends_with(".spill"));
        assert!(!spilt, "the spill file is removed");
        let raw = dir.path().join(format!("{name}.raw"));
        let out = Command::new("python3")
            .args(["-c", script])
            .arg(&npz)
            .arg(&raw)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "scipy.sparse.load_npz failed on {name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let said = String::from_utf8_lossy(&out.stdout);
        assert_eq!(said.trim(), format!("{n} {n} int32"), "{name}");
        let ext = |e: &str| PathBuf::from(format!("{}.{e}", raw.display()));
        let indptr = read_vec(
            &ext("indptr"),
            |b| i64::from_le_bytes(b.try_into().unwrap()),
            8,
        );
        let indices = read_vec(
            &ext("indices"),
            |b| u32::from_le_bytes(b.try_into().unwrap()),
            4,
        );
        let data = read_vec(
            &ext("data"),
            |b| u32::from_le_bytes(b.try_into().unwrap()),
            4,
        );
        let rd = FfzReader::open(&path).unwrap();
        let rows = assert_csr_is_rows(&rd, &indptr, &indices, &data, min_ff);
        let mut nonzero = 0;
        for r in rows.iter().flatten() {
            r.for_each_nonzero(|_, _| nonzero += 1);
        }
        // The cut leaves some entries out, and keeps some.
        assert!(!data.is_empty());
        assert_eq!(min_ff > 0.0, data.len() < nonzero, "{name}");
    }
}
