//! STL, PLY and glTF scenes: the Cornell box written in each format (by the small,
//! independent writers below, not by ffstream) loads as the same faces, groups and
//! materials as the same box in OBJ, and `compute` gives bitwise the same rows; the
//! malformed files of `tests/data/bad/` (made by `tests/data/bad/make_mesh_corpus.py`,
//! which says what each breaks) each give one error line naming the file and element.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use ffstream::scene::{builtin, load_file, open_scene, write_obj, Face, Scene, SceneFormat};
use glam::DVec3;

use crate::common::{ffstream, ok, path_str};
use crate::service::assert_same_row_values;

/// The built-in Cornell box as triangles (each quad as the fan 0-1-2, 0-2-3) with
/// coordinates rounded to f32, which every format here can hold exactly.
fn cornell_triangles() -> Scene {
    let s = builtin("cornell", None).unwrap();
    let mut out = Scene {
        faces: Vec::new(),
        ..s.clone()
    };
    let r = |p: DVec3| DVec3::new(p.x as f32 as f64, p.y as f32 as f64, p.z as f32 as f64);
    for f in &s.faces {
        let c: Vec<DVec3> = f.corners.iter().map(|&p| r(p)).collect();
        for k in 1..c.len() - 1 {
            out.faces.push(Face {
                corners: vec![c[0], c[k], c[k + 1]],
                ..f.clone()
            });
        }
    }
    out
}

/// The faces of `s` group by group, in order (every format writes them so).
fn by_group(s: &Scene) -> Vec<(usize, Vec<&Face>)> {
    (0..s.groups.len())
        .map(|g| {
            (
                g,
                s.faces.iter().filter(|f| f.group as usize == g).collect(),
            )
        })
        .collect()
}

/// An MTL file whose materials are named after the groups of `s` (the materials file
/// of STL and PLY).
fn write_group_mtl(s: &Scene, path: &Path, default_name: Option<&str>) {
    let mut m = String::new();
    for (g, faces) in by_group(s) {
        let mat = &s.materials[faces[0].material as usize];
        assert!(
            faces.iter().all(|f| f.material == faces[0].material),
            "one material per group"
        );
        let name = default_name.unwrap_or(&s.groups[g]);
        let [r, gr, b] = mat.rho;
        let [er, eg, eb] = mat.emission;
        let _ = writeln!(m, "newmtl {name}\nKd {r} {gr} {b}\nKe {er} {eg} {eb}\n");
        if default_name.is_some() {
            break;
        }
    }
    std::fs::write(path, m).unwrap();
}

fn f32s(p: DVec3) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

fn write_stl_ascii(s: &Scene, path: &Path) {
    let mut t = String::new();
    for (g, faces) in by_group(s) {
        let _ = writeln!(t, "solid {}", s.groups[g]);
        for f in faces {
            let _ = writeln!(t, "  facet normal 0 0 0\n    outer loop");
            for &c in &f.corners {
                let [x, y, z] = f32s(c);
                let _ = writeln!(t, "      vertex {x:?} {y:?} {z:?}");
            }
            let _ = writeln!(t, "    endloop\n  endfacet");
        }
        let _ = writeln!(t, "endsolid {}", s.groups[g]);
    }
    std::fs::write(path, t).unwrap();
}

