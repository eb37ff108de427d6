//! Loading a scene from STL, ASCII or binary, parsed by `stl_io`.
//!
//! Each facet is a face; its front is the side its corners run counter-clockwise
//! around (the stored facet normal is ignored, as most tools recompute it). Facets are
//! not welded: a face needs only its own corners. Groups: each `solid NAME ...
//! endsolid` block of an ASCII file is a group (OpenFOAM and uDALES write one solid per
//! boundary patch); a binary file is one group named after the file. Materials come from
//! the materials file beside it ([`super::mesh::materials_file`]).
//!
//! Which kind a file is: binary when its size is exactly 84 + 50 × (the facet count in
//! bytes 80..84), whatever its header says (some exporters start binary headers with
//! `solid`); else ASCII when it starts with `solid` in any case, after an optional
//! UTF-8 byte-order mark (keywords are read in any case); else an error for UTF-16
//! text; else binary, and then the size is checked against the count before anything
//! is parsed.

use std::io::Cursor;
use std::path::Path;

use super::mesh::{check_point, one_line, Assembler};
use super::{Scene, SceneError};

const UNIT: &str = "facet";

/// Load an STL file (ASCII or binary).
///
/// # Errors
/// [`SceneError::Read`] when the file cannot be read; [`SceneError::Element`] naming the
/// facet for a truncated or malformed file, a facet count that disagrees with the
/// size, or a coordinate that is not finite; as [`Assembler::new`] for a bad
/// materials file; [`SceneError::Empty`] when no facet is usable.
pub(super) fn load_stl(path: &Path) -> Result<Scene, SceneError> {
    let mut bytes = crate::input::read(path).map_err(|cause| SceneError::Read {
        path: path.to_owned(),
        cause,
    })?;
    let mut out = Assembler::new(path, UNIT)?;
    let stem = file_stem(path);
    let declared = (bytes.len() >= 84)
        .then(|| u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64);
    let binary_size = declared.map(|n| 84 + 50 * n);
    let sized_as_binary = binary_size == Some(bytes.len() as u64);
    if !sized_as_binary && utf16(&bytes) {
        return Err(element(
            path,
            "file",
            "UTF-16 text: an ASCII STL is read as ASCII (UTF-8); save it as UTF-8 or as a binary STL".into(),
        ));
    }
    let ascii = !sized_as_binary && starts_with_solid(&bytes);
    if ascii {
        let text = String::from_utf8_lossy(&bytes);
        let text = text.trim_start_matches('\u{feff}');
        let mut first = 1u32;
        let blocks =
            solids(text).map_err(|(line, what)| element(path, &format!("line {line}"), what))?;
        for (name, block, line) in blocks {
            let name = if name.is_empty() { stem.clone() } else { name };
            first = read_block(path, &mut out, &name, &block, first, line)?;
        }
    } else {
        let Some(n) = declared else {
            return Err(element(
                path,
                "header",
                format!(
                    "{} bytes: a binary STL needs at least 84 (80-byte header, facet count), an ASCII STL starts with `solid`",
                    bytes.len()
                ),
            ));
        };
        let need = 84 + 50 * n;
        let have = bytes.len() as u64;
        if have < need {
            return Err(element(
                path,
                &format!("{UNIT} {}", (have.saturating_sub(84)) / 50 + 1),
                format!(
                    "truncated binary STL: the header says {n} facets ({need} bytes), the file has {have} bytes"
                ),
            ));
        }
        if have > need {
            out.warn(format!(
                "{}: {} bytes after the {n} facets the header declares: ignored",
                path.display(),
                have - need
            ));
        }
        // The ASCII probe of stl_io would take a header starting with `solid ` for
        // text; the header carries no data, so blank it.
        bytes[..80].fill(b' ');
        bytes.truncate(need as usize);
        let material = out.material_for(&stem, None);
        read_triangles(path, &mut out, &stem, material, &bytes, 1, None)?;
    }
    out.finish()
}

/// True when `bytes` begin, after an optional UTF-8 byte-order mark and white space,
/// with `solid` in any case (`SOLID` is written by some CAD exporters): an ASCII STL,
/// unless the size says binary (decided first, by the caller).
fn starts_with_solid(bytes: &[u8]) -> bool {
    let b = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
    b.trim_ascii_start()
        .get(..5)
        .is_some_and(|w| w.eq_ignore_ascii_case(b"solid"))
}

/// True when `bytes` look like UTF-16 text: a byte-order mark, or `s` / `S` next to a
/// zero byte at the start.
fn utf16(bytes: &[u8]) -> bool {
    match bytes {
        [0xff, 0xfe, ..] | [0xfe, 0xff, ..] => true,
        [a, 0, ..] | [0, a, ..] => a.eq_ignore_ascii_case(&b's'),
        _ => false,
    }
}

