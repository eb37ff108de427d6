//! The lit scene as a PLY mesh with per-vertex colours, for any mesh viewer.
//!
//! Vertices. Patch corners are welded by position: two corners closer than
//! 1e-7 × the scene's bounding-box diagonal become one vertex (a hash of positions
//! quantised to that step, searching the 27 neighbouring cells so that points on either
//! side of a cell boundary still meet). Faces are the patches, as triangles or quads,
//! corners in the patch's counter-clockwise order; a patch whose corners weld together
//! (degenerate) is left out.
//!
//! Colours. Each vertex gets the area-weighted average radiosity of the patches that
//! touch it, Σ A_p B_p / Σ A_p (a smooth Gouraud look; across a crease this mixes the
//! two sides, like any shared-vertex mesh). Tone mapping to 8 bits: linear scaling by a
//! white point W, clamping to [0, 1], then the sRGB transfer function (IEC 61966-2-1:
//! 12.92 x below 0.0031308, else 1.055 x^(1/2.4) − 0.055), rounded to 0..255. W is
//! given ([`PlyOptions::white`]) or robust: the area-weighted 97th percentile of the
//! patches' brightest channel, so that a small light source saturates instead of
//! darkening the whole scene.

use std::collections::HashMap;
use std::io::{BufWriter, Write};
use std::path::Path;

use glam::DVec3;

use crate::patch::PatchSet;

use super::error::SolveError;

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
    /// Radiosity that maps to full white; `None`: the robust maximum (module docs).
    pub white: Option<f64>,
}

/// The tone mapping of the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToneMap {
    pub white: f64,
}

impl ToneMap {
    /// White point from the radiosities: area-weighted 97th percentile of each patch's
    /// brightest channel; falls back to the maximum, then to 1, when that is not positive.
    pub(crate) fn robust(patches: &PatchSet, radiosity: &[[f64; 3]]) -> Self {
        let mut v: Vec<(f64, f64)> = patches
            .patches
            .iter()
            .zip(radiosity)
            .map(|(p, b)| (b.iter().copied().fold(0.0, f64::max), p.area))
            .filter(|(x, a)| x.is_finite() && a.is_finite() && *a > 0.0)
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let total: f64 = v.iter().map(|x| x.1).sum();
        let mut acc = 0.0;
        let mut white = 0.0;
        for &(x, a) in &v {
            acc += a;
            white = x;
            if acc >= 0.97 * total {
                break;
            }
        }
        if white <= 0.0 {
            white = v.last().map_or(0.0, |x| x.0);
        }
        ToneMap {
            white: if white > 0.0 { white } else { 1.0 },
        }
    }

