//! The `point` kernel: the paper's baseline.
//!
//! F_ij ≈ cosθ_i cosθ_j A_j / (π r²) · V(c_i, c_j), evaluated between the centroids
//! c_i, c_j, with one visibility ray between them. It is the differential-area form
//! factor dA_i → dA_j with dA_j = A_j, accurate only when r is large against the
//! patch sizes; for neighbours it overestimates without bound (1/r² at r → 0), so an
//! entry is clamped to 1 (a form factor cannot exceed 1). Rows are not renormalized:
//! their sums show the method's error, which is the point of having a baseline.

use super::geom::PatchGeom;
use super::scratch::Counters;
use crate::geometry::occluders::Occluders;

/// F_ij by the centroid kernel (0 when either patch faces away from the other's
/// centroid).
pub(crate) fn pair(
    gi: &PatchGeom,
    gj: &PatchGeom,
    occ: &Occluders,
    counters: &mut Counters,
) -> f64 {
    let d = gj.centroid - gi.centroid;
    let r2 = d.length_squared();
    let ci = gi.normal.dot(d);
    let cj = -gj.normal.dot(d);
    if !(ci > 0.0 && cj > 0.0 && r2 > 0.0) {
        counters.pairs_facing_away += 1;
        return 0.0;
    }
    counters.pairs_evaluated += 1;
    // cosθ_i cosθ_j / r² = (n_i·d)(−n_j·d) / r⁴
    let f = (ci * cj / (r2 * r2) * gj.area / std::f64::consts::PI).min(1.0);
    if !occ.any_between(&gi.between(gj)) {
        counters.pairs_unoccludable += 1;
        counters.rays_skipped += 1;
        return f;
    }
    counters.rays_cast += 1;
    counters.pairs_rays += 1;
    if occ.occluded(gi.centroid, gj.centroid, (gi.face, gj.face)) {
        0.0
    } else {
        f
    }
}
