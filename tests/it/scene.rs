//! Scenes and patches: OBJ loading and validation, built-in scenes, OBJ writing and
//! subdivision, against answers known independently of the code (hand-computed
//! areas, the shared Cornell file, round trips, the bad-input corpus in
//! `tests/data/bad/`, whose first line says what each file breaks).

use std::path::{Path, PathBuf};

use ffstream::geometry::subdivide::{default_max_edge, patch_count, subdivide};
use ffstream::scene::{
    builtin, builtin_names, builtin_room, load_obj, write_obj, Scene, SceneError,
};
use glam::DVec3;

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

fn cornell_file() -> Scene {
    load_obj(&data("scenes/cornell_box.obj")).expect("the Cornell box of tests/data loads")
}

fn group_area(s: &Scene, name: &str) -> f64 {
    let g = s
        .groups
        .iter()
        .position(|g| g == name)
        .expect("group exists") as u32;
    s.faces
        .iter()
        .filter(|f| f.group == g)
        .map(|f| f.area())
        .sum()
}

/// Same geometry, groups and materials; `line` and `source` may differ.
fn assert_same_scene(a: &Scene, b: &Scene) {
    assert_eq!(a.groups, b.groups);
    assert_eq!(a.materials, b.materials);
    assert_eq!(a.faces.len(), b.faces.len());
    for (i, (fa, fb)) in a.faces.iter().zip(&b.faces).enumerate() {
        assert_eq!(fa.corners, fb.corners, "face {i}");
        assert_eq!(fa.group, fb.group, "face {i}");
        assert_eq!(fa.material, fb.material, "face {i}");
    }
}

#[test]
fn cornell_file_groups_and_areas() {
    let s = cornell_file();
    assert_eq!(
        s.groups,
        [
            "floor",
            "ceiling",
            "back_wall",
            "right_wall",
            "left_wall",
            "short_block",
            "tall_block",
            "light"
        ]
    );
    assert_eq!(s.faces.len(), 20);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert_eq!(s.validate(), Ok(()));
    // Floor: shoelace formula on (x, z) of its corners, by hand: 308231.04 mm².
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    assert!(rel(group_area(&s, "floor"), 308_231.04) < 1e-12);
    // Light 130 × 105; ceiling = 556 × 559.2 minus the light's hole.
    assert!(rel(group_area(&s, "light"), 13_650.0) < 1e-12);
    assert!(rel(group_area(&s, "ceiling"), 556.0 * 559.2 - 13_650.0) < 1e-12);
    // Back wall: trapezoid-like quad in z = 559.2, corners x 549.6/0 at y 0, 0/556 at y 548.8.
    assert!(rel(group_area(&s, "back_wall"), 0.5 * (549.6 + 556.0) * 548.8) < 1e-12);
    // Faces on the floor and light face the right way.
    assert_eq!(s.faces[0].normal(), DVec3::Y);
    assert_eq!(s.faces[19].normal(), -DVec3::Y);
    let light = &s.materials[s.faces[19].material as usize];
    assert_eq!(light.name, "light");
    let ke = [53.407_075_1_f64, 37.699_111_8, 12.566_370_6];
    assert_eq!(light.emission, ke.map(|x| x as f32));
    assert_eq!(s.faces[19].line, 93);
    assert!(s.has_emitter());
}

#[test]
fn cornell_builtin_equals_file() {
    assert_same_scene(&builtin("cornell", None).unwrap(), &cornell_file());
}

#[test]
fn write_then_load_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let mut scenes: Vec<Scene> = builtin_names()
        .iter()
        .map(|n| builtin(n, None).unwrap())
        .collect();
    scenes.push(builtin_room(7));
    scenes.push(builtin("cube", Some(0.3)).unwrap());
    scenes.push(cornell_file());
    for (i, s) in scenes.iter().enumerate() {
        let path = dir.path().join(format!("s{i}.obj"));
        write_obj(s, &path).unwrap();
        assert!(path.with_extension("mtl").exists());
        let back = load_obj(&path).unwrap();
        // A scene lit only from outside (the daylight `office`) has no emitter, which the
        // loader rightly points out; that warning is the scene's, not the round trip's.
        let unlit = s.materials.iter().all(|m| m.emission == [0.0; 3]);
        let warnings: Vec<&String> = back.warnings_for(unlit).collect();
        assert!(warnings.is_empty(), "{}: {:?}", s.source, warnings);
        assert_same_scene(s, &back);
    }
}

#[test]
fn write_to_unwritable_path_is_an_error() {
    let s = builtin("plates", None).unwrap();
    let e = write_obj(&s, Path::new("/nonexistent-dir/x.obj")).unwrap_err();
    assert!(matches!(e, SceneError::Write { .. }), "{e}");
}

