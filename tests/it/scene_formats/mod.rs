//! STL, PLY and glTF scenes: the Cornell box written in each format (by the small,
//! independent writers below, not by ffstream) loads as the same faces, groups and
//! materials as the same box in OBJ, and `compute` gives bitwise the same rows; the
//! malformed files of `tests/data/bad/` (made by `tests/data/bad/make_mesh_corpus.py`,
//! which says what each breaks) each give one error line naming the file and element.
//!
//! This file holds the independent writers and the Cornell box in every format;
//! `bad_files`: the malformed and mutated files; `reader_rules`: how the readers
//! decide (PLY polygons repaired as OBJ faces are, the STL kind, glTF hierarchies,
//! materials and versions).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use ffstream::scene::{builtin, load_file, open_scene, write_obj, Face, Scene, SceneFormat};
use glam::DVec3;

use crate::common::{ffstream, ok, path_str};
use crate::service::assert_same_row_values;

mod bad_files;
mod reader_rules;

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
