//! Occluders: a bounding volume hierarchy over the scene triangles, answering the two
//! visibility questions the form-factor kernels ask.
//!
//! - [`Occluders::occluded`]: does any triangle (other than those of two given scene
//!   faces) cut the open segment between two points? Every face is opaque from both
//!   sides (docs/known-answers.md §7, Cornell box: the blocks have no bottom faces, and the floor
//!   under them must stay dark, so rays from the floor hit the blocks from inside).
//! - [`Occluders::any_between`]: can any triangle come between two given polygons at
//!   all? When not, the pair needs no rays (docs/numerics.md §9, "pairs with no possible
//!   occluder cast no rays"), decided from the hierarchy, not from a flag.
//!
//! The hierarchy is built by obvhs (PLOC, then its collapse to an eight-wide tree,
//! Ylitie et al. 2017) and laid out for SIMD traversal by `geometry/bvh8.rs`; it works in
//! f32. To make results independent of the scene's units and position, everything is
//! mapped to a normalized frame first: x ↦ (x − centre) / d with d the diagonal of the
//! triangles' bounding box. The exact triangle tests run in f64 on the normalized
//! triangles; the f32 hierarchy and its triangle filter only cull. Ray offsets are
//! fractions of d ([`RAY_EPSILON`]), so scaling a scene by 10⁻³ or 10³ changes no
//! visibility decision.
//!
//! Traversal takes closures (`Bvh8::any_hit`, `Bvh8::for_each_in_box`), so the
//! geometry tests stay out of the hierarchy and the accelerator can be swapped
//! (docs/conventions.md §7).

use std::time::Duration;

use glam::DVec3;
use obvhs::{cwbvh::builder::build_cwbvh_from_tris, triangle::Triangle, BvhBuildParams};

pub(crate) use super::bvh8::TreeStats;
use super::bvh8::{Bvh8, SegmentPacket, SegmentRay};

/// Most segments [`Occluders::occluded_packet`] takes at once.
pub const PACKET: usize = super::bvh8::PACKET;

/// Rays ignore hits closer than this to either end point (normalized units, i.e. a
/// fraction of the scene diagonal).
pub const RAY_EPSILON: f64 = 1e-6;

/// Tolerance (normalized units) of the plane-side tests of [`Occluders::any_between`]:
/// a triangle that only touches the pair's hull within it cannot block a ray.
pub(crate) const PLANE_TOLERANCE: f64 = 1e-9;

/// Most candidate triangles [`Occluders::collect_between`] hands out for one pair; with
/// more, the pair's rays use the hierarchy.
pub(crate) const MAX_PAIR_CANDIDATES: usize = 16;

/// Work bound of [`Occluders::any_between`]: candidate triangles examined in detail
/// before it gives up and answers "rays needed".
pub(crate) const MAX_REJECTED_CANDIDATES: usize = 32;

/// obvhs' build of the occluder hierarchy: its slowest preset (PLOC over pre-split
/// triangles) with four times that preset's reinsertion passes (Meister and Bittner,
/// "Parallel reinsertion for bounding volume hierarchy optimization", 2018). Measured
/// (bench/PERF.md §12), 94.5k triangles: the SAH cost of the nodes falls from 10.3
/// (`slow_build`, used before) to 7.1, Embree's being 7.4 ([`Occluders::stats`]);
/// nodes tested per incoherent ray 9.2 → 7.7; single rays 17 % faster at 9.5k and at
/// 94.5k triangles, packets 7 % (9.5k) to 23 % (94.5k). The price is build time: 0.15 → 0.55 s
/// at 94.5k triangles, 2.2 → 12 s at 945k, once per process.
const BUILD_PARAMS: BvhBuildParams = BvhBuildParams {
    reinsertion_batch_ratio: 4.0,
    ..BvhBuildParams::very_slow_build()
};

/// Runs `$body` with `$kx`, `$ky`, `$kz` bound (as constants, usable as const generic
/// arguments) to the axis permutation `$axes` of a [`ShearedRay`]: one copy of a ray's
/// hot loop per permutation.
macro_rules! by_axes {
    ($axes:expr, |$kx:ident, $ky:ident, $kz:ident| $body:expr) => {
        match $axes {
            [1, 2, 0] => by_axes!(@arm 1, 2, 0, $kx, $ky, $kz, $body),
            [2, 1, 0] => by_axes!(@arm 2, 1, 0, $kx, $ky, $kz, $body),
            [2, 0, 1] => by_axes!(@arm 2, 0, 1, $kx, $ky, $kz, $body),
            [0, 2, 1] => by_axes!(@arm 0, 2, 1, $kx, $ky, $kz, $body),
            [0, 1, 2] => by_axes!(@arm 0, 1, 2, $kx, $ky, $kz, $body),
            [1, 0, 2] => by_axes!(@arm 1, 0, 2, $kx, $ky, $kz, $body),
            axes => unreachable!("not a permutation: {axes:?}"),
        }
    };
    (@arm $x:literal, $y:literal, $z:literal, $kx:ident, $ky:ident, $kz:ident, $body:expr) => {{
        const $kx: usize = $x;
        const $ky: usize = $y;
        const $kz: usize = $z;
        $body
    }};
}

/// A triangle in the normalized frame, with what the exact tests need.
#[derive(Clone, Copy, Debug)]
pub(super) struct OccluderTriangle {
    pub(super) v: [DVec3; 3],
    /// Unit normal (either orientation; faces block from both sides).
    pub(super) normal: DVec3,
    /// normal · v₀.
    pub(super) offset: f64,
    pub(super) min: DVec3,
    pub(super) max: DVec3,
    pub(super) face: u32,
}