fn kind(e: &SceneError) -> &'static str {
    match e {
        SceneError::Read { .. } => "Read",
        SceneError::Malformed { .. } => "Malformed",
        SceneError::IndexOutOfRange { .. } => "IndexOutOfRange",
        SceneError::NonFinite { .. } => "NonFinite",
        SceneError::MissingMtl { .. } => "MissingMtl",
        SceneError::MissingMaterial { .. } => "MissingMaterial",
        SceneError::NoMaterial { .. } => "NoMaterial",
        SceneError::Reflectance { .. } => "Reflectance",
        SceneError::Emission { .. } => "Emission",
        SceneError::Empty { .. } => "Empty",
        SceneError::Parser { .. } => "Parser",
        SceneError::UnknownBuiltin { .. } => "UnknownBuiltin",
        SceneError::BadParam { .. } => "BadParam",
        SceneError::Write { .. } => "Write",
        SceneError::Element { .. } => "Element",
    }
}

#[test]
fn bad_inputs_give_the_right_error_file_and_line() {
    // (OBJ file, error kind, file the error must name, line)
    let cases: &[(&str, &str, &str, Option<u32>)] = &[
        ("malformed.obj", "Malformed", "malformed.obj", Some(5)),
        (
            "malformed_face.obj",
            "Malformed",
            "malformed_face.obj",
            Some(13),
        ),
        ("short_face.obj", "Malformed", "short_face.obj", Some(16)),
        ("missing_mtl.obj", "MissingMtl", "missing_mtl.obj", Some(2)),
        (
            "missing_material.obj",
            "MissingMaterial",
            "missing_material.obj",
            Some(15),
        ),
        ("no_material.obj", "NoMaterial", "no_material.obj", Some(12)),
        (
            "index_out_of_range.obj",
            "IndexOutOfRange",
            "index_out_of_range.obj",
            Some(16),
        ),
        (
            "index_zero.obj",
            "IndexOutOfRange",
            "index_zero.obj",
            Some(16),
        ),
        (
            "index_negative.obj",
            "IndexOutOfRange",
            "index_negative.obj",
            Some(16),
        ),
        ("nan.obj", "NonFinite", "nan.obj", Some(7)),
        ("inf.obj", "NonFinite", "inf.obj", Some(9)),
        ("overflow.obj", "NonFinite", "overflow.obj", Some(10)),
        ("kd_high.obj", "Reflectance", "kd_high.mtl", Some(3)),
        ("kd_negative.obj", "Reflectance", "kd_negative.mtl", Some(6)),
        ("kd_short.obj", "Malformed", "kd_short.mtl", Some(3)),
        ("ke_negative.obj", "Emission", "ke_negative.mtl", Some(6)),
        ("empty.obj", "Empty", "empty.obj", None),
        ("empty_file.obj", "Empty", "empty_file.obj", None),
        ("all_degenerate.obj", "Empty", "all_degenerate.obj", None),
        ("does_not_exist.obj", "Read", "does_not_exist.obj", None),
    ];
    for &(file, want, named, line) in cases {
        let e = match load_obj(&data(&format!("bad/{file}"))) {
            Ok(_) => panic!("{file}: loaded, expected {want}"),
            Err(e) => e,
        };
        assert_eq!(kind(&e), want, "{file}: {e}");
        let p = e.path().expect("names a file");
        assert_eq!(p.file_name().unwrap(), named, "{file}: {e}");
        assert_eq!(e.line(), line, "{file}: {e}");
        // The message itself carries file and line.
        let msg = e.to_string();
        assert!(msg.contains(named), "{msg}");
        if let Some(l) = line {
            assert!(msg.contains(&format!(":{l}:")), "{msg}");
        }
    }
}

#[test]
fn degenerate_faces_are_dropped_with_one_warning() {
    let s = load_obj(&data("bad/degenerate.obj")).unwrap();
    assert_eq!(s.faces.len(), 2);
    let w: Vec<&String> = s
        .warnings
        .iter()
        .filter(|w| w.contains("degenerate"))
        .collect();
    assert_eq!(w.len(), 1, "{:?}", s.warnings);
    assert!(
        w[0].contains("dropped 3 ") && w[0].contains("first at line 15"),
        "{}",
        w[0]
    );
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
}

#[test]
fn non_planar_quad_is_split_with_a_warning() {
    let s = load_obj(&data("bad/nonplanar.obj")).unwrap();
    assert_eq!(s.faces.len(), 4);
    assert_eq!(s.faces.iter().filter(|f| f.line == 16).count(), 2);
    assert!(s
        .faces
        .iter()
        .filter(|f| f.line == 16)
        .all(|f| f.corners.len() == 3));
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("non-planar") && s.warnings[0].contains("line 16"));
    assert_eq!(s.validate(), Ok(()));
}

