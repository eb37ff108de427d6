//! How the readers decide: PLY polygons are repaired as OBJ faces are, an STL file's
//! kind is decided by its size and then by `solid` in any case, and glTF node
//! hierarchies, materials and versions are checked.

use super::*;

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
