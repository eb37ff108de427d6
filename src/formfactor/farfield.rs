//! Well-separated pairs for the `contour` method: a tensor Gauss rule on both patches.
//!
//! When two patches are far apart relative to their size and neither reaches behind
//! the other's plane, the kernel cosθ_i cosθ_j / (π r²) = (n_i·d)(−n_j·d) / (π |d|⁴)
//! is analytic over the whole pair: its only singularities are at complex points where
//! |d|² = 0, at an imaginary distance of at least the gap between the patches. A
//! q × q Gauss–Legendre rule on each patch (q⁴ kernel evaluations, no transcendental
//! functions) then converges like ρ^(−2q) with ρ = b + √(b² + 1), b = gap / radius
//! (the same Bernstein-ellipse bound as in [`super::contour`]), so for most pairs of
//! a large scene a handful of points reach the target `quad_tol` and cost a fraction
//! of the 16 edge pairs of the contour integral. Pairs that are close, touching or
//! need clipping go to the contour integral.
//!
//! Maps from [-1, 1]² onto a patch: bilinear for quads (Jacobian |∂x/∂u × ∂x/∂v|),
//! the collapsed (Duffy) square for triangles, x = a + s (b − a) + s t (c − b) with
//! s, t ∈ [0, 1] and Jacobian 2A·s; both are polynomial, so Gauss points stay exact
//! for polynomial integrands.

use glam::DVec3;

use super::quadrature::GaussTable;

/// Largest order per dimension used for far pairs (q⁴ = 81 kernel evaluations, about
/// half the cost of the contour integral of two quads; at q = 4 the tensor rule would
/// cost more than the contour integral).
pub const MAX_FAR_ORDER: usize = 3;

/// Constant in front of the error bound ρ^(−2q) (see [`far_order`]). The kernel has
/// double poles, which put a factor growing with q in front of ρ^(−2q); measured on
/// cube pairs (test below) the actual error reaches ~250·ρ^(−6) at q = 3, so 1000
/// leaves a margin of 4.
const SAFETY: f64 = 1000.0;

/// Gauss points with area weights (Σ w = area) on one patch, for one order.
#[derive(Clone, Copy, Debug)]
pub struct PatchPoints {
    pub p: [DVec3; MAX_FAR_ORDER * MAX_FAR_ORDER],
    pub w: [f64; MAX_FAR_ORDER * MAX_FAR_ORDER],
    pub n: usize,
}

impl PatchPoints {
    /// The q × q rule (q clamped to 1..=MAX_FAR_ORDER) on a triangle or quad.
    pub fn new(corners: &[DVec3], area: f64, q: usize, gauss: &GaussTable) -> Self {
        let q = q.clamp(1, MAX_FAR_ORDER);
        let rule = gauss.rule(q);
        let mut out = PatchPoints {
            p: [DVec3::ZERO; MAX_FAR_ORDER * MAX_FAR_ORDER],
            w: [0.0; MAX_FAR_ORDER * MAX_FAR_ORDER],
            n: 0,
        };
        for &(xu, wu) in rule {
            for &(xv, wv) in rule {
                let (s, t) = (0.5 * (xu + 1.0), 0.5 * (xv + 1.0));
                let w = 0.25 * wu * wv;
                let (p, j) = if corners.len() == 3 {
                    let (a, b, c) = (corners[0], corners[1], corners[2]);
                    (a + (b - a) * s + (c - b) * (s * t), 2.0 * area * s)
                } else {
                    let c = corners;
                    let x = c[0] * ((1.0 - s) * (1.0 - t))
                        + c[1] * (s * (1.0 - t))
                        + c[2] * (s * t)
                        + c[3] * ((1.0 - s) * t);
                    let du = (c[1] - c[0]) * (1.0 - t) + (c[2] - c[3]) * t;
                    let dv = (c[3] - c[0]) * (1.0 - s) + (c[2] - c[1]) * s;
                    (x, du.cross(dv).length())
                };
                out.p[out.n] = p;
                out.w[out.n] = w * j;
                out.n += 1;
            }
        }
        out
    }
}

/// The order per dimension that meets relative error `tol` for two patches with a gap
/// of at least `gap` and radii (centroid to farthest corner) at most `radius`, or
/// `None` when more than [`MAX_FAR_ORDER`] points would be needed (or they touch).
#[inline]
pub fn far_order(gap: f64, radius: f64, tol: f64) -> Option<usize> {
    if gap.is_nan() || gap <= 0.0 || radius <= 0.0 {
        return None;
    }
    let b = gap / radius;
    let rho = b + (b * b + 1.0).sqrt();
    // Four dimensions, each contributing its own ρ^(−2q) error, times SAFETY.
    let q = ((SAFETY / tol).ln() / (2.0 * rho.ln())).ceil();
    if q.is_finite() && q <= MAX_FAR_ORDER as f64 {
        Some((q as usize).max(1))
    } else {
        None
    }
}

