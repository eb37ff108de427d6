//! One pair as the exact route sees it ([`Pair`]: the two clipped polygons, the casters
//! that may come between them, the tolerances) and what the occluders take from it
//! ([`Blocked`]).

use glam::DVec3;

use super::caster::Caster;
use crate::formfactor::clip::Polygon;
use crate::formfactor::contour::ContourParams;
use crate::formfactor::shadow::solids::Solid;

/// The outer integral of one pair: what [`super::integral::blocked_integral`] needs besides the rule.
pub(crate) struct Pair<'a> {
    /// P_i clipped to P_j's front, and its unit front normal.
    pub(crate) pi: &'a Polygon,
    pub(crate) ni: DVec3,
    /// P_j clipped to P_i's front.
    pub(crate) pj: &'a Polygon,
    /// The occluder triangles that may come between them.
    pub(crate) casters: &'a [Caster],
    /// The convex solids that the casters' [`Caster::solid`] refer to.
    pub(crate) solids: &'a [Solid],
    /// Length under which a point counts as on a plane.
    pub(crate) tol: f64,
    /// The contour integral's settings, for the cells hidden whole.
    pub(crate) params: ContourParams,
}

/// What the occluders take from a pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Blocked {
    /// Nothing: no caster crosses a segment between the two polygons.
    Nothing,
    /// Everything: one caster, or one convex solid, hides all of P_j from every point
    /// of P_i.
    All,
    /// Some, and the rule worked it out.
    Part {
        /// ∫_{P_i} F(x → B_j(x)) dA_x (= A_i F^B_ij).
        blocked: f64,
        /// The outer rule's evaluations of the integrand.
        points: u32,
        /// Whether the rule's error estimate met the tolerance; false when it ran
        /// out of points ([`super::integral::MAX_POINTS`]) or of depth ([`super::integral::MAX_DEPTH`]) first.
        met: bool,
    },
}
