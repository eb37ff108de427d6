//! Malformed mesh files: each file of `tests/data/bad/` gives one error line naming the
//! file and the element, and mutated binary files never make a reader panic.

use super::*;

/// (corpus file, text the error line must hold besides the file name)
const BAD: &[(&str, &str)] = &[
    ("stl_truncated.stl", "facet 3: truncated binary STL"),
    ("stl_too_short.stl", "header:"),
    (
        "stl_nan.stl",
        "facet 2 (solid `box` of line 1): malformed facet: expected finite",
    ),
    (
        "stl_malformed.stl",
        "facet 2 (solid `box` of line 1): malformed facet",
    ),
    ("ply_truncated.ply", "not readable as PLY"),
    (
        "ply_wrong_count.ply",
        "line 16: the file ends after 2 of the header's 3 `face` elements",
    ),
    // Issue 48: a face count one short, a value too many, facets after `endsolid`
    // were dropped or ignored without a word.
    (
        "ply_face_count_short.ply",
        "line 15: data after the last element the header declares (4 `vertex`, 1 `face`)",
    ),
    (
        "ply_extra_value.ply",
        "line 12: 4 values, but a `vertex` element here has 3",
    ),
    (
        "ply_binary_extra.ply",
        "file: 13 bytes after the last element the header declares",
    ),
    (
        "stl_after_endsolid.stl",
        "line 10: `facet normal 0 0 1` outside any `solid ... endsolid` block (the last one ended at line 9)",
    ),
    ("ply_index.ply", "face 2: vertex index 9 out of range"),
    ("ply_nan.ply", "face 1: vertex coordinate NaN"),
    ("ply_points.ply", "no `face` element"),
    ("gltf_missing_buffer.gltf", "buffer 0: cannot read"),
    (
        "gltf_short_buffer.gltf",
        "buffer 0: has 24 bytes, its byteLength says 36",
    ),
    (
        "gltf_accessor_range.gltf",
        "accessor 0: 4 elements of 12 bytes",
    ),
    ("gltf_nan.gltf", "triangle 1: vertex coordinate NaN"),
    (
        "gltf_index.gltf",
        "triangle 1 (mesh 0 primitive 0): vertex index 7 out of range",
    ),
    ("gltf_not_json.gltf", "not readable as glTF"),
    (
        "gltf_data_not_base64.gltf",
        "buffer 0: data: URI `data:application/octet-stream,...` is not base64",
    ),
    (
        "gltf_data_bad_base64.gltf",
        "buffer 0: data: URI is not valid base64",
    ),
    ("glb_truncated.glb", "not readable as glTF"),
];

#[test]
fn malformed_mesh_files_give_one_error_line_naming_file_and_element() {
    let dir = tempfile::tempdir().unwrap();
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad");
    for &(file, want) in BAD {
        let path = corpus.join(file);
        let e = open_scene(path_str(&path)).expect_err(file).to_string();
        assert!(e.contains(file) && e.contains(want), "{file}: {e}");
        let out = ffstream(&[
            "compute",
            path_str(&path),
            "-o",
            path_str(&dir.path().join("x.ffz")),
            "--patches",
            "20",
            "--quiet",
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{file}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{file}: {stderr}");
        assert!(
            stderr.contains(file) && stderr.contains(want),
            "{file}: {stderr}"
        );
    }
}

/// Truncated and byte-flipped copies of the binary files (STL, PLY, GLB, a glTF's
/// .bin): every one loads or gives an error, none panics.
#[test]
fn mutated_binary_mesh_files_never_panic() {
    let (_, w) = write_all();
    let dir = tempfile::tempdir().unwrap();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut tried = 0;
    for (file, companion) in [
        ("binary.stl", None),
        ("binary_le.ply", None),
        ("box.glb", None),
        ("box.gltf", Some("box.bin")),
    ] {
        let target = companion.unwrap_or(file);
        let original = std::fs::read(w.dir.path().join(target)).unwrap();
        let mut cases: Vec<Vec<u8>> = (0..40)
            .map(|k| original[..original.len() * k / 40].to_vec())
            .collect();
        for _ in 0..120 {
            let mut b = original.clone();
            for _ in 0..1 + next() % 4 {
                let at = (next() % b.len() as u64) as usize;
                b[at] ^= 1 << (next() % 8);
            }
            cases.push(b);
        }
        for bytes in cases {
            let path = dir.path().join(file);
            if let Some(c) = companion {
                std::fs::copy(w.dir.path().join(file), &path).unwrap();
                std::fs::write(dir.path().join(c), &bytes).unwrap();
            } else {
                std::fs::write(&path, &bytes).unwrap();
            }
            let format = SceneFormat::of_path(&path);
            let r = std::panic::catch_unwind(|| load_file(&path, format).map(|s| s.faces.len()));
            assert!(r.is_ok(), "{file}: a mutated copy made the loader panic");
            tried += 1;
        }
    }
    assert_eq!(tried, 4 * 160);
}