/// A_i F_ij (unoccluded) by the tensor rule: Σ_a Σ_b w_a w_b (n_i·d)(−n_j·d) / (π |d|⁴).
/// Valid only when both cosines are non-negative over the whole pair (the caller
/// checks that neither patch reaches behind the other's plane).
pub fn area_form_factor(pi: &PatchPoints, ni: DVec3, pj: &PatchPoints, nj: DVec3) -> f64 {
    let mut sum = 0.0;
    for a in 0..pi.n {
        let x = pi.p[a];
        let mut inner = 0.0;
        for b in 0..pj.n {
            let d = pj.p[b] - x;
            let r2 = d.length_squared();
            inner += pj.w[b] * ni.dot(d) * -nj.dot(d) / (r2 * r2);
        }
        sum += pi.w[a] * inner;
    }
    sum / std::f64::consts::PI
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::contour::{self, ContourParams};
    use crate::formfactor::polygon::Polygon;
    use crate::formfactor::quadrature::gauss_table;
    use glam::dvec3;

    #[test]
    fn weights_sum_to_area() {
        let tri = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(2.0, 0.0, 0.0),
            dvec3(0.0, 1.0, 1.0),
        ];
        let quad = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(2.0, 0.0, 0.0),
            dvec3(1.5, 1.0, 0.0),
            dvec3(0.0, 2.0, 0.0),
        ];
        for q in 1..=MAX_FAR_ORDER {
            let t = PatchPoints::new(&tri, 2f64.sqrt(), q, gauss_table());
            assert!((t.w[..t.n].iter().sum::<f64>() - 2f64.sqrt()).abs() < 1e-14);
            let u = PatchPoints::new(&quad, 2.5, q, gauss_table());
            assert!((u.w[..u.n].iter().sum::<f64>() - 2.5).abs() < 1e-14);
        }
    }

    #[test]
    fn agrees_with_contour_when_far() {
        // A tilted triangle facing a quad from a distance of several sizes.
        let quad = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(1.0, 1.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
        ];
        let nq = dvec3(0.0, 0.0, 1.0);
        for dist in [4.0, 8.0, 20.0] {
            let tri = [
                dvec3(0.3, 0.2, dist),
                dvec3(0.4, 1.1, dist + 0.3),
                dvec3(1.2, 0.5, dist - 0.2),
            ];
            let nt = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize();
            let (tri, nt) = if nt.z > 0.0 {
                ([tri[0], tri[2], tri[1]], -nt)
            } else {
                (tri, nt)
            };
            let area = 0.5 * (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
            let exact = contour::area_form_factor(
                &Polygon::new(&quad),
                &Polygon::new(&tri),
                gauss_table(),
                ContourParams {
                    max_order: 16,
                    tol: 1e-14,
                },
            );
            let ci = quad.iter().sum::<DVec3>() / 4.0;
            let cj = tri.iter().sum::<DVec3>() / 3.0;
            let radius = quad
                .iter()
                .map(|p| (*p - ci).length())
                .chain(tri.iter().map(|p| (*p - cj).length()))
                .fold(0.0, f64::max);
            let gap = (ci - cj).length() - 2.0 * radius;
            for tol in [1e-6, 1e-9] {
                let Some(q) = far_order(gap, radius, tol) else {
                    continue;
                };
                let v = area_form_factor(
                    &PatchPoints::new(&quad, 1.0, q, gauss_table()),
                    nq,
                    &PatchPoints::new(&tri, area, q, gauss_table()),
                    nt,
                );
                let rel = (v - exact).abs() / exact;
                assert!(rel < tol, "dist {dist} tol {tol} q {q}: rel {rel:e}");
            }
        }
    }
}

#[cfg(test)]
mod calibrate {
    use super::*;
    use crate::formfactor::contour::{self, ContourParams};
    use crate::formfactor::polygon::Polygon;
    use crate::formfactor::quadrature::gauss_table;
    use glam::dvec3;

    /// The bound behind [`far_order`], checked on every pair of a cube corner patch
    /// (18 × 18 per face) with the patches of the adjacent and the opposite face:
    /// actual relative error ≤ SAFETY · ρ^(−2q) for q = 1..=3 (or below 1e-12, the
    /// accuracy of the contour reference for far pairs).
    #[test]
    fn error_bound_holds_on_cube_pairs() {
        let m = 18;
        let h = 1.0 / m as f64;
        let quad = |o: DVec3, u: DVec3, v: DVec3| [o, o + u, o + u + v, o + v];
        let pi = quad(DVec3::ZERO, dvec3(h, 0.0, 0.0), dvec3(0.0, h, 0.0));
        let ni = dvec3(0.0, 0.0, 1.0);
        let ci = pi.iter().sum::<DVec3>() / 4.0;
        let r = (pi[0] - ci).length();
        let mut worst = [0.0f64; MAX_FAR_ORDER + 1];
        for a in 0..m {
            for k in 1..m {
                let (x, y, z) = (a as f64 * h, k as f64 * h, 1.0);
                let side = quad(dvec3(x, 0.0, y), dvec3(0.0, 0.0, h), dvec3(h, 0.0, 0.0));
                let top = quad(dvec3(x, y, z), dvec3(0.0, h, 0.0), dvec3(h, 0.0, 0.0));
                for (pj, nj) in [(side, dvec3(0.0, 1.0, 0.0)), (top, dvec3(0.0, 0.0, -1.0))] {
                    let cj = pj.iter().sum::<DVec3>() / 4.0;
                    let gap = (ci - cj).length() - 2.0 * r;
                    if gap <= 0.0 {
                        continue;
                    }
                    let exact = contour::area_form_factor(
                        &Polygon::new(&pi),
                        &Polygon::new(&pj),
                        gauss_table(),
                        ContourParams {
                            max_order: 16,
                            tol: 1e-15,
                        },
                    );
                    let b = gap / r;
                    let rho = b + (b * b + 1.0).sqrt();
                    for (q, w) in worst.iter_mut().enumerate().skip(1) {
                        let v = area_form_factor(
                            &PatchPoints::new(&pi, h * h, q, gauss_table()),
                            ni,
                            &PatchPoints::new(&pj, h * h, q, gauss_table()),
                            nj,
                        );
                        let rel = ((v - exact) / exact).abs();
                        let bound = (SAFETY * rho.powi(-2 * q as i32)).max(1e-12);
                        *w = w.max(rel / bound);
                    }
                }
            }
        }
        assert!(
            worst[1..].iter().all(|&w| w < 1.0),
            "actual/bound per q: {worst:?}"
        );
    }
}
