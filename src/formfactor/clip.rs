//! Small fixed-capacity planar polygons (patches and their clipped parts) and
//! clipping against a plane, without heap allocation in the hot loop.
//!
//! A patch is a triangle or a convex quad; clipping a convex polygon by one plane
//! adds at most one vertex, and the `contour` kernel clips each polygon by one plane,
//! so [`MAX_VERTS`] = 8 leaves room to spare.

use glam::DVec3;

/// Capacity of a [`Polygon`].
pub(crate) const MAX_VERTS: usize = 8;

/// A closed planar polygon of at most `N` vertices; the first `n` entries of `v`
/// count, in contour order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PolygonN<const N: usize> {
    pub(crate) v: [DVec3; N],
    pub(crate) n: usize,
}

/// A patch or a patch clipped by a plane.
pub(crate) type Polygon = PolygonN<MAX_VERTS>;

/// Whether `y` (in the plane of the convex polygon `v`) lies inside it, each edge
/// widened by `tol`: `v` winds counter-clockwise seen from the side `normal` points to.
pub(crate) fn convex_holds(v: &[DVec3], normal: DVec3, y: DVec3, tol: f64) -> bool {
    (0..v.len()).all(|k| {
        let (a, b) = (v[k], v[(k + 1) % v.len()]);
        (b - a).cross(y - a).dot(normal) >= -tol * (b - a).length()
    })
}

impl<const N: usize> Default for PolygonN<N> {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl<const N: usize> PolygonN<N> {
    /// No vertex.
    pub(crate) const EMPTY: Self = PolygonN {
        v: [DVec3::ZERO; N],
        n: 0,
    };

    /// A polygon from up to `N` vertices (extra vertices are ignored).
    pub(crate) fn new(pts: &[DVec3]) -> Self {
        let mut out = Self::EMPTY;
        let n = pts.len().min(N);
        out.v[..n].copy_from_slice(&pts[..n]);
        out.n = n;
        out
    }

    /// The vertices that count.
    #[inline]
    pub(crate) fn verts(&self) -> &[DVec3] {
        &self.v[..self.n]
    }

    /// Vector area (½ Σ v_k × v_{k+1}): its length is the area, its direction the
    /// normal of the side the contour winds counter-clockwise around.
    pub(crate) fn vector_area(&self) -> DVec3 {
        if self.n < 3 {
            return DVec3::ZERO;
        }
        let o = self.v[0];
        let mut s = DVec3::ZERO;
        for k in 1..self.n - 1 {
            s += (self.v[k] - o).cross(self.v[k + 1] - o);
        }
        0.5 * s
    }

    /// Mean of the vertices (a point inside a convex polygon).
    pub(crate) fn vertex_mean(&self) -> DVec3 {
        let mut s = DVec3::ZERO;
        for p in self.verts() {
            s += *p;
        }
        s / self.n.max(1) as f64
    }

    /// Keeps the part where `normal·x − offset ≥ 0` (Sutherland–Hodgman against one
    /// plane). Signed distances within `tol` of zero count as on the plane, so a
    /// polygon touching the plane along an edge is kept whole and not split into
    /// slivers.
    pub(crate) fn clip_front(&self, normal: DVec3, offset: f64, tol: f64) -> Self {
        let mut out = Self::EMPTY;
        self.clip_front_into(normal, offset, tol, &mut out);
        out
    }

    /// [`PolygonN::clip_front`] into `out` (no copy of a whole polygon).
    pub(crate) fn clip_front_into(&self, normal: DVec3, offset: f64, tol: f64, out: &mut Self) {
        let mut d = [0.0; N];
        self.distances(normal, offset, tol, &mut d);
        self.clip_by(&d, out);
    }

    /// [`PolygonN::clip_front`] in place, with the same result bit for bit; `spare` is
    /// working memory. Nothing is copied when the plane does not cut the polygon, and
    /// only the vertices kept when it does.
    pub(crate) fn clip_front_in_place(
        &mut self,
        normal: DVec3,
        offset: f64,
        tol: f64,
        spare: &mut Self,
    ) {
        let mut d = [0.0; N];
        let (keep, drop) = self.distances(normal, offset, tol, &mut d);
        if !drop {
            return;
        }
        if !keep {
            self.n = 0;
            return;
        }
        self.clip_by(&d, spare);
        self.v[..spare.n].copy_from_slice(&spare.v[..spare.n]);
        self.n = spare.n;
    }

    /// The signed distances of the vertices to the plane, within `tol` of zero counted
    /// as zero, into `d`; whether some vertex is kept (d ≥ 0) and some dropped (d < 0).
    #[inline]
    fn distances(&self, normal: DVec3, offset: f64, tol: f64, d: &mut [f64; N]) -> (bool, bool) {
        let (mut keep, mut drop) = (false, false);
        for (k, p) in self.verts().iter().enumerate() {
            let x = normal.dot(*p) - offset;
            d[k] = if x.abs() <= tol { 0.0 } else { x };
            keep |= d[k] >= 0.0;
            drop |= d[k] < 0.0;
        }
        (keep, drop)
    }