/// Binary STL; the header starts with `solid`, as some exporters write it.
fn write_stl_binary(s: &Scene, path: &Path) {
    let mut b = vec![b' '; 80];
    b[..14].copy_from_slice(b"solid exported");
    b.extend((s.faces.len() as u32).to_le_bytes());
    for f in &s.faces {
        b.extend([0u8; 12]);
        for &c in &f.corners {
            for x in f32s(c) {
                b.extend(x.to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    std::fs::write(path, b).unwrap();
}

/// PLY with welded vertices (each distinct corner once), ASCII or little-endian binary.
fn write_ply(s: &Scene, path: &Path, binary: bool) {
    let mut verts: Vec<[f32; 3]> = Vec::new();
    let mut faces: Vec<Vec<u32>> = Vec::new();
    for f in &s.faces {
        let idx = f
            .corners
            .iter()
            .map(|&c| {
                let p = f32s(c);
                match verts
                    .iter()
                    .position(|v| v.map(f32::to_bits) == p.map(f32::to_bits))
                {
                    Some(k) => k as u32,
                    None => {
                        verts.push(p);
                        (verts.len() - 1) as u32
                    }
                }
            })
            .collect();
        faces.push(idx);
    }
    let format = if binary {
        "binary_little_endian"
    } else {
        "ascii"
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment Cornell box, by the ffstream tests\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        verts.len(),
        faces.len()
    )
    .into_bytes();
    if binary {
        for v in &verts {
            for x in v {
                out.extend(x.to_le_bytes());
            }
        }
        for f in &faces {
            out.push(f.len() as u8);
            for &i in f {
                out.extend((i as i32).to_le_bytes());
            }
        }
    } else {
        let mut t = String::new();
        for [x, y, z] in &verts {
            let _ = writeln!(t, "{x:?} {y:?} {z:?}");
        }
        for f in &faces {
            let _ = write!(t, "{}", f.len());
            for i in f {
                let _ = write!(t, " {i}");
            }
            t.push('\n');
        }
        out.extend(t.into_bytes());
    }
    std::fs::write(path, out).unwrap();
}

/// glTF: one node, mesh and material per group; positions unwelded, no indices for
/// the first group (non-indexed primitive) and u16 indices for the others; emission
/// as emissiveFactor × KHR_materials_emissive_strength with a power-of-two strength,
/// so the product is exact in f32. Where the buffer goes: see [`Buffer`].
fn write_gltf(s: &Scene, path: &Path, buffer: Buffer) {
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut nodes, mut materials) =
        (vec![], vec![], vec![], vec![], vec![]);
    for (g, faces) in by_group(s) {
        let start = bin.len();
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for f in &faces {
            for &c in &f.corners {
                let p = f32s(c);
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                    bin.extend(p[k].to_le_bytes());
                }
            }
        }
        let count = faces.len() * 3;
        views.push(format!(
            r#"{{"buffer":0,"byteOffset":{start},"byteLength":{}}}"#,
            count * 12
        ));
        accessors.push(format!(
            r#"{{"bufferView":{},"componentType":5126,"count":{count},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}}"#,
            views.len() - 1,
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        ));
        let pos = accessors.len() - 1;
        let indices = if g == 0 {
            String::new()
        } else {
            let at = bin.len();
            for k in 0..count as u16 {
                bin.extend(k.to_le_bytes());
            }
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            views.push(format!(
                r#"{{"buffer":0,"byteOffset":{at},"byteLength":{}}}"#,
                count * 2
            ));
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":5123,"count":{count},"type":"SCALAR"}}"#,
                views.len() - 1
            ));
            format!(r#","indices":{}"#, accessors.len() - 1)
        };
        let m = &s.materials[faces[0].material as usize];
        let [r, gr, b] = m.rho;
        let [er, eg, eb] = m.emission.map(|e| e / 32.0);
        materials.push(format!(
            r#"{{"name":"{}","pbrMetallicRoughness":{{"baseColorFactor":[{r:?},{gr:?},{b:?},1.0]}},"emissiveFactor":[{er:?},{eg:?},{eb:?}],"extensions":{{"KHR_materials_emissive_strength":{{"emissiveStrength":32.0}}}}}}"#,
            m.name
        ));
        meshes.push(format!(
            r#"{{"primitives":[{{"attributes":{{"POSITION":{pos}}}{indices},"material":{}}}]}}"#,
            materials.len() - 1
        ));
        nodes.push(format!(
            r#"{{"name":"{}","mesh":{}}}"#,
            s.groups[g],
            meshes.len() - 1
        ));
    }
    let uri = match buffer {
        Buffer::Glb => String::new(),
        Buffer::File(name, uri) => {
            std::fs::write(path.with_file_name(name), &bin).unwrap();
            format!(r#","uri":"{uri}""#)
        }
        Buffer::Embedded => format!(
            r#","uri":"data:application/octet-stream;base64,{}""#,
            base64(&bin)
        ),
    };
    let node_ids: Vec<String> = (0..nodes.len()).map(|k| k.to_string()).collect();
    let mut json = format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["KHR_materials_emissive_strength"],"scene":0,"scenes":[{{"nodes":[{}]}}],"nodes":[{}],"meshes":[{}],"materials":[{}],"accessors":[{}],"bufferViews":[{}],"buffers":[{{"byteLength":{}{uri}}}]}}"#,
        node_ids.join(","),
        nodes.join(","),
        meshes.join(","),
        materials.join(","),
        accessors.join(","),
        views.join(","),
        bin.len()
    )
    .into_bytes();
    if !matches!(buffer, Buffer::Glb) {
        std::fs::write(path, json).unwrap();
        return;
    }
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    std::fs::write(path, out).unwrap();
}