impl OccluderTriangle {
    fn new(face: u32, v: [DVec3; 3]) -> Option<Self> {
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

    fn vertices(&self) -> [DVec3; 3] {
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
    /// once per ray by [`by_axes`]): constant indices instead of a branch per vector
    /// component in the hottest function of a `contour` row.
    #[inline(always)]
    fn hit<const KX: usize, const KY: usize, const KZ: usize>(
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
struct Segment {
    f: DVec3,
    dir: DVec3,
    t0: f64,
    t1: f64,
    sheared: ShearedRay,
}

impl Segment {
    /// The segment from `f` to `f + d` (normalized frame), hits counted between
    /// [`RAY_EPSILON`] of either end; `None` when it is too short.
    fn new(f: DVec3, d: DVec3) -> Option<Self> {
        let len = d.length();
        if len.is_nan() || len <= 2.0 * RAY_EPSILON {
            return None;
        }
        let dir = d * (1.0 / len);
        Some(Segment {
            f,
            dir,
            t0: RAY_EPSILON,
            t1: len - RAY_EPSILON,
            sheared: ShearedRay::new(f, d, len),
        })
    }

    /// Whether a hit at `t` blocks: with foreign occluders, not when the hit point lies
    /// on the plane of one of the end patches (that is the patch itself, in the coarse
    /// mesh).
    #[inline]
    fn counts(&self, t: f64, planes: &Option<[(DVec3, f64); 2]>) -> bool {
        match planes {
            Some(ps) => {
                let x = self.f + self.dir * t;
                !ps.iter().any(|(n, o)| (n.dot(x) - o).abs() <= RAY_EPSILON)
            }
            None => true,
        }
    }
}

/// How [`Occluders::scan_between`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scan {
    /// Every triangle was examined.
    Done,
    /// The callback asked to stop.
    Stopped,
    /// Too many candidates to examine ([`MAX_REJECTED_CANDIDATES`]).
    GaveUp,
}

/// A ray prepared for [`OccluderTriangle::hit`]: the axis permutation that makes the
/// largest direction component z, and the shear that maps the direction to +z.
struct ShearedRay {
    origin: DVec3,
    axes: [usize; 3],
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

/// Most side axes of [`HullAxes`] (edges of two polygons of up to 8 vertices).
const MAX_HULL_AXES: usize = 16;

/// Candidate separating axes between the convex hull H of two polygons a, b and a
/// triangle, with H's extent along each (normalized units).
///
/// Every segment from a to b lies in H, so a plane that has the whole triangle on one
/// side and all of H on the other proves that no such segment can be blocked
/// (separating axis theorem; any axis that separates is a proof, so testing a subset
/// of the axes is conservative). The axes used here are e × c for every edge e of a
/// and of b, with c the direction between the polygons' vertex means: for two
/// polygons seen across a distance these approximate the side faces of H, which the
/// bounding box and the planes of the triangle, a and b (the other tests of
/// [`Occluders::any_between`]) miss, so a box in the bounding box of a long thin H
/// but beside it no longer costs rays.
struct HullAxes {
    axes: [DVec3; MAX_HULL_AXES],
    lo: [f64; MAX_HULL_AXES],
    hi: [f64; MAX_HULL_AXES],
    n: usize,
}

impl HullAxes {
    /// `pts`: the vertices of a (first `na`) then of b (next `nb`), normalized.
    fn new(pts: &[DVec3], na: usize, nb: usize) -> Self {
        let mut h = HullAxes {
            axes: [DVec3::ZERO; MAX_HULL_AXES],
            lo: [0.0; MAX_HULL_AXES],
            hi: [0.0; MAX_HULL_AXES],
            n: 0,
        };
        if na == 0 || nb == 0 || na + nb > pts.len() {
            return h;
        }
        let (a, b) = (&pts[..na], &pts[na..na + nb]);
        let mean = |p: &[DVec3]| p.iter().sum::<DVec3>() / p.len() as f64;
        let c = mean(b) - mean(a);
        let c2 = c.length_squared();
        for poly in [a, b] {
            for k in 0..poly.len() {
                if h.n == MAX_HULL_AXES {
                    break;
                }
                let e = poly[(k + 1) % poly.len()] - poly[k];
                let axis = e.cross(c);
                let len2 = axis.length_squared();
                // Edges (nearly) along c give no useful axis: |e × c| ≤ 1e-12 |e| |c|.
                // (Written so that NaN lengths are skipped too.)
                let useful = len2 > 1e-24 * e.length_squared() * c2 && len2.is_finite();
                if !useful {
                    continue;
                }
                let len = len2.sqrt();
                // Opposite edges of a parallelogram, and the aligned edges of grid
                // patches, give the same axis: test it once (checked before dividing).
                if h.axes[..h.n]
                    .iter()
                    .any(|b| b.dot(axis).abs() > (1.0 - 1e-12) * len)
                {
                    continue;
                }
                let axis = axis / len;
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for p in pts {
                    let s = axis.dot(*p);
                    lo = lo.min(s);
                    hi = hi.max(s);
                }
                h.axes[h.n] = axis;
                h.lo[h.n] = lo;
                h.hi[h.n] = hi;
                h.n += 1;
            }
        }
        h
    }

    /// True when one of the axes separates the box [lo, hi] from the hull (beyond
    /// [`PLANE_TOLERANCE`]).
    #[inline]
    fn separates_box(&self, lo: DVec3, hi: DVec3) -> bool {
        let c = 0.5 * (lo + hi);
        let h = 0.5 * (hi - lo);
        (0..self.n).any(|k| {
            let a = self.axes[k];
            let mid = a.dot(c);
            let r = a.abs().dot(h);
            mid + r < self.lo[k] - PLANE_TOLERANCE || mid - r > self.hi[k] + PLANE_TOLERANCE
        })
    }

    /// True when one of the axes separates the triangle from the hull (beyond
    /// [`PLANE_TOLERANCE`], so a triangle touching H is not separated).
    #[inline]
    fn separates(&self, v: &[DVec3; 3]) -> bool {
        (0..self.n).any(|k| {
            let a = self.axes[k];
            let (s0, s1, s2) = (a.dot(v[0]), a.dot(v[1]), a.dot(v[2]));
            s0.max(s1).max(s2) < self.lo[k] - PLANE_TOLERANCE
                || s0.min(s1).min(s2) > self.hi[k] + PLANE_TOLERANCE
        })
    }
}

/// The question of [`Occluders::any_between`] and its siblings: polygon `a` (front
/// normal `na`) and polygon `b` (front normal `nb`), world units, each already clipped
/// to the other's front half-space; triangles of the faces `ignore` never count.
#[derive(Clone, Copy, Debug)]
pub struct Between<'a> {
    pub(crate) a: &'a [DVec3],
    pub(crate) na: DVec3,
    pub(crate) b: &'a [DVec3],
    pub(crate) nb: DVec3,
    pub(crate) ignore: (u32, u32),
}

impl<'a> Between<'a> {
    pub fn new(a: &'a [DVec3], na: DVec3, b: &'a [DVec3], nb: DVec3, ignore: (u32, u32)) -> Self {
        Between {
            a,
            na,
            b,
            nb,
            ignore,
        }
    }
}

/// Most polygon vertices [`PairHull`] takes. Callers pass polygons of at most 8
/// vertices each (`Polygon`'s capacity), so none is dropped; a vertex dropped would
/// shrink the hull, which would not be conservative.
const MAX_PAIR_POINTS: usize = 16;

/// Two polygons a (front normal na) and b (nb) in the normalized frame, and the tests
/// that decide whether a triangle may come between them, i.e. cut a segment from a
/// point of a to a point of b (all with [`PLANE_TOLERANCE`]): it may not when
/// 1. it belongs to one of the two ignored faces, or
/// 2. its box misses the box of the two polygons, or
/// 3. all corners of both polygons lie on one side of its plane (segments between
///    them never cross it), or
/// 4. it lies entirely behind the plane of a or of b (every segment between the
///    polygons stays in front of both planes), or
/// 5. an axis of [`HullAxes`] separates it from their convex hull.
struct PairHull {
    pts: [DVec3; MAX_PAIR_POINTS],
    np: usize,
    na_len: usize,
    /// The box of the points, shrunk by the tolerance (faces merely touching the hull,
    /// like the walls around a corner, do not count).
    qlo: DVec3,
    qhi: DVec3,
    na: DVec3,
    oa: f64,
    nb: DVec3,
    ob: f64,
    ignore: (u32, u32),
}

impl PairHull {
    /// `None` when there is nothing to test (no hierarchy, or an empty polygon).
    fn new(occ: &Occluders, q: &Between<'_>) -> Option<Self> {
        let Between {
            a,
            na,
            b,
            nb,
            ignore,
        } = *q;
        if occ.bvh.is_none() || a.is_empty() || b.is_empty() {
            return None;
        }
        // Foreign occluders: triangles on the planes of a or b are rejected by test 4.
        let ignore = occ.ignored_faces(ignore);
        let mut pts = [DVec3::ZERO; MAX_PAIR_POINTS];
        let mut np = 0;
        for p in a.iter().chain(b.iter()).take(MAX_PAIR_POINTS) {
            pts[np] = occ.to_norm(*p);
            np += 1;
        }
        let (mut lo, mut hi) = (pts[0], pts[0]);
        for p in &pts[..np] {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let mid = 0.5 * (lo + hi);
        let na_len = a.len().min(MAX_PAIR_POINTS);
        Some(PairHull {
            pts,
            np,
            na_len,
            qlo: (lo + DVec3::splat(PLANE_TOLERANCE)).min(mid),
            qhi: (hi - DVec3::splat(PLANE_TOLERANCE)).max(mid),
            na,
            // The planes through the first corner of each (already normalized above).
            oa: na.dot(pts[0]),
            nb,
            ob: nb.dot(pts[na_len]),
            ignore,
        })
    }

    /// The axes of test 5.
    fn hull_axes(&self) -> HullAxes {
        HullAxes::new(&self.pts[..self.np], self.na_len, self.np - self.na_len)
    }

    /// Tests 1 and 2 (cheap: a triangle passing them counts as examined in detail).
    #[inline]
    fn near(&self, t: &OccluderTriangle) -> bool {
        t.face != self.ignore.0
            && t.face != self.ignore.1
            && !(t.max.cmplt(self.qlo).any() || t.min.cmpgt(self.qhi).any())
    }

    /// Tests 3 and 4, for a triangle that passed [`PairHull::near`].
    #[inline]
    fn crosses(&self, t: &OccluderTriangle) -> bool {
        let (mut above, mut below) = (false, false);
        for p in &self.pts[..self.np] {
            let s = t.normal.dot(*p) - t.offset;
            above |= s > PLANE_TOLERANCE;
            below |= s < -PLANE_TOLERANCE;
        }
        if !(above && below) {
            return false;
        }
        let behind = |n: DVec3, o: f64| t.v.iter().all(|v| n.dot(*v) - o <= PLANE_TOLERANCE);
        !(behind(self.na, self.oa) || behind(self.nb, self.ob))
    }
}

/// Triangles that block light, in a hierarchy. Immutable after [`Occluders::new`], so
/// it is `Send + Sync` and shared by all threads.
#[derive(Clone, Debug)]
pub struct Occluders {
    bvh: Option<Bvh8>,
    /// Triangles in hierarchy primitive order (so no index indirection at traversal).
    tris: Vec<OccluderTriangle>,
    center: DVec3,
    /// 1 / the scene diagonal (world units): normalized = (world − center) · inv_scale.
    inv_scale: f64,
    /// Built from another mesh than the patches' (`--occluders`): face ids of the
    /// patches mean nothing here, so self-occlusion is told apart by planes instead
    /// (see [`Occluders::occluded_between_planes`]).
    foreign: bool,
}

impl Occluders {
    /// As [`Occluders::new`] for a mesh other than the one the patches come from (a
    /// coarser occluder mesh of the same geometry): the `ignore` face ids of every
    /// query are disregarded; [`Occluders::occluded_between_planes`] ignores hits on
    /// the planes of the two patches instead, and [`Occluders::any_between`] already
    /// rejects triangles lying on (or behind) them.
    pub fn new_foreign(tris: Vec<(u32, [DVec3; 3])>) -> Self {
        let mut o = Occluders::new(tris);
        o.foreign = true;
        o
    }

    /// Whether the triangles come from another mesh than the patches.
    pub(crate) fn is_foreign(&self) -> bool {
        self.foreign
    }

    /// Builds the hierarchy over `(scene face, triangle)` pairs. Degenerate (zero
    /// area) or non-finite triangles are dropped: they cannot block anything.
    pub fn new(tris: Vec<(u32, [DVec3; 3])>) -> Self {
        let Some((norm, center, diag)) = Self::normalized(tris) else {
            return Occluders::empty();
        };
        let f32_tris: Vec<Triangle> = norm
            .iter()
            .map(|t| {
                let [a, b, c] = t.vertices();
                Triangle {
                    v0: a.as_vec3a(),
                    v1: b.as_vec3a(),
                    v2: c.as_vec3a(),
                }
            })
            .collect();
        let bvh = build_cwbvh_from_tris(&f32_tris, BUILD_PARAMS, &mut Duration::default());
        let ordered: Vec<OccluderTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&k| norm[k as usize])
            .collect();
        Occluders {
            bvh: Bvh8::from_cwbvh(&bvh, &ordered),
            tris: ordered,
            center,
            inv_scale: 1.0 / diag,
            foreign: false,
        }
    }

    /// The triangles [`Occluders::new`] keeps, in its normalized frame, with that
    /// frame's centre and scale (None when none is kept).
    fn normalized(tris: Vec<(u32, [DVec3; 3])>) -> Option<(Vec<OccluderTriangle>, DVec3, f64)> {
        let finite: Vec<(u32, [DVec3; 3])> = tris
            .into_iter()
            .filter(|(_, t)| t.iter().all(|p| p.is_finite()))
            .collect();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for (_, t) in &finite {
            for p in t {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        let diag = (hi - lo).length();
        if finite.is_empty() || !diag.is_finite() || diag <= 0.0 {
            return None;
        }
        let center = 0.5 * (lo + hi);
        let inv_scale = 1.0 / diag;
        let norm: Vec<OccluderTriangle> = finite
            .iter()
            .filter_map(|(f, t)| {
                OccluderTriangle::new(
                    *f,
                    [
                        (t[0] - center) * inv_scale,
                        (t[1] - center) * inv_scale,
                        (t[2] - center) * inv_scale,
                    ],
                )
            })
            .collect();
        (!norm.is_empty()).then_some((norm, center, diag))
    }

    /// How many of `tris` [`Occluders::new`] would keep, without building anything
    /// (what a rank that casts no rays needs to describe the job).
    pub fn count_kept(tris: Vec<(u32, [DVec3; 3])>) -> usize {
        Self::normalized(tris).map_or(0, |(kept, _, _)| kept.len())
    }

    /// No occluders at all: nothing is ever occluded.
    pub(crate) fn empty() -> Self {
        Occluders {
            bvh: None,
            tris: Vec::new(),
            center: DVec3::ZERO,
            inv_scale: 1.0,
            foreign: false,
        }
    }

    /// Number of triangles in the hierarchy.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The shape of the hierarchy (`None` without triangles), for benchmarks.
    pub fn stats(&self) -> Option<TreeStats> {
        self.bvh.as_ref().map(Bvh8::stats)
    }

    #[inline]
    fn to_norm(&self, p: DVec3) -> DVec3 {
        (p - self.center) * self.inv_scale
    }

    /// The segment `from` → `to` (world units) in the normalized frame, as its start
    /// and its end minus its start.
    #[inline]
    fn norm_segment(&self, from: DVec3, to: DVec3) -> (DVec3, DVec3) {
        let f = self.to_norm(from);
        (f, self.to_norm(to) - f)
    }

    /// True when a triangle of a face other than `ignore.0` and `ignore.1` cuts the
    /// segment from `from` to `to`, ignoring hits within [`RAY_EPSILON`] × diagonal of
    /// either end.
    pub fn occluded(&self, from: DVec3, to: DVec3, ignore: (u32, u32)) -> bool {
        self.occluded_between_planes(from, to, ignore, None)
    }

    /// As [`Occluders::occluded`] for a segment between two patches with planes
    /// `planes` = ((normal, offset) of the source, of the target), world units, used
    /// when the occluders are foreign ([`Occluders::new_foreign`]): a hit counts only
    /// if its point lies farther than [`RAY_EPSILON`] × diagonal from both planes (a
    /// coarse mesh of the same flat faces has triangles on those planes, which the
    /// face ids of the fine patches cannot name). For native occluders the planes are
    /// not needed and `ignore` works as in [`Occluders::occluded`].
    pub(crate) fn occluded_between_planes(
        &self,
        from: DVec3,
        to: DVec3,
        ignore: (u32, u32),
        planes: Option<[(DVec3, f64); 2]>,
    ) -> bool {
        let Some(bvh) = &self.bvh else { return false };
        let ignore = self.ignored_faces(ignore);
        let planes = self.normalized_planes(planes);
        let (f, d) = self.norm_segment(from, to);
        let Some(ray) = SegmentRay::new(f, d) else {
            return false;
        };
        // The exact test runs only for the few triangles the f32 filter cannot
        // decide, and most rays need none: its set-up waits for the first one. A
        // segment too short for `Segment::new` answers "not blocked" all the same:
        // the filter is never sure of a crossing within FILTER_SLACK (> RAY_EPSILON)
        // of either end. One dispatch per test keeps a single copy of the walk.
        let mut setup = None;
        bvh.any_hit(&ray, ignore, planes.is_none(), |id| {
            self.exact_blocks(&mut setup, (f, d), id, &planes)
        })
    }

    /// The exact test: does triangle `id` block the segment from `f` to `f + d`
    /// (normalized frame; with foreign occluders, by a hit off the end patches'
    /// `planes`)? The segment's set-up is made into `setup` on the first call for it
    /// (`Some(None)`: too short to be blocked).
    fn exact_blocks(
        &self,
        setup: &mut Option<Option<Segment>>,
        (f, d): (DVec3, DVec3),
        id: usize,
        planes: &Option<[(DVec3, f64); 2]>,
    ) -> bool {
        let Some(seg) = setup.get_or_insert_with(|| Segment::new(f, d)) else {
            return false;
        };
        by_axes!(seg.sheared.axes, |KX, KY, KZ| {
            self.tris[id]
                .hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                .is_some_and(|t| seg.counts(t, planes))
        })
    }

    /// [`Occluders::occluded_between_planes`] for up to [`PACKET`] segments at once:
    /// bit l of the answer is set when segment l is blocked, with the same answer as
    /// alone. The segments are walked through the hierarchy together, which pays when
    /// they are close to each other (the rays of one pair of patches).
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    pub fn occluded_packet(
        &self,
        segs: &[(DVec3, DVec3)],
        ignore: (u32, u32),
        planes: Option<[(DVec3, f64); 2]>,
    ) -> u32 {
        let ignore = self.ignored_faces(ignore);
        self.with_packet(segs, planes, |bvh, pk, trust_sure, exact| {
            bvh.any_hit_packet(pk, ignore, trust_sure, exact)
        })
    }

    /// [`Occluders::occluded_by`] for up to [`PACKET`] segments at once, against the
    /// same candidate list `ids`: bit l of the answer is set when segment l is blocked,
    /// with the same answer as alone. Each candidate's f32 filter runs for all the
    /// segments together; the exact test only for what it cannot decide.
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    pub fn occluded_packet_by(
        &self,
        segs: &[(DVec3, DVec3)],
        ids: &[u32],
        planes: Option<[(DVec3, f64); 2]>,
        first: &mut usize,
    ) -> u32 {
        self.with_packet(segs, planes, |bvh, pk, trust_sure, exact| {
            bvh.any_hit_list(pk, ids, trust_sure, first, exact)
        })
    }

    /// The set-up both packet queries share: `segs` (world units) as a packet in the
    /// normalized frame, handed to `walk` with whether sure crossings block (native
    /// occluders) and the exact test of (lane, triangle).
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    fn with_packet(
        &self,
        segs: &[(DVec3, DVec3)],
        planes: Option<[(DVec3, f64); 2]>,
        walk: impl FnOnce(&Bvh8, &SegmentPacket, bool, &mut dyn FnMut(usize, usize) -> bool) -> u32,
    ) -> u32 {
        assert!(segs.len() <= PACKET, "{} segments in a packet", segs.len());
        let Some(bvh) = &self.bvh else { return 0 };
        let planes = self.normalized_planes(planes);
        let mut ends = [(DVec3::ZERO, DVec3::ZERO); PACKET];
        for (l, &(from, to)) in segs.iter().enumerate() {
            ends[l] = self.norm_segment(from, to);
        }
        let packet = SegmentPacket::new(&ends[..segs.len()]);
        // As in `occluded_between_planes`: each lane's exact set-up waits for its
        // first undecided triangle.
        let mut setups: [Option<Option<Segment>>; PACKET] = Default::default();
        walk(bvh, &packet, planes.is_none(), &mut |lane, id| {
            self.exact_blocks(&mut setups[lane], ends[lane], id, &planes)
        })
    }

    /// The faces whose triangles a query ignores: `ignore` for native occluders, none
    /// for foreign ones (their face ids mean nothing to the patches; planes decide).
    fn ignored_faces(&self, ignore: (u32, u32)) -> (u32, u32) {
        if self.foreign {
            (u32::MAX, u32::MAX)
        } else {
            ignore
        }
    }

    /// For foreign occluders, the planes of the two end patches in the normalized frame
    /// (n·x' = (n·x − n·c) / d); `None` for native occluders, which use face ids.
    fn normalized_planes(&self, planes: Option<[(DVec3, f64); 2]>) -> Option<[(DVec3, f64); 2]> {
        if !self.foreign {
            return None;
        }
        planes.map(|ps| ps.map(|(n, o)| (n, (o - n.dot(self.center)) * self.inv_scale)))
    }

    /// The segment `from` → `to` (world units) as a ray in the normalized frame, hits
    /// counted between [`RAY_EPSILON`] of either end; `None` when it is too short.
    fn segment(&self, from: DVec3, to: DVec3) -> Option<Segment> {
        let (f, d) = self.norm_segment(from, to);
        Segment::new(f, d)
    }

    /// Calls `visit` with the index of every triangle whose hierarchy leaf box
    /// overlaps the box [lo, hi] (normalized units) and is not separated from `hull`
    /// by one of its axes, until `visit` returns `true` ("stop"). Returns whether a
    /// visit stopped the traversal.
    fn for_each_in_hull(
        &self,
        lo: DVec3,
        hi: DVec3,
        hull: &HullAxes,
        visit: impl FnMut(usize) -> bool,
    ) -> bool {
        let Some(bvh) = &self.bvh else { return false };
        bvh.for_each_in_box(lo, hi, |blo, bhi| !hull.separates_box(blo, bhi), visit)
    }

    /// Can any triangle (other than those of faces `ignore.0`, `ignore.1`) come between
    /// polygon `a` (front normal `na`) and polygon `b` (front normal `nb`)? Both are
    /// given in world units and should already be clipped to each other's front
    /// half-space. Conservative: `false` means that no segment from a point of `a` to
    /// a point of `b` can be blocked, so the pair needs no rays; `true` means rays are
    /// needed.
    ///
    /// A triangle cannot block when one of the tests of the pair's hull (`PairHull`)
    /// rejects it (its box, its plane, the planes of `a` and `b`, the hull's side axes;
    /// all with [`PLANE_TOLERANCE`]).
    ///
    /// The work is bounded: after [`MAX_REJECTED_CANDIDATES`] triangles that pass the
    /// cheap tests 1–2 (face, box), the answer is `true` (rays will decide), so a pair
    /// in a cluttered region costs a short traversal, never a scan.
    pub fn any_between(&self, q: &Between<'_>) -> bool {
        self.scan_between(q, MAX_REJECTED_CANDIDATES, |_| true) != Scan::Done
    }

    /// The triangles that may come between polygons `a` and `b` (the candidates of
    /// [`Occluders::any_between`], all of them), into `out`. Returns `false` (and
    /// `out` is then of no use) when there are more than [`MAX_PAIR_CANDIDATES`] or
    /// the search gave up ([`MAX_REJECTED_CANDIDATES`]); rays must then use the
    /// hierarchy. An empty `out` with `true` means no segment between the polygons
    /// can be blocked. A triangle left out cannot block any segment from a point of
    /// `a` to a point of `b`, so [`Occluders::occluded_by`] with these candidates
    /// answers as the hierarchy would for such segments (up to rays grazing a
    /// triangle that only touches the pair's hull, which `any_between` ignores too).
    pub fn collect_between(&self, q: &Between<'_>, out: &mut Vec<u32>) -> bool {
        self.collect_between_up_to(q, MAX_PAIR_CANDIDATES, MAX_REJECTED_CANDIDATES, out)
    }

    /// The search behind [`Occluders::any_between`] and
    /// [`Occluders::collect_between`]: calls `found` with every triangle that may come
    /// between the polygons, until it returns `true`; gives up after `max_rejected`
    /// triangles examined in detail.
    fn scan_between(
        &self,
        q: &Between<'_>,
        max_rejected: usize,
        mut found: impl FnMut(usize) -> bool,
    ) -> Scan {
        let Some(pair) = PairHull::new(self, q) else {
            return Scan::Done;
        };
        let hull = pair.hull_axes();
        let tris = &self.tris;
        let mut rejected = 0usize;
        let mut gave_up = false;
        let stopped = self.for_each_in_hull(pair.qlo, pair.qhi, &hull, |k| {
            let t = &tris[k];
            if !pair.near(t) {
                return false;
            }
            rejected += 1;
            if rejected > max_rejected {
                gave_up = true;
                return true;
            }
            pair.crosses(t) && !hull.separates(&t.v) && found(k)
        });
        match (stopped, gave_up) {
            (_, true) => Scan::GaveUp,
            (true, false) => Scan::Stopped,
            (false, false) => Scan::Done,
        }
    }

    /// As [`Occluders::collect_between`] with the limits given (`max_found`
    /// candidates, `max_rejected` triangles examined in detail), for queries between
    /// larger polygons whose lists are then narrowed pair by pair with
    /// [`Occluders::filter_between`].
    pub(crate) fn collect_between_up_to(
        &self,
        q: &Between<'_>,
        max_found: usize,
        max_rejected: usize,
        out: &mut Vec<u32>,
    ) -> bool {
        out.clear();
        let scan = self.scan_between(q, max_rejected, |k| {
            out.push(k as u32);
            out.len() > max_found
        });
        scan == Scan::Done
    }

    /// The triangles of `list` that may come between polygons `a` and `b`, into `out`
    /// (in the order of `list`). When `list` holds every triangle that may come
    /// between two polygons containing `a` and `b` (a [`Occluders::collect_between_up_to`]
    /// answer for them, with the same planes and ignored faces), `out` is within the
    /// set [`Occluders::collect_between`] finds for `a` and `b` and holds every
    /// triangle that can block a segment between them (up to triangles that only touch
    /// the hull within [`PLANE_TOLERANCE`], as every test here), without walking the
    /// hierarchy:
    /// a triangle that cannot come between the larger polygons cannot come between the
    /// smaller ones. Stops once `out` holds more than `max_found` (0: "is there any").
    pub(crate) fn filter_between(
        &self,
        q: &Between<'_>,
        list: &[u32],
        max_found: usize,
        out: &mut Vec<u32>,
    ) {
        out.clear();
        if list.is_empty() {
            return;
        }
        let Some(pair) = PairHull::new(self, q) else {
            return;
        };
        // Test 5's axes cost more than the other tests: built on first need.
        let mut hull = None;
        for &k in list {
            let t = &self.tris[k as usize];
            if pair.near(t)
                && pair.crosses(t)
                && !hull.get_or_insert_with(|| pair.hull_axes()).separates(&t.v)
            {
                out.push(k);
                if out.len() > max_found {
                    return;
                }
            }
        }
    }

    /// Is the segment `from` → `to` (world units) blocked by one of the triangles
    /// `ids` (from [`Occluders::collect_between`])? The same ray set-up and exact test
    /// as [`Occluders::occluded_between_planes`], without the hierarchy.
    ///
    /// `first` is tested first (the pair's last blocker: its rays are coherent, so it
    /// likely blocks the next one too) and is set to the blocker found. The answer does
    /// not depend on it.
    pub fn occluded_by(
        &self,
        from: DVec3,
        to: DVec3,
        ids: &[u32],
        planes: Option<[(DVec3, f64); 2]>,
        first: &mut usize,
    ) -> bool {
        let Some(seg) = self.segment(from, to) else {
            return false;
        };
        let planes = self.normalized_planes(planes);
        by_axes!(seg.sheared.axes, |KX, KY, KZ| {
            self.first_blocker::<KX, KY, KZ>(&seg, ids, &planes, first)
        })
    }

    /// [`Occluders::occluded_by`] for a segment whose axes are (KX, KY, KZ).
    #[inline(always)]
    fn first_blocker<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        seg: &Segment,
        ids: &[u32],
        planes: &Option<[(DVec3, f64); 2]>,
        first: &mut usize,
    ) -> bool {
        let blocks = |k: usize| {
            self.tris[ids[k] as usize]
                .hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                .is_some_and(|t| seg.counts(t, planes))
        };
        if *first < ids.len() && blocks(*first) {
            return true;
        }
        match (0..ids.len()).find(|&k| k != *first && blocks(k)) {
            Some(k) => {
                *first = k;
                true
            }
            None => false,
        }
    }

    /// Checks internal invariants (for tests): every triangle is finite with a unit
    /// normal, lies inside the normalized unit-diagonal box, and the hierarchy holds
    /// each triangle exactly once.
    #[cfg(test)]
    pub(crate) fn validate(&self) {
        for t in &self.tris {
            assert!((t.normal.length() - 1.0).abs() < 1e-12);
            for v in t.vertices() {
                assert!(v.is_finite() && v.abs().max_element() <= 0.5 + 1e-12);
            }
        }
        if let Some(bvh) = &self.bvh {
            bvh.validate(&self.tris);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::dvec3;

    fn quad(face: u32, p: [DVec3; 4]) -> Vec<(u32, [DVec3; 3])> {
        vec![(face, [p[0], p[1], p[2]]), (face, [p[0], p[2], p[3]])]
    }

    /// Floor (face `ids.0`, at height `floor_z`) and ceiling (`ids.1`, z = 1) over the
    /// unit square, and a blocker (`ids.2`) over [0.25, 0.75]² at z = 0.5, split along
    /// its diagonal (0.25, 0.25)–(0.75, 0.75); everything scaled by `s`.
    fn blocker_scene(ids: (u32, u32, u32), floor_z: f64, s: f64) -> Vec<(u32, [DVec3; 3])> {
        let mut t = quad(
            ids.2,
            [
                dvec3(0.25, 0.25, 0.5) * s,
                dvec3(0.75, 0.25, 0.5) * s,
                dvec3(0.75, 0.75, 0.5) * s,
                dvec3(0.25, 0.75, 0.5) * s,
            ],
        );
        t.extend(quad(
            ids.0,
            [
                dvec3(0.0, 0.0, floor_z) * s,
                dvec3(1.0, 0.0, floor_z) * s,
                dvec3(1.0, 1.0, floor_z) * s,
                dvec3(0.0, 1.0, floor_z) * s,
            ],
        ));
        t.extend(quad(
            ids.1,
            [
                dvec3(0.0, 0.0, 1.0) * s,
                dvec3(0.0, 1.0, 1.0) * s,
                dvec3(1.0, 1.0, 1.0) * s,
                dvec3(1.0, 0.0, 1.0) * s,
            ],
        ));
        t
    }

    /// A unit square blocker (face 7) in the plane z = 0.5 over [0.25, 0.75]², between
    /// a floor (8) and a ceiling (9) that make the scene box larger than the blocker.
    fn blocker(scale: f64) -> Occluders {
        let o = Occluders::new(blocker_scene((8, 9, 7), 0.0, scale));
        o.validate();
        o
    }

    /// The candidate list of a pair gives every segment between the two polygons the
    /// answer the hierarchy gives (random squares facing each other across the
    /// blocker, at three scales); an empty list means nothing can block.
    #[test]
    fn pair_candidates_answer_like_the_hierarchy() {
        let square = |c: DVec3, h: f64, z: f64, up: bool| -> Vec<DVec3> {
            let mut v = vec![
                dvec3(c.x - h, c.y - h, z),
                dvec3(c.x + h, c.y - h, z),
                dvec3(c.x + h, c.y + h, z),
                dvec3(c.x - h, c.y + h, z),
            ];
            if !up {
                v.reverse();
            }
            v
        };
        let point_in = |p: &[DVec3], u: f64, v: f64| {
            p[0] * ((1.0 - u) * (1.0 - v))
                + p[1] * (u * (1.0 - v))
                + p[2] * (u * v)
                + p[3] * ((1.0 - u) * v)
        };
        let mut rng = crate::formfactor::sampling::SplitMix64::new(5);
        let mut ids = Vec::new();
        let (mut listed, mut empty, mut blocked, mut free) = (0, 0, 0, 0);
        for s in [1e-3, 1.0, 1e3] {
            let o = blocker(s);
            for _ in 0..300 {
                let mut r = || rng.next_f64();
                let ca = dvec3(0.1 + 0.8 * r(), 0.1 + 0.8 * r(), 0.0) * s;
                let cb = dvec3(0.1 + 0.8 * r(), 0.1 + 0.8 * r(), 0.0) * s;
                let (ha, hb) = ((0.01 + 0.1 * r()) * s, (0.01 + 0.1 * r()) * s);
                // a below the blocker facing up, b above or below it facing down.
                let za = (0.05 + 0.4 * r()) * s;
                let zb = if r() < 0.7 {
                    0.55 + 0.4 * r()
                } else {
                    za / s + 0.01 + 0.4 * r()
                } * s;
                let a = square(ca, ha, za, true);
                let b = square(cb, hb, zb, false);
                let (na, nb) = (DVec3::Z, -DVec3::Z);
                if !o.collect_between(&Between::new(&a, na, &b, nb, (8, 9)), &mut ids) {
                    continue;
                }
                listed += 1;
                empty += ids.is_empty() as usize;
                let mut first = 0;
                assert_eq!(
                    ids.is_empty(),
                    !o.any_between(&Between::new(&a, na, &b, nb, (8, 9)))
                );
                for _ in 0..50 {
                    let x = point_in(&a, rng.next_f64(), rng.next_f64());
                    let y = point_in(&b, rng.next_f64(), rng.next_f64());
                    let by_list = o.occluded_by(x, y, &ids, None, &mut first);
                    assert_eq!(by_list, o.occluded(x, y, (8, 9)), "scale {s}: {x} -> {y}");
                    blocked += by_list as usize;
                    free += !by_list as usize;
                }
            }
        }
        assert!(
            listed > 500 && empty > 50 && blocked > 1000 && free > 1000,
            "cases: {listed} listed, {empty} empty, {blocked} blocked, {free} free"
        );
    }

    #[test]
    fn ray_through_blocker_is_occluded_from_both_sides() {
        for s in [1e-3, 1.0, 1e3] {
            let o = blocker(s);
            let a = dvec3(0.5, 0.5, 0.0) * s;
            let b = dvec3(0.5, 0.5, 1.0) * s;
            assert!(o.occluded(a, b, (8, 9)));
            assert!(o.occluded(b, a, (8, 9)));
            // Ignoring the blocker's face lets it through.
            assert!(!o.occluded(a, b, (7, 9)));
            // A ray beside the blocker passes.
            assert!(!o.occluded(dvec3(0.1, 0.1, 0.0) * s, dvec3(0.1, 0.9, 1.0) * s, (8, 9)));
            // Segment ending before the blocker.
            assert!(!o.occluded(a, dvec3(0.5, 0.5, 0.4) * s, (8, 9)));
        }
    }

    #[test]
    fn single_and_degenerate_triangles() {
        let one = Occluders::new(vec![(
            0,
            [
                dvec3(0.0, 0.0, 1.0),
                dvec3(1.0, 0.0, 1.0),
                dvec3(0.0, 1.0, 1.0),
            ],
        )]);
        one.validate();
        assert_eq!(one.len(), 1);
        // One leaf filling the root's box: one node and one block, each met by every
        // line through the root.
        let stats = TreeStats {
            nodes: 1,
            leaves: 1,
            depth: 1,
            blocks: 1,
            node_sah: 1.0,
            block_sah: 1.0,
        };
        assert_eq!(one.stats(), Some(stats));
        assert!(one.occluded(dvec3(0.2, 0.2, 0.0), dvec3(0.2, 0.2, 2.0), (9, 9)));
        let flat = Occluders::new(vec![(
            0,
            [
                dvec3(0.0, 0.0, 0.0),
                dvec3(1.0, 0.0, 0.0),
                dvec3(2.0, 0.0, 0.0),
            ],
        )]);
        assert!(flat.is_empty());
        assert_eq!(flat.stats(), None);
        assert!(!flat.occluded(dvec3(0.5, -1.0, 0.0), dvec3(0.5, 1.0, 0.0), (9, 9)));
        assert!(Occluders::new(Vec::new()).is_empty());
    }

    #[test]
    fn ray_through_a_shared_diagonal_is_blocked() {
        // A quad face as two triangles sharing the diagonal (0.25,0.25)–(0.75,0.75) at
        // z = 0.5; rays crossing the plane exactly on the diagonal, in many directions,
        // must all be blocked (a non-watertight test lets some through).
        let o = Occluders::new(blocker_scene((2, 3, 1), 0.0, 1.0));
        let mut missed = 0;
        for a in 0..=16 {
            for b in 0..=16 {
                let on = 0.3 + 0.4 * a as f64 / 16.0; // point on the diagonal
                let from = dvec3(
                    on - 0.3 + 0.6 * b as f64 / 16.0,
                    on + 0.1 * (a as f64 - 8.0) / 8.0,
                    0.0,
                );
                let to = 2.0 * dvec3(on, on, 0.5) - from;
                if !o.occluded(from, to, (2, 3)) {
                    missed += 1;
                }
            }
        }
        assert_eq!(missed, 0, "{missed} rays slipped through the diagonal");
    }

    #[test]
    fn ray_ending_on_a_face_is_not_blocked_by_it() {
        let o = blocker(1.0);
        // From the floor to a point on the blocker itself (face 7 not ignored): the
        // end point lies on face 7 and the epsilon keeps that hit out.
        assert!(!o.occluded(dvec3(0.5, 0.5, 0.0), dvec3(0.5, 0.5, 0.5), (8, 9)));
    }

    #[test]
    fn short_segments_near_geometry_are_not_culled() {
        // A tiny triangle right next to the ray origin (within obvhs' fixed node
        // epsilon) must still block.
        let mut t = vec![(
            1,
            [
                dvec3(-1e-6, -1e-6, 1e-5),
                dvec3(1e-6, -1e-6, 1e-5),
                dvec3(0.0, 1e-6, 1e-5),
            ],
        )];
        t.extend(quad(
            2,
            [
                dvec3(-1.0, -1.0, -1.0),
                dvec3(1.0, -1.0, -1.0),
                dvec3(1.0, 1.0, -1.0),
                dvec3(-1.0, 1.0, -1.0),
            ],
        ));
        let o = Occluders::new(t);
        assert!(o.occluded(dvec3(0.0, 0.0, 0.0), dvec3(0.0, 0.0, 0.5), (99, 99)));
    }

    #[test]
    fn any_between_ignores_blockers_beside_a_slanted_pair() {
        // Floor patch at x, y ∈ [0, 0.1], ceiling patch at x, y ∈ [0.9, 1]: their hull is
        // a thin slanted prism along the diagonal. A small blocker in the corner
        // (0.8, 0.1, 0.5) is inside their bounding box but beside the prism; one at the
        // centre of the diagonal is inside it.
        let floor = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(0.1, 0.0, 0.0),
            dvec3(0.1, 0.1, 0.0),
            dvec3(0.0, 0.1, 0.0),
        ];
        let ceiling = [
            dvec3(0.9, 0.9, 1.0),
            dvec3(0.9, 1.0, 1.0),
            dvec3(1.0, 1.0, 1.0),
            dvec3(1.0, 0.9, 1.0),
        ];
        let n_up = dvec3(0.0, 0.0, 1.0);
        let blocker_at = |c: DVec3| {
            let mut t = quad(
                7,
                [
                    c + dvec3(-0.05, -0.05, 0.0),
                    c + dvec3(0.05, -0.05, 0.0),
                    c + dvec3(0.05, 0.05, 0.0),
                    c + dvec3(-0.05, 0.05, 0.0),
                ],
            );
            t.extend(quad(8, floor));
            t.extend(quad(9, ceiling));
            Occluders::new(t)
        };
        let beside = blocker_at(dvec3(0.8, 0.1, 0.5));
        assert!(!beside.any_between(&Between::new(&floor, n_up, &ceiling, -n_up, (8, 9))));
        let inside = blocker_at(dvec3(0.5, 0.5, 0.5));
        assert!(inside.any_between(&Between::new(&floor, n_up, &ceiling, -n_up, (8, 9))));
        // And the ray test agrees: the centre blocker stops the centre ray.
        assert!(inside.occluded(dvec3(0.05, 0.05, 0.0), dvec3(0.95, 0.95, 1.0), (8, 9)));
    }

    #[test]
    fn foreign_occluders_ignore_the_endpoint_planes_not_blockers() {
        // A coarse mesh whose floor lies 5e-7 above the fine floor z = 0 (within the
        // plane skin), a ceiling at z = 1 and a blocker at z = 0.5 over [0.25, 0.75]².
        let t = blocker_scene((1, 2, 3), 5e-7, 1.0);
        let occ = Occluders::new_foreign(t.clone());
        assert!(occ.is_foreign());
        let up = dvec3(0.0, 0.0, 1.0);
        let floor = (up, 0.0);
        // A shallow ray from the fine floor to a wall point: it crosses the coarse
        // floor ~1e-5 along, past the end-point epsilon. Planes tell it apart; the
        // patches' face ids (here 1, 2) mean nothing to a foreign mesh.
        let (a, b) = (dvec3(0.1, 0.1, 0.0), dvec3(1.0, 1.0, 0.05));
        let wall = (dvec3(-1.0, 0.0, 0.0), -1.0);
        assert!(occ.occluded(a, b, (1, 2)));
        assert!(!occ.occluded_between_planes(a, b, (1, 2), Some([floor, wall])));
        // Floor to ceiling through the blocker: still blocked.
        let ceiling = (-up, -1.0);
        let (a, c) = (dvec3(0.5, 0.5, 0.0), dvec3(0.5, 0.5, 1.0));
        assert!(occ.occluded_between_planes(a, c, (1, 3), Some([floor, ceiling])));
        assert!(!occ.occluded_between_planes(
            dvec3(0.1, 0.1, 0.0),
            dvec3(0.1, 0.9, 1.0),
            (1, 2),
            Some([floor, ceiling])
        ));
        // The same mesh as native occluders honours the face ids.
        let native = Occluders::new(t);
        assert!(!native.occluded(a, c, (1, 3)));
    }

    #[test]
    fn any_between_sees_blocker_and_ignores_walls() {
        let o = blocker(1.0);
        let n_up = dvec3(0.0, 0.0, 1.0);
        let lower = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(1.0, 1.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
        ];
        let upper = [
            dvec3(0.0, 0.0, 1.0),
            dvec3(0.0, 1.0, 1.0),
            dvec3(1.0, 1.0, 1.0),
            dvec3(1.0, 0.0, 1.0),
        ];
        assert!(o.any_between(&Between::new(&lower, n_up, &upper, -n_up, (8, 9))));
        // Patches on the floor and ceiling away from the blocker's column, only the
        // walls (faces 8, 9 ignored) around: a corner patch pair at x, y ∈ [0, 0.2].
        let lo = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(0.2, 0.0, 0.0),
            dvec3(0.2, 0.2, 0.0),
            dvec3(0.0, 0.2, 0.0),
        ];
        let hi = [
            dvec3(0.0, 0.0, 1.0),
            dvec3(0.0, 0.2, 1.0),
            dvec3(0.2, 0.2, 1.0),
            dvec3(0.2, 0.0, 1.0),
        ];
        assert!(!o.any_between(&Between::new(&lo, n_up, &hi, -n_up, (8, 9))));
        // Both below the blocker's plane: it is on one side of the whole hull.
        let mid = [
            dvec3(0.0, 0.0, 0.3),
            dvec3(0.0, 1.0, 0.3),
            dvec3(1.0, 1.0, 0.3),
            dvec3(1.0, 0.0, 0.3),
        ];
        assert!(!o.any_between(&Between::new(&lower, n_up, &mid, -n_up, (8, 9))));
        assert!(!Occluders::empty().any_between(&Between::new(
            &lower,
            n_up,
            &upper,
            -n_up,
            (8, 9)
        )));
    }

    /// A cluttered scene for the f32-filter tests: random triangles of all shapes
    /// (slivers, needles, large ones) and sizes, a few sharing edges or planes, in a
    /// box of `scale`.
    fn clutter(seed: u64, scale: f64) -> Vec<(u32, [DVec3; 3])> {
        let mut rng = crate::formfactor::sampling::SplitMix64::new(seed);
        let mut r = move || rng.next_f64();
        let mut tris = Vec::new();
        for f in 0..300u32 {
            let c = dvec3(r(), r(), r()) * scale;
            let size = scale * [0.3, 0.05, 0.005][f as usize % 3];
            let a = c + (dvec3(r(), r(), r()) - 0.5) * size;
            let b = c + (dvec3(r(), r(), r()) - 0.5) * size;
            let t = match f % 5 {
                // a sliver: the third vertex almost on the first edge
                0 => a + (b - a) * r() + dvec3(r(), r(), r()) * size * 1e-9,
                // axis-aligned, in the plane z = c.z (shared by the next ones)
                1 => dvec3(a.x, b.y, a.z),
                _ => c + (dvec3(r(), r(), r()) - 0.5) * size,
            };
            let t = if f % 5 == 1 {
                [
                    dvec3(a.x, a.y, c.z),
                    dvec3(b.x, b.y, c.z),
                    dvec3(t.x, t.y, c.z),
                ]
            } else {
                [a, b, t]
            };
            tris.push((f, t));
            // every seventh triangle gets a neighbour across its first edge
            if f % 7 == 0 {
                tris.push((
                    f + 1000,
                    [t[1], t[0], c + (dvec3(r(), r(), r()) - 0.5) * size],
                ));
            }
        }
        tris
    }

    /// Segments of every kind through `occ`'s scene: random, along the axes, grazing
    /// or ending on triangles, through shared edges, in triangle planes, and reaching
    /// far outside the scene.
    fn test_segments(
        tris: &[(u32, [DVec3; 3])],
        seed: u64,
        scale: f64,
        n: usize,
    ) -> Vec<(DVec3, DVec3)> {
        let mut rng = crate::formfactor::sampling::SplitMix64::new(seed);
        let mut r = move || rng.next_f64();
        (0..n)
            .map(|k| {
                let t = &tris[(r() * tris.len() as f64) as usize % tris.len()].1;
                let u = &tris[(r() * tris.len() as f64) as usize % tris.len()].1;
                let on = |t: &[DVec3; 3], a: f64, b: f64| {
                    let (a, b) = if a + b > 1.0 {
                        (1.0 - a, 1.0 - b)
                    } else {
                        (a, b)
                    };
                    t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b
                };
                let p = dvec3(r(), r(), r()) * scale;
                match k % 8 {
                    0 => (p, dvec3(r(), r(), r()) * scale),
                    // along an axis
                    1 => (p, p + DVec3::AXES[k / 8 % 3] * scale * (r() - 0.5)),
                    // from a point of one triangle to a point of another
                    2 => (on(t, r(), r()), on(u, r(), r())),
                    // through a vertex or an edge of a triangle
                    3 => {
                        let x = if r() < 0.5 {
                            t[0]
                        } else {
                            t[0] + (t[1] - t[0]) * r()
                        };
                        let d = dvec3(r(), r(), r()) - 0.5;
                        (x - d * scale, x + d * scale)
                    }
                    // in the plane of a triangle, across it
                    4 => (on(t, -0.5, r()), on(t, 1.5, r() * 0.5)),
                    // far outside on both sides
                    5 => (
                        p - dvec3(r(), r(), r()) * scale * 1e3,
                        p + dvec3(r(), r(), r()) * scale * 1e3,
                    ),
                    // short, near a triangle
                    6 => {
                        let x = on(t, r(), r());
                        (
                            x + dvec3(r(), r(), r()) * scale * 1e-6,
                            x - dvec3(r(), r(), r()) * scale * 1e-6,
                        )
                    }
                    // grazing: almost parallel to a triangle, just above it
                    _ => {
                        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
                        let lift = n * scale * 1e-7 * (r() - 0.5);
                        (on(t, -0.2, 0.3) + lift, on(t, 1.2, 0.1) - lift)
                    }
                }
            })
            .collect()
    }

    /// The f32 filter never contradicts the exact test: a triangle it misses for
    /// sure is missed by the exact test, and one it crosses for sure is hit (every
    /// triangle, every kind of segment, at three scales).
    #[test]
    fn f32_filter_agrees_with_the_exact_test() {
        let (mut sure, mut maybe, mut hits, mut short) = (0usize, 0usize, 0usize, 0usize);
        for (seed, scale) in [(1u64, 1.0), (2, 1e-3), (3, 1e4)] {
            let tris = clutter(seed, scale);
            let occ = Occluders::new(tris.clone());
            occ.validate();
            let bvh = occ.bvh.as_ref().unwrap();
            for (from, to) in test_segments(&tris, seed + 10, scale, 6000) {
                let (f, d) = occ.norm_segment(from, to);
                let Some(ray) = SegmentRay::new(f, d) else {
                    continue;
                };
                let classes = bvh.classify_all(&ray, occ.tris.len());
                let Some(seg) = Segment::new(f, d) else {
                    // Too short to count any hit: `occluded` relies on the filter
                    // being sure of no crossing either.
                    assert!(
                        classes.iter().all(|(s, _)| !s),
                        "sure hit on {from} -> {to}"
                    );
                    short += 1;
                    continue;
                };
                for (id, (s, m)) in classes.into_iter().enumerate() {
                    let exact = by_axes!(seg.sheared.axes, |KX, KY, KZ| {
                        occ.tris[id].hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                    })
                    .is_some();
                    assert!(
                        !s || exact,
                        "sure hit that the exact test misses: tri {id}, {from} -> {to}"
                    );
                    assert!(s || m || !exact, "missed a hit: tri {id}, {from} -> {to}");
                    sure += s as usize;
                    maybe += m as usize;
                    hits += exact as usize;
                }
            }
        }
        // The filter must decide most hits itself, or it saves nothing.
        assert!(
            hits > 3000 && sure > hits / 2 && short > 0,
            "{hits} hits, {sure} sure, {maybe} maybe, {short} too short"
        );
    }

    /// The walk answers as the exact test over every triangle does (random faces
    /// ignored), native and foreign, on the cluttered scenes.
    #[test]
    fn walk_answers_like_a_scan_of_every_triangle() {
        let (mut blocked, mut free) = (0, 0);
        for (seed, scale) in [(4u64, 1.0), (5, 1e-3)] {
            let tris = clutter(seed, scale);
            for foreign in [false, true] {
                let occ = if foreign {
                    Occluders::new_foreign(tris.clone())
                } else {
                    Occluders::new(tris.clone())
                };
                // Leaves hold at most eight triangles; below the root, nodes add area.
                let st = occ.stats().expect("triangles");
                assert!(st.depth >= 2 && st.nodes >= 2, "{st:?}");
                assert!(st.leaves >= occ.len().div_ceil(8), "{st:?}");
                assert!(st.node_sah > 1.0 && st.block_sah > 0.0, "{st:?}");
                for (k, (from, to)) in test_segments(&tris, seed + 20, scale, 5000)
                    .into_iter()
                    .enumerate()
                {
                    let ignore = (tris[k % tris.len()].0, tris[k * 7 % tris.len()].0);
                    let planes = foreign.then(|| {
                        let n = (to - from).normalize_or_zero().any_orthonormal_vector();
                        [(n, n.dot(from)), (n, n.dot(to))]
                    });
                    let got = occ.occluded_between_planes(from, to, ignore, planes);
                    let scan = occ.segment(from, to).is_some_and(|seg| {
                        let skip = occ.ignored_faces(ignore);
                        let planes = occ.normalized_planes(planes);
                        occ.tris.iter().any(|t| {
                            t.face != skip.0
                                && t.face != skip.1
                                && by_axes!(seg.sheared.axes, |KX, KY, KZ| {
                                    t.hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                                })
                                .is_some_and(|t| seg.counts(t, &planes))
                        })
                    });
                    assert_eq!(
                        got, scan,
                        "{from} -> {to}, ignoring {ignore:?}, foreign {foreign}"
                    );
                    blocked += got as usize;
                    free += !got as usize;
                }
            }
        }
        assert!(
            blocked > 1000 && free > 1000,
            "{blocked} blocked, {free} free"
        );
    }

    /// A packet of segments gets, lane by lane, the answers the segments get alone:
    /// packets of 1–16 of the test segments (every kind, mixed directions, some lying
    /// wholly outside the occluders' box: empty lanes) and
    /// packets of rays between two random triangles, as a pair casts them; native and
    /// foreign, the pair's faces ignored. The same packets against a random candidate
    /// list answer as each segment does against that list alone.
    #[test]
    fn packets_answer_like_single_segments() {
        let (mut blocked, mut free, mut mixed, mut empty) = (0, 0, 0, 0);
        let (mut list_blocked, mut list_mixed) = (0, 0);
        for (seed, scale) in [(8u64, 1.0), (9, 1e3)] {
            let tris = clutter(seed, scale);
            let mut rng = crate::formfactor::sampling::SplitMix64::new(seed);
            // (the two triangles whose faces are ignored and whose planes bound a
            // foreign pair, the segments)
            let mut packets = Vec::new();
            for _ in 0..400 {
                let a = rng.below(tris.len() as u32) as usize;
                let b = rng.below(tris.len() as u32) as usize;
                let rays: Vec<_> = (0..PACKET)
                    .map(|_| {
                        (
                            point_in(&tris[a].1, &mut rng),
                            point_in(&tris[b].1, &mut rng),
                        )
                    })
                    .collect();
                packets.push(((a, b), rays));
            }
            let singles = test_segments(&tris, seed + 30, scale, 3000);
            let mut at = 0;
            while at < singles.len() {
                let n = (1 + rng.below(PACKET as u32) as usize).min(singles.len() - at);
                let k = rng.below(tris.len() as u32) as usize;
                packets.push(((k, (k * 7) % tris.len()), singles[at..at + n].to_vec()));
                at += n;
            }
            let plane = |t: &[DVec3; 3]| {
                let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                (n, n.dot(t[0]))
            };
            for foreign in [false, true] {
                let occ = if foreign {
                    Occluders::new_foreign(tris.clone())
                } else {
                    Occluders::new(tris.clone())
                };
                for ((a, b), segs) in &packets {
                    let faces = (tris[*a].0, tris[*b].0);
                    let planes = foreign.then(|| [plane(&tris[*a].1), plane(&tris[*b].1)]);
                    let got = occ.occluded_packet(segs, faces, planes);
                    let alone = segs.iter().enumerate().fold(0u32, |m, (l, &(x, y))| {
                        m | (occ.occluded_between_planes(x, y, faces, planes) as u32) << l
                    });
                    assert_eq!(
                        got, alone,
                        "packet {segs:?}, faces {faces:?}, foreign {foreign}"
                    );
                    // The same segments against a candidate list (a random quarter of
                    // the triangles, internal ids), the last blocker anywhere in it or
                    // past its end.
                    let ids: Vec<u32> = (0..occ.len() as u32)
                        .filter(|_| rng.below(4) == 0)
                        .collect();
                    let mut first = rng.below(ids.len() as u32 + 2) as usize;
                    let got = occ.occluded_packet_by(segs, &ids, planes, &mut first);
                    let mut first = 0;
                    let alone_list = segs.iter().enumerate().fold(0u32, |m, (l, &(x, y))| {
                        m | (occ.occluded_by(x, y, &ids, planes, &mut first) as u32) << l
                    });
                    assert_eq!(
                        got, alone_list,
                        "packet {segs:?} against {ids:?}, foreign {foreign}"
                    );
                    list_blocked += alone_list.count_ones();
                    list_mixed +=
                        (alone_list != 0 && alone_list.count_ones() < segs.len() as u32) as usize;
                    let n = segs.len() as u32;
                    blocked += alone.count_ones();
                    free += n - alone.count_ones();
                    mixed += (alone != 0 && alone.count_ones() < n) as usize;
                    // Lanes left empty (nothing of the segment inside the box) next to
                    // lanes that walk.
                    let outside = segs
                        .iter()
                        .filter(|&&(x, y)| {
                            let (f, d) = occ.norm_segment(x, y);
                            SegmentRay::new(f, d).is_none()
                        })
                        .count();
                    empty += (outside > 0 && outside < segs.len()) as usize;
                }
            }
        }
        assert!(
            blocked > 5000 && free > 10000 && mixed > 500 && empty > 200,
            "{blocked} blocked, {free} free, {mixed} packets partly blocked, \
             {empty} with empty lanes"
        );
        assert!(
            list_blocked > 2000 && list_mixed > 300,
            "candidate lists: {list_blocked} blocked, {list_mixed} packets partly blocked"
        );
    }

    /// More undecided (lane, triangle) pairs than the put-off list holds: with foreign
    /// occluders every crossing waits for its exact test, and here ray 0's only blocker
    /// (face 0, first in the list) is put off before twenty triangles that only ray 1
    /// crosses. Both rays must come out blocked, as each does alone: the test fails
    /// if a full list is emptied without running its tests.
    #[test]
    fn list_packets_settle_a_full_queue() {
        let square = |x: f64, z: f64| {
            [
                dvec3(x - 1.0, -1.0, z),
                dvec3(x + 1.0, -1.0, z),
                dvec3(x, 1.0, z),
            ]
        };
        let mut tris = vec![(0u32, square(0.0, 0.0))];
        for k in 1..=20 {
            tris.push((k, square(10.0, -0.9 + 0.08 * k as f64)));
        }
        let occ = Occluders::new_foreign(tris);
        let mut ids: Vec<u32> = (0..occ.len() as u32).collect();
        ids.sort_by_key(|&id| occ.tris[id as usize].face);
        let up = DVec3::Z;
        let planes = Some([(up, -1.0), (up, 1.0)]);
        let segs = [
            (dvec3(0.0, 0.0, -1.0), dvec3(0.0, 0.0, 1.0)),
            (dvec3(10.0, 0.0, -1.0), dvec3(10.0, 0.0, 1.0)),
        ];
        for (l, &(x, y)) in segs.iter().enumerate() {
            assert!(occ.occluded_by(x, y, &ids, planes, &mut 0), "ray {l} alone");
        }
        let mut first = 0;
        assert_eq!(
            occ.occluded_packet_by(&segs, &ids, planes, &mut first),
            0b11
        );
    }

    /// A uniform random point of triangle `t`.
    fn point_in(t: &[DVec3; 3], rng: &mut crate::formfactor::sampling::SplitMix64) -> DVec3 {
        let (u, v) = (rng.next_f64(), rng.next_f64());
        let s = u.sqrt();
        t[0] * (1.0 - s) + t[1] * (s * (1.0 - v)) + t[2] * (s * v)
    }

    /// The box walk offers every triangle whose box meets the query box (a superset is
    /// fine: the callers test each triangle again).
    #[test]
    fn box_walk_offers_every_overlapping_triangle() {
        let tris = clutter(6, 1.0);
        let occ = Occluders::new(tris.clone());
        let bvh = occ.bvh.as_ref().unwrap();
        let mut rng = crate::formfactor::sampling::SplitMix64::new(7);
        for _ in 0..500 {
            let c = dvec3(rng.next_f64(), rng.next_f64(), rng.next_f64()) - 0.5;
            let h = DVec3::splat(0.2 * rng.next_f64());
            let (lo, hi) = (c - h, c + h);
            let mut seen = vec![false; occ.tris.len()];
            bvh.for_each_in_box(
                lo,
                hi,
                |_, _| true,
                |id| {
                    seen[id] = true;
                    false
                },
            );
            for (id, t) in occ.tris.iter().enumerate() {
                let overlaps = !(t.max.cmplt(lo).any() || t.min.cmpgt(hi).any());
                assert!(
                    !overlaps || seen[id],
                    "triangle {id} overlapping the box not offered"
                );
            }
        }
    }
}
