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

/// Line numbers the checks of one material need.
#[derive(Clone, Default)]
struct MtlLines {
    newmtl: u32,
    kd: Option<u32>,
    ke: Option<u32>,
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

/// The materials of the `mtllib` statements of `pre`, in `mtllib` order, which is the
/// order tobj concatenates them in (its material ids index this concatenation), and
/// the text of each library, by the name the OBJ gives it.
/// The text of an OBJ or MTL file. A line that is not UTF-8 is kept as it is in a
/// comment (which nothing reads) and read as Latin-1 (ISO 8859-1) elsewhere, with a
/// warning naming the first such line; a byte that is no text in either (NUL, or a
/// C1 control 0x80-0x9F) is an error naming the line.
///
/// # Errors
/// [`SceneError::Read`] naming the file (and the line for bytes that are not text).
fn read_text(path: &Path, warnings: &mut Vec<String>) -> Result<String, SceneError> {
    let read_error = |cause| SceneError::Read {
        path: path.to_owned(),
        cause,
    };
    let bytes = crate::input::read(path).map_err(read_error)?;
    let bytes = match String::from_utf8(bytes) {
        Ok(text) => return Ok(plain(text)),
        Err(e) => e.into_bytes(),
    };
    let mut text = String::with_capacity(bytes.len());
    let mut first_latin1 = None;
    for (i, line) in bytes.split_inclusive(|&b| b == b'\n').enumerate() {
        match std::str::from_utf8(line) {
            Ok(s) => text.push_str(s),
            Err(_) if line.trim_ascii_start().starts_with(b"#") => {
                text.push_str(&String::from_utf8_lossy(line));
            }
            Err(_) => {
                if let Some(b) = line.iter().find(|&&b| b == 0 || (0x80..0xa0).contains(&b)) {
                    return Err(read_error(std::io::Error::new(
                        std::io::ErrorKind::InvalidData,
                        format!(
                            "line {}: byte {b:#04x} is neither UTF-8 nor Latin-1 text",
                            i + 1
                        ),
                    )));
                }
                first_latin1.get_or_insert(i + 1);
                text.extend(line.iter().map(|&b| char::from(b)));
            }
        }
    }
    if let Some(line) = first_latin1 {
        warnings.push(format!(
            "{}: line {line} is not UTF-8: read as Latin-1 (ISO 8859-1)",
            path.display()
        ));
    }
    Ok(plain(text))
}

/// The text as both parsers (ours and tobj's) read it: without a UTF-8 byte-order mark
/// (which made the first statement, `mtllib` or `newmtl`, an unknown keyword), and with
/// the white space after a line's keyword a single space (tobj takes the argument of
/// `mtllib`, `usemtl` and `newmtl` after the first space, so `mtllib<TAB>a.mtl` named
/// no file). Line numbers are unchanged.
fn plain(text: String) -> String {
    let text = match text.strip_prefix('\u{feff}') {
        Some(t) => t.to_owned(),
        None => text,
    };
    if !text.contains('\t') {
        return text;
    }
    let mut out = String::with_capacity(text.len());
    for line in text.split_inclusive('\n') {
        let body = line.trim_start();
        let lead = &line[..line.len() - body.len()];
        match body.find(char::is_whitespace) {
            Some(k) if body[k..].starts_with('\t') => {
                let rest = body[k..].trim_start_matches([' ', '\t']);
                out.push_str(lead);
                out.push_str(&body[..k]);
                out.push(' ');
                out.push_str(rest);
            }
            _ => out.push_str(line),
        }
    }
    out
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

/// The materials of an MTL file, read (see [`read_text`]) and checked.
///
/// # Errors
/// As [`parse_mtl`], and [`SceneError::Read`] when the file cannot be read.
pub(super) fn read_mtl(
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<Vec<Material>, SceneError> {
    let text = read_text(path, warnings)?;
    parse_mtl(path, &text, warnings)
}

/// The materials of the MTL text `text` (from `path`), in file order: each `Kd` in
/// [0, 1), each `Ke` finite and >= 0, errors naming the line.
fn parse_mtl(
    path: &Path,
    text: &str,
    warnings: &mut Vec<String>,
) -> Result<Vec<Material>, SceneError> {
    let lines = mtl_prepass(path, text)?;
    let (mats, _) =
        tobj::load_mtl_buf(&mut Cursor::new(text.as_bytes())).map_err(|e| SceneError::Parser {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
    mats.iter()
        .map(|m| {
            let at = lines.get(&m.name).cloned().unwrap_or_default();
            convert_material(path, m, &at, warnings)
        })
        .collect()
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

/// The statement keyword of a line, and the rest split on whitespace (as tobj does).
fn words(line: &str) -> (Option<&str>, std::str::SplitWhitespace<'_>) {
    let mut w = line.split_whitespace();
    (w.next(), w)
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

/// Check the colour statements of an MTL file (tobj panics on a `Kd` with fewer than 3
/// values) and record the lines each material's checks will name.
fn mtl_prepass(path: &Path, text: &str) -> Result<HashMap<String, MtlLines>, SceneError> {
    let mut out: HashMap<String, MtlLines> = HashMap::new();
    let mut current: Option<String> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = (i + 1) as u32;
        let trimmed = raw.trim();
        let (kw, rest) = words(trimmed);
        let Some(kw) = kw else { continue };
        let malformed = |reason: String| SceneError::Malformed {
            path: path.to_owned(),
            line,
            keyword: kw.to_owned(),
            reason,
        };
        match kw {
            "newmtl" => {
                // tobj: everything after the keyword, trimmed.
                let name = trimmed.get(6..).unwrap_or("").trim();
                if name.is_empty() {
                    return Err(malformed("missing material name".into()));
                }
                out.insert(
                    name.to_owned(),
                    MtlLines {
                        newmtl: line,
                        ..MtlLines::default()
                    },
                );
                current = Some(name.to_owned());
            }
            "Ka" | "Kd" | "Ks" | "Ke" => {
                let toks: Vec<&str> = rest.collect();
                if toks.len() < 3 || toks[..3].iter().any(|t| t.parse::<f64>().is_err()) {
                    return Err(malformed("expected 3 numbers (r g b)".into()));
                }
                if let Some(m) = current.as_ref().and_then(|c| out.get_mut(c)) {
                    match kw {
                        "Kd" => m.kd = Some(line),
                        "Ke" => m.ke = Some(line),
                        _ => {}
                    }
                }
            }
            _ => {}
        }
    }
    Ok(out)
}

/// Turn a tobj material into ours, enforcing docs/numerics.md §3: `Kd` in [0, 1), `Ke` >= 0.
fn convert_material(
    mtl: &Path,
    m: &tobj::Material,
    lines: &MtlLines,
    warnings: &mut Vec<String>,
) -> Result<Material, SceneError> {
    let kd = match m.diffuse {
        Some(kd) => kd,
        None => {
            warnings.push(format!(
                "{}:{}: material `{}` has no Kd: reflectance 0",
                mtl.display(),
                lines.newmtl,
                m.name
            ));
            [0.0; 3]
        }
    };
    // tobj 4.0 reads `Ke` into `emissive`; older versions left it in `unknown_param`.
    let ke = match (m.emissive, m.unknown_param.get("Ke")) {
        (Some(ke), _) => ke,
        (None, Some(s)) => {
            let v: Vec<f64> = s
                .split_whitespace()
                .filter_map(|t| t.parse().ok())
                .collect();
            if v.len() < 3 {
                return Err(SceneError::Malformed {
                    path: mtl.to_owned(),
                    line: lines.ke.unwrap_or(lines.newmtl),
                    keyword: "Ke".into(),
                    reason: "expected 3 numbers (r g b)".into(),
                });
            }
            [v[0], v[1], v[2]]
        }
        (None, None) => [0.0; 3],
    };
    let mut rho = [0.0f32; 3];
    let mut emission = [0.0f32; 3];
    for c in 0..3 {
        rho[c] = kd[c] as f32;
        // Checked after the cast too: 0.99999999 is < 1 but rounds to 1.0f32.
        if !((0.0..1.0).contains(&kd[c]) && rho[c] < 1.0) {
            return Err(SceneError::Reflectance {
                path: mtl.to_owned(),
                line: lines.kd.unwrap_or(lines.newmtl),
                material: m.name.clone(),
                value: kd[c],
            });
        }
        emission[c] = ke[c] as f32;
        if !(ke[c] >= 0.0 && emission[c].is_finite()) {
            return Err(SceneError::Emission {
                path: mtl.to_owned(),
                line: lines.ke.unwrap_or(lines.newmtl),
                material: m.name.clone(),
                value: ke[c],
            });
        }
    }
    Ok(Material {
        name: m.name.clone(),
        rho,
        emission,
    })
}