/// The file name without its extension: the group of a binary STL or an unnamed solid.
fn file_stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "stl".into())
}

fn element(path: &Path, element: &str, reason: String) -> SceneError {
    SceneError::Element {
        path: path.to_owned(),
        element: element.to_owned(),
        reason,
    }
}

/// One `solid NAME ... endsolid` block: (name, the block as stl_io reads it, 1-based
/// line of its `solid`).
type Solid = (String, String, u32);

/// The `solid NAME ... endsolid` blocks of an ASCII STL.
///
/// # Errors
/// The line and what is wrong when anything but white space lies outside every
/// block: facets after the last `endsolid` were dropped without a word.
fn solids(text: &str) -> Result<Vec<Solid>, (u32, String)> {
    let mut out = Vec::new();
    let mut current: Option<Solid> = None;
    let mut closed = None;
    for (i, raw) in text.lines().enumerate() {
        let t = raw.trim();
        // Keywords in any case (`SOLID`, `FACET NORMAL`): stl_io reads lower case.
        let lower = t.to_ascii_lowercase();
        if let Some(rest) = lower.strip_prefix("endsolid") {
            if rest.is_empty() || rest.starts_with(char::is_whitespace) {
                if let Some((name, mut block, line)) = current.take() {
                    block.push_str("endsolid\n");
                    out.push((name, block, line));
                    closed = Some(i + 1);
                }
                continue;
            }
        }
        if let Some(rest) = lower.strip_prefix("solid") {
            if current.is_none() && (rest.is_empty() || rest.starts_with(char::is_whitespace)) {
                // The name as written (`solid` is five ASCII bytes in any case).
                let name = t[5..].trim().to_owned();
                // stl_io wants `solid ` with a space and a name.
                current = Some((name, "solid s\n".to_owned(), (i + 1) as u32));
                continue;
            }
        }
        match current.as_mut() {
            Some((_, block, _)) => {
                block.push_str(&lower);
                block.push('\n');
            }
            None if t.is_empty() => {}
            None => {
                let after = closed.map_or(String::new(), |l| {
                    format!(" (the last one ended at line {l})")
                });
                return Err((
                    (i + 1) as u32,
                    format!(
                        "`{}` outside any `solid ... endsolid` block{after}",
                        cut(t, 60)
                    ),
                ));
            }
        }
    }
    // A last solid without `endsolid` is read as far as it goes.
    out.extend(current);
    Ok(out)
}

/// The first `max` characters of `s`, with `...` when it was longer.
fn cut(s: &str, max: usize) -> String {
    match s.char_indices().nth(max) {
        Some((at, _)) => format!("{}...", &s[..at]),
        None => s.to_string(),
    }
}

/// Read one ASCII solid into group `name`; its facets are numbered from `first`.
/// Returns the number of the next facet.
fn read_block(
    path: &Path,
    out: &mut Assembler<'_>,
    name: &str,
    block: &str,
    first: u32,
    line: u32,
) -> Result<u32, SceneError> {
    let material = out.material_for(name, None);
    read_triangles(
        path,
        out,
        name,
        material,
        block.as_bytes(),
        first,
        Some(line),
    )
}

/// Read the facets stl_io finds in `bytes` (one ASCII solid or a whole binary file)
/// into `group`, numbering them from `first`; returns the next number.
fn read_triangles(
    path: &Path,
    out: &mut Assembler<'_>,
    group: &str,
    material: u32,
    bytes: &[u8],
    first: u32,
    solid_line: Option<u32>,
) -> Result<u32, SceneError> {
    let mut cursor = Cursor::new(bytes);
    let where_ = |k: u32| match solid_line {
        Some(l) => format!("{UNIT} {k} (solid `{group}` of line {l})"),
        None => format!("{UNIT} {k}"),
    };
    let reader = stl_io::create_stl_reader(&mut cursor).map_err(|e| {
        element(
            path,
            &where_(first),
            format!("not readable as STL: {}", one_line(e)),
        )
    })?;
    let mut k = first;
    for t in reader {
        let t = t.map_err(|e| {
            element(
                path,
                &where_(k),
                format!("malformed facet: {}", one_line(e)),
            )
        })?;
        let mut corners = Vec::with_capacity(3);
        for v in t.vertices {
            let p = v.0.map(f64::from);
            corners.push(check_point(path, UNIT, k, p)?);
        }
        out.polygon(group, material, k, &corners);
        k += 1;
    }
    Ok(k)
}