/// Where [`write_gltf`] puts the buffer.
#[derive(Clone, Copy)]
enum Buffer {
    /// A GLB file: the buffer is its binary chunk.
    Glb,
    /// A file of this name beside the .gltf, referred to by this URI.
    File(&'static str, &'static str),
    /// In the JSON, as a base64 `data:` URI.
    Embedded,
}

/// RFC 4648 base64 with padding, written out here so the loader's decoder is checked
/// against an encoder that is not its own crate.
fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Faces of `a` and `b`: the same corners bit for bit, in the same order, with the
/// same reflectance and emission; groups compared when `groups`.
fn assert_same_faces(a: &Scene, b: &Scene, groups: bool, what: &str) {
    assert_eq!(a.faces.len(), b.faces.len(), "{what}: face count");
    for (k, (x, y)) in a.faces.iter().zip(&b.faces).enumerate() {
        let bits = |f: &Face| -> Vec<u64> {
            f.corners
                .iter()
                .flat_map(|c| c.to_array())
                .map(f64::to_bits)
                .collect()
        };
        assert_eq!(bits(x), bits(y), "{what}: face {k} corners");
        if groups {
            assert_eq!(
                a.groups[x.group as usize], b.groups[y.group as usize],
                "{what}: face {k} group"
            );
            let (ma, mb) = (
                &a.materials[x.material as usize],
                &b.materials[y.material as usize],
            );
            assert_eq!(
                (ma.rho, ma.emission),
                (mb.rho, mb.emission),
                "{what}: face {k} material"
            );
        }
    }
}

struct Written {
    dir: tempfile::TempDir,
    obj: PathBuf,
}

/// The triangulated Cornell box in every format, in one directory.
fn write_all() -> (Scene, Written) {
    let s = cornell_triangles();
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let obj = p("box.obj");
    write_obj(&s, &obj).unwrap();
    write_stl_ascii(&s, &p("ascii.stl"));
    write_group_mtl(&s, &p("ascii.mtl"), None);
    write_stl_binary(&s, &p("binary.stl"));
    write_group_mtl(&s, &p("binary.mtl"), Some("default"));
    write_ply(&s, &p("ascii.ply"), false);
    write_ply(&s, &p("binary_le.ply"), true);
    write_gltf(&s, &p("box.gltf"), Buffer::File("box.bin", "box.bin"));
    write_gltf(&s, &p("box.glb"), Buffer::Glb);
    write_gltf(&s, &p("embedded.gltf"), Buffer::Embedded);
    // A buffer file whose name has a space, escaped in the URI as RFC 3986 has it.
    write_gltf(
        &s,
        &p("spaced.gltf"),
        Buffer::File("box data.bin", "box%20data.bin"),
    );
    (s, Written { dir, obj })
}

