//! Loading a scene from OBJ + MTL.
//!
//! Parsing is `tobj`'s (untriangulated, so quads stay quads). `tobj` reports no line
//! numbers and accepts some inputs the pipeline must refuse (NaN coordinates, index 0,
//! a `Kd` with one value makes it panic), so a light pre-pass over the text comes first:
//! it checks every statement the loader relies on, maps the k-th face element to its
//! line, and records which `usemtl` was in force. `tobj`'s result is then turned into
//! faces by [`super::polygon::repair`]: triangles and planar convex quads are kept,
//! other polygons split, degenerate ones dropped; each kind of repair is reported as
//! one warning line with a count and the first line concerned.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::mesh::{finish, Tally, MAX_COORDINATE};
use super::mtl::{parse_mtl, read_text, words};
use super::polygon::{repair, MAX_FACE_CORNERS};
use super::{Face, Material, Scene, SceneError};

/// One face element (`f`, or `l` which `tobj` also returns as a face) in file order.
struct Element {
    line: u32,
    /// `f` (a polygon) rather than `l` (a polyline, ignored).
    polygon: bool,
    /// Index into [`PrePass::usemtl`] of the `usemtl` in force, if any.
    usemtl: Option<u32>,
}

/// What the pre-pass learns about the OBJ text.
struct PrePass {
    elements: Vec<Element>,
    /// `(material name, line)` of each `usemtl` statement.
    usemtl: Vec<(String, u32)>,
    /// `(library as written, line)` of each `mtllib` statement.
    mtllibs: Vec<(String, u32)>,
}

/// Load and validate an OBJ file and the MTL libraries it names (relative to the
/// OBJ file's directory). Each `o`/`g` name is a group (a name used twice is one
/// group); faces before any of them are in group `unnamed_object`.
///
/// # Errors
/// [`SceneError`] naming the OBJ or MTL file and line: unreadable file, malformed
/// statement, index out of range, non-finite coordinate, missing library or material,
/// face without material, `Kd` outside [0, 1), negative `Ke`, or no usable face.
/// Degenerate, non-planar and non-convex faces and a scene with no emitter are not
/// errors: they end up in [`Scene::warnings`].
pub fn load_obj(path: &Path) -> Result<Scene, SceneError> {
    let mut warnings = Vec::new();
    let text = read_text(path, &mut warnings)?;
    let pre = prepass(path, &text)?;

    let (materials, mtl_texts) = load_materials(path, &pre, &mut warnings)?;

    let options = tobj::LoadOptions {
        triangulate: false,
        single_index: false,
        ignore_points: false,
        ignore_lines: false,
    };
    let (models, _) =
        tobj::load_obj_buf(
            &mut Cursor::new(text.as_bytes()),
            &options,
            |p| match mtl_texts.get(p) {
                Some(t) => tobj::load_mtl_buf(&mut Cursor::new(t.as_bytes())),
                None => Err(tobj::LoadError::OpenFileFailed),
            },
        )
        .map_err(|e| SceneError::Parser {
            path: path.to_owned(),
            message: e.to_string(),
        })?;

    let mut scene = Scene {
        source: path.display().to_string(),
        materials,
        ..Scene::default()
    };
    let mut tally = Tally::default();
    add_faces(path, &models, &pre, &mut scene, &mut tally)?;
    scene.warnings = warnings;
    finish(path, scene, &tally, "line")
}

fn load_materials(
    path: &Path,
    pre: &PrePass,
    warnings: &mut Vec<String>,
) -> Result<(Vec<Material>, HashMap<PathBuf, String>), SceneError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut mtl_texts: HashMap<PathBuf, String> = HashMap::new();
    let mut materials = Vec::new();
    for (lib, line) in &pre.mtllibs {
        let full = dir.join(lib);
        let mtl_text = read_text(&full, warnings).map_err(|e| match e {
            SceneError::Read { cause, .. } => SceneError::MissingMtl {
                path: path.to_owned(),
                line: *line,
                mtl: full.clone(),
                reason: cause.to_string(),
            },
            other => other,
        })?;
        materials.extend(parse_mtl(&full, &mtl_text, warnings)?);
        mtl_texts.insert(PathBuf::from(lib), mtl_text);
    }
    Ok((materials, mtl_texts))
}

