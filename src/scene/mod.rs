//! Scenes: the input of the pipeline, before subdivision into patches.
//!
//! A [`Scene`] is a list of one-sided planar [`Face`]s (triangles and planar convex
//! quads, counter-clockwise seen from the front, docs/numerics.md §3), each tagged with the
//! OBJ group it came from and a [`Material`] (diffuse reflectance `Kd`, emitted
//! exitance `Ke`). Scenes come from three places:
//!
//! - [`load_obj`]: an OBJ file and its MTL libraries, read with `tobj` and validated
//!   (errors name the file and line, see [`SceneError`]);
//! - [`load_file`] with a [`SceneFormat`]: STL (`stl.rs`, ASCII and binary, one group per
//!   `solid`), PLY (`ply.rs`, ASCII and binary, one group) and glTF 2.0 (`gltf.rs`,
//!   `.gltf` + buffers or `.glb`, one group per node). They share `mesh.rs`: the same
//!   checks as OBJ (finite corners, repairs as warnings, errors naming the file and the
//!   facet, face or triangle number) and the materials file `NAME.mtl` beside the mesh
//!   for formats that have no materials of their own;
//! - [`builtin`](mod@builtin): scenes written as Rust tables or generated (`cornell`, `cube`,
//!   `plates`, `perpendicular`, `obstructed`, `room`, `city`), used by tests and benchmarks
//!   because their form factors are known or their size can be dialled.
//!
//! [`write_obj`] writes a scene back as OBJ + MTL; loading that file gives the same
//! scene. [`open_scene`] takes any of these names from the command line (a file by its
//! extension or `FORMAT:PATH`, or `builtin:NAME[:PARAM]`). Subdivision into patches lives
//! in [`crate::geometry::subdivide`].

mod builder;
mod builtin;
mod city;
mod duplicates;
mod error;
mod gltf;
mod mesh;
mod mtl;
mod obj;
mod office;
mod ply;
mod polygon;
mod room;
mod spec;
mod stl;
mod write;

pub use builtin::{builtin, builtin_names, builtin_perpendicular};
pub use error::SceneError;
pub use obj::load_obj;
pub(crate) use polygon::{polygon_area, polygon_normal};
pub use room::builtin_room;
pub use spec::{load_file, open_scene, SceneFormat, SceneSource, SceneSpec};
pub use write::write_obj;

use glam::DVec3;

/// A surface material: ideal diffuse reflector and emitter.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name as in the MTL file (`newmtl NAME`).
    pub name: String,
    /// Diffuse reflectance per RGB channel (MTL `Kd`), each in [0, 1).
    pub rho: [f32; 3],
    /// Emitted exitance per RGB channel (MTL `Ke`), radiosity units, each >= 0.
    pub emission: [f32; 3],
}

impl Material {
    /// True when any channel emits.
    pub(crate) fn is_emitter(&self) -> bool {
        self.emission.iter().any(|&e| e > 0.0)
    }
}

/// One planar face of a scene: a triangle or a planar convex quad.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// 3 or 4 corners, counter-clockwise seen from the front.
    pub corners: Vec<DVec3>,
    /// Index into [`Scene::groups`].
    pub group: u32,
    /// Index into [`Scene::materials`].
    pub material: u32,
    /// Where the face came from, 1-based: the line of the `f` statement of an OBJ file,
    /// the facet of an STL file, the face of a PLY file, the triangle of a glTF file
    /// (counted over the file's primitives in order; [`Scene::element`] says which);
    /// 0 for built-in scenes.
    pub line: u32,
}

impl Face {
    /// Area of the face (exact for planar polygons).
    pub fn area(&self) -> f64 {
        polygon_area(&self.corners)
    }

    /// Unit normal of the front side (zero for a degenerate face).
    pub fn normal(&self) -> DVec3 {
        polygon_normal(&self.corners)
    }

    /// Length of the longest edge.
    pub(crate) fn longest_edge(&self) -> f64 {
        let n = self.corners.len();
        (0..n)
            .map(|i| self.corners[i].distance(self.corners[(i + 1) % n]))
            .fold(0.0, f64::max)
    }
}

/// The end of the load warning of a scene without an emitting material.
pub const NO_EMITTER: &str =
    "no face uses an emitting material (Ke > 0): a radiosity solve has no light source";

