//! Planar-polygon geometry shared by the loader, the built-in scenes and subdivision:
//! vector area, normal, classification (triangle / planar convex quad / problem) and
//! the repair of OBJ polygons into faces the pipeline accepts.
//!
//! Tolerances are relative to the polygon's own size, so a scene means the same at any
//! scale (docs/numerics.md §6: results independent of scene scale).

use glam::{DVec2, DVec3};

/// A face whose area is below this fraction of (longest edge)² is degenerate
/// (zero-area or collinear corners).
const DEGENERATE_REL: f64 = 1e-10;
/// A corner whose turning angle has |sin| below this is collinear with its neighbours
/// and is removed (it adds a corner but no shape).
const COLLINEAR_SIN: f64 = 1e-10;
/// A quad whose corners are farther than this fraction of its longest edge from its
/// mean plane is non-planar.
const PLANAR_REL: f64 = 1e-6;

/// Most corners a face may have. Repairing a polygon costs time growing as the square
/// of its corners (the collinear-corner pass and the ear clipping each rescan it):
/// one face of 400,000 corners took 26 s to load (issue 48). Ten thousand is a circle
/// at 0.036° steps, far beyond the faces of CAD or scanning exports; the loaders refuse
/// more, naming the face.
pub(crate) const MAX_FACE_CORNERS: usize = 10_000;

/// Vector area ½ Σ (p_k − p_0) × (p_{k+1} − p_0): a fan around the first corner, so
/// rounding does not depend on the distance to the origin. Its length is the area and
/// its direction the front normal, for any planar polygon.
pub(crate) fn vector_area(c: &[DVec3]) -> DVec3 {
    let mut s = DVec3::ZERO;
    for k in 1..c.len().saturating_sub(1) {
        s += (c[k] - c[0]).cross(c[k + 1] - c[0]);
    }
    0.5 * s
}

/// Area of a planar polygon (triangle or planar quad).
pub(crate) fn polygon_area(c: &[DVec3]) -> f64 {
    vector_area(c).length()
}

/// Unit front normal of a planar polygon (counter-clockwise corners); zero when the
/// polygon is degenerate.
pub(crate) fn polygon_normal(c: &[DVec3]) -> DVec3 {
    vector_area(c).normalize_or_zero()
}

fn longest_edge(c: &[DVec3]) -> f64 {
    let n = c.len();
    (0..n)
        .map(|i| c[i].distance(c[(i + 1) % n]))
        .fold(0.0, f64::max)
}

/// What a corner list is, as far as the pipeline is concerned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Shape {
    /// Fewer than 3 distinct corners, zero area or all corners collinear.
    Degenerate,
    Triangle,
    ConvexQuad,
    NonPlanarQuad,
    NonConvexQuad,
    /// More than 4 corners.
    Polygon,
}

/// Classify a corner list without changing it.
pub(crate) fn classify(c: &[DVec3]) -> Shape {
    if c.len() < 3 {
        return Shape::Degenerate;
    }
    let l = longest_edge(c);
    let va = vector_area(c);
    if l.is_nan() || l <= 0.0 || va.length() <= DEGENERATE_REL * l * l {
        return Shape::Degenerate;
    }
    match c.len() {
        3 => Shape::Triangle,
        4 => {
            let n = va.normalize();
            let centre = (c[0] + c[1] + c[2] + c[3]) * 0.25;
            if c.iter()
                .any(|p| (*p - centre).dot(n).abs() > PLANAR_REL * l)
            {
                return Shape::NonPlanarQuad;
            }
            // Convex: every corner turns the same way as the normal, and no corner is
            // collinear with its neighbours (such a quad is really a triangle).
            let convex = (0..4).all(|i| {
                let a = c[i];
                let b = c[(i + 1) % 4];
                let d = c[(i + 2) % 4];
                let t = (b - a).cross(d - b);
                t.dot(n) > COLLINEAR_SIN * (b - a).length() * (d - b).length()
            });
            if convex {
                Shape::ConvexQuad
            } else {
                Shape::NonConvexQuad
            }
        }
        _ => Shape::Polygon,
    }
}

