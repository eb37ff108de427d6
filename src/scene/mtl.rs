//! Reading an MTL materials file (for OBJ, and beside an STL, PLY or glTF mesh): the
//! text read as UTF-8 or Latin-1 ([`read_text`], which the OBJ reader shares), a
//! pre-pass that checks the colour statements, then `tobj`'s parse turned into
//! [`Material`]s with `Kd` in [0, 1) and `Ke` >= 0 (docs/numerics.md §3).

use std::collections::HashMap;
use std::io::Cursor;
use std::path::Path;

use super::{Material, SceneError};

/// Line numbers the checks of one material need.
#[derive(Clone, Default)]
struct MtlLines {
    newmtl: u32,
    kd: Option<u32>,
    ke: Option<u32>,
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
pub(super) fn read_text(path: &Path, warnings: &mut Vec<String>) -> Result<String, SceneError> {
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
pub(super) fn parse_mtl(
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

/// The statement keyword of a line, and the rest split on whitespace (as tobj does).
pub(super) fn words(line: &str) -> (Option<&str>, std::str::SplitWhitespace<'_>) {
    let mut w = line.split_whitespace();
    (w.next(), w)
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