/// The faces of tobj's `models` into `scene`, each named by its line in `pre`:
/// repaired or split where [`repair`] says so, in one group per model name; line
/// elements and repairs are noted in `tally`.
fn add_faces(
    path: &Path,
    models: &[tobj::Model],
    pre: &PrePass,
    scene: &mut Scene,
    tally: &mut Tally,
) -> Result<(), SceneError> {
    let mut group_ids: HashMap<String, u32> = HashMap::new();
    let mut k = 0usize; // global element counter, matches `pre.elements`
    for model in models {
        let mesh = &model.mesh;
        // tobj names faces before any `o`/`g` (or after a bare `g`) `unnamed_object`.
        let name = model.name.as_str();
        let arities: Vec<usize> = if mesh.face_arities.is_empty() {
            vec![3; mesh.indices.len() / 3]
        } else {
            mesh.face_arities.iter().map(|&a| a as usize).collect()
        };
        let mut start = 0usize;
        for a in arities {
            let idx = &mesh.indices[start..start + a];
            start += a;
            let Some(el) = pre.elements.get(k) else {
                return Err(mismatch(path));
            };
            k += 1;
            if !el.polygon {
                tally.lines.note(el.line);
                continue;
            }
            let material = match mesh.material_id {
                Some(m) if m < scene.materials.len() => m as u32,
                _ => return Err(material_error(path, pre, el)),
            };
            let corners: Vec<DVec3> = idx
                .iter()
                .map(|&i| {
                    let i = i as usize * 3;
                    DVec3::new(
                        mesh.positions[i],
                        mesh.positions[i + 1],
                        mesh.positions[i + 2],
                    )
                })
                .collect();
            let (parts, what) = repair(&corners);
            tally.note(what, el.line);
            if parts.is_empty() {
                continue;
            }
            let next = group_ids.len() as u32;
            let group = *group_ids.entry(name.to_owned()).or_insert_with(|| {
                scene.groups.push(name.to_owned());
                next
            });
            for corners in parts {
                scene.faces.push(Face {
                    corners,
                    group,
                    material,
                    line: el.line,
                });
            }
        }
    }
    if k != pre.elements.len() {
        return Err(mismatch(path));
    }
    Ok(())
}

fn mismatch(path: &Path) -> SceneError {
    SceneError::Parser {
        path: path.to_owned(),
        message: "face elements returned by the parser do not match the file's `f`/`l` lines"
            .into(),
    }
}

fn material_error(path: &Path, pre: &PrePass, el: &Element) -> SceneError {
    match el.usemtl {
        Some(u) => {
            let (name, line) = &pre.usemtl[u as usize];
            SceneError::MissingMaterial {
                path: path.to_owned(),
                line: *line,
                name: name.clone(),
            }
        }
        None => SceneError::NoMaterial {
            path: path.to_owned(),
            line: el.line,
        },
    }
}

/// The argument of `usemtl`/`mtllib`, taken exactly as tobj takes it (everything after
/// the first space, trimmed), so both agree on names with spaces in them.
fn argument(line: &str) -> &str {
    line.split_once(' ').map(|(_, r)| r.trim()).unwrap_or("")
}

fn prepass(path: &Path, text: &str) -> Result<PrePass, SceneError> {
    let mut pre = PrePass {
        elements: Vec::new(),
        usemtl: Vec::new(),
        mtllibs: Vec::new(),
    };
    let (mut nv, mut nt, mut nn) = (0usize, 0usize, 0usize);
    let mut current_mtl: Option<u32> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = (i + 1) as u32;
        let (kw, rest) = words(raw);
        let Some(kw) = kw else { continue };
        let malformed = |reason: String| SceneError::Malformed {
            path: path.to_owned(),
            line,
            keyword: kw.to_owned(),
            reason,
        };
        match kw {
            "v" => {
                check_vertex(&rest.collect::<Vec<_>>(), &malformed, path, line)?;
                nv += 1;
            }
            "vt" | "vn" => {
                let need = if kw == "vt" { 2 } else { 3 };
                let toks: Vec<&str> = rest.collect();
                if toks.len() < need || toks[..need].iter().any(|t| t.parse::<f64>().is_err()) {
                    return Err(malformed(format!("expected {need} numbers")));
                }
                if kw == "vt" {
                    nt += 1
                } else {
                    nn += 1
                }
            }
            "f" | "l" => {
                check_element(kw, rest, [nv, nt, nn], &malformed, path, line)?;
                pre.elements.push(Element {
                    line,
                    polygon: kw == "f",
                    usemtl: current_mtl,
                });
            }
            "usemtl" => {
                let name = argument(raw);
                if name.is_empty() {
                    return Err(malformed("missing material name".into()));
                }
                pre.usemtl.push((name.to_owned(), line));
                current_mtl = Some((pre.usemtl.len() - 1) as u32);
            }
            "mtllib" => {
                let lib = argument(raw);
                if lib.is_empty() {
                    return Err(malformed("missing file name".into()));
                }
                pre.mtllibs.push((lib.to_owned(), line));
            }
            _ => {}
        }
    }
    Ok(pre)
}

