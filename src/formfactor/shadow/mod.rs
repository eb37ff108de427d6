//! Exact visibility by shadow clipping: the part of a `contour` form factor that the
//! occluders between two patches take away, computed without rays.
//!
//! With occluders, F_ij = F⁰_ij − F^B_ij, where F⁰ is the exact unoccluded form factor
//! of the mutually clipped polygons (`contour`) and
//!
//! ```text
//! F^B_ij = (1/A_i) ∫_{x ∈ P_i} F(x → B_j(x)) dA_x
//! ```
//!
//! the blocked part: B_j(x) is the part of P_j that x does not see, and F(x → Q) the
//! point-to-polygon form factor of a planar polygon Q, in closed form (Lambert's
//! formula, [`point_polygon`]). Only the blocked part is integrated numerically, so
//! the quadrature error is a fraction of what the occluders take away, not of the
//! whole entry, and a pair that nothing blocks from any point comes out exact.
//!
//! **The shadow of a triangle, clipped.** A segment from x to a point y of P_j
//! crosses triangle T exactly when y lies in the cone from x spanned by T and on the
//! far side of T's plane from x (the segment then meets T's plane inside the cone,
//! i.e. inside T). Both conditions are half-spaces in y: the three planes through x
//! and an edge of T, and T's plane. So P_j ∩ shadow(T) is P_j clipped by four planes,
//! a convex polygon; no projection onto P_j's plane is needed (a central projection
//! blows up for occluder points near the plane through x parallel to P_j). Triangles
//! seen edge-on block nothing. Occluders block from both sides, as the rays do, and
//! a blocker within the ray tolerance of P_j's plane blocks nothing (as a ray ignores
//! hits that close to its end).
//!
//! **The union of the shadows**, cut into disjoint convex pieces: the k-th shadow
//! minus the cones of the shadows before it, each subtraction of a convex cone from a
//! convex piece leaving at most four convex pieces (the parts outside each of its
//! half-spaces in turn; pieces entirely outside a cone are kept whole, pieces inside
//! it dropped). F(x → B_j) is the sum over the pieces. Too many pieces (many
//! overlapping shadows) is the one way this can fail: the caller then casts rays.
//!
//! **The outer integral** over P_i is adaptive. P_i is first cut into convex cells
//! along the lines where the integrand is not smooth: where it jumps (the plane of a
//! caster that touches P_i's plane, such as a box standing on the floor: a point
//! under it sees nothing, a point beside it much), all of them, or the pair goes to
//! rays; and where it has kinks (a caster vertex lines up with an edge of P_j, or a
//! vertex of P_j with a caster edge), as far as [`cells::MAX_CELLS`] allows. Each cell is
//! fanned into triangles; on each, a 19-point degree-8 rule (Laurie 1982) gives the
//! value and the 7-point degree-5 rule embedded in it (Radon 1948, the same points'
//! first seven) its error estimate, their difference. The estimate is of the lower
//! rule, so on smooth parts it is pessimistic for the value kept. The triangle with
//! the largest estimate is cut at its edge midpoints into four (globally adaptive, as
//! QUADPACK's QAG) until the estimates add up to the tolerance. A triangle whose
//! samples all see no shadow although an occluder may come between it and P_j
//! counts as error what it could hold.
//! Cells that need no rule are settled exactly: a cell between which and P_j no
//! occluder can come blocks nothing (tested when the rule's first samples on it see
//! no shadow), and a cell from
//! which one caster or one convex solid hides all of P_j blocks F(x → P_j) at every
//! point, whose integral over the cell is the unoccluded polygon-to-polygon form
//! factor ([`super::contour`]); the same test on the whole of P_i proves a pair
//! hidden. Measured against the independent references of
//! tests/data/occluded_refs.json: within 1e-7 of group factors at the default
//! tolerance (1e-6 of each entry's F⁰).
//!
//! The method follows View3D's (Walton, NISTIR 6925: obstruction polygons projected
//! from a point of the emitter and clipped from the receiver) and Elmer's shadow
//! clipping per source point, with these departures: the shadow is clipped in 3D by
//! its cone instead of being projected, only the blocked part is integrated, and the
//! outer rule is globally adaptive with an error estimate per triangle. The rule pair
//! is the one of Laurie's CUBTRI (ACM TOMS Algorithm 584); the estimate here is the
//! plain difference of the two rules.
//!
//! **Files.** [`cone`]: the casters, and the cone of the points whose segment from x
//! crosses a caster or a convex solid; [`lambert`]: F(x → Q) in closed form;
//! [`union`]: the union of the shadows at one point, F(x → B_j(x)); [`hidden`]: tests on
//! whole polygons (no caster comes between them; one caster or solid hides all);
//! [`pair`]: a pair as this route sees it and what it loses; [`cells`]: P_i cut at the
//! lines where the integrand jumps or has kinks; [`triangles`] and [`adaptive`]: the
//! outer rule's triangles and its refinement; [`integral`]: the blocked part of a pair,
//! from these steps. The rule pair itself is in [`super::quadrature`].

mod adaptive;
mod caster;
mod cells;
mod cone;
#[cfg(test)]
mod fixtures;
mod hidden;
mod integral;
mod lambert;
mod pair;
pub(crate) mod solids;
mod triangles;
mod union;

pub(crate) use caster::Caster;
pub(crate) use cells::cut;
pub(crate) use cone::Piece;
pub(crate) use hidden::polygon_hides;
pub(crate) use integral::{blocked_integral, UNRESOLVED};
pub(crate) use lambert::point_polygon;
pub(crate) use pair::{Blocked, Pair};
pub(crate) use union::ShadowScratch;
