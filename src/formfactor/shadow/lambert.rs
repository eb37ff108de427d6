//! Lambert's point-to-polygon form factor F(x → Q) in closed form: what every piece
//! of a shadow contributes at a point, and what a lit sample could hold.

use glam::DVec3;

/// The point-to-polygon form factor F(x → Q) of the planar polygon `q` seen from `x`
/// with unit normal `n`, in closed form (Lambert; e.g. Howell's catalogue, the
/// contour integral of the differential element):
///
/// ```text
/// F = |Σ_k θ_k n · (R_k × R_{k+1}) / |R_k × R_{k+1}|| / 2π,   R_k = q_k − x,
/// ```
///
/// θ_k the angle between R_k and R_{k+1}. Valid when all of `q` lies in front of x's
/// plane, as the clipped polygons do.
pub(crate) fn point_polygon(x: DVec3, n: DVec3, q: &[DVec3]) -> f64 {
    let mut s = 0.0;
    for k in 0..q.len() {
        let a = q[k] - x;
        let b = q[(k + 1) % q.len()] - x;
        let c = a.cross(b);
        let len = c.length();
        if len > 0.0 {
            s += len.atan2(a.dot(b)) * n.dot(c) / len;
        }
    }
    s.abs() / (2.0 * std::f64::consts::PI)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::shadow::fixtures::{corner_rectangle, square};

    #[test]
    fn point_polygon_matches_the_corner_formula() {
        let q = square(0.0, 0.7, 0.0, 1.3, 1.0);
        let got = point_polygon(DVec3::ZERO, DVec3::Y, q.verts());
        assert!(
            (got - corner_rectangle(0.7, 1.3, 1.0)).abs() < 1e-15,
            "{got}"
        );
        // Either orientation, and a point inside the rectangle's shadow: four corners.
        let q = square(-0.5, 1.0, -0.25, 2.0, 2.0);
        let got = point_polygon(DVec3::ZERO, DVec3::Y, q.verts());
        let want = corner_rectangle(0.5, 0.25, 2.0)
            + corner_rectangle(1.0, 0.25, 2.0)
            + corner_rectangle(0.5, 2.0, 2.0)
            + corner_rectangle(1.0, 2.0, 2.0);
        assert!((got - want).abs() < 1e-15, "{got} vs {want}");
    }
}
