//! Loading a scene from PLY (ASCII or binary, either byte order), parsed by `ply-rs-bw`.
//!
//! The `vertex` element's `x`, `y`, `z` (any numeric type) are the positions; each
//! entry of the `face` element's `vertex_indices` (or `vertex_index`) list is a polygon,
//! repaired as OBJ faces are (triangles and planar convex quads kept, other polygons
//! split, degenerate ones dropped). Other elements and properties (normals, colours,
//! `edge`) are ignored. The whole file is one group named after it; materials come from
//! the materials file beside it ([`super::mesh::materials_file`]).

use std::path::Path;

use std::io::BufRead;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, Encoding, Header, Payload, Property};

use super::mesh::{check_point, one_line, Assembler};
use super::polygon::MAX_FACE_CORNERS;
use super::{Scene, SceneError};

const UNIT: &str = "face";

/// Load a PLY file.
///
/// # Errors
/// [`SceneError::Read`] when the file cannot be read; [`SceneError::Element`] for a
/// header or body the parser refuses (truncated, wrong counts), a missing `x`/`y`/`z`
/// or index list, an index out of range (naming the face) or a coordinate that is not
/// finite (naming the vertex's first face); as [`Assembler::new`] for a bad materials
/// file; [`SceneError::Empty`] when no face is usable.
pub(super) fn load_ply(path: &Path) -> Result<Scene, SceneError> {
    let file = crate::input::open(path).map_err(|cause| SceneError::Read {
        path: path.to_owned(),
        cause,
    })?;
    let err = |element: &str, reason: String| SceneError::Element {
        path: path.to_owned(),
        element: element.to_owned(),
        reason,
    };
    let unreadable = |e| err("file", format!("not readable as PLY: {}", one_line(e)));
    let parser = Parser::<DefaultElement>::new();
    let mut reader = Reader::new(std::io::BufReader::new(file));
    let header = parser.read_header(&mut reader).map_err(unreadable)?;
    let payload = match header.encoding {
        Encoding::Ascii => {
            let first = reader.line();
            ascii_payload(path, &parser, reader.get_mut(), &header, first)?
        }
        _ => {
            let payload = parser
                .read_payload(&mut reader, &header)
                .map_err(unreadable)?;
            nothing_after(path, reader.get_mut(), &header, None)?;
            payload
        }
    };
    let vertices = payload.get("vertex").map(Vec::as_slice).unwrap_or(&[]);
    let faces = payload.get("face").ok_or_else(|| {
        err(
            "header",
            "no `face` element: a PLY point cloud has no surfaces".into(),
        )
    })?;

    let mut positions = Vec::with_capacity(vertices.len());
    for (k, v) in vertices.iter().enumerate() {
        let mut p = [0.0f64; 3];
        for (c, name) in ["x", "y", "z"].iter().enumerate() {
            p[c] = v.get(*name).and_then(scalar).ok_or_else(|| {
                err(
                    &format!("vertex {}", k + 1),
                    format!("no numeric `{name}` property"),
                )
            })?;
        }
        positions.push(p);
    }

    let mut out = Assembler::new(path, UNIT)?;
    let group = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "ply".into());
    let material = out.material_for(&group, None);
    for (k, f) in faces.iter().enumerate() {
        let at = (k + 1) as u32;
        let here = format!("{UNIT} {at}");
        let list = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(indices)
            .ok_or_else(|| err(&here, "no integer `vertex_indices` list".into()))?;
        if list.len() > MAX_FACE_CORNERS {
            return Err(err(
                &here,
                format!(
                    "a face of {} corners, more than the {MAX_FACE_CORNERS} a face may have: split it",
                    list.len()
                ),
            ));
        }
        if list.len() < 3 {
            return Err(err(
                &here,
                format!("a face needs at least 3 vertices, found {}", list.len()),
            ));
        }
        let mut corners = Vec::with_capacity(list.len());
        for &i in &list {
            let p = usize::try_from(i)
                .ok()
                .and_then(|i| positions.get(i))
                .ok_or_else(|| {
                    err(
                        &here,
                        format!(
                            "vertex index {i} out of range ({} vertices, numbered from 0)",
                            positions.len()
                        ),
                    )
                })?;
            corners.push(check_point(path, UNIT, at, *p)?);
        }
        out.polygon(&group, material, at, &corners);
    }
    out.finish()
}

