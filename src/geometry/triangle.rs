//! The exact segment–triangle test of the occluders ([`super::occluders`]): a triangle in the normalized frame
//! ([`OccluderTriangle`]) and a shadow segment prepared for the watertight test
//! ([`Segment`], [`ShearedRay`]).

use glam::DVec3;

/// Rays ignore hits closer than this to either end point (normalized units, i.e. a
/// fraction of the scene diagonal).
pub const RAY_EPSILON: f64 = 1e-6;

/// A triangle in the normalized frame, with what the exact tests need.
#[derive(Clone, Copy, Debug)]
pub(crate) struct OccluderTriangle {
    pub(crate) v: [DVec3; 3],
    /// Unit normal (either orientation; faces block from both sides).
    pub(crate) normal: DVec3,
    /// normal · v₀.
    pub(crate) offset: f64,
    pub(crate) min: DVec3,
    pub(crate) max: DVec3,
    pub(crate) face: u32,
}

impl OccluderTriangle {
    pub(crate) fn new(face: u32, v: [DVec3; 3]) -> Option<Self> {
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let len = n.length();
        if !len.is_finite() || len <= 0.0 {
            return None;
        }
        let normal = n / len;
        Some(OccluderTriangle {
            v,
            normal,
            offset: normal.dot(v[0]),
            min: v[0].min(v[1]).min(v[2]),
            max: v[0].max(v[1]).max(v[2]),
            face,
        })
    }

    pub(crate) fn vertices(&self) -> [DVec3; 3] {
        self.v
    }

    /// Watertight two-sided ray/triangle test (Woop, Benthin & Wald, "Watertight
    /// Ray/Triangle Intersection", JCGT 2013) in f64: true when the ray hits the closed
    /// triangle at a distance in [t0, t1] (returned). Watertight: the edge functions of an edge
    /// shared by two triangles (with bit-identical vertices) are computed by the same
    /// operations with opposite signs, so a ray through the edge hits at least one of
    /// them. A test that is not (Möller–Trumbore) lets rays slip through the diagonal
    /// of a quad face, which on subdivided scenes happens for whole families of
    /// grid-aligned rays (regression test `ray_through_a_shared_diagonal_is_blocked`).
    ///
    /// Const generic in the ray's axis permutation ([`ShearedRay::axes`], dispatched
    /// once per ray by `by_axes`): constant indices instead of a branch per vector
    /// component in the hottest function of a `contour` row.
    #[inline(always)]
    pub(crate) fn hit<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        ray: &ShearedRay,
        t0: f64,
        t1: f64,
    ) -> Option<f64> {
        let a = (self.v[0] - ray.origin).to_array();
        let b = (self.v[1] - ray.origin).to_array();
        let c = (self.v[2] - ray.origin).to_array();
        let (ax, ay) = (a[KX] - ray.sx * a[KZ], a[KY] - ray.sy * a[KZ]);
        let (bx, by) = (b[KX] - ray.sx * b[KZ], b[KY] - ray.sy * b[KZ]);
        let (cx, cy) = (c[KX] - ray.sx * c[KZ], c[KY] - ray.sy * c[KZ]);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        // Zero counts as inside (closed triangle), from either side.
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t = (u * (ray.sz * a[KZ]) + v * (ray.sz * b[KZ]) + w * (ray.sz * c[KZ])) / det;
        (t >= t0 && t <= t1).then_some(t)
    }
}

/// A shadow segment in the normalized frame, ready for [`OccluderTriangle::hit`].
pub(crate) struct Segment {
    pub(crate) t0: f64,
    pub(crate) t1: f64,
    pub(crate) sheared: ShearedRay,
}

impl Segment {
    /// The segment from `f` to `f + d` (normalized frame), hits counted between
    /// [`RAY_EPSILON`] of either end; `None` when it is too short.
    pub(crate) fn new(f: DVec3, d: DVec3) -> Option<Self> {
        let len = d.length();
        if len.is_nan() || len <= 2.0 * RAY_EPSILON {
            return None;
        }
        Some(Segment {
            t0: RAY_EPSILON,
            t1: len - RAY_EPSILON,
            sheared: ShearedRay::new(f, d, len),
        })
    }

    /// Whether a hit on `tri` blocks: with foreign occluders, not when the triangle
    /// lies in the plane of one of the end patches (within [`RAY_EPSILON`]: in a
    /// coarse or merged mesh that is the patch itself). The triangle decides, not the
    /// hit point: a wall standing on a floor blocks a floor patch's rays down to its
    /// foot (an earlier rule ignored hits near the planes, so light under the blocks of
    /// the Cornell box leaked at grazing angles).
    #[inline]
    pub(crate) fn counts(tri: &OccluderTriangle, planes: &Option<[(DVec3, f64); 2]>) -> bool {
        match planes {
            Some(ps) => !ps
                .iter()
                .any(|(n, o)| tri.v.iter().all(|v| (n.dot(*v) - o).abs() <= RAY_EPSILON)),
            None => true,
        }
    }
}

/// How [`super::occluders::Occluders::scan_between`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scan {
    /// Every triangle was examined.
    Done,
    /// The callback asked to stop.
    Stopped,
    /// Too many candidates to examine ([`crate::geometry::occluders::MAX_REJECTED_CANDIDATES`]).
    GaveUp,
}

/// A ray prepared for [`OccluderTriangle::hit`]: the axis permutation that makes the
/// largest direction component z, and the shear that maps the direction to +z.
pub(crate) struct ShearedRay {
    origin: DVec3,
    pub(crate) axes: [usize; 3],
    sx: f64,
    sy: f64,
    sz: f64,
}

impl ShearedRay {
    /// The ray from `origin` along `d` (not normalized), |d| = `len` > 0. Written with
    /// the components in registers and two independent divisions (1/|d| for the
    /// caller's unit direction, 1/d_z here): the set-up runs once per shadow ray.
    fn new(origin: DVec3, d: DVec3, len: f64) -> Self {
        let a = d.abs();
        // z = the largest component (the first one on ties).
        let (mut kx, mut ky, kz, mut x, mut y, z) = if a.x >= a.y && a.x >= a.z {
            (1, 2, 0, d.y, d.z, d.x)
        } else if a.y >= a.z {
            (2, 0, 1, d.z, d.x, d.y)
        } else {
            (0, 1, 2, d.x, d.y, d.z)
        };
        if z < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
            std::mem::swap(&mut x, &mut y);
        }
        let inv = 1.0 / z;
        ShearedRay {
            origin,
            axes: [kx, ky, kz],
            sx: x * inv,
            sy: y * inv,
            // 1 / (unit direction)_z
            sz: len * inv,
        }
    }
}