#[test]
fn scene_without_emitter_loads_with_a_warning() {
    let s = load_obj(&data("bad/no_emitter.obj")).unwrap();
    assert!(!s.has_emitter());
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("no face uses an emitting material"));
    // Daylight (`annual`) needs no emitter: the warning is not one for it.
    assert_eq!(s.warnings_for(true).count(), 0);
    assert_eq!(s.warnings_for(false).count(), 1);
}

#[test]
fn triangles_bounds_area_scaled() {
    let s = cornell_file();
    let tris: Vec<(u32, [DVec3; 3])> = s.triangles().collect();
    // 18 quads → 2 triangles each, 2 triangles as they are.
    assert_eq!(tris.len(), 18 * 2 + 2);
    let tri_area: f64 = tris
        .iter()
        .map(|(_, t)| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length())
        .sum();
    assert!((tri_area - s.total_area()).abs() < 1e-9 * tri_area);
    assert_eq!(s.bounds(), (DVec3::ZERO, DVec3::new(556.0, 548.8, 559.2)));
    let t = s.scaled(0.001);
    assert!((t.total_area() - s.total_area() * 1e-6).abs() < 1e-12 * s.total_area());
    assert_eq!(t.bounds().1, DVec3::new(556.0, 548.8, 559.2) * 0.001);
}

#[test]
fn subdivision_respects_max_edge_and_conserves_area() {
    for s in [
        cornell_file(),
        builtin_room(20),
        builtin("cube", None).unwrap(),
    ] {
        let (lo, hi) = s.bounds();
        let max_edge = (hi - lo).length() / 23.7;
        let ps = subdivide(&s, max_edge);
        assert_eq!(ps.groups, s.groups);
        let mut area = vec![0.0; s.faces.len()];
        for p in &ps.patches {
            let c = p.corners();
            for i in 0..c.len() {
                assert!(c[i].distance(c[(i + 1) % c.len()]) <= max_edge * (1.0 + 1e-12));
            }
            let f = &s.faces[p.face as usize];
            assert!((p.normal.length() - 1.0).abs() < 1e-12);
            assert_eq!(p.normal, f.normal());
            assert_eq!(p.group, f.group);
            let m = &s.materials[f.material as usize];
            assert_eq!((p.rho, p.emission), (m.rho, m.emission));
            // Every patch corner lies in its face's plane.
            for q in c {
                assert!((*q - f.corners[0]).dot(p.normal).abs() < 1e-9 * max_edge);
            }
            area[p.face as usize] += p.area;
        }
        for (f, a) in s.faces.iter().zip(&area) {
            assert!((a - f.area()).abs() <= 1e-12 * f.area(), "{}", s.source);
        }
        let total: f64 = ps.patches.iter().map(|p| p.area).sum();
        assert!((total - s.total_area()).abs() <= 1e-12 * total);
    }
}

#[test]
fn default_max_edge_gives_about_the_target() {
    let s = cornell_file();
    for target in [500, 2000, 8000] {
        let e = default_max_edge(&s, target);
        let n = subdivide(&s, e).len();
        assert!(
            (n as f64 / target as f64 - 1.0).abs() < 0.05,
            "target {target}: {n} patches at max_edge {e}"
        );
    }
    // The benchmark size: a room big enough for 100k patches.
    let room = builtin_room(200);
    let e = default_max_edge(&room, 100_000);
    let n = patch_count(&room, e);
    assert!((n as f64 / 1e5 - 1.0).abs() < 0.05, "{n}");
}

#[test]
fn subdivision_is_scale_invariant() {
    let s = cornell_file();
    let (max_edge, k) = (37.3, 3.7);
    let a = subdivide(&s, max_edge);
    let b = subdivide(&s.scaled(k), max_edge * k);
    assert_eq!(a.len(), b.len());
    for (p, q) in a.patches.iter().zip(&b.patches) {
        assert_eq!(
            (p.face, p.group, p.n_corners),
            (q.face, q.group, q.n_corners)
        );
        assert!((p.normal - q.normal).length() < 1e-12);
        assert!((q.area / (k * k) - p.area).abs() < 1e-9 * p.area);
        for (x, y) in p.corners().iter().zip(q.corners()) {
            assert!((*x * k - *y).length() < 1e-9 * k * 600.0);
        }
    }
}