/// What had to be done to turn an OBJ polygon into pipeline faces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Repair {
    /// Nothing: a triangle or planar convex quad as given (possibly with duplicate or
    /// collinear corners removed).
    None,
    /// Zero area or collinear: dropped.
    Degenerate,
    /// A non-planar quad or polygon: split into triangles.
    NonPlanar,
    /// A planar non-convex quad: split into two triangles at its reflex corner.
    NonConvex,
    /// A planar polygon with more than 4 corners: triangulated (not a problem).
    Triangulated,
}

/// Turn one OBJ polygon into faces of 3 or 4 corners with the same orientation.
pub(crate) fn repair(corners: &[DVec3]) -> (Vec<Vec<DVec3>>, Repair) {
    let c = simplify(corners);
    match classify(&c) {
        Shape::Degenerate => (Vec::new(), Repair::Degenerate),
        Shape::Triangle | Shape::ConvexQuad => (vec![c], Repair::None),
        Shape::NonPlanarQuad => {
            // Split along the shorter diagonal: the two triangles then deviate least
            // from the surface the quad was meant to be.
            let parts = if c[0].distance(c[2]) <= c[1].distance(c[3]) {
                vec![vec![c[0], c[1], c[2]], vec![c[0], c[2], c[3]]]
            } else {
                vec![vec![c[1], c[2], c[3]], vec![c[1], c[3], c[0]]]
            };
            (keep_nondegenerate(parts), Repair::NonPlanar)
        }
        Shape::NonConvexQuad => {
            // A simple planar quad has at most one reflex corner r; the diagonal from r
            // lies inside, so (r, r+1, r+2) and (r, r+2, r+3) keep the orientation.
            let n = vector_area(&c);
            let r = (0..4)
                .find(|&i| {
                    let p = c[(i + 3) % 4];
                    (c[i] - p).cross(c[(i + 1) % 4] - c[i]).dot(n) <= 0.0
                })
                .unwrap_or(0);
            let q = |k: usize| c[(r + k) % 4];
            let parts = vec![vec![q(0), q(1), q(2)], vec![q(0), q(2), q(3)]];
            (keep_nondegenerate(parts), Repair::NonConvex)
        }
        Shape::Polygon => {
            let n = polygon_normal(&c);
            let l = longest_edge(&c);
            let centre = c.iter().copied().sum::<DVec3>() / c.len() as f64;
            let planar = c
                .iter()
                .all(|p| (*p - centre).dot(n).abs() <= PLANAR_REL * l);
            let tris = ear_clip(&c, n);
            let repair = if planar {
                Repair::Triangulated
            } else {
                Repair::NonPlanar
            };
            (keep_nondegenerate(tris), repair)
        }
    }
}

fn keep_nondegenerate(parts: Vec<Vec<DVec3>>) -> Vec<Vec<DVec3>> {
    parts
        .into_iter()
        .filter(|p| classify(p) != Shape::Degenerate)
        .collect()
}

/// Remove repeated corners and corners collinear with their neighbours (including
/// back-tracking spikes), which add corners but no area.
fn simplify(corners: &[DVec3]) -> Vec<DVec3> {
    let mut c: Vec<DVec3> = Vec::with_capacity(corners.len());
    for &p in corners {
        if c.last() != Some(&p) {
            c.push(p);
        }
    }
    while c.len() > 1 && c.first() == c.last() {
        c.pop();
    }
    let mut changed = true;
    while changed && c.len() > 3 {
        changed = false;
        let n = c.len();
        for i in 0..n {
            let a = c[(i + n - 1) % n];
            let b = c[i];
            let d = c[(i + 1) % n];
            let e1 = b - a;
            let e2 = d - b;
            if e1.cross(e2).length() <= COLLINEAR_SIN * e1.length() * e2.length() {
                c.remove(i);
                changed = true;
                break;
            }
        }
    }
    c
}

