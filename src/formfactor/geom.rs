//! What the kernels know of one patch ([`PatchGeom`]): its plane, centre, corners as a
//! polygon and as contour edges, and its sampling map, computed once per patch by the
//! row engine and read by every kernel.

use glam::DVec3;

use super::clip::{EdgeSet, Polygon};
use super::sampling::PatchMap;
use crate::geometry::occluders::Between;

/// Bounding sphere and plane of a patch (one cache line): what the engine's facing
/// test and the patch tree's bounds read of a row patch.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct PatchBound {
    pub(crate) centre: DVec3,
    /// Largest distance from the centre to a corner.
    pub(crate) radius: f64,
    pub(crate) normal: DVec3,
    /// normal · x for x on the patch's plane.
    pub(crate) offset: f64,
}

impl PatchBound {
    pub(crate) fn of(g: &PatchGeom) -> Self {
        PatchBound {
            centre: g.centroid,
            radius: g.radius,
            normal: g.normal,
            offset: g.offset,
        }
    }
}

/// Everything the kernels need about one patch, computed once.
///
/// `repr(C)` keeps the fields in this order: what every evaluated pair reads first
/// (plane, centre, corners, sampling map), the edges of the contour integral (near
/// pairs only) last, so a far pair touches a few adjacent cache lines of a record.
#[derive(Clone, Debug)]
#[repr(C)]
pub(crate) struct PatchGeom {
    pub(crate) normal: DVec3,
    /// normal · x for x on the patch's plane.
    pub(crate) offset: f64,
    pub(crate) centroid: DVec3,
    pub(crate) area: f64,
    /// Longest edge.
    pub(crate) size: f64,
    /// Largest distance from the centroid to a corner.
    pub(crate) radius: f64,
    pub(crate) face: u32,
    pub(crate) poly: Polygon,
    pub(crate) map: PatchMap,
    pub(crate) edges: EdgeSet,
}

impl PatchGeom {
    /// The points of this patch and of `other` at the unit-square coordinates
    /// `q` = (p_i, q_i, p_j, q_j) and the form factor's integrand there without 1/π,
    /// J_i J_j cos θ_i cos θ_j / r² (J the parametrisations' area elements; the
    /// cosines taken unnormalised, so J_i J_j (n_i · d)(−n_j · d) / r⁴): `None` where
    /// either side faces away. Σ over uniform `q` of it, over π A_i times the count, is
    /// an unbiased estimate of F⁰_ij (visibility left to the caller).
    #[inline]
    pub(crate) fn kernel_point(
        &self,
        other: &PatchGeom,
        q: [f64; 4],
    ) -> Option<(DVec3, DVec3, f64)> {
        self.kernel_point_on(&other.map, other.normal, q)
    }

    /// [`PatchGeom::kernel_point`] toward the patch with map `map` and normal `normal`.
    #[inline]
    pub(crate) fn kernel_point_on(
        &self,
        map: &PatchMap,
        normal: DVec3,
        q: [f64; 4],
    ) -> Option<(DVec3, DVec3, f64)> {
        let (x, jx) = self.map.eval(q[0], q[1]);
        let (y, jy) = map.eval(q[2], q[3]);
        let d = y - x;
        let r2 = d.length_squared();
        let ci = self.normal.dot(d);
        let cj = -normal.dot(d);
        (ci > 0.0 && cj > 0.0 && r2 > 0.0).then(|| (x, y, jx * jy * ci * cj / (r2 * r2)))
    }

    pub(crate) fn new(p: &crate::patch::Patch) -> Self {
        let poly = Polygon::new(p.corners());
        let edges = EdgeSet::from_polygon(&poly);
        let size = edges.edges().iter().map(|e| e.len).fold(0.0, f64::max);
        let centroid = p.centroid();
        let radius = p
            .corners()
            .iter()
            .map(|c| (*c - centroid).length())
            .fold(0.0, f64::max);
        PatchGeom {
            poly,
            edges,
            normal: p.normal,
            offset: p.normal.dot(centroid),
            centroid,
            area: p.area,
            size,
            radius,
            face: p.face,
            map: PatchMap::new(p.corners(), p.area),
        }
    }

    /// Largest and smallest signed distance of this patch's corners to `other`'s plane.
    #[inline]
    pub(crate) fn extent_wrt(&self, other: &PatchGeom) -> (f64, f64) {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for c in self.poly.verts() {
            let d = other.normal.dot(*c) - other.offset;
            lo = lo.min(d);
            hi = hi.max(d);
        }
        (lo, hi)
    }

    /// The occluder question between this patch and `other`, unclipped.
    pub(crate) fn between<'a>(&'a self, other: &'a PatchGeom) -> Between<'a> {
        Between::new(
            self.poly.verts(),
            self.normal,
            other.poly.verts(),
            other.normal,
            (self.face, other.face),
        )
    }

    /// A usable patch: positive finite area and a unit normal.
    pub(crate) fn is_valid(&self) -> bool {
        self.area > 0.0
            && self.area.is_finite()
            && (self.normal.length() - 1.0).abs() < 1e-6
            && self.poly.n >= 3
    }
}