    /// One channel to 8 bits.
    pub(crate) fn map(&self, x: f64) -> u8 {
        let v = if x.is_finite() {
            (x / self.white).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (srgb_encode(v) * 255.0).round() as u8
    }
}

/// sRGB transfer function (IEC 61966-2-1), linear [0, 1] → encoded [0, 1].
pub fn srgb_encode(v: f64) -> f64 {
    if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Welded vertices with their area-weighted radiosity, and faces indexing them.
#[derive(Clone, Debug, PartialEq)]
pub struct VertexMesh {
    pub(crate) positions: Vec<DVec3>,
    pub(crate) radiosity: Vec<[f64; 3]>,
    /// Per patch kept: its vertex indices (3 or 4).
    pub(crate) faces: Vec<Vec<u32>>,
}

/// Weld the patch corners and average the radiosity at each vertex (module docs).
pub fn vertex_radiosity(patches: &PatchSet, radiosity: &[[f64; 3]]) -> VertexMesh {
    let (lo, hi) = patches.bounds().unwrap_or((DVec3::ZERO, DVec3::ZERO));
    let diag = (hi - lo).length();
    let step = if diag > 0.0 { diag * 1e-7 } else { 1.0 };
    let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut positions: Vec<DVec3> = Vec::new();
    let mut sum: Vec<[f64; 3]> = Vec::new();
    let mut weight: Vec<f64> = Vec::new();
    let mut faces = Vec::with_capacity(patches.len());
    for (p, b) in patches.patches.iter().zip(radiosity) {
        let mut face: Vec<u32> = Vec::with_capacity(4);
        for &c in p.corners() {
            let q = (c - lo) / step;
            let key = [q.x.floor() as i64, q.y.floor() as i64, q.z.floor() as i64];
            let found = neighbours(key).find_map(|k| {
                cells.get(&k).and_then(|ids| {
                    ids.iter()
                        .copied()
                        .find(|&id| (positions[id as usize] - c).length() <= step)
                })
            });
            let id = found.unwrap_or_else(|| {
                let id = positions.len() as u32;
                positions.push(c);
                sum.push([0.0; 3]);
                weight.push(0.0);
                cells.entry(key).or_default().push(id);
                id
            });
            if !face.contains(&id) {
                face.push(id);
            }
        }
        if face.len() < 3 {
            continue;
        }
        for &id in &face {
            for (s, x) in sum[id as usize].iter_mut().zip(b) {
                *s += p.area * x;
            }
            weight[id as usize] += p.area;
        }
        faces.push(face);
    }
    let radiosity = sum
        .iter()
        .zip(&weight)
        .map(|(s, &w)| if w > 0.0 { s.map(|x| x / w) } else { [0.0; 3] })
        .collect();
    VertexMesh {
        positions,
        radiosity,
        faces,
    }
}

fn neighbours(key: [i64; 3]) -> impl Iterator<Item = [i64; 3]> {
    (-1..=1).flat_map(move |dx| {
        (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| [key[0] + dx, key[1] + dy, key[2] + dz]))
    })
}

/// Write the lit mesh as a binary PLY with the robust tone mapping.
///
/// # Errors
/// [`SolveError::InvalidInput`] when `radiosity` does not have one value per patch;
/// [`SolveError::Io`] naming the file.
pub fn write_ply(
    path: &Path,
    patches: &PatchSet,
    radiosity: &[[f64; 3]],
) -> Result<(), SolveError> {
    write_ply_with(path, patches, radiosity, &PlyOptions::default()).map(|_| ())
}

/// Write the lit mesh as PLY with the given options; returns the tone map used.
///
/// # Errors
/// As [`write_ply`].
pub fn write_ply_with(
    path: &Path,
    patches: &PatchSet,
    radiosity: &[[f64; 3]],
    opts: &PlyOptions,
) -> Result<ToneMap, SolveError> {
    if radiosity.len() != patches.len() {
        return Err(SolveError::InvalidInput(format!(
            "{} radiosity values for {} patches",
            radiosity.len(),
            patches.len()
        )));
    }
    let tone = match opts.white {
        Some(w) if w.is_finite() && w > 0.0 => ToneMap { white: w },
        Some(w) => {
            return Err(SolveError::InvalidInput(format!(
                "PLY white point {w} must be a positive number"
            )))
        }
        None => ToneMap::robust(patches, radiosity),
    };
    let mesh = vertex_radiosity(patches, radiosity);
    let io = |e| SolveError::io(path, e);
    let file = std::fs::File::create(path).map_err(io)?;
    let mut w = BufWriter::new(file);
    let format = match opts.encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
    };
    write!(
        w,
        "ply\nformat {format} 1.0\n\
         comment ffstream radiosity: per-vertex area-weighted B, linear / {} then sRGB\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        tone.white,
        mesh.positions.len(),
        mesh.faces.len()
    )
    .map_err(io)?;
    for (p, b) in mesh.positions.iter().zip(&mesh.radiosity) {
        let rgb = b.map(|x| tone.map(x));
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
    for f in &mesh.faces {
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
    Ok(tone)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::patch::Patch;

    fn quad(corners: [DVec3; 4], area: f64) -> Patch {
        Patch {
            corners,
            n_corners: 4,
            normal: DVec3::Z,
            area,
            group: 0,
            face: 0,
            rho: [0.5; 3],
            emission: [0.0; 3],
        }
    }

    #[test]
    fn srgb_known_values() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-12);
        // 0.5 linear is 0.7354 encoded (188 of 255), the usual mid-grey figure.
        assert!((srgb_encode(0.5) - 0.735_357).abs() < 1e-5);
        let t = ToneMap { white: 2.0 };
        assert_eq!(t.map(2.0), 255);
        assert_eq!(t.map(10.0), 255);
        assert_eq!(t.map(1.0), 188);
        assert_eq!(t.map(-1.0), 0);
        assert_eq!(t.map(f64::NAN), 0);
    }

    #[test]
    fn shared_vertices_average_by_area() {
        // Two quads sharing the edge x = 1: [0,1]x[0,1] (area 1, B = 1) and
        // [1,3]x[0,1] (area 2, B = 4). Shared vertices: (1·1 + 2·4) / 3 = 3.
        let y = DVec3::Y;
        let a = quad([DVec3::ZERO, DVec3::X, DVec3::X + y, y], 1.0);
        let x3 = DVec3::new(3.0, 0.0, 0.0);
        // The shared corners differ by far less than the weld step (1e-7 × diagonal).
        let eps = DVec3::new(1e-12, -1e-12, 0.0);
        let b = quad([DVec3::X + eps, x3, x3 + y, DVec3::X + y - eps], 2.0);
        let ps = PatchSet {
            patches: vec![a, b],
            groups: vec!["g".into()],
        };
        let mesh = vertex_radiosity(&ps, &[[1.0; 3], [4.0; 3]]);
        assert_eq!(mesh.positions.len(), 6);
        assert_eq!(mesh.faces, vec![vec![0, 1, 2, 3], vec![1, 4, 5, 2]]);
        assert_eq!(mesh.radiosity[0], [1.0; 3]);
        assert_eq!(mesh.radiosity[1], [3.0; 3]);
        assert_eq!(mesh.radiosity[2], [3.0; 3]);
        assert_eq!(mesh.radiosity[4], [4.0; 3]);
    }

    #[test]
    fn robust_white_ignores_a_small_bright_patch() {
        // 99 % of the area at B = 1, a 1 % light at B = 1000: white = 1.
        let y = DVec3::Y;
        let p = |area| quad([DVec3::ZERO, DVec3::X, DVec3::X + y, y], area);
        let ps = PatchSet {
            patches: vec![p(99.0), p(1.0)],
            groups: vec!["g".into()],
        };
        assert_eq!(ToneMap::robust(&ps, &[[1.0; 3], [1000.0; 3]]).white, 1.0);
        // All dark: falls back to 1.
        assert_eq!(ToneMap::robust(&ps, &[[0.0; 3], [0.0; 3]]).white, 1.0);
    }
}