#[test]
fn polygons_are_triangulated_keeping_area_and_orientation() {
    let s = load_obj(&data("scenes/polygons.obj")).unwrap();
    // Only the non-convex quad is worth a warning; polygons with more corners are normal.
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("1 non-convex quad") && s.warnings[0].contains("line 34"));
    assert_eq!(s.validate(), Ok(()));
    // (line, triangles, area by the shoelace formula)
    for (line, n, area) in [(26, 4, 3.0), (30, 3, 1.5), (34, 2, 1.5)] {
        let faces: Vec<_> = s.faces.iter().filter(|f| f.line == line).collect();
        assert_eq!(faces.len(), n, "line {line}");
        assert!(faces.iter().all(|f| f.corners.len() == 3));
        assert!(faces.iter().all(|f| f.normal() == DVec3::Y), "line {line}");
        let a: f64 = faces.iter().map(|f| f.area()).sum();
        assert!((a - area).abs() < 1e-12, "line {line}: {a}");
    }
    let light: Vec<_> = s.faces.iter().filter(|f| f.line == 37).collect();
    assert_eq!(light.len(), 1);
    assert_eq!(light[0].corners.len(), 4);
    assert_eq!(s.groups, ["l_shape", "pentagon", "dart", "light"]);
}

#[test]
fn polylines_are_ignored_and_ungrouped_faces_get_a_group() {
    let s = load_obj(&data("bad/line_element.obj")).unwrap();
    // tobj names faces before any `o`/`g` (or after a bare `g`) `unnamed_object`.
    assert_eq!(s.groups, ["unnamed_object", "light"]);
    assert_eq!(s.faces.len(), 2);
    assert_eq!((s.faces[0].line, s.faces[1].line), (12, 16));
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("ignored 1 line element") && s.warnings[0].contains("line 13"));
}

/// OBJ and MTL text as editors write it (issue 48): a UTF-8 byte-order mark before
/// `mtllib` (OBJ) or `newmtl` (MTL) made the statement an unknown keyword, so every
/// `usemtl` failed; a tab after `mtllib` gave "missing file name". Both load now. A
/// file whose lines end in CR alone is one line to the loader: its error used to quote
/// the whole file (and its CRs sent the cursor back over the message); the quote is
/// now cut to 200 characters, control characters escaped.
#[test]
fn byte_order_marks_tabs_and_cr_only_files_are_read_or_quoted_briefly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let body = "v 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl white\nf 1 2 3\n";
    std::fs::write(d.join("m.mtl"), "newmtl white\nKd 0.5 0.5 0.5\nKe 1 1 1\n").unwrap();
    std::fs::write(
        d.join("bom.mtl"),
        "\u{feff}newmtl white\nKd 0.5 0.5 0.5\nKe 1 1 1\n",
    )
    .unwrap();
    for (name, text) in [
        ("bom.obj", format!("\u{feff}mtllib m.mtl\n{body}")),
        ("tab.obj", format!("mtllib\tm.mtl\n{body}")),
        ("bom_mtl.obj", format!("mtllib bom.mtl\n{body}")),
    ] {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        let s = load_obj(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(s.faces.len(), 1, "{name}");
        assert_eq!(s.materials[0].emission, [1.0, 1.0, 1.0], "{name}");
    }
    let mut cr = String::from("mtllib m.mtl\r");
    for i in 0..300 {
        cr += &format!("v {i} 0 0\rv {i} 1 0\rv {i} 1 1\r");
    }
    cr += "usemtl white\rf 1 2 3\r";
    let p = d.join("cr.obj");
    std::fs::write(&p, &cr).unwrap();
    let e = load_obj(&p).unwrap_err().to_string();
    assert!(e.contains("cr.obj:1"), "{e}");
    assert!(e.len() < 400, "{} characters: {e}", e.len());
    assert!(!e.contains('\r') && e.contains("characters in all"), "{e}");
}

/// One face of 400,000 corners took 26 s to load (the polygon repair rescans the face
/// for every corner it removes or clips): faces are limited to 10,000 corners, refused
/// above at once naming the line. A 9,000-corner star (every other corner reflex)
/// still loads, as its 8,998 triangles, in about a second.
#[test]
fn a_face_with_too_many_corners_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let polygon = |n: usize, star: bool| {
        let mut t = String::from("newmtl white\nKd 0.5 0.5 0.5\n");
        std::fs::write(dir.path().join("m.mtl"), &t).unwrap();
        t = String::from("mtllib m.mtl\n");
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let r = if star && k % 2 == 1 { 1.3 } else { 1.0 };
            t += &format!("v {} {} 0\n", r * a.cos(), r * a.sin());
        }
        t += "usemtl white\nf";
        for k in 1..=n {
            t += &format!(" {k}");
        }
        t.push('\n');
        t
    };
    let big = dir.path().join("big.obj");
    std::fs::write(&big, polygon(400_000, false)).unwrap();
    let start = std::time::Instant::now();
    let e = load_obj(&big).unwrap_err().to_string();
    assert!(start.elapsed().as_secs() < 5, "{:?}", start.elapsed());
    assert!(
        e.contains("big.obj:400003") && e.contains("400000 corners") && e.contains("10000"),
        "{e}"
    );
    let star = dir.path().join("star.obj");
    std::fs::write(&star, polygon(9_000, true)).unwrap();
    let s = load_obj(&star).unwrap();
    assert_eq!(s.faces.len(), 8_998);
}
