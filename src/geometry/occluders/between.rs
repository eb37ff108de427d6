//! Which triangles may come between two polygons: the question ([`Between`]) and the
//! conservative tests that rule a triangle out ([`PairHull`], [`HullAxes`]).

use glam::DVec3;

use super::{OccluderTriangle, Occluders, PLANE_TOLERANCE};

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
pub(crate) struct HullAxes {
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
    pub(crate) fn separates_box(&self, lo: DVec3, hi: DVec3) -> bool {
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
    pub(crate) fn separates(&self, v: &[DVec3; 3]) -> bool {
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
pub(crate) struct PairHull {
    pts: [DVec3; MAX_PAIR_POINTS],
    np: usize,
    na_len: usize,
    /// The box of the points, shrunk by the tolerance (faces merely touching the hull,
    /// like the walls around a corner, do not count).
    pub(crate) qlo: DVec3,
    pub(crate) qhi: DVec3,
    na: DVec3,
    oa: f64,
    nb: DVec3,
    ob: f64,
    ignore: (u32, u32),
}

impl PairHull {
    /// `None` when there is nothing to test (no hierarchy, or an empty polygon).
    pub(crate) fn new(occ: &Occluders, q: &Between<'_>) -> Option<Self> {
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
    pub(crate) fn hull_axes(&self) -> HullAxes {
        HullAxes::new(&self.pts[..self.np], self.na_len, self.np - self.na_len)
    }

    /// Tests 1 and 2 (cheap: a triangle passing them counts as examined in detail).
    #[inline]
    pub(crate) fn near(&self, t: &OccluderTriangle) -> bool {
        t.face != self.ignore.0
            && t.face != self.ignore.1
            && !(t.max.cmplt(self.qlo).any() || t.min.cmpgt(self.qhi).any())
    }

    /// Tests 3 and 4, for a triangle that passed [`PairHull::near`].
    #[inline]
    pub(crate) fn crosses(&self, t: &OccluderTriangle) -> bool {
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