/// A scene: faces, the group names and materials they refer to, where it came from,
/// and the warnings raised while loading it (the caller decides how to show them).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    pub faces: Vec<Face>,
    /// Group (OBJ `o`/`g`) names, in order of first appearance.
    pub groups: Vec<String>,
    pub materials: Vec<Material>,
    /// Path of the OBJ file, or `builtin:NAME`.
    pub source: String,
    /// One line per kind of problem that was repaired or tolerated while loading.
    pub warnings: Vec<String>,
    /// What [`Face::line`] counts: `line` (OBJ), `facet` (STL), `face` (PLY),
    /// `triangle` (glTF); empty for built-in scenes.
    pub element: &'static str,
    /// Degenerate faces dropped while loading (zero area, collinear corners): the
    /// faces after one have indices one less than their place in the file, which a
    /// consumer that numbers faces as the file does must know (`export --udales`).
    pub dropped: usize,
}

impl Scene {
    /// Every face as triangles (a quad as the fan 0-1-2, 0-2-3), with its face index:
    /// the input of the occlusion structure.
    pub fn triangles(&self) -> impl Iterator<Item = (u32, [DVec3; 3])> + '_ {
        self.faces.iter().enumerate().flat_map(|(f, face)| {
            let c = &face.corners;
            (1..c.len().saturating_sub(1)).map(move |k| (f as u32, [c[0], c[k], c[k + 1]]))
        })
    }

    /// Axis-aligned bounds `(min, max)` of all corners; `(+inf, -inf)` when empty.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.faces
            .iter()
            .flat_map(|f| f.corners.iter())
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            })
    }

    /// Sum of the face areas.
    pub fn total_area(&self) -> f64 {
        self.faces.iter().map(Face::area).sum()
    }

    /// The same scene with every coordinate multiplied by `s` (> 0). Materials are
    /// unchanged: `Ke` is an exitance, so the radiosity solution does not change.
    pub fn scaled(&self, s: f64) -> Scene {
        debug_assert!(s > 0.0 && s.is_finite(), "scale must be positive, got {s}");
        let mut out = self.clone();
        for f in &mut out.faces {
            for c in &mut f.corners {
                *c *= s;
            }
        }
        out
    }

    /// The load warnings that matter for a scene lit by emitters (`lit_from_outside`
    /// false: all of them) or by daylight only (the missing emitter is no fault then).
    pub fn warnings_for(&self, lit_from_outside: bool) -> impl Iterator<Item = &String> + '_ {
        self.warnings
            .iter()
            .filter(move |w| !(lit_from_outside && w.ends_with(NO_EMITTER)))
    }

    /// True when at least one face uses an emitting material.
    pub fn has_emitter(&self) -> bool {
        self.faces
            .iter()
            .any(|f| self.materials[f.material as usize].is_emitter())
    }

    /// Check the invariants every constructor must establish: indices in range, 3 or 4
    /// finite corners, non-degenerate, quads planar and convex. Used by tests and debug
    /// builds.
    ///
    /// # Errors
    /// A description of the first broken invariant.
    pub fn validate(&self) -> Result<(), String> {
        for (i, f) in self.faces.iter().enumerate() {
            if f.group as usize >= self.groups.len() {
                return Err(format!("face {i}: group {} out of range", f.group));
            }
            if f.material as usize >= self.materials.len() {
                return Err(format!("face {i}: material {} out of range", f.material));
            }
            if !(3..=4).contains(&f.corners.len()) {
                return Err(format!("face {i}: {} corners", f.corners.len()));
            }
            if f.corners.iter().any(|c| !c.is_finite()) {
                return Err(format!("face {i}: non-finite corner"));
            }
            match polygon::classify(&f.corners) {
                polygon::Shape::Triangle | polygon::Shape::ConvexQuad => {}
                other => return Err(format!("face {i}: {other:?}")),
            }
        }
        for m in &self.materials {
            if m.rho.iter().any(|&r| !(0.0..1.0).contains(&r)) {
                return Err(format!("material {}: Kd outside [0, 1)", m.name));
            }
            if m.emission.iter().any(|&e| !(e >= 0.0 && e.is_finite())) {
                return Err(format!("material {}: Ke negative or not finite", m.name));
            }
        }
        Ok(())
    }
}