#[test]
fn the_cornell_box_in_every_format_loads_as_the_same_faces() {
    let (s, w) = write_all();
    let obj = load_file(&w.obj, SceneFormat::Obj).unwrap();
    assert_same_faces(&s, &obj, true, "obj");
    let p = |n: &str| w.dir.path().join(n);
    for (file, groups) in [
        ("ascii.stl", true),
        ("binary.stl", false),
        ("ascii.ply", false),
        ("binary_le.ply", false),
        ("box.gltf", true),
        ("box.glb", true),
        ("embedded.gltf", true),
        ("spaced.gltf", true),
    ] {
        let got = open_scene(path_str(&p(file))).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_same_faces(&obj, &got, groups, file);
        // binary.stl has one group with the materials file's `default` (white), so no
        // emitter: the only warning any of them may raise.
        // The PLY files have no materials file: every face gets the fallback grey, with
        // a warning saying so.
        let allowed = |w: &String| {
            (file == "binary.stl" && w.contains("no face uses an emitting"))
                || (file.ends_with(".ply")
                    && (w.contains("no face uses an emitting")
                        || w.contains("no material for group(s)")))
        };
        assert!(
            got.warnings.iter().all(allowed),
            "{file}: {:?}",
            got.warnings
        );
        if !groups {
            // One group named after the file, every face with the default material.
            assert_eq!(got.groups.len(), 1, "{file}");
            assert_eq!(got.groups[0], file.split('.').next().unwrap(), "{file}");
        }
    }
    // Materials by group name from the materials file (binary.mtl has only `default`).
    let bin = open_scene(path_str(&p("binary.stl"))).unwrap();
    assert!(bin
        .faces
        .iter()
        .all(|f| bin.materials[f.material as usize].name == "default"));
}

#[test]
fn the_cornell_box_in_every_format_gives_bitwise_the_same_rows() {
    let (_, w) = write_all();
    let p = |n: &str| w.dir.path().join(n);
    let compute = |scene: &str, out: &Path, extra: &[&str]| {
        let mut a = vec![
            "compute",
            scene,
            "-o",
            path_str(out),
            "--max-edge",
            "120",
            "--quiet",
        ];
        a.extend_from_slice(extra);
        ok(&a);
    };
    let reference = p("obj.ffz");
    compute(path_str(&w.obj), &reference, &[]);
    for file in [
        "ascii.stl",
        "binary.stl",
        "ascii.ply",
        "binary_le.ply",
        "box.gltf",
        "box.glb",
        "embedded.gltf",
        "spaced.gltf",
    ] {
        let out = p(&format!("{file}.ffz"));
        compute(path_str(&p(file)), &out, &[]);
        assert_same_row_values(&reference, &out);
    }
    // --format overrides the extension, and the header records it so solve reopens
    // the scene the same way.
    let odd = p("mesh.dat");
    std::fs::copy(p("ascii.stl"), &odd).unwrap();
    std::fs::copy(p("ascii.mtl"), p("mesh.mtl")).unwrap();
    let out = p("dat.ffz");
    compute(path_str(&odd), &out, &["--format", "stl"]);
    assert_same_row_values(&reference, &out);
    let info = ffstream(&["info", path_str(&out)]);
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.contains(&format!("scene_path=stl:{}", path_str(&odd))),
        "{info}"
    );
    ok(&[
        "solve",
        path_str(&out),
        "-o",
        path_str(&p("dat.csv")),
        "--quiet",
    ]);
}

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

