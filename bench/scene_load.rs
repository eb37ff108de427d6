//! Scene loading benchmark: how long `load_file` takes on a large mesh in each format.
//!
//!     cargo bench --bench scene_load                   # 100k triangles, 5 runs each
//!     cargo bench --bench scene_load -- --triangles N  # another size
//!
//! The mesh is a city of box buildings (5 triangulated sides each, 10 triangles; the
//! counts are rounded to whole buildings) on a ground of triangles, written by this
//! program as binary STL, ASCII STL, binary PLY (indexed, vertices shared within a
//! building), GLB and OBJ into a temporary directory. Each file is loaded `runs` times
//! through `ffstream::scene::load_file` (read, parse, validate, duplicates check) and
//! the median wall time printed with the file size. The target of the issue: a
//! 100k-triangle binary STL in under a second.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use ffstream::scene::{load_file, SceneFormat};

/// Triangles of the city (each a counter-clockwise corner triple seen from outside),
/// with the building each belongs to.
fn city(triangles: usize) -> Vec<[[f32; 3]; 3]> {
    let buildings = triangles.div_ceil(10);
    let side = (buildings as f64).sqrt().ceil() as usize;
    let mut out = Vec::with_capacity(buildings * 10);
    for b in 0..buildings {
        let (x0, y0) = ((b % side) as f32 * 3.0, (b / side) as f32 * 3.0);
        let (x1, y1) = (x0 + 2.0, y0 + 2.0);
        let h = 4.0 + (b * 7919 % 23) as f32;
        let c = |x: f32, y: f32, z: f32| [x, y, z];
        let quads = [
            // roof, then the four walls (outward normals)
            [c(x0, y0, h), c(x1, y0, h), c(x1, y1, h), c(x0, y1, h)],
            [c(x0, y0, 0.0), c(x1, y0, 0.0), c(x1, y0, h), c(x0, y0, h)],
            [c(x1, y0, 0.0), c(x1, y1, 0.0), c(x1, y1, h), c(x1, y0, h)],
            [c(x1, y1, 0.0), c(x0, y1, 0.0), c(x0, y1, h), c(x1, y1, h)],
            [c(x0, y1, 0.0), c(x0, y0, 0.0), c(x0, y0, h), c(x0, y1, h)],
        ];
        for q in quads {
            out.push([q[0], q[1], q[2]]);
            out.push([q[0], q[2], q[3]]);
        }
    }
    out
}

