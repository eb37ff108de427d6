//! Tests on whole polygons, without the rule: whether any segment between two convex
//! polygons may cross a caster at all ([`segments_may_cross`], separating axes), and
//! whether one caster ([`hides`], [`polygon_hides`]) or one convex solid
//! ([`solid_hides`]) hides all of one polygon from every point of the other. They
//! settle whole pairs, and whole cells of P_i, exactly.

use glam::DVec3;

use super::caster::Caster;
use crate::formfactor::shadow::solids::Solid;

/// Whether some segment from a point of the convex polygon `t` to a point of the
/// convex polygon `q` may cross the triangle `c`: false when a plane separates `c`
/// from the convex hull H of `t` and `q` (which is the union of those segments) by
/// more than `tol`. Exact for polytopes (separating axis theorem) with the axes of H
/// known from its shape: H's faces lie in the planes of `t` and `q` and in planes
/// through an edge of one polygon and a vertex of the other; its edges are the
/// polygons' edges and segments from a vertex of one to a vertex of the other. So the
/// axes tried are those face normals, the normal of `c`, and the cross products of
/// those edges with the edges of `c`. Touching counts as separated.
pub(super) fn segments_may_cross(t: &[DVec3], q: &[DVec3], c: &[DVec3; 3], tol: f64) -> bool {
    let separates = |axis: DVec3| {
        let len = axis.length();
        if len.is_nan() || len <= 1e-300 {
            return false;
        }
        let a = axis / len;
        let (mut h_lo, mut h_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in t.iter().chain(q) {
            let d = a.dot(*p);
            h_lo = h_lo.min(d);
            h_hi = h_hi.max(d);
        }
        let (mut c_lo, mut c_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in c {
            let d = a.dot(*p);
            c_lo = c_lo.min(d);
            c_hi = c_hi.max(d);
        }
        c_lo >= h_hi - tol || c_hi <= h_lo + tol
    };
    let ce = [c[1] - c[0], c[2] - c[1], c[0] - c[2]];
    // The cheap axes first (they settle most candidates): the planes of c, of t and
    // of q, then the coordinate axes.
    if separates(ce[0].cross(ce[1]))
        || separates((t[1] - t[0]).cross(t[2] - t[0]))
        || (q.len() >= 3 && separates((q[1] - q[0]).cross(q[2] - q[0])))
        || separates(DVec3::X)
        || separates(DVec3::Y)
        || separates(DVec3::Z)
    {
        return false;
    }
    let edge_axes = |e: DVec3| ce.iter().any(|k| separates(e.cross(*k)));
    for (a, b) in [(t, q), (q, t)] {
        for k in 0..a.len() {
            let e = a[(k + 1) % a.len()] - a[k];
            // Faces of H through this edge and a vertex of the other polygon, and the
            // edge itself against c's edges.
            if b.iter().any(|&v| separates(e.cross(v - a[k]))) || edge_axes(e) {
                return false;
            }
        }
    }
    // Edges of H from a vertex of t to a vertex of q.
    !t.iter().any(|&u| q.iter().any(|&v| edge_axes(v - u)))
}

/// True when caster `c` hides all of the polygon `q` from every point of the polygon
/// `p`: every segment from a vertex x of `p` to a vertex y of `q` crosses it, with
/// margin. The conditions (y in the cone of `c` from x, and beyond `c`'s plane) are
/// affine in x for fixed y and in y for fixed x, so holding at the vertex pairs they
/// hold for all pairs of points.
pub(crate) fn hides(p: &[DVec3], q: &[DVec3], c: &Caster, tol: f64) -> bool {
    polygon_hides(p, q, &c.v, c.normal, c.offset, tol)
}

/// [`hides`] for a convex planar polygon `v` (at least 3 vertices, in order) with unit
/// normal `normal` and plane `normal · y = offset`.
pub(crate) fn polygon_hides(
    p: &[DVec3],
    q: &[DVec3],
    v: &[DVec3],
    normal: DVec3,
    offset: f64,
    tol: f64,
) -> bool {
    let side = |y: DVec3| normal.dot(y) - offset;
    let s = side(p[0]).signum();
    if p.iter().any(|&x| s * side(x) <= tol) || q.iter().any(|&y| s * side(y) >= -2.0 * tol) {
        return false;
    }
    // Seen from x, y lies on the polygon's side of the plane through x and each edge
    // (a, b); the polygon's centre tells which side that is.
    let centre = v.iter().copied().sum::<DVec3>() / v.len() as f64;
    (0..v.len()).all(|e| {
        let (a, b) = (v[e], v[(e + 1) % v.len()]);
        p.iter().all(|&x| {
            let m = (a - x).cross(b - x);
            let len = m.length();
            let inward = m.dot(centre - x).signum();
            len > 0.0 && q.iter().all(|&y| inward * m.dot(y - x) > tol * len)
        })
    })
}

/// True when the convex solid `k` hides all of the polygon `q` from every point of the
/// polygon `p`: every segment from a point of `p` to a point of `q` passes through `k`
/// shrunk by `tol` (and so through one of its real faces: a segment cannot enter and
/// leave through the same plane, so at most one of the two is the open face), and
/// neither polygon reaches into that shrunk solid. Seen from a point x, the points y
/// whose segment meets a convex set form a convex set (the segment from x to a mix of
/// two such points crosses the chord between their meeting points), and the same holds
/// with x and y swapped; so it is enough that the segments between the vertices pass
/// through.
pub(crate) fn solid_hides(p: &[DVec3], q: &[DVec3], k: &Solid, tol: f64) -> bool {
    // Outside the shrunk solid: wholly in front of one face's plane moved in by tol.
    let outside = |v: &[DVec3]| {
        k.faces
            .iter()
            .any(|f| v.iter().all(|y| f.normal.dot(*y) - f.offset > -tol))
    };
    if !outside(p) || !outside(q) || !p.iter().chain(q).all(|v| v.is_finite()) {
        return false;
    }
    // Liang–Barsky: the part of the segment a → b inside every face's plane moved in
    // by 2 tol must have length.
    let through = |a: DVec3, b: DVec3| {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for f in &k.faces {
            let s = f.normal.dot(a) - f.offset + 2.0 * tol;
            let d = f.normal.dot(b - a);
            if d == 0.0 {
                if s >= 0.0 {
                    return false;
                }
            } else if d < 0.0 {
                t0 = t0.max(-s / d);
            } else {
                t1 = t1.min(-s / d);
            }
            if t0 >= t1 {
                return false;
            }
        }
        true
    };
    p.iter().all(|&a| q.iter().all(|&b| through(a, b)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::shadow::fixtures::{box_between_squares, square_facing};
    use glam::dvec3;

    /// `solid_hides` says yes only where every segment passes through the solid (checked
    /// on random segments between the two polygons against the box itself), and says
    /// yes where no single triangle of the box hides the receiver alone.
    #[test]
    fn a_solid_hides_only_what_every_segment_through_it_shows() {
        use crate::formfactor::sampling::SplitMix64;
        let (found, _, one_by_one) = box_between_squares();
        let k = &found.solids[0];
        let through_box = |a: DVec3, b: DVec3| {
            // The segment meets the open box (0.4, 1.6) × (1, 2) × (0.4, 1.6).
            let (lo, hi) = (dvec3(0.4, 1.0, 0.4), dvec3(1.6, 2.0, 1.6));
            let (mut t0, mut t1) = (0.0f64, 1.0f64);
            for axis in 0..3 {
                let (p, d) = (a[axis], b[axis] - a[axis]);
                if d == 0.0 {
                    if p <= lo[axis] || p >= hi[axis] {
                        return false;
                    }
                    continue;
                }
                let (u, v) = ((lo[axis] - p) / d, (hi[axis] - p) / d);
                t0 = t0.max(u.min(v));
                t1 = t1.min(u.max(v));
            }
            t0 < t1
        };
        let mut rng = SplitMix64::new(11);
        let (mut yes, mut tried, mut no_single) = (0, 0, 0);
        for _ in 0..400 {
            let mut corner = |lo: f64, hi: f64| {
                let a = lo + (hi - lo) * rng.next_f64();
                let b = lo + (hi - lo) * rng.next_f64();
                (a.min(b), a.max(b))
            };
            let ((x0, x1), (z0, z1)) = (corner(-0.5, 2.5), corner(-0.5, 2.5));
            let ((u0, u1), (w0, w1)) = (corner(0.0, 2.0), corner(0.0, 2.0));
            let p = square_facing(x0, x1, z0, z1, 0.0, true);
            let q = square_facing(u0, u1, w0, w1, 3.0, false);
            tried += 1;
            if !solid_hides(p.verts(), q.verts(), k, 1e-12) {
                continue;
            }
            yes += 1;
            no_single += usize::from(
                !one_by_one
                    .iter()
                    .any(|c| hides(p.verts(), q.verts(), c, 1e-12)),
            );
            for _ in 0..200 {
                let a = dvec3(
                    x0 + (x1 - x0) * rng.next_f64(),
                    0.0,
                    z0 + (z1 - z0) * rng.next_f64(),
                );
                let b = dvec3(
                    u0 + (u1 - u0) * rng.next_f64(),
                    3.0,
                    w0 + (w1 - w0) * rng.next_f64(),
                );
                assert!(through_box(a, b), "{a} → {b} misses the box");
            }
        }
        // Not vacuous: some pairs were hidden, and in some no triangle alone hides.
        assert!(yes >= 20 && yes < tried, "hidden {yes} of {tried}");
        assert!(no_single >= 10, "only {no_single} need the solid whole");
        // A patch that reaches into the solid, or lies on its far side, is not hidden.
        let inside = square_facing(0.8, 1.2, 0.8, 1.2, 1.5, true);
        let q = square_facing(0.9, 1.1, 0.9, 1.1, 3.0, false);
        assert!(!solid_hides(inside.verts(), q.verts(), k, 1e-12));
        let above = square_facing(0.9, 1.1, 0.9, 1.1, 2.5, true);
        assert!(!solid_hides(above.verts(), q.verts(), k, 1e-12));
    }
}