#[test]
fn ply_polygons_are_repaired_as_obj_faces_are() {
    // A planar quad (kept), a planar convex pentagon (split), a non-planar quad (split)
    // and a degenerate triangle (dropped): the same faces from PLY as from OBJ, and
    // the same warnings apart from what names the element.
    let dir = tempfile::tempdir().unwrap();
    let verts = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [2.0, 0.0, 0.0],
        [3.0, 0.0, 0.0],
        [3.5, 0.5, 0.0],
        [3.0, 1.0, 0.0],
        [2.0, 1.0, 0.0],
        [4.0, 0.0, 0.0],
        [5.0, 0.0, 0.0],
        [5.0, 1.0, 0.3],
        [4.0, 1.0, 0.0],
        [6.0, 0.0, 0.0],
        [7.0, 0.0, 0.0],
        [8.0, 0.0, 0.0],
    ];
    let faces: [&[usize]; 4] = [
        &[0, 1, 2, 3],
        &[4, 5, 6, 7, 8],
        &[9, 10, 11, 12],
        &[13, 14, 15],
    ];
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        verts.len(),
        faces.len()
    );
    let mut obj = String::from("mtllib poly.mtl\n");
    for v in verts {
        writeln!(ply, "{} {} {}", v[0], v[1], v[2]).unwrap();
        writeln!(obj, "v {} {} {}", v[0], v[1], v[2]).unwrap();
    }
    obj.push_str("g poly\nusemtl default\n");
    for f in faces {
        let ids: Vec<String> = f.iter().map(|i| i.to_string()).collect();
        writeln!(ply, "{} {}", f.len(), ids.join(" ")).unwrap();
        let ids: Vec<String> = f.iter().map(|i| (i + 1).to_string()).collect();
        writeln!(obj, "f {}", ids.join(" ")).unwrap();
    }
    // The materials file of the PLY is also the OBJ's library: `default` for both.
    std::fs::write(
        dir.path().join("poly.mtl"),
        "newmtl default\nKd 0.5 0.5 0.5\nKe 1 1 1\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("poly.ply"), ply).unwrap();
    std::fs::write(dir.path().join("poly.obj"), obj).unwrap();
    let from_obj = load_file(&dir.path().join("poly.obj"), SceneFormat::Obj).unwrap();
    let from_ply = load_file(&dir.path().join("poly.ply"), SceneFormat::Ply).unwrap();
    assert_same_faces(&from_obj, &from_ply, true, "poly.ply");
    // 1 quad + 3 triangles of the pentagon + 2 of the bent quad; the sliver dropped.
    assert_eq!(from_ply.faces.len(), 6, "{:?}", from_ply.warnings);
    assert_eq!(
        from_obj.warnings.len(),
        from_ply.warnings.len(),
        "{:?} vs {:?}",
        from_obj.warnings,
        from_ply.warnings
    );
    // The repairs name PLY faces (1-based), as OBJ warnings name lines: the bent quad
    // is face 3 and the sliver face 4 (the planar pentagon is split without a word).
    for (what, at) in [("non-planar", "face 3"), ("degenerate", "face 4")] {
        assert!(
            from_ply
                .warnings
                .iter()
                .any(|w| w.contains(what) && w.contains(at)),
            "no {what} warning at {at}: {:?}",
            from_ply.warnings
        );
    }
}

/// Which kind an STL is (issue 48): a binary file whose 80-byte header starts with
/// `solid` and whose size is 84 + 50 × its count is binary; an ASCII file with a UTF-8
/// byte-order mark, or written in upper case (`SOLID`, `FACET NORMAL`), is ASCII (both
/// were read as binary and refused as "truncated binary STL" with a count of a billion
/// facets); UTF-16 text is an error that says so.
#[test]
fn stl_kind_is_decided_by_size_then_by_solid_in_any_case() {
    let dir = tempfile::tempdir().unwrap();
    let square = [
        [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
        [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ];
    let mut binary = b"solid exported by a CAD tool".to_vec();
    binary.resize(80, b' ');
    binary.extend(2u32.to_le_bytes());
    for t in &square {
        binary.extend([0u8; 12]);
        for v in t {
            for x in v {
                binary.extend(x.to_le_bytes());
            }
        }
        binary.extend([0u8; 2]);
    }
    let mut ascii = String::from("solid box\n");
    for t in &square {
        ascii += "  facet normal 0 0 1\n    outer loop\n";
        for v in t {
            ascii += &format!("      vertex {} {} {}\n", v[0], v[1], v[2]);
        }
        ascii += "    endloop\n  endfacet\n";
    }
    ascii += "endsolid box\n";
    let mut bom = b"\xef\xbb\xbf".to_vec();
    bom.extend(ascii.as_bytes());
    let utf16: Vec<u8> = std::iter::once(0xfeff_u16)
        .chain(ascii.encode_utf16())
        .flat_map(|u| u.to_le_bytes())
        .collect();
    let cases: [(&str, Vec<u8>, &str); 3] = [
        ("binary_solid.stl", binary, "binary_solid"),
        ("bom.stl", bom, "box"),
        ("upper.stl", ascii.to_uppercase().into_bytes(), "BOX"),
    ];
    for (name, bytes, group) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let s = open_scene(path_str(&p)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(s.faces.len(), 2, "{name}");
        assert_eq!(s.groups, vec![group.to_string()], "{name}");
    }
    let p = dir.path().join("utf16.stl");
    std::fs::write(&p, utf16).unwrap();
    let e = open_scene(path_str(&p)).unwrap_err().to_string();
    assert!(e.contains("utf16.stl") && e.contains("UTF-16"), "{e}");
}

/// A glTF document with one triangle (positions in a base64 `data:` buffer) on node
/// `mesh_node`, the given `nodes` (JSON objects; the mesh is added to node
/// `mesh_node`), scene roots `roots`, and a material from `material` (JSON object).
fn gltf_doc(
    version: &str,
    mut nodes: Vec<serde_json::Value>,
    mesh_node: usize,
    roots: &[usize],
    material: serde_json::Value,
) -> String {
    let tri: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    nodes[mesh_node]["mesh"] = serde_json::json!(0);
    serde_json::json!({
        "asset": {"version": version},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [material],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3,
                       "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36,
                     "uri": format!("data:application/octet-stream;base64,{}", base64(&tri))}],
    })
    .to_string()
}