fn write_binary_stl(path: &Path, tris: &[[[f32; 3]; 3]]) {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend_from_slice(&[0u8; 12]);
        for v in t {
            for x in v {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    std::fs::write(path, b).unwrap();
}

fn write_ascii_stl(path: &Path, tris: &[[[f32; 3]; 3]]) {
    let mut s = String::from("solid city\n");
    for t in tris {
        s.push_str(" facet normal 0 0 0\n  outer loop\n");
        for v in t {
            s.push_str(&format!("   vertex {:e} {:e} {:e}\n", v[0], v[1], v[2]));
        }
        s.push_str("  endloop\n endfacet\n");
    }
    s.push_str("endsolid city\n");
    std::fs::write(path, s).unwrap();
}

/// Vertices shared by exact coordinates (the way an indexed format stores a mesh).
fn indexed(tris: &[[[f32; 3]; 3]]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut at = std::collections::HashMap::new();
    let mut verts = Vec::new();
    let faces = tris
        .iter()
        .map(|t| {
            t.map(|v| {
                *at.entry(v.map(f32::to_bits)).or_insert_with(|| {
                    verts.push(v);
                    verts.len() as u32 - 1
                })
            })
        })
        .collect();
    (verts, faces)
}

fn write_ply(path: &Path, tris: &[[[f32; 3]; 3]]) {
    let (verts, faces) = indexed(tris);
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        verts.len(),
        faces.len()
    )
    .into_bytes();
    for v in &verts {
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    for f in &faces {
        b.push(3);
        for i in f {
            b.extend_from_slice(&i.to_le_bytes());
        }
    }
    std::fs::write(path, b).unwrap();
}

fn write_obj(path: &Path, tris: &[[[f32; 3]; 3]]) {
    let (verts, faces) = indexed(tris);
    let mtl = path.with_extension("mtl");
    std::fs::write(&mtl, "newmtl grey\nKd 0.5 0.5 0.5\nKe 1 1 1\n").unwrap();
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(f, "mtllib {}", mtl.file_name().unwrap().to_str().unwrap()).unwrap();
    for v in &verts {
        writeln!(f, "v {:e} {:e} {:e}", v[0], v[1], v[2]).unwrap();
    }
    writeln!(f, "g city\nusemtl grey").unwrap();
    for t in &faces {
        writeln!(f, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).unwrap();
    }
}

fn write_glb(path: &Path, tris: &[[[f32; 3]; 3]]) {
    let (verts, faces) = indexed(tris);
    let mut bin = Vec::new();
    for v in &verts {
        for x in v {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    let pos_len = bin.len();
    for f in &faces {
        for i in f {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for v in &verts {
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0,"name":"city"}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],"buffers":[{{"byteLength":{}}}],"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{pos_len}}},{{"buffer":0,"byteOffset":{pos_len},"byteLength":{}}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},{{"bufferView":1,"componentType":5125,"count":{},"type":"SCALAR"}}]}}"#,
        bin.len(),
        bin.len() - pos_len,
        verts.len(),
        lo[0],
        lo[1],
        lo[2],
        hi[0],
        hi[1],
        hi[2],
        3 * faces.len()
    );
    let mut j = json.into_bytes();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + bin.len();
    let mut b = Vec::with_capacity(total);
    b.extend_from_slice(b"glTF");
    b.extend_from_slice(&2u32.to_le_bytes());
    b.extend_from_slice(&(total as u32).to_le_bytes());
    b.extend_from_slice(&(j.len() as u32).to_le_bytes());
    b.extend_from_slice(b"JSON");
    b.extend_from_slice(&j);
    b.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    b.extend_from_slice(b"BIN\0");
    b.extend_from_slice(&bin);
    std::fs::write(path, b).unwrap();
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|k| args.get(k + 1))
            .map(|v| v.parse::<usize>().expect("a whole number"))
    };
    let triangles = arg("--triangles").unwrap_or(100_000);
    let runs = arg("--runs").unwrap_or(5);
    let tris = city(triangles);
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A materials file for the formats without materials (one emitting grey).
    for stem in ["binary", "ascii", "city"] {
        std::fs::write(
            d.join(format!("{stem}.mtl")),
            "newmtl default\nKd 0.5 0.5 0.5\nKe 1 1 1\n",
        )
        .unwrap();
    }
    let files = [
        ("binary STL", "binary.stl", SceneFormat::Stl),
        ("ASCII STL", "ascii.stl", SceneFormat::Stl),
        ("binary PLY", "city.ply", SceneFormat::Ply),
        ("GLB", "city.glb", SceneFormat::Gltf),
        ("OBJ", "obj.obj", SceneFormat::Obj),
    ];
    write_binary_stl(&d.join("binary.stl"), &tris);
    write_ascii_stl(&d.join("ascii.stl"), &tris);
    write_ply(&d.join("city.ply"), &tris);
    write_glb(&d.join("city.glb"), &tris);
    write_obj(&d.join("obj.obj"), &tris);
    println!(
        "scene_load: {} triangles ({} buildings), median of {runs} loads each (ffstream::scene::load_file)",
        tris.len(),
        tris.len() / 10
    );
    println!("| format | file MB | median s | triangles/s | faces loaded |");
    println!("|---|---|---|---|---|");
    for (label, name, format) in files {
        let path = d.join(name);
        let mb = std::fs::metadata(&path).unwrap().len() as f64 / 1e6;
        let mut times = Vec::new();
        let mut faces = 0;
        for _ in 0..runs {
            let t = Instant::now();
            let scene = load_file(&path, format).unwrap_or_else(|e| panic!("{name}: {e}"));
            times.push(t.elapsed().as_secs_f64());
            faces = scene.faces.len();
            assert!(scene.warnings.is_empty(), "{name}: {:?}", scene.warnings);
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        println!(
            "| {label} | {mb:.1} | {median:.3} | {:.2e} | {faces} |",
            tris.len() as f64 / median
        );
        assert_eq!(faces, tris.len(), "{name}: every triangle is a face");
    }
}