/// Checks a `v` statement's values (`toks`): 3 coordinates, plus a weight w or an
/// r g b colour; every coordinate a number no larger than [`MAX_COORDINATE`].
fn check_vertex(
    toks: &[&str],
    malformed: &dyn Fn(String) -> SceneError,
    path: &Path,
    line: u32,
) -> Result<(), SceneError> {
    if !matches!(toks.len(), 3 | 4 | 6) {
        return Err(malformed(format!(
            "expected 3 coordinates (plus an optional w or r g b), found {} values",
            toks.len()
        )));
    }
    let mut vals = [0.0f64; 6];
    for (j, t) in toks.iter().enumerate() {
        vals[j] = t
            .parse::<f64>()
            .map_err(|_| malformed(format!("`{t}` is not a number")))?;
    }
    for (j, t) in toks.iter().take(3).enumerate() {
        let x = if toks.len() == 4 {
            vals[j] / vals[3]
        } else {
            vals[j]
        };
        // Beyond 1e150 squares overflow: edge lengths and areas of the faces would be
        // infinite (and subdivision could not finish).
        if !x.is_finite() || x.abs() > MAX_COORDINATE {
            return Err(SceneError::NonFinite {
                path: path.to_owned(),
                line,
                value: (*t).to_owned(),
            });
        }
    }
    if toks.len() == 4 && (vals[3] == 0.0 || !vals[3].is_finite()) {
        return Err(malformed(format!("weight w = {} is not usable", toks[3])));
    }
    Ok(())
}

/// Checks an `f` or `l` statement (`kw`): every reference `v[/vt[/vn]]` an integer
/// index into the vertices, texture coordinates and normals defined so far
/// (`defined`, negative indices counting back), and enough of them.
fn check_element<'a>(
    kw: &str,
    refs: impl Iterator<Item = &'a str>,
    [nv, nt, nn]: [usize; 3],
    malformed: &dyn Fn(String) -> SceneError,
    path: &Path,
    line: u32,
) -> Result<(), SceneError> {
    let mut count = 0usize;
    for tok in refs {
        count += 1;
        let parts: Vec<&str> = tok.split('/').collect();
        if parts.len() > 3 || parts[0].is_empty() {
            return Err(malformed(format!("`{tok}` is not a vertex reference")));
        }
        let kinds = [(nv, "vertex"), (nt, "texture coordinate"), (nn, "normal")];
        for (part, (defined, what)) in parts.iter().zip(kinds) {
            if part.is_empty() {
                continue; // `v//vn`
            }
            let x: i64 = part
                .parse()
                .map_err(|_| malformed(format!("`{tok}`: `{part}` is not an integer index")))?;
            let ok = if x > 0 {
                (x as u64) <= defined as u64
            } else {
                x < 0 && x.unsigned_abs() <= defined as u64
            };
            if !ok {
                return Err(SceneError::IndexOutOfRange {
                    path: path.to_owned(),
                    line,
                    what,
                    index: x,
                    count: defined,
                });
            }
        }
    }
    let (least, what) = if kw == "f" { (3, "face") } else { (2, "line") };
    if kw == "f" && count > MAX_FACE_CORNERS {
        return Err(malformed(format!(
            "a face of {count} corners, more than the {MAX_FACE_CORNERS} a face may have: split it"
        )));
    }
    if count < least {
        return Err(malformed(format!(
            "a {what} needs at least {least} vertices, found {count}"
        )));
    }
    Ok(())
}
