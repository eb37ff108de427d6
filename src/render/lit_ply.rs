//! The lit scene as a PLY mesh with per-vertex colours, for any mesh viewer (MeshLab,
//! Blender, ParaView).
//!
//! The mesh is what the picture shows: the vertices and colours of Gouraud shading
//! ([`super::shading::smooth_vertices`]: corners welded within a group and across
//! gentle creases, each vertex the area-weighted average radiosity of the patches
//! around it), and the tone map of the PNG ([`super::tonemap`]: the automatic exposure
//! of [`auto_exposure`], or a given one, then clamping, the sRGB transfer function and
//! 8-bit quantisation). Faces are the patches, as triangles or quads, corners in the
//! patch's counter-clockwise order; a patch whose corners weld together (degenerate)
//! is left out.

use std::io::{BufWriter, Write};
use std::path::Path;

use super::shading::smooth_vertices;
use super::tonemap::{auto_exposure, quantise, srgb_encode};
use super::RenderError;
use crate::patch::PatchSet;

/// PLY body encoding.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlyEncoding {
    Ascii,
    #[default]
    BinaryLittleEndian,
}

/// How to write the PLY file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyOptions {
    pub encoding: PlyEncoding,
    /// Linear radiosity is multiplied by this before the sRGB encoding; `None`: the
    /// automatic exposure of the PNG ([`auto_exposure`]).
    pub exposure: Option<f32>,
}

/// Writes the lit mesh as a binary PLY with the automatic exposure.
///
/// # Errors
/// As [`write_ply_with`].
pub fn write_ply(
    path: &Path,
    patches: &PatchSet,
    radiosity: &[[f32; 3]],
) -> Result<(), RenderError> {
    write_ply_with(path, patches, radiosity, &PlyOptions::default()).map(|_| ())
}

/// Writes the lit mesh as PLY with the given options; returns the exposure used.
///
/// # Errors
/// [`RenderError::RadiosityLength`] when `radiosity` does not have one value per
/// patch, [`RenderError::InvalidOptions`] for an exposure that is not a positive
/// number, [`RenderError::Io`] naming the file.
pub fn write_ply_with(
    path: &Path,
    patches: &PatchSet,
    radiosity: &[[f32; 3]],
    opts: &PlyOptions,
) -> Result<f32, RenderError> {
    if radiosity.len() != patches.len() {
        return Err(RenderError::RadiosityLength {
            expected: patches.len(),
            got: radiosity.len(),
        });
    }
    let exposure = match opts.exposure {
        Some(x) if x.is_finite() && x > 0.0 => x,
        Some(x) => {
            return Err(RenderError::InvalidOptions(format!(
                "PLY exposure {x} must be a positive number"
            )))
        }
        None => auto_exposure(patches, radiosity),
    };
    let mesh = smooth_vertices(patches, radiosity);
    let faces: Vec<Vec<u32>> = patches
        .patches
        .iter()
        .zip(&mesh.corner_vertex)
        .filter_map(|(p, ids)| {
            let mut face: Vec<u32> = Vec::with_capacity(4);
            for &id in &ids[..p.n_corners as usize] {
                if !face.contains(&id) {
                    face.push(id);
                }
            }
            (face.len() >= 3).then_some(face)
        })
        .collect();
    let io = |cause| RenderError::Io {
        path: path.to_path_buf(),
        cause,
    };
    let file = std::fs::File::create(path).map_err(io)?;
    let mut w = BufWriter::new(file);
    let format = match opts.encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
    };
    write!(
        w,
        "ply\nformat {format} 1.0\n\
         comment ffstream radiosity: per-vertex area-weighted B, linear x {exposure} then sRGB\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        faces.len()
    )
    .map_err(io)?;
    for (p, b) in mesh.positions.iter().zip(&mesh.colours) {
        let rgb = b.map(|x| quantise(srgb_encode(x * exposure)));
        match opts.encoding {
            PlyEncoding::Ascii => writeln!(
                w,
                "{} {} {} {} {} {}",
                p.x as f32, p.y as f32, p.z as f32, rgb[0], rgb[1], rgb[2]
            )
            .map_err(io)?,
            PlyEncoding::BinaryLittleEndian => {
                for x in [p.x, p.y, p.z] {
                    w.write_all(&(x as f32).to_le_bytes()).map_err(io)?;
                }
                w.write_all(&rgb).map_err(io)?;
            }
        }
    }
    for f in &faces {
        match opts.encoding {
            PlyEncoding::Ascii => {
                let ids: Vec<String> = f.iter().map(|i| i.to_string()).collect();
                writeln!(w, "{} {}", f.len(), ids.join(" ")).map_err(io)?;
            }
            PlyEncoding::BinaryLittleEndian => {
                w.write_all(&[f.len() as u8]).map_err(io)?;
                for &i in f {
                    w.write_all(&(i as i32).to_le_bytes()).map_err(io)?;
                }
            }
        }
    }
    w.flush().map_err(io)?;
    Ok(exposure)
}