/// glTF checks of issue 48: a legal 300-deep chain of nodes was refused as "a cycle?"
/// (depth limit 256); nodes sharing children (each of 40 levels' two nodes the child
/// of both nodes above: 2^41 paths) were walked path by path, forever; a real cycle
/// must be named; negative base colour, emissive factor or emissive strength were
/// clamped to 0 without a word (the MTL loader refuses them); asset version 1.0 was
/// read as 2.0.
#[test]
fn gltf_hierarchies_materials_and_versions_are_checked() {
    use serde_json::json;
    let dir = tempfile::tempdir().unwrap();
    let white = json!({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]},
                       "emissiveFactor": [1.0, 1.0, 1.0]});
    let load = |name: &str, text: String| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        open_scene(path_str(&p))
    };
    // A chain 0 -> 1 -> ... -> 299, the mesh on the last.
    let chain: Vec<_> = (0..300)
        .map(|k| {
            if k < 299 {
                json!({"children": [k + 1]})
            } else {
                json!({})
            }
        })
        .collect();
    let s = load(
        "chain.gltf",
        gltf_doc("2.0", chain, 299, &[0], white.clone()),
    )
    .unwrap_or_else(|e| panic!("a 300-deep chain is legal: {e}"));
    assert_eq!(s.faces.len(), 1);
    // 40 levels of two nodes, each the child of both nodes of the level above.
    let mut dag: Vec<_> = (0..80)
        .map(|k| {
            let next = 2 * (k / 2 + 1);
            if next < 80 {
                json!({"children": [next, next + 1]})
            } else {
                json!({})
            }
        })
        .collect();
    dag[0] = json!({"children": [2, 3]});
    let start = std::time::Instant::now();
    let e = load("dag.gltf", gltf_doc("2.0", dag, 79, &[0], white.clone()))
        .unwrap_err()
        .to_string();
    assert!(
        start.elapsed().as_secs() < 5,
        "the DAG was walked path by path"
    );
    assert!(
        e.contains("dag.gltf") && e.contains("node instances"),
        "{e}"
    );
    assert!(e.contains("is a child of nodes"), "{e}");
    // A cycle 0 -> 1 -> 2 -> 1.
    let cycle = vec![
        json!({"children": [1]}),
        json!({"children": [2]}),
        json!({"children": [1]}),
    ];
    let e = load("cycle.gltf", gltf_doc("2.0", cycle, 2, &[0], white.clone()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("node 2") && e.contains("cycle"), "{e}");
    // Materials.
    let one = || vec![json!({})];
    for (name, material, want) in [
        (
            "kd.gltf",
            json!({"pbrMetallicRoughness": {"baseColorFactor": [0.5, -0.25, 0.5, 1.0]}}),
            "baseColorFactor -0.25 must be finite and >= 0",
        ),
        (
            "ke.gltf",
            json!({"emissiveFactor": [1.0, -1.0, 0.0]}),
            "emissiveFactor -1 must be finite and >= 0",
        ),
        (
            "strength.gltf",
            json!({"emissiveFactor": [1.0, 1.0, 1.0],
                   "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": -2.0}}}),
            "emissive strength -2 must be finite and >= 0",
        ),
    ] {
        let e = load(name, gltf_doc("2.0", one(), 0, &[0], material))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(name) && e.contains("material 0") && e.contains(want),
            "{e}"
        );
    }
    let e = load("v1.gltf", gltf_doc("1.0", one(), 0, &[0], white.clone()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("v1.gltf") && e.contains("version `1.0`"), "{e}");
    assert!(load("v21.gltf", gltf_doc("2.1", one(), 0, &[0], white)).is_ok());
}