/// The elements of an ASCII body, one line each from line `first` on, as the header
/// declares them; then nothing but white space. Read here rather than by the parser's
/// own loop, which ignored values beyond a line's properties and anything after the
/// declared counts (a face count one short lost the last face without a word).
///
/// # Errors
/// [`SceneError::Element`] naming the line: a line the parser refuses, one with more
/// values than its element's properties, the file ending early, data after the last
/// element.
fn ascii_payload(
    path: &Path,
    parser: &Parser<DefaultElement>,
    reader: &mut impl BufRead,
    header: &Header,
    first: usize,
) -> Result<Payload<DefaultElement>, SceneError> {
    let at = |line: usize, reason: String| SceneError::Element {
        path: path.to_owned(),
        element: format!("line {line}"),
        reason,
    };
    let mut payload = Payload::new();
    let mut line = first;
    let mut text = String::new();
    for (name, def) in &header.elements {
        let mut elements = Vec::with_capacity(def.count.min(1 << 20));
        for k in 0..def.count {
            text.clear();
            let read = reader
                .read_line(&mut text)
                .map_err(|e| at(line, format!("cannot read: {e}")))?;
            if read == 0 {
                return Err(at(
                    line,
                    format!(
                        "the file ends after {k} of the header's {} `{name}` elements",
                        def.count
                    ),
                ));
            }
            let e = parser
                .read_ascii_element(&text, def)
                .map_err(|e| at(line, format!("`{name}` element: {}", one_line(e))))?;
            let want: usize = def
                .properties
                .keys()
                .map(|p| e.get(p).map_or(1, values))
                .sum();
            let found = text.split_whitespace().count();
            if found != want {
                return Err(at(
                    line,
                    format!(
                        "{found} values, but a `{name}` element here has {want} (its properties as the header declares them)"
                    ),
                ));
            }
            elements.push(e);
            line += 1;
        }
        payload.insert(name.clone(), elements);
    }
    nothing_after(path, reader, header, Some(line))?;
    Ok(payload)
}

/// Refuse anything but white space after the declared elements: a header whose counts
/// are short (ASCII: naming the `line`; binary: the bytes left).
fn nothing_after(
    path: &Path,
    reader: &mut impl BufRead,
    header: &Header,
    line: Option<usize>,
) -> Result<(), SceneError> {
    let mut rest = Vec::new();
    std::io::Read::read_to_end(reader, &mut rest).map_err(|cause| SceneError::Read {
        path: path.to_owned(),
        cause,
    })?;
    let Some(start) = rest.iter().position(|b| !b.is_ascii_whitespace()) else {
        return Ok(());
    };
    let counts: Vec<String> = header
        .elements
        .iter()
        .map(|(n, d)| format!("{} `{n}`", d.count))
        .collect();
    let (element, what) = match line {
        Some(l) => (
            format!(
                "line {}",
                l + rest[..start].iter().filter(|&&b| b == b'\n').count()
            ),
            "data".to_string(),
        ),
        None => ("file".to_string(), format!("{} bytes", rest.len())),
    };
    Err(SceneError::Element {
        path: path.to_owned(),
        element,
        reason: format!(
            "{what} after the last element the header declares ({}): its counts are short",
            counts.join(", ")
        ),
    })
}

/// How many values a parsed property took on its line: 1 for a scalar, the count and
/// the items for a list.
fn values(p: &Property) -> usize {
    match p {
        Property::ListChar(v) => 1 + v.len(),
        Property::ListUChar(v) => 1 + v.len(),
        Property::ListShort(v) => 1 + v.len(),
        Property::ListUShort(v) => 1 + v.len(),
        Property::ListInt(v) => 1 + v.len(),
        Property::ListUInt(v) => 1 + v.len(),
        Property::ListFloat(v) => 1 + v.len(),
        Property::ListDouble(v) => 1 + v.len(),
        _ => 1,
    }
}

/// A numeric scalar property as f64.
fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(x) => x.into(),
        Property::UChar(x) => x.into(),
        Property::Short(x) => x.into(),
        Property::UShort(x) => x.into(),
        Property::Int(x) => x.into(),
        Property::UInt(x) => x.into(),
        Property::Float(x) => x.into(),
        Property::Double(x) => x,
        _ => return None,
    })
}

/// An integer list property as i64.
fn indices(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x.into()).collect(),
        _ => return None,
    })
}