/// Ear-clipping triangulation of a simple polygon, projected onto the plane
/// perpendicular to `n`. Falls back to a fan for what it cannot clip (a
/// self-intersecting polygon has no consistent answer anyway).
fn ear_clip(c: &[DVec3], n: DVec3) -> Vec<Vec<DVec3>> {
    let (u, v) = n.any_orthonormal_pair();
    let p: Vec<DVec2> = c.iter().map(|q| DVec2::new(q.dot(u), q.dot(v))).collect();
    // (u, v, n) is right-handed, so counter-clockwise about n is counter-clockwise in 2D.
    let cross = |a: DVec2, b: DVec2, d: DVec2| (b - a).perp_dot(d - a);
    let inside = |q: DVec2, a: DVec2, b: DVec2, d: DVec2| {
        cross(a, b, q) >= 0.0 && cross(b, d, q) >= 0.0 && cross(d, a, q) >= 0.0
    };
    let mut idx: Vec<usize> = (0..c.len()).collect();
    let mut out = Vec::with_capacity(c.len() - 2);
    while idx.len() > 3 {
        let m = idx.len();
        let ear = (0..m).find(|&i| {
            let (ia, ib, id) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
            cross(p[ia], p[ib], p[id]) > 0.0
                && idx
                    .iter()
                    .filter(|&&k| k != ia && k != ib && k != id)
                    .all(|&k| !inside(p[k], p[ia], p[ib], p[id]))
        });
        match ear {
            Some(i) => {
                let (ia, ib, id) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
                out.push(vec![c[ia], c[ib], c[id]]);
                idx.remove(i);
            }
            None => break,
        }
    }
    for k in 1..idx.len() - 1 {
        out.push(vec![c[idx[0]], c[idx[k]], c[idx[k + 1]]]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    #[test]
    fn unit_square_area_and_normal() {
        let q = [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)];
        assert_eq!(polygon_area(&q), 1.0);
        assert_eq!(polygon_normal(&q), DVec3::Z);
        assert_eq!(classify(&q), Shape::ConvexQuad);
    }

    #[test]
    fn classifies_problems() {
        let collinear = [v(0., 0., 0.), v(1., 0., 0.), v(2., 0., 0.)];
        assert_eq!(classify(&collinear), Shape::Degenerate);
        let bent = [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.3), v(0., 1., 0.)];
        assert_eq!(classify(&bent), Shape::NonPlanarQuad);
        let dart = [v(0., 0., 0.), v(2., 0., 0.), v(0.5, 0.5, 0.), v(0., 2., 0.)];
        assert_eq!(classify(&dart), Shape::NonConvexQuad);
    }

    #[test]
    fn repairs_keep_area_and_orientation() {
        let dart = [v(0., 0., 0.), v(2., 0., 0.), v(0.5, 0.5, 0.), v(0., 2., 0.)];
        let (parts, r) = repair(&dart);
        assert_eq!(r, Repair::NonConvex);
        let a: f64 = parts.iter().map(|p| polygon_area(p)).sum();
        assert!((a - polygon_area(&dart)).abs() < 1e-12);
        assert!(parts
            .iter()
            .all(|p| polygon_normal(p).dot(DVec3::Z) > 0.999));

        // An L-shaped hexagon (area 3), clockwise about -z = counter-clockwise about z.
        let ell = [
            v(0., 0., 0.),
            v(2., 0., 0.),
            v(2., 1., 0.),
            v(1., 1., 0.),
            v(1., 2., 0.),
            v(0., 2., 0.),
        ];
        let (parts, r) = repair(&ell);
        assert_eq!(r, Repair::Triangulated);
        assert_eq!(parts.len(), 4);
        let a: f64 = parts.iter().map(|p| polygon_area(p)).sum();
        assert!((a - 3.0).abs() < 1e-12, "area {a}");
        assert!(parts
            .iter()
            .all(|p| polygon_normal(p).dot(DVec3::Z) > 0.999));
    }

    #[test]
    fn simplify_drops_midpoints_and_duplicates() {
        let q = [
            v(0., 0., 0.),
            v(0.5, 0., 0.),
            v(1., 0., 0.),
            v(1., 0., 0.),
            v(0., 1., 0.),
        ];
        let (parts, r) = repair(&q);
        assert_eq!(r, Repair::None);
        assert_eq!(
            parts,
            vec![vec![v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)]]
        );
    }
}
