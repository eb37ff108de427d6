//! Loading a scene from PLY (ASCII or binary, either byte order), parsed by `ply-rs-bw`.
//!
//! The `vertex` element's `x`, `y`, `z` (any numeric type) are the positions; each
//! entry of the `face` element's `vertex_indices` (or `vertex_index`) list is a polygon,
//! repaired as OBJ faces are (triangles and planar convex quads kept, other polygons
//! split, degenerate ones dropped). Other elements and properties (normals, colours,
//! `edge`) are ignored. The whole file is one group named after it; materials come from
//! the materials file beside it ([`super::mesh::materials_file`]).

use std::path::Path;

use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};

use super::mesh::{check_point, one_line, Assembler};
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
    let file = std::fs::File::open(path).map_err(|cause| SceneError::Read {
        path: path.to_owned(),
        cause,
    })?;
    let err = |element: &str, reason: String| SceneError::Element {
        path: path.to_owned(),
        element: element.to_owned(),
        reason,
    };
    let mut reader = std::io::BufReader::new(file);
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| err("file", format!("not readable as PLY: {}", one_line(e))))?;
    let vertices = ply.payload.get("vertex").map(Vec::as_slice).unwrap_or(&[]);
    let faces = ply.payload.get("face").ok_or_else(|| {
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