    /// Sutherland–Hodgman with the vertices' distances `d` given.
    #[inline]
    fn clip_by(&self, d: &[f64; N], out: &mut Self) {
        out.n = 0;
        if self.n == 0 {
            return;
        }
        let mut prev = self.v[self.n - 1];
        let mut dprev = d[self.n - 1];
        for (&cur, &dcur) in self.verts().iter().zip(d) {
            if dcur >= 0.0 {
                if dprev < 0.0 && dcur > 0.0 {
                    out.push(prev + (cur - prev) * (dprev / (dprev - dcur)));
                }
                out.push(cur);
            } else if dprev > 0.0 {
                out.push(prev + (cur - prev) * (dprev / (dprev - dcur)));
            }
            prev = cur;
            dprev = dcur;
        }
    }

    #[inline]
    fn push(&mut self, p: DVec3) {
        if self.n < N {
            self.v[self.n] = p;
            self.n += 1;
        } else {
            debug_assert!(false, "polygon capacity exceeded");
        }
    }
}

/// One directed polygon edge: `start + t·dir` for t in [0, len], `dir` unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Edge {
    pub(crate) start: DVec3,
    pub(crate) dir: DVec3,
    pub(crate) len: f64,
}

/// The edges of a polygon in contour order; zero-length edges are dropped (they
/// contribute nothing to a contour integral).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct EdgeSet {
    pub(crate) e: [Edge; MAX_VERTS],
    pub(crate) n: usize,
}

impl EdgeSet {
    pub(crate) fn from_polygon(p: &Polygon) -> Self {
        let blank = Edge {
            start: DVec3::ZERO,
            dir: DVec3::ZERO,
            len: 0.0,
        };
        let mut out = EdgeSet {
            e: [blank; MAX_VERTS],
            n: 0,
        };
        for k in 0..p.n {
            let a = p.v[k];
            let b = p.v[(k + 1) % p.n];
            let d = b - a;
            let len = d.length();
            if len > 0.0 {
                out.e[out.n] = Edge {
                    start: a,
                    dir: d / len,
                    len,
                };
                out.n += 1;
            }
        }
        out
    }

    #[inline]
    pub(crate) fn edges(&self) -> &[Edge] {
        &self.e[..self.n]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::dvec3;

    fn unit_square() -> Polygon {
        Polygon::new(&[
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(1.0, 1.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
        ])
    }

    /// In place or into another polygon, a clip gives the same vertices bit for bit:
    /// planes that miss, cut, touch (within the tolerance) and contain the square.
    #[test]
    fn clipping_in_place_equals_clipping_into() {
        let sq = unit_square();
        for (normal, offset) in [
            (dvec3(1.0, 0.0, 0.0), 0.5),
            (dvec3(1.0, 1.0, 0.0).normalize(), 0.3),
            (dvec3(-1.0, 0.2, 0.0).normalize(), -0.1),
            (dvec3(1.0, 0.0, 0.0), 1.0 + 1e-13),
            (dvec3(1.0, 0.0, 0.0), -2.0),
            (dvec3(1.0, 0.0, 0.0), 2.0),
            (dvec3(0.0, 0.0, 1.0), 0.0),
        ] {
            let want = sq.clip_front(normal, offset, 1e-12);
            let (mut got, mut spare) = (sq, Polygon::EMPTY);
            got.clip_front_in_place(normal, offset, 1e-12, &mut spare);
            assert_eq!(got.verts(), want.verts(), "{normal} {offset}");
        }
    }

    #[test]
    fn vector_area_of_square() {
        let a = unit_square().vector_area();
        assert!((a - dvec3(0.0, 0.0, 1.0)).length() < 1e-15);
    }

    #[test]
    fn clip_halves_square() {
        let c = unit_square().clip_front(dvec3(1.0, 0.0, 0.0), 0.5, 1e-12);
        assert_eq!(c.n, 4);
        assert!((c.vector_area().z - 0.5).abs() < 1e-15);
        for p in c.verts() {
            assert!(p.x >= 0.5 - 1e-15);
        }
    }

    #[test]
    fn clip_diagonal_gives_pentagon() {
        // keep x + y ≥ 0.5: cuts one corner off.
        let n = dvec3(1.0, 1.0, 0.0).normalize();
        let c = unit_square().clip_front(n, 0.5 * n.x, 1e-12);
        assert_eq!(c.n, 5);
        assert!((c.vector_area().z - (1.0 - 0.125)).abs() < 1e-14);
    }

    #[test]
    fn touching_plane_keeps_whole_polygon() {
        // The square lies in x ≥ 0 and touches x = 0 along an edge.
        let c = unit_square().clip_front(dvec3(1.0, 0.0, 0.0), 0.0, 1e-12);
        assert_eq!(c.n, 4);
        let c = unit_square().clip_front(dvec3(-1.0, 0.0, 0.0), 0.0, 1e-12);
        assert!(c.vector_area().length() < 1e-15);
    }

    #[test]
    fn edges_skip_zero_length() {
        let p = Polygon::new(&[
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
        ]);
        assert_eq!(EdgeSet::from_polygon(&p).n, 3);
    }
}
