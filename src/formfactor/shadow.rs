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
//! vertex of P_j with a caster edge), as far as [`MAX_CELLS`] allows. Each cell is
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

use std::collections::BinaryHeap;

use glam::DVec3;

use super::contour::{area_form_factor, ContourParams};
use super::polygon::{Polygon, PolygonN, MAX_VERTS};
use super::quadrature::gauss_table;
use super::solids::{Solid, NO_SOLID};

/// A receiver piece: `P_j` (at most 8 vertices) clipped by the four planes of a cone
/// (one vertex more per plane).
pub(crate) type Piece = PolygonN<16>;

/// Most pieces the union of the shadows of one point may be cut into before the
/// pair goes to rays.
const MAX_PIECES: usize = 256;

/// An occluder triangle prepared for one pair: corners and unit plane normal.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Caster {
    pub(crate) v: [DVec3; 3],
    pub(crate) normal: DVec3,
    pub(crate) offset: f64,
    /// The convex solid it belongs to ([`super::solids`]), or [`NO_SOLID`].
    pub(crate) solid: u32,
}

impl Caster {
    /// None for a degenerate triangle (it blocks nothing).
    pub(crate) fn new(v: [DVec3; 3]) -> Option<Self> {
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let len = n.length();
        if !(len > 0.0 && len.is_finite()) {
            return None;
        }
        let normal = n / len;
        Some(Caster {
            v,
            normal,
            offset: normal.dot(v[0]),
            solid: NO_SOLID,
        })
    }

    /// The same caster, part of solid `solid` (or [`NO_SOLID`]).
    pub(crate) fn in_solid(self, solid: u32) -> Self {
        Caster { solid, ..self }
    }
}

/// A half-space `normal · y ≥ offset`.
#[derive(Clone, Copy, Debug)]
struct Half {
    normal: DVec3,
    offset: f64,
}

/// Most half-spaces of a cone: a triangle's four, a solid's silhouette planes and the
/// planes of the faces x sees (a box: at most six and three).
const MAX_HALVES: usize = 12;

/// The points y whose segment from x crosses a caster: an intersection of half-spaces.
#[derive(Clone, Copy, Debug)]
struct Cone {
    h: [Half; MAX_HALVES],
    n: usize,
}

/// What a convex solid hides from one point.
enum SolidShadow {
    /// Nothing (the point lies on one of its faces).
    Nothing,
    /// What lies in the cone written out.
    Cone,
    /// Not decided as a whole: its triangles one by one.
    Triangles,
}

impl Default for Cone {
    fn default() -> Self {
        Cone::EMPTY
    }
}

impl Cone {
    /// No half-space yet.
    const EMPTY: Cone = Cone {
        h: [Half {
            normal: DVec3::ZERO,
            offset: 0.0,
        }; MAX_HALVES],
        n: 0,
    };

    fn halves(&self) -> &[Half] {
        &self.h[..self.n]
    }

    /// Adds a half-space; false when the cone is full.
    fn push(&mut self, h: Half) -> bool {
        if self.n == MAX_HALVES {
            return false;
        }
        self.h[self.n] = h;
        self.n += 1;
        true
    }

    /// The half-space of the points beyond the plane `normal · y = offset` seen from a
    /// point at signed distance `side` from it, by more than the tolerance band of the
    /// clip (a blocker lying on P_j's plane blocks nothing, as a ray ignores hits that
    /// close to its end).
    fn beyond(normal: DVec3, offset: f64, side: f64, tol: f64) -> Half {
        let s = side.signum();
        Half {
            normal: -s * normal,
            offset: -s * offset + 2.0 * tol,
        }
    }

    /// The half-space bounded by the plane through `x`, `a` and `b` that holds
    /// `inside`; None when the plane is undefined (x on the line of a, b).
    fn through(x: DVec3, a: DVec3, b: DVec3, inside: DVec3) -> Option<Half> {
        let m = (a - x).cross(b - x);
        let len = m.length();
        if len.is_nan() || len <= 0.0 {
            return None;
        }
        let m = if m.dot(inside - x) < 0.0 {
            -m / len
        } else {
            m / len
        };
        Some(Half {
            normal: m,
            offset: m.dot(x),
        })
    }

    /// Makes this the cone of `t` seen from `x`; false when `t` is seen edge-on (the
    /// cone is then not to be used). `tol`: length under which a point counts as on a
    /// plane. Written in place: a cone is 400 bytes, and a copy per caster and point
    /// showed in the profile.
    fn set_triangle(&mut self, x: DVec3, t: &Caster, tol: f64) -> bool {
        self.n = 0;
        let side = t.normal.dot(x) - t.offset;
        if side.abs() <= tol {
            return false;
        }
        self.push(Self::beyond(t.normal, t.offset, side, tol));
        for k in 0..3 {
            let (p, q, r) = (t.v[k], t.v[(k + 1) % 3], t.v[(k + 2) % 3]);
            // x on the line of an edge: in the plane, edge-on.
            match Self::through(x, p, q, r) {
                Some(h) => self.push(h),
                None => return false,
            };
        }
        true
    }

    /// What the convex solid `k` hides of `receiver` from `x` ([`super::solids`]): the
    /// cone of its silhouette beyond the faces x sees, written into `c`.
    fn of_solid(x: DVec3, k: &Solid, receiver: &Piece, tol: f64, c: &mut Cone) -> SolidShadow {
        let mut side = [0.0; super::solids::MAX_FACES];
        let mut sees = 0u32;
        for (f, face) in k.faces.iter().enumerate() {
            side[f] = face.normal.dot(x) - face.offset;
            if side[f] > tol {
                sees |= 1 << f;
            }
        }
        c.n = 0;
        if sees == 0 {
            // x inside K or on its surface. On the open face alone (the floor under a
            // box), every segment into K's side of its plane leaves through a real
            // face. On real faces that P_j lies wholly in front of (x on the patch's
            // own face), no segment enters K. Otherwise (strictly inside, on an edge,
            // or on a real face with P_j partly behind it), the triangles decide.
            let faces = &k.faces[..];
            let on = |f: usize| side[f] >= -tol;
            let open = faces.iter().position(|f| f.open).filter(|&f| on(f));
            let real_on = || (0..faces.len()).filter(|&f| !faces[f].open && on(f));
            return match open {
                Some(f) if real_on().next().is_none() => {
                    c.push(Self::beyond(faces[f].normal, faces[f].offset, 1.0, tol));
                    SolidShadow::Cone
                }
                None if real_on().next().is_some()
                    && real_on().all(|f| {
                        receiver
                            .verts()
                            .iter()
                            .all(|y| faces[f].normal.dot(*y) - faces[f].offset > tol)
                    }) =>
                {
                    SolidShadow::Nothing
                }
                _ => SolidShadow::Triangles,
            };
        }
        for (f, face) in k.faces.iter().enumerate() {
            if sees & (1 << f) != 0 && !c.push(Self::beyond(face.normal, face.offset, 1.0, tol)) {
                return SolidShadow::Triangles;
            }
        }
        for e in &k.edges {
            let [f, g] = e.faces.map(|f| sees & (1 << f) != 0);
            if f != g {
                match Self::through(x, e.a, e.b, k.centre) {
                    Some(h) if c.push(h) => {}
                    _ => return SolidShadow::Triangles,
                }
            }
        }
        SolidShadow::Cone
    }

    /// True when no point of `p` lies inside (`p` entirely outside one half-space).
    fn misses(&self, p: &Piece, tol: f64) -> bool {
        self.halves()
            .iter()
            .any(|h| p.verts().iter().all(|v| h.normal.dot(*v) - h.offset <= tol))
    }
}

/// A piece worth keeping: three vertices or more (slivers of area 0 add nothing).
fn usable(p: &Piece) -> bool {
    p.n >= 3
}

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

/// Working memory of [`blocked_at`] and [`blocked_integral`], reused.
#[derive(Debug, Default)]
pub(crate) struct ShadowScratch {
    clip: Clip,
    /// The cone of the caster or solid at hand.
    cone: Cone,
    active: Vec<Caster>,
    loose: Vec<Caster>,
    cells: Vec<Piece>,
    /// The outer rule's open triangles.
    open: BinaryHeap<Open>,
}

/// Working memory of [`shadow_part`].
#[derive(Debug, Default)]
struct Clip {
    /// The cones of the shadows so far at this point.
    cones: Vec<Cone>,
    pieces: Vec<Piece>,
    next: Vec<Piece>,
    /// The shadow being clipped.
    shadow: Piece,
    /// Working memory of the clips.
    spare: Piece,
}

/// F(x → B_j(x)): the form factor from the point `x` (unit normal `n`) to the part of
/// `receiver` (P_j) that the `casters` and `solids` hide from it. None when the union of the
/// shadows needs more than [`MAX_PIECES`] pieces, or a piece more vertices than a
/// [`Piece`] holds.
pub(crate) fn blocked_at(
    x: DVec3,
    n: DVec3,
    receiver: &Piece,
    casters: &[Caster],
    solids: &[&Solid],
    tol: f64,
    s: &mut ShadowScratch,
) -> Option<f64> {
    let ShadowScratch { clip, cone, .. } = s;
    clip.cones.clear();
    let mut total = 0.0;
    for k in solids {
        match Cone::of_solid(x, k, receiver, tol, cone) {
            SolidShadow::Nothing => {}
            SolidShadow::Cone => shadow_part(x, n, receiver, cone, tol, clip, &mut total)?,
            SolidShadow::Triangles => {
                for t in &k.triangles {
                    if cone.set_triangle(x, t, tol) {
                        shadow_part(x, n, receiver, cone, tol, clip, &mut total)?;
                    }
                }
            }
        }
    }
    for t in casters {
        if cone.set_triangle(x, t, tol) {
            shadow_part(x, n, receiver, cone, tol, clip, &mut total)?;
        }
    }
    Some(total)
}

/// Adds to `total` F(x → ·) of the part of `receiver` in `cone` and outside the cones
/// of the shadows before it (`clip.cones`), to which `cone` is then added.
fn shadow_part(
    x: DVec3,
    n: DVec3,
    receiver: &Piece,
    cone: &Cone,
    tol: f64,
    clip: &mut Clip,
    total: &mut f64,
) -> Option<()> {
    if cone.misses(receiver, tol) {
        return Some(());
    }
    // This shadow on P_j, then minus the cones of the shadows before it. The first
    // clip writes the receiver's kept part straight into `shadow` (no copy of it first).
    let Clip {
        cones,
        pieces,
        next,
        shadow,
        spare,
    } = clip;
    let mut halves = cone.halves().iter();
    match halves.next() {
        Some(h) => {
            if receiver.n == receiver.v.len() {
                return None;
            }
            receiver.clip_front_into(h.normal, h.offset, tol, shadow);
        }
        None => *shadow = *receiver,
    }
    if usable(shadow) {
        for h in halves {
            if shadow.n == shadow.v.len() {
                return None;
            }
            shadow.clip_front_in_place(h.normal, h.offset, tol, spare);
            if !usable(shadow) {
                break;
            }
        }
    }
    let earlier = cones.len();
    cones.push(*cone);
    if !usable(shadow) {
        return Some(());
    }
    if earlier == 0 {
        *total += point_polygon(x, n, shadow.verts());
        return Some(());
    }
    pieces.clear();
    pieces.push(*shadow);
    for c in &cones[..earlier] {
        next.clear();
        for piece in pieces.iter() {
            if !subtract(piece, c, tol, next, spare) {
                return None;
            }
        }
        std::mem::swap(pieces, next);
        if pieces.is_empty() {
            break;
        }
        if pieces.len() > MAX_PIECES {
            return None;
        }
    }
    for piece in pieces.iter() {
        *total += point_polygon(x, n, piece.verts());
    }
    Some(())
}

/// Appends the convex pieces of `p` outside the cone `c` to `out`; false when a piece
/// would have more vertices than a [`Piece`] holds. `spare`: working memory.
fn subtract(p: &Piece, c: &Cone, tol: f64, out: &mut Vec<Piece>, spare: &mut Piece) -> bool {
    if c.misses(p, tol) {
        out.push(*p);
        return true;
    }
    let mut inside = *p;
    for h in c.halves() {
        if inside.n == inside.v.len() {
            return false;
        }
        inside.clip_front_into(-h.normal, -h.offset, tol, spare);
        if usable(spare) {
            out.push(*spare);
        }
        inside.clip_front_in_place(h.normal, h.offset, tol, spare);
        if !usable(&inside) {
            return true;
        }
    }
    true
}

/// The 7-point degree-5 rule on a triangle (Radon 1948; e.g. Stroud T2:5-1):
/// barycentric points and weights (summing to 1), centroid first, then the two orbits
/// of three.
const RADON: [([f64; 3], f64); 7] = {
    const S15: f64 = 3.872_983_346_207_417; // √15
    const A1: f64 = (6.0 - S15) / 21.0;
    const B1: f64 = (9.0 + 2.0 * S15) / 21.0;
    const A2: f64 = (6.0 + S15) / 21.0;
    const B2: f64 = (9.0 - 2.0 * S15) / 21.0;
    const W1: f64 = (155.0 - S15) / 1200.0;
    const W2: f64 = (155.0 + S15) / 1200.0;
    [
        ([1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0], 9.0 / 40.0),
        ([B1, A1, A1], W1),
        ([A1, B1, A1], W1),
        ([A1, A1, B1], W1),
        ([B2, A2, A2], W2),
        ([A2, B2, A2], W2),
        ([A2, A2, B2], W2),
    ]
};

/// The 19-point degree-8 rule on a triangle in which [`RADON`]'s seven points are
/// embedded (Laurie 1982, ACM TOMS 8(2), Algorithm 584 CUBTRI): the same seven points
/// first, in [`RADON`]'s order and with their own weights, then an orbit of three at
/// `A3`, one at `A4` and the six points (1 − A3 − A4, A3, A4). Weights sum to 1.
const LAURIE: [([f64; 3], f64); 19] = {
    let r = RADON;
    const A3: f64 = 0.232_102_326_775_050_4;
    const A4: f64 = 0.029_480_860_884_439_6;
    const B3: f64 = 1.0 - 2.0 * A3;
    const B4: f64 = 1.0 - 2.0 * A4;
    const C: f64 = 1.0 - A3 - A4;
    const W0: f64 = 0.037_861_091_200_314_7;
    const W1: f64 = 0.037_620_425_413_182_9;
    const W2: f64 = 0.078_357_352_244_117_4;
    const W3: f64 = 0.116_271_479_656_965_9;
    const W4: f64 = 0.013_444_267_375_165_5;
    const W6: f64 = 0.037_509_722_455_231_7;
    [
        (r[0].0, W0),
        (r[1].0, W1),
        (r[2].0, W1),
        (r[3].0, W1),
        (r[4].0, W2),
        (r[5].0, W2),
        (r[6].0, W2),
        ([B3, A3, A3], W3),
        ([A3, B3, A3], W3),
        ([A3, A3, B3], W3),
        ([B4, A4, A4], W4),
        ([A4, B4, A4], W4),
        ([A4, A4, B4], W4),
        ([C, A3, A4], W6),
        ([C, A4, A3], W6),
        ([A3, C, A4], W6),
        ([A4, C, A3], W6),
        ([A3, A4, C], W6),
        ([A4, A3, C], W6),
    ]
};

/// The share of a pair's tolerance that the exact route treats as nothing: 1 /
/// `UNRESOLVED` of it. A pair whose remainder is below that share of F⁰ ×
/// `--shadow-tol` is stored as hidden (`RowEngine::exact_occluded`). Tied to the tolerance itself, the snap was most of
/// the error at loose tolerances (bench/PERF.md §28).
pub(crate) const UNRESOLVED: u32 = 64;

/// Refinement limit of a first triangle (depth 0) of the outer rule: its triangles at
/// depth `MAX_DEPTH − 1` (cut 15 times: 4⁻¹⁵ of its area, ~3e-5 of its edge) are not
/// cut again, and what error they still estimate makes the pair's tolerance unmet.
const MAX_DEPTH: u32 = 16;

/// Most evaluations of the integrand for one pair: the rule stops refining there and
/// keeps its estimate, with the tolerance unmet.
const MAX_POINTS: u32 = 2_000_000;

/// Whether some segment from a point of the convex polygon `t` to a point of the
/// convex polygon `q` may cross the triangle `c`: false when a plane separates `c`
/// from the convex hull H of `t` and `q` (which is the union of those segments) by
/// more than `tol`. Exact for polytopes (separating axis theorem) with the axes of H
/// known from its shape: H's faces lie in the planes of `t` and `q` and in planes
/// through an edge of one polygon and a vertex of the other; its edges are the
/// polygons' edges and segments from a vertex of one to a vertex of the other. So the
/// axes tried are those face normals, the normal of `c`, and the cross products of
/// those edges with the edges of `c`. Touching counts as separated.
fn segments_may_cross(t: &[DVec3], q: &[DVec3], c: &[DVec3; 3], tol: f64) -> bool {
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

/// The outer integral of one pair: what [`blocked_integral`] needs besides the rule.
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
        /// out of points ([`MAX_POINTS`]) or of depth ([`MAX_DEPTH`]) first.
        met: bool,
    },
}

/// What the casters take from the pair, the blocked part to within `tol_abs` as
/// estimated (or as near as [`MAX_POINTS`] and [`MAX_DEPTH`] allow: see
/// [`Blocked::Part`]); None when it could not be done (too many shadow pieces).
pub(crate) fn blocked_integral(
    pair: &Pair<'_>,
    tol_abs: f64,
    s: &mut ShadowScratch,
) -> Option<Blocked> {
    blocked_integral_within(pair, tol_abs, (MAX_POINTS, MAX_DEPTH), s)
}

/// [`blocked_integral`] with at most about `max_points` points and refinement to
/// `max_depth` instead of [`MAX_POINTS`] and [`MAX_DEPTH`].
fn blocked_integral_within(
    pair: &Pair<'_>,
    tol_abs: f64,
    (max_points, max_depth): (u32, u32),
    s: &mut ShadowScratch,
) -> Option<Blocked> {
    let v = pair.pi.verts();
    if v.len() < 3 {
        return Some(Blocked::Nothing);
    }
    let area: f64 = (1..v.len() - 1)
        .map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length())
        .sum();
    if area.is_nan() || area <= 0.0 {
        return Some(Blocked::Nothing);
    }
    if pair
        .casters
        .iter()
        .any(|c| hides(v, pair.pj.verts(), c, pair.tol))
    {
        return Some(Blocked::All);
    }
    // Casters that cross no segment between the polygons block nothing: a pair all of
    // whose candidates are such is fully visible, exactly. A solid is used whole once
    // one of its triangles may cross, so its other triangles need no test here: they
    // are all kept (the tests below on parts of P_i settle them where it matters, and
    // a triangle that crosses no segment from P_i crosses none from a part of it).
    let q = pair.pj.verts();
    let mut ids: Vec<u32> = Vec::new();
    for c in pair.casters {
        if c.solid != NO_SOLID
            && !ids.contains(&c.solid)
            && segments_may_cross(v, q, &c.v, pair.tol)
        {
            ids.push(c.solid);
        }
    }
    let mut active = std::mem::take(&mut s.active);
    active.clear();
    active.extend(pair.casters.iter().filter(|c| {
        if c.solid == NO_SOLID {
            segments_may_cross(v, q, &c.v, pair.tol)
        } else {
            ids.contains(&c.solid)
        }
    }));
    if active.is_empty() {
        s.active = active;
        return Some(Blocked::Nothing);
    }
    let narrowed = Pair {
        casters: &active,
        ..*pair
    };
    // The shadows at a point: each solid whole, the other casters one by one.
    let mut loose = std::mem::take(&mut s.loose);
    loose.clear();
    loose.extend(active.iter().filter(|c| c.solid == NO_SOLID));
    let solids: Vec<&Solid> = ids.iter().map(|&k| &pair.solids[k as usize]).collect();
    if solids.iter().any(|k| solid_hides(v, q, k, pair.tol)) {
        s.active = active;
        s.loose = loose;
        return Some(Blocked::All);
    }
    let mut cells = std::mem::take(&mut s.cells);
    if !split_at_events(&narrowed, &loose, &solids, &mut cells) {
        s.cells = cells;
        s.active = active;
        s.loose = loose;
        return None;
    }
    let mut run = Run {
        pair: &narrowed,
        loose: &loose,
        solids: &solids,
        receiver: Piece::new(pair.pj.verts()),
        points: 0,
        max_points,
        max_depth,
        seq: 0,
        added: 0.0,
    };
    let mut open = std::mem::take(&mut s.open);
    open.clear();
    let result = run
        .start(&cells, &mut open, s)
        .and_then(|settled| run.integrate(&mut open, settled, tol_abs, s));
    let points = run.points;
    s.open = open;
    s.cells = cells;
    s.active = active;
    s.loose = loose;
    result.map(|(blocked, met)| Blocked::Part {
        blocked,
        points,
        met,
    })
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

/// Most cells [`split_at_events`] cuts P_i into. A kink left uncut can fool the rule:
/// a triangle that barely crosses it may have all its samples on one side, so that its
/// two rules agree to rounding while the sliver beyond differs. With 64
/// cells a box between two squares came out 1.8e-8 of F⁰ off with its estimate at
/// 1e-11; it needs 88 (bench/PERF.md §30). 256 cost nothing measurable on the Cornell
/// box and 3 % on the room at 1e-3.
const MAX_CELLS: usize = 256;

/// Cuts P_i into convex cells along the lines where the shadows change shape (where
/// the integrand has kinks), so that the rule sees a smooth integrand on each: the
/// points x at which a caster vertex v lines up with an edge p→q of P_j (x in the plane
/// of p, q, v), or a vertex p of P_j with a caster edge v→w (the plane of p, v, w), and
/// the caster's own plane (where the integrand jumps: a caster touching P_i's plane
/// hides much from one side of its plane and nothing from the plane itself).
/// (Where two casters' shadow edges cross, and where three edges line up, kinks
/// remain; the adaptive rule handles those.) At most [`MAX_CELLS`] cells.
///
/// Returns false when the jumps could not all be cut (too many cells): the rule would
/// then converge only slowly across them, and the pair goes to rays.
fn split_at_events(
    pair: &Pair<'_>,
    loose: &[Caster],
    solids: &[&Solid],
    cells: &mut Vec<Piece>,
) -> bool {
    cells.clear();
    cells.push(Piece::new(pair.pi.verts()));
    let q = pair.pj.verts();
    let tol = pair.tol;
    let ni = pair.ni;
    let oi = ni.dot(pair.pi.v[0]);
    // Where x crosses the caster's own plane, what it hides jumps when the caster
    // touches P_i's plane (a wall standing on P_i hides much from one side of it,
    // nothing from its plane). Jumps first: the rule converges far more slowly across
    // a jump than across a kink, so they get the cells when there are not enough.
    // A caster whose plane does not cross P_i cuts nothing (`cut` would find no cell
    // on both sides): asked first, as it is cheaper than the separating axes. The half
    // tolerance leaves the planes `cut` computes from the corners a margin.
    let crosses_pi = |c: &Caster| {
        let d = |p: &DVec3| c.normal.dot(*p) - c.offset;
        let pv = pair.pi.verts();
        pv.iter().any(|p| d(p) < -0.5 * tol) && pv.iter().any(|p| d(p) > 0.5 * tol)
    };
    for c in pair.casters {
        if c.v.iter().any(|v| (ni.dot(*v) - oi).abs() <= tol)
            && crosses_pi(c)
            && (c.solid == NO_SOLID || segments_may_cross(pair.pi.verts(), q, &c.v, tol))
            && !cut(cells, MAX_CELLS, c.v[0], c.v[1], c.v[2], tol, &|_| true)
        {
            return false;
        }
    }
    for (k, c) in loose.iter().enumerate() {
        let edges = (0..3)
            .filter(|&e| !inner_edge(loose, k, e, tol))
            .map(|e| (c.v[e], c.v[(e + 1) % 3]));
        cut_at_kinks(cells, q, &c.v, edges, tol);
    }
    // A convex solid's shadow is bounded by its silhouette: only edges that are on it
    // from some point of P_i (between a face that some point sees and one that it does
    // not) and their ends make kinks.
    let pv = pair.pi.verts();
    for k in solids {
        // Per face: how many vertices of P_i see it (a point sees a face when it lies
        // in front of its plane by more than the tolerance, affine in the point).
        let seen_by: Vec<usize> = k
            .faces
            .iter()
            .map(|f| {
                pv.iter()
                    .filter(|x| f.normal.dot(**x) - f.offset > tol)
                    .count()
            })
            .collect();
        let edges: Vec<(DVec3, DVec3)> = k
            .edges
            .iter()
            .filter(|e| {
                // On the silhouette from no point of P_i when every point sees both
                // faces, or none sees either.
                let [f, g] = e.faces.map(|f| seen_by[f as usize]);
                !(f == g && (f == 0 || f == pv.len()))
            })
            .map(|e| (e.a, e.b))
            .collect();
        let mut ends: Vec<DVec3> = edges.iter().flat_map(|&(a, b)| [a, b]).collect();
        ends.sort_by(|a, b| {
            (a.x.total_cmp(&b.x))
                .then(a.y.total_cmp(&b.y))
                .then(a.z.total_cmp(&b.z))
        });
        ends.dedup();
        cut_at_kinks(cells, q, &ends, edges.into_iter(), tol);
    }
    true
}

/// Whether edge `e` (from corner e to e + 1) of `casters[k]` is no edge of the shadows:
/// another caster in the same plane shares it from the other side (an inner edge of
/// merged triangles, a box face's diagonal). A coplanar caster on the same side (the
/// same triangle given facing the other way) leaves it an edge.
fn inner_edge(casters: &[Caster], k: usize, e: usize, tol: f64) -> bool {
    let c = &casters[k];
    let (v, w, r) = (c.v[e], c.v[(e + 1) % 3], c.v[(e + 2) % 3]);
    let side = |p: DVec3| (w - v).cross(p - v).dot(c.normal);
    casters.iter().enumerate().any(|(l, d)| {
        l != k
            && d.normal.dot(c.normal).abs() > 1.0 - 1e-12
            && (d.normal.dot(v) - d.offset).abs() <= tol
            && (0..3).any(|f| {
                let (a, b, o) = (d.v[f], d.v[(f + 1) % 3], d.v[(f + 2) % 3]);
                ((a == v && b == w) || (a == w && b == v)) && side(o) * side(r) < 0.0
            })
    })
}

/// Cuts `cells` where a vertex of `vertices` lines up with an edge of `q` (P_j), and a
/// vertex of `q` with an edge of `edges`.
fn cut_at_kinks(
    cells: &mut Vec<Piece>,
    q: &[DVec3],
    vertices: &[DVec3],
    edges: impl Iterator<Item = (DVec3, DVec3)> + Clone,
    tol: f64,
) {
    for m in 0..q.len() {
        let (p0, p1) = (q[m], q[(m + 1) % q.len()]);
        // A caster vertex v seen on the edge p0 → p1 of P_j: from x, the ray through v
        // meets the edge itself, beyond v.
        for &v in vertices {
            cut(cells, MAX_CELLS, p0, p1, v, tol, &|x| {
                ray_meets_segment(x, v, p0, p1)
            });
        }
        // A vertex p0 of P_j seen on a caster edge v → w: the segment from x to p0
        // crosses the edge itself.
        for (v, w) in edges.clone() {
            cut(cells, MAX_CELLS, p0, v, w, tol, &|x| {
                segment_meets_segment(x, p0, v, w)
            });
        }
    }
}

/// True when the line from `x` through `v` meets the segment `a`–`b` (x, v, a, b
/// coplanar) with v between x and the meeting point, give or take a margin.
fn ray_meets_segment(x: DVec3, v: DVec3, a: DVec3, b: DVec3) -> bool {
    line_meets_segment(x, v, a, b).is_some_and(|lambda| lambda >= 1.0 - 1e-9)
}

/// True when the segment `x`–`y` meets the segment `a`–`b` (all four coplanar), give
/// or take a margin.
fn segment_meets_segment(x: DVec3, y: DVec3, a: DVec3, b: DVec3) -> bool {
    line_meets_segment(x, y, a, b).is_some_and(|lambda| (-1e-6..=1.0 + 1e-6).contains(&lambda))
}

/// Where the line x + λ (v − x) meets the segment `a`–`b` (all four coplanar), as λ;
/// None when it misses the segment (by more than a margin) or runs parallel to it.
fn line_meets_segment(x: DVec3, v: DVec3, a: DVec3, b: DVec3) -> Option<f64> {
    let (d, e) = (v - x, b - a);
    let c = d.cross(e);
    let cc = c.length_squared();
    if cc.is_nan() || cc <= 0.0 {
        return None;
    }
    // x + λ d = a + t e.
    let w = a - x;
    let t = w.cross(d).dot(c) / cc;
    (-1e-6..=1.0 + 1e-6)
        .contains(&t)
        .then(|| w.cross(e).dot(c) / cc)
}

/// Cuts the cells that the plane through `a`, `b`, `c` crosses, where `matters` holds
/// at one of the ends or the middle of the cell's chord on that plane (the event
/// happens along only part of the line: elsewhere the line is no kink), up to
/// `max_cells` cells. Returns whether every cell the plane crosses where it matters
/// was cut.
pub(crate) fn cut(
    cells: &mut Vec<Piece>,
    max_cells: usize,
    a: DVec3,
    b: DVec3,
    c: DVec3,
    tol: f64,
    matters: &dyn Fn(DVec3) -> bool,
) -> bool {
    let n = (b - a).cross(c - a);
    let len = n.length();
    if len.is_nan() || len <= 0.0 {
        return true;
    }
    let (n, o) = (n / len, n.dot(a) / len);
    let mut complete = true;
    let mut k = 0;
    while k < cells.len() {
        let cell = cells[k];
        k += 1;
        let v = cell.verts();
        let d: Vec<f64> = v.iter().map(|p| n.dot(*p) - o).collect();
        if !(d.iter().any(|&x| x < -tol) && d.iter().any(|&x| x > tol)) {
            continue;
        }
        // The chord: where the cell's edges cross the plane.
        let mut ends = [DVec3::ZERO; 2];
        let mut found = 0;
        for m in 0..v.len() {
            let (d0, d1) = (d[m], d[(m + 1) % v.len()]);
            if (d0 < 0.0) != (d1 < 0.0) && found < 2 {
                ends[found] = v[m] + (v[(m + 1) % v.len()] - v[m]) * (d0 / (d0 - d1));
                found += 1;
            }
        }
        if found == 2
            && ![ends[0], ends[1], 0.5 * (ends[0] + ends[1])]
                .into_iter()
                .any(matters)
        {
            continue;
        }
        // A cut adds a vertex to each side: a cell at capacity stays whole, and so
        // does every cell once there are max_cells.
        if cell.n >= cell.v.len() || cells.len() >= max_cells {
            complete = false;
            continue;
        }
        let front = cell.clip_front(n, o, tol);
        let back = cell.clip_front(-n, -o, tol);
        if usable(&front) && usable(&back) {
            cells[k - 1] = front;
            cells.push(back);
        }
    }
    complete
}

/// The state of one outer integral.
struct Run<'p, 'a> {
    pair: &'p Pair<'a>,
    /// The casters that belong to no solid, and the solids.
    loose: &'p [Caster],
    solids: &'p [&'a Solid],
    /// P_j as a [`Piece`], for [`blocked_at`].
    receiver: Piece,
    points: u32,
    /// Points after which the rule stops refining.
    max_points: u32,
    /// Depth at which a triangle is not refined again.
    max_depth: u32,
    /// Triangles put in the open list so far (each gets the next number).
    seq: u64,
    /// The errors of the triangles put in the open list since [`Run::integrate`] last
    /// took them into its running sum.
    added: f64,
}

impl Run<'_, '_> {
    /// Whether no caster can cross a segment from the convex cell `w` to P_j.
    fn lit(&self, w: &[DVec3]) -> bool {
        let p = self.pair;
        !p.casters
            .iter()
            .any(|c| segments_may_cross(w, p.pj.verts(), &c.v, p.tol))
    }

    /// What the convex cell `w` (three vertices or more) blocks when one caster or one
    /// convex solid hides all of P_j from all of it: ∫_cell F(x → P_j) dA_x, the
    /// unoccluded contour integral from it to P_j, per fan triangle when it has more
    /// vertices than a [`Polygon`]. None when it is not so hidden, or the value comes out
    /// negative or not finite (the rule then takes the cell). The tests are on vertex
    /// pairs and fail fast, unlike [`Run::lit`]'s separating axes.
    fn hidden(&self, w: &[DVec3]) -> Option<f64> {
        let p = self.pair;
        let q = p.pj.verts();
        let hidden = p.casters.iter().any(|c| hides(w, q, c, p.tol))
            || self.solids.iter().any(|k| solid_hides(w, q, k, p.tol));
        if !hidden {
            return None;
        }
        let contour = |poly: &Polygon| area_form_factor(poly, p.pj, gauss_table(), p.params);
        let value = if w.len() <= MAX_VERTS {
            contour(&Polygon::new(w))
        } else {
            (1..w.len() - 1)
                .map(|k| contour(&Polygon::new(&[w[0], w[k], w[k + 1]])))
                .sum()
        };
        (value.is_finite() && value >= 0.0).then_some(value)
    }
}

/// The point of triangle `t` with barycentric coordinates `b`.
fn barycentric(t: &[DVec3; 3], b: [f64; 3]) -> DVec3 {
    b[0] * t[0] + b[1] * t[1] + b[2] * t[2]
}

/// One triangle of the outer rule with its degree-8 estimate and that estimate's error.
#[derive(Clone, Copy, Debug)]
struct Cell {
    t: [DVec3; 3],
    area: f64,
    /// [`LAURIE`]'s estimate of the integral over the triangle.
    value: f64,
    /// Its error estimate: how far the embedded [`RADON`] rule lies from it.
    err: f64,
    /// Every sample saw no shadow.
    dark_free: bool,
}

impl Run<'_, '_> {
    /// The degree-8 estimate on triangle `t` and its error: the 19 points of
    /// [`LAURIE`], of which the first seven also give [`RADON`]'s degree-5 value.
    fn cell(&mut self, t: [DVec3; 3], s: &mut ShadowScratch) -> Option<Cell> {
        let area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        let p = self.pair;
        let (mut high, mut low, mut dark_free) = (0.0, 0.0, true);
        for (k, (b, w)) in LAURIE.into_iter().enumerate() {
            let g = blocked_at(
                barycentric(&t, b),
                p.ni,
                &self.receiver,
                self.loose,
                self.solids,
                p.tol,
                s,
            )?;
            high += w * g;
            if let Some(&(_, w5)) = RADON.get(k) {
                low += w5 * g;
            }
            dark_free &= g == 0.0;
        }
        self.points += LAURIE.len() as u32;
        Some(Cell {
            t,
            area,
            value: high * area,
            err: (high - low).abs() * area,
            dark_free,
        })
    }

    /// What the triangle of `c` could hold when its samples see no shadow: twice its
    /// area times the largest unoccluded F(x → P_j) over the samples (a shadow may hide
    /// between them). Asked only when such a triangle goes into the open list: the
    /// first triangles of a lit cell ([`Run::start`]) never need it.
    fn could_hold(&self, c: &Cell) -> f64 {
        let p = self.pair;
        let lit_max = LAURIE
            .iter()
            .map(|&(b, _)| point_polygon(barycentric(&c.t, b), p.ni, p.pj.verts()))
            .fold(0.0f64, f64::max);
        2.0 * c.area * lit_max
    }

    /// Settles the cells that need no rule and puts the first triangles of the others
    /// (each cell fanned) in `open`; returns what the settled cells block. A cell is
    /// settled when one caster or solid hides all of P_j from it ([`Run::hidden`]), or
    /// when it is lit ([`Run::lit`]): that takes separating-axis tests, so it is asked
    /// only when none of the first samples on the cell sees a shadow. None: as
    /// [`Run::cell`].
    fn start(
        &mut self,
        cells: &[Piece],
        open: &mut BinaryHeap<Open>,
        s: &mut ShadowScratch,
    ) -> Option<f64> {
        let mut settled = 0.0;
        let mut first: Vec<Cell> = Vec::new();
        for c in cells {
            let w = c.verts();
            if w.len() < 3 {
                continue;
            }
            if let Some(x) = self.hidden(w) {
                settled += x;
                continue;
            }
            first.clear();
            for k in 1..w.len() - 1 {
                first.push(self.cell([w[0], w[k], w[k + 1]], s)?);
            }
            if first.iter().all(|c| c.dark_free) && self.lit(w) {
                continue;
            }
            for &cell in &first {
                self.push(open, cell, 0);
            }
        }
        Some(settled)
    }

    /// Puts triangle `c` (at refinement depth `depth`) in the open list with its error.
    /// A triangle whose samples all see no shadow has value 0 and as its error what it
    /// could hold ([`Run::could_hold`]); when that is 0 it is dropped. Any other carries
    /// its rules' difference.
    fn push(&mut self, open: &mut BinaryHeap<Open>, c: Cell, depth: u32) {
        let err = if c.dark_free {
            self.could_hold(&c)
        } else {
            c.err
        };
        if c.dark_free && err <= 0.0 {
            return;
        }
        self.seq += 1;
        self.added += err;
        open.push(Open {
            err,
            seq: self.seq,
            cell: c,
            depth,
        });
    }

    /// Refines the open triangle with the largest error until the errors sum to at
    /// most `tol` (globally adaptive, as QUADPACK's QAG does on an interval: the
    /// tolerance goes where the error is, not in proportion to area), then returns
    /// `settled` plus the open triangles' values, and whether the tolerance was met.
    /// A triangle is refined by cutting it at its edge midpoints into four, each
    /// estimated afresh.
    fn integrate(
        &mut self,
        open: &mut BinaryHeap<Open>,
        settled: f64,
        tol: f64,
        s: &mut ShadowScratch,
    ) -> Option<(f64, bool)> {
        let (mut done, mut unmet) = (settled, 0.0);
        let exact = |open: &BinaryHeap<Open>| open.iter().map(|o| o.err).sum::<f64>();
        // A running sum of the open errors, added up afresh every so often and before
        // it is believed (subtracting drifts by rounding).
        let mut err = exact(open);
        self.added = 0.0;
        let mut steps = 0u32;
        // The target: the open errors plus those of triangles kept at the deepest level.
        while self.points < self.max_points {
            if err + unmet <= tol || steps % 1024 == 1023 {
                err = exact(open);
                if err + unmet <= tol {
                    break;
                }
            }
            steps += 1;
            let Some(top) = open.pop() else { break };
            if !top.err.is_finite() {
                return None; // no estimate to refine (it should not happen): rays
            }
            err -= top.err;
            // A triangle that sees no shadow: 0 exactly when nothing crosses between it
            // and P_j (at any depth), else its children decide.
            if top.cell.dark_free && self.lit(&top.cell.t) {
                continue;
            }
            if top.depth + 1 >= self.max_depth {
                done += top.cell.value;
                unmet += top.err;
                continue;
            }
            let t = top.cell.t;
            let m = [
                0.5 * (t[0] + t[1]),
                0.5 * (t[1] + t[2]),
                0.5 * (t[2] + t[0]),
            ];
            for child in [
                [t[0], m[0], m[2]],
                [m[0], t[1], m[1]],
                [m[2], m[1], t[2]],
                [m[0], m[1], m[2]],
            ] {
                let c = self.cell(child, s)?;
                self.push(open, c, top.depth + 1);
            }
            err += std::mem::take(&mut self.added);
        }
        let err = exact(open);
        let value = done + open.iter().map(|o| o.cell.value).sum::<f64>();
        // A value that is not a number (it should not happen) is no estimate: rays.
        value.is_finite().then_some((value, err + unmet <= tol))
    }
}

/// A triangle of the outer rule not refined further (yet).
#[derive(Debug)]
struct Open {
    /// Its error estimate.
    err: f64,
    /// Order of creation: among equal errors the older is refined first, so the order
    /// of refinement, and with it the sum, never depends on the heap's layout.
    seq: u64,
    cell: Cell,
    depth: u32,
}

impl PartialEq for Open {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == std::cmp::Ordering::Equal
    }
}

impl Eq for Open {}

impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}

impl Ord for Open {
    /// The larger error first; among equal ones the older.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.err
            .total_cmp(&o.err)
            .then_with(|| o.seq.cmp(&self.seq))
    }
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
    use crate::formfactor::solids::Solids;
    use glam::dvec3;

    /// Howell's differential element to a parallel rectangle with a corner above
    /// it (a × b at height c), written out independently of [`point_polygon`].
    fn corner_rectangle(a: f64, b: f64, c: f64) -> f64 {
        let (x, y) = (a / c, b / c);
        let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
        (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
    }

    fn square(x0: f64, x1: f64, z0: f64, z1: f64, y: f64) -> Polygon {
        // Seen from below (y smaller), counter-clockwise about −y.
        Polygon::new(&[
            dvec3(x0, y, z0),
            dvec3(x0, y, z1),
            dvec3(x1, y, z1),
            dvec3(x1, y, z0),
        ])
    }

    #[test]
    fn the_rules_integrate_what_they_should() {
        // ∫ λ₁^a λ₂^b λ₃^c over a triangle / area = 2 a! b! c! / (a + b + c + 2)!.
        let f = |n: u32| (1..=n).product::<u32>() as f64;
        let moment = |rule: &[([f64; 3], f64)], (a, b, c): (u32, u32, u32)| -> (f64, f64) {
            let want = 2.0 * f(a) * f(b) * f(c) / f(a + b + c + 2);
            let got: f64 = rule
                .iter()
                .map(|(l, w)| w * l[0].powi(a as i32) * l[1].powi(b as i32) * l[2].powi(c as i32))
                .sum();
            (got, want)
        };
        let upto = |degree: u32| {
            (0..=degree).flat_map(move |a| {
                (0..=degree - a).flat_map(move |b| (0..=degree - a - b).map(move |c| (a, b, c)))
            })
        };
        for e in upto(5) {
            let (got, want) = moment(&RADON, e);
            assert!(
                (got - want).abs() < 1e-15,
                "degree 5: {e:?} {got} vs {want}"
            );
        }
        for e in upto(8) {
            let (got, want) = moment(&LAURIE, e);
            assert!(
                (got - want).abs() < 1e-15,
                "degree 8: {e:?} {got} vs {want}"
            );
        }
        // Neither is exact one degree up (else the error estimate would be blind there).
        let (got, want) = moment(&RADON, (6, 0, 0));
        assert!((got - want).abs() > 1e-6, "{got} vs {want}");
        let (got, want) = moment(&LAURIE, (9, 0, 0));
        assert!((got - want).abs() > 1e-8, "{got} vs {want}");
        // The degree-5 rule's points are the first seven of the degree-8 rule's.
        for (k, (l, _)) in RADON.iter().enumerate() {
            assert_eq!(*l, LAURIE[k].0);
        }
        for (l, w) in LAURIE {
            assert!(
                w > 0.0
                    && l.iter().all(|&x| x > 0.0)
                    && (l.iter().sum::<f64>() - 1.0).abs() < 1e-15
            );
        }
    }

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

    /// A convex solid, whole, hides what its triangles hide one by one, from points on
    /// the floor (beside and under a box without a bottom), on walls, on the ceiling
    /// and on the boxes' own faces, of receivers that include the boxes' faces.
    #[test]
    fn a_convex_solid_hides_what_its_triangles_hide() {
        use crate::formfactor::sampling::SplitMix64;
        use crate::formfactor::solids::{tests::box_triangles, Solids};
        let tris: Vec<[DVec3; 3]> = [
            box_triangles(dvec3(1.0, 0.0, 1.0), dvec3(2.0, 1.5, 2.5), true),
            box_triangles(dvec3(2.5, 0.5, 0.5), dvec3(3.0, 2.5, 1.0), false),
        ]
        .concat();
        let found = Solids::find(&tris, 1e-9);
        assert_eq!(found.solids.len(), 2);
        let solids: Vec<&Solid> = found.solids.iter().collect();
        let one_by_one: Vec<Caster> = tris.iter().filter_map(|t| Caster::new(*t)).collect();
        // Planes as (origin, u, v): the rectangle origin + [0,1]² (u, v); normal u × v.
        let rect = |o: [f64; 3], u: [f64; 3], v: [f64; 3]| {
            (DVec3::from(o), DVec3::from(u), DVec3::from(v))
        };
        let floor = rect([0.0; 3], [0.0, 0.0, 4.0], [4.0, 0.0, 0.0]);
        let ceiling = rect([0.0, 3.0, 0.0], [4.0, 0.0, 0.0], [0.0, 0.0, 4.0]);
        let east = rect([4.0, 0.0, 0.0], [0.0, 0.0, 4.0], [0.0, 3.0, 0.0]);
        let west = rect([0.0; 3], [0.0, 3.0, 0.0], [0.0, 0.0, 4.0]);
        let south = rect([0.0; 3], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]);
        let roof = rect([1.0, 1.5, 1.0], [0.0, 0.0, 1.5], [1.0, 0.0, 0.0]);
        let box_west = rect([1.0, 0.0, 1.0], [0.0, 0.0, 1.5], [0.0, 1.5, 0.0]);
        let box_east = rect([3.0, 0.5, 0.5], [0.0, 2.0, 0.0], [0.0, 0.0, 0.5]);
        let pairs = [
            (floor, ceiling),
            (floor, east),
            (floor, box_west),
            (ceiling, floor),
            (west, east),
            (west, box_west),
            (east, floor),
            (south, ceiling),
            (roof, ceiling),
            (box_east, east),
            (box_east, ceiling),
        ];
        let mut rng = SplitMix64::new(7);
        let (mut compared, mut whole, mut shaded) = (0, 0, 0);
        for ((oi, ui, vi), (oj, uj, vj)) in pairs {
            let ni = ui.cross(vi).normalize();
            let nj = uj.cross(vj);
            let pj = Polygon::new(&[oj, oj + uj, oj + uj + vj, oj + vj]);
            let pj_piece = Piece::new(pj.verts());
            for _ in 0..400 {
                let x = oi + rng.next_f64() * ui + rng.next_f64() * vi;
                if nj.dot(x - oj) <= 1e-9 {
                    continue; // the engine clips P_i to P_j's front
                }
                let mut s = ShadowScratch::default();
                let a = blocked_at(x, ni, &pj_piece, &[], &solids, 1e-12, &mut s).unwrap();
                let b = blocked_at(x, ni, &pj_piece, &one_by_one, &[], 1e-12, &mut s).unwrap();
                assert!((a - b).abs() <= 1e-10, "x {x}: solids {a}, triangles {b}");
                compared += 1;
                shaded += usize::from(b > 1e-6);
                let receiver = Piece::new(pj.verts());
                let mut cone = Cone::EMPTY;
                whole += solids
                    .iter()
                    .filter(|k| {
                        !matches!(
                            Cone::of_solid(x, k, &receiver, 1e-12, &mut cone),
                            SolidShadow::Triangles
                        )
                    })
                    .count();
            }
        }
        // The solids were used whole nearly everywhere, and there were shadows.
        assert!(
            whole >= 2 * compared * 95 / 100,
            "whole {whole} of {}",
            2 * compared
        );
        assert!(shaded >= compared / 4, "shaded {shaded} of {compared}");
    }

    /// A closed box between a floor square and a smaller ceiling square, as one solid
    /// and as its twelve triangles each on its own.
    fn box_between_squares() -> (Solids, Vec<Caster>, Vec<Caster>) {
        use crate::formfactor::solids::tests::box_triangles;
        let tris = box_triangles(dvec3(0.4, 1.0, 0.4), dvec3(1.6, 2.0, 1.6), false);
        let found = Solids::find(&tris, 1e-9);
        assert_eq!(found.solids.len(), 1);
        let whole = tris
            .iter()
            .filter_map(|t| Caster::new(*t))
            .map(|c| c.in_solid(0))
            .collect();
        let one_by_one = tris.iter().filter_map(|t| Caster::new(*t)).collect();
        (found, whole, one_by_one)
    }

    /// The square [x0, x1] × [z0, z1] at height y, facing up (`up`) or down.
    fn square_facing(x0: f64, x1: f64, z0: f64, z1: f64, y: f64, up: bool) -> Polygon {
        let mut v = vec![
            dvec3(x0, y, z0),
            dvec3(x0, y, z1),
            dvec3(x1, y, z1),
            dvec3(x1, y, z0),
        ];
        if !up {
            v.reverse();
        }
        Polygon::new(&v)
    }

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

    /// The cells the route settles without its rule (hidden whole by the solid: the
    /// unoccluded contour integral; seeing no caster: 0) give what the rule gives on
    /// the box's triangles one by one, which no single triangle hides: both keep
    /// |value − exact| ≤ tol at 1e-7 and 1e-9 of F⁰, so they differ by 2 tol at most. A
    /// pair the solid hides whole is `Blocked::All` with the solid and comes to F⁰ by
    /// the rule. With at most 64 cells the solid's route settled 1.8e-8 of F⁰ off here
    /// while its estimate said 1e-11 (bench/PERF.md §30: a kink left uncut).
    #[test]
    fn cells_settled_whole_agree_with_the_rule() {
        let (found, whole, one_by_one) = box_between_squares();
        let pj = square_facing(0.6, 1.4, 0.6, 1.4, 3.0, false);
        let cases = [
            // Partly hidden: umbra in the middle, penumbra and lit cells around it.
            (square_facing(-1.0, 3.0, -1.0, 3.0, 0.0, true), false),
            // Hidden whole by the box, by no triangle of it alone.
            (square_facing(0.9, 1.1, 0.8, 1.2, 0.0, true), true),
        ];
        for ((pi, all), rel) in cases.iter().flat_map(|c| [(*c, 1e-7), (*c, 1e-9)]) {
            let f0 = area_form_factor(&pi, &pj, gauss_table(), ContourParams::default());
            let tol_abs = rel * f0;
            let run = |casters: &[Caster], solids: &[Solid]| {
                let pair = Pair {
                    pi: &pi,
                    ni: DVec3::Y,
                    pj: &pj,
                    casters,
                    solids,
                    tol: 1e-12,
                    params: ContourParams::default(),
                };
                blocked_integral(&pair, tol_abs, &mut ShadowScratch::default())
            };
            let Some(Blocked::Part {
                blocked: by_rule,
                points,
                met,
            }) = run(&one_by_one, &[])
            else {
                panic!("the triangles one by one need the rule");
            };
            assert!(points > 0 && met);
            match run(&whole, &found.solids) {
                Some(Blocked::All) => {
                    assert!(all);
                    assert!(
                        (by_rule - f0).abs() <= 2.0 * tol_abs,
                        "{by_rule} vs F0 {f0}"
                    );
                }
                Some(Blocked::Part {
                    blocked: settled,
                    met,
                    ..
                }) => {
                    assert!(!all && met);
                    assert!(
                        (settled - by_rule).abs() <= 2.0 * tol_abs,
                        "settled {settled}, rule {by_rule}, tolerance {tol_abs}"
                    );
                    assert!(settled > 0.1 * f0 && settled < f0, "{settled} of {f0}");
                }
                other => panic!("{other:?}"),
            }
        }
    }

    fn casters_of_square(x0: f64, x1: f64, z0: f64, z1: f64, y: f64) -> Vec<Caster> {
        let (a, b, c, d) = (
            dvec3(x0, y, z0),
            dvec3(x1, y, z0),
            dvec3(x1, y, z1),
            dvec3(x0, y, z1),
        );
        [[a, b, c], [a, c, d]]
            .into_iter()
            .filter_map(Caster::new)
            .collect()
    }

    /// Only an edge with coplanar triangles on both sides is inner: a square's
    /// diagonal, not its outline, also when the square is given twice, once facing each
    /// way (as `builtin:obstructed` gives its blocker when coplanar occluders are not
    /// merged).
    /// A vertex of P_j seen across an occluder edge between the patches is a kink: the
    /// cells are cut where the segment from x to that vertex crosses the edge. (The
    /// test used to look for the edge beyond the vertex or behind x, and never cut.)
    #[test]
    fn a_receiver_corner_behind_an_occluder_edge_cuts_the_cells() {
        // P_i: the unit square at y = 0; P_j: the unit square at y = 2; an occluder
        // edge along x at y = 1, z = 0.25. From x = (·, 0, 0.5) the segment to P_j's
        // corners at z = 0 crosses that edge: the one line where the kink lies.
        let pi = square(0.0, 1.0, 0.0, 1.0, 0.0);
        let pj = square(0.0, 1.0, 0.0, 1.0, 2.0);
        let edge = (dvec3(-5.0, 1.0, 0.25), dvec3(5.0, 1.0, 0.25));
        let mut cells = vec![Piece::new(pi.verts())];
        cut_at_kinks(&mut cells, pj.verts(), &[], [edge].into_iter(), 1e-9);
        assert_eq!(cells.len(), 2, "one cut, at z = 0.5");
        for c in &cells {
            let z: Vec<f64> = c.verts().iter().map(|v| v.z).collect();
            let (lo, hi) = z
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
            assert!(
                (lo.abs() < 1e-12 || (lo - 0.5).abs() < 1e-12)
                    && ((hi - 0.5).abs() < 1e-12 || (hi - 1.0).abs() < 1e-12)
                    && hi - lo > 0.49,
                "cell spans z {lo}..{hi}"
            );
        }
        // An edge beyond P_j (y = 3, z = −0.25) lines up with its corners at z = 0 from
        // the same line of P_i, but behind P_j, where it hides nothing: no cut.
        let beyond = (dvec3(-5.0, 3.0, -0.25), dvec3(5.0, 3.0, -0.25));
        let mut cells = vec![Piece::new(pi.verts())];
        cut_at_kinks(&mut cells, pj.verts(), &[], [beyond].into_iter(), 1e-9);
        assert_eq!(cells.len(), 1);
    }

    #[test]
    fn only_edges_between_coplanar_triangles_are_inner() {
        let one = casters_of_square(0.3, 0.8, 0.2, 0.6, 0.5);
        let back: Vec<Caster> = one
            .iter()
            .filter_map(|c| Caster::new([c.v[0], c.v[2], c.v[1]]))
            .collect();
        let both = [one.clone(), back].concat();
        for casters in [&one[..], &both[..]] {
            for (k, c) in casters.iter().enumerate() {
                for e in 0..3 {
                    let (v, w) = (c.v[e], c.v[(e + 1) % 3]);
                    // The diagonal runs corner to opposite corner: x and z both change.
                    let diagonal = v.x != w.x && v.z != w.z;
                    assert_eq!(
                        inner_edge(casters, k, e, 1e-12),
                        diagonal,
                        "{} casters, edge {v} {w}",
                        casters.len()
                    );
                }
            }
        }
    }

    #[test]
    fn a_parallel_square_blocker_casts_its_scaled_square() {
        // From x = (0.3, 0, 0.4), a blocker at height 0.5 over [0.25, 0.75]² casts the
        // square [0.5 − x, 1.5 − x] on the plane y = 1 (scale 2 about x): on the unit
        // receiver that is [0.2, 1] × [0.1, 1].
        let x = dvec3(0.3, 0.0, 0.4);
        let pj = square(0.0, 1.0, 0.0, 1.0, 1.0);
        let pj_piece = Piece::new(pj.verts());
        let casters = casters_of_square(0.25, 0.75, 0.25, 0.75, 0.5);
        let mut s = ShadowScratch::default();
        let got = blocked_at(x, DVec3::Y, &pj_piece, &casters, &[], 1e-12, &mut s).unwrap();
        let shadow = square(0.2, 1.0, 0.1, 1.0, 1.0);
        let want = point_polygon(x, DVec3::Y, shadow.verts());
        assert!((got - want).abs() < 1e-14, "{got} vs {want}");
        // The two triangles' shadows share the diagonal: nothing counted twice.
        let x = dvec3(0.5, 0.0, 0.5);
        let got = blocked_at(x, DVec3::Y, &pj_piece, &casters, &[], 1e-12, &mut s).unwrap();
        let want = point_polygon(x, DVec3::Y, square(0.0, 1.0, 0.0, 1.0, 1.0).verts());
        assert!((got - want).abs() < 1e-14, "{got} vs {want}");
    }

    #[test]
    fn overlapping_shadows_count_once_and_behind_or_beyond_count_nothing() {
        let x = dvec3(0.5, 0.0, 0.5);
        let pj = square(0.0, 1.0, 0.0, 1.0, 1.0);
        let pj_piece = Piece::new(pj.verts());
        let mut s = ShadowScratch::default();
        let one = casters_of_square(0.4, 0.6, 0.4, 0.6, 0.5);
        let alone = blocked_at(x, DVec3::Y, &pj_piece, &one, &[], 1e-12, &mut s).unwrap();
        // The same square again, and a smaller one inside its shadow cone.
        let mut many = one.clone();
        many.extend(casters_of_square(0.4, 0.6, 0.4, 0.6, 0.5));
        many.extend(casters_of_square(0.47, 0.53, 0.47, 0.53, 0.8));
        let got = blocked_at(x, DVec3::Y, &pj_piece, &many, &[], 1e-12, &mut s).unwrap();
        assert!((got - alone).abs() < 1e-15, "{got} vs {alone}");
        // Below x, or beyond the receiver's plane: no shadow.
        let behind = casters_of_square(0.0, 1.0, 0.0, 1.0, -0.5);
        let beyond = casters_of_square(0.0, 1.0, 0.0, 1.0, 1.5);
        for c in [behind, beyond] {
            assert_eq!(
                blocked_at(x, DVec3::Y, &pj_piece, &c, &[], 1e-12, &mut s),
                Some(0.0)
            );
        }
    }

    /// Gauss–Legendre nodes and weights on [0, 1] by Newton's method on P_n (written
    /// here, independent of the crate's own table).
    fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
        (0..n)
            .map(|k| {
                let mut x = (std::f64::consts::PI * (k as f64 + 0.75) / (n as f64 + 0.5)).cos();
                let mut dp = 0.0;
                for _ in 0..100 {
                    let (mut p0, mut p1) = (1.0, x);
                    for m in 2..=n {
                        let p2 = ((2 * m - 1) as f64 * x * p1 - (m - 1) as f64 * p0) / m as f64;
                        (p0, p1) = (p1, p2);
                    }
                    dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                    let dx = p1 / dp;
                    x -= dx;
                    if dx.abs() < 1e-16 {
                        break;
                    }
                }
                (0.5 * (1.0 - x), 1.0 / ((1.0 - x * x) * dp * dp))
            })
            .collect()
    }

    /// The obstructed plates (builtin:obstructed): F from the bottom unit square to
    /// the top one at distance 1 with the blocker [0.25, 0.75]² midway, by an
    /// independent route: the shadow from x = (x, 0, z) is the square
    /// [0.5 − x, 1.5 − x] × [0.5 − z, 1.5 − z], so the blocked part is Howell's
    /// point-to-rectangle formula by corners, integrated by Gauss–Legendre on the four
    /// sub-squares split at the kinks x = 0.5, z = 0.5 (the integrand is analytic on
    /// each).
    fn obstructed_reference() -> f64 {
        let g = |a: f64, b: f64| a.signum() * b.signum() * corner_rectangle(a.abs(), b.abs(), 1.0);
        let rect = |x: f64, z: f64, u0: f64, u1: f64, v0: f64, v1: f64| {
            if u1 <= u0 || v1 <= v0 {
                return 0.0;
            }
            g(u1 - x, v1 - z) - g(u0 - x, v1 - z) - g(u1 - x, v0 - z) + g(u0 - x, v0 - z)
        };
        let gl = gauss_legendre(40);
        let mut blocked = 0.0;
        for (x0, z0) in [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5)] {
            for &(tx, wx) in &gl {
                for &(tz, wz) in &gl {
                    let (x, z) = (x0 + 0.5 * tx, z0 + 0.5 * tz);
                    let (u0, u1) = ((0.5 - x).max(0.0), (1.5 - x).min(1.0));
                    let (v0, v1) = ((0.5 - z).max(0.0), (1.5 - z).min(1.0));
                    blocked += 0.25 * wx * wz * rect(x, z, u0, u1, v0, v1);
                }
            }
        }
        0.199_824_895_698_8 - blocked // Howell C-11, X = Y = 1, minus the blocked part
    }

    /// The blocked part of the plates of [`obstructed_reference`] by the rule, to
    /// `tol` within at most about `budget` (points, depth): (value, points, met).
    fn plates_blocked(tol: f64, budget: (u32, u32)) -> (f64, u32, bool) {
        // Bottom (facing +y) as seen by the kernel: counter-clockwise about +y.
        let pi = Polygon::new(&[
            dvec3(0.0, 0.0, 0.0),
            dvec3(0.0, 0.0, 1.0),
            dvec3(1.0, 0.0, 1.0),
            dvec3(1.0, 0.0, 0.0),
        ]);
        let pj = square(0.0, 1.0, 0.0, 1.0, 1.0);
        let mut casters = casters_of_square(0.25, 0.75, 0.25, 0.75, 0.5);
        // Two-sided, as builtin:obstructed has it: the same square facing both ways.
        let back: Vec<Caster> = casters
            .iter()
            .filter_map(|c| Caster::new([c.v[0], c.v[2], c.v[1]]))
            .collect();
        casters.extend(back);
        let pair = Pair {
            pi: &pi,
            ni: DVec3::Y,
            pj: &pj,
            casters: &casters,
            solids: &[],
            tol: 1e-12,
            params: ContourParams::default(),
        };
        match blocked_integral_within(&pair, tol, budget, &mut ShadowScratch::default()) {
            Some(Blocked::Part {
                blocked,
                points,
                met,
            }) => (blocked, points, met),
            other => panic!("the plates are partly blocked: {other:?}"),
        }
    }

    /// A rule that runs out of points before its error estimate meets the tolerance
    /// says so (the run counts such pairs), and keeps its best estimate.
    #[test]
    fn a_rule_out_of_points_says_its_tolerance_is_unmet() {
        let reference = obstructed_reference();
        let mut last = f64::INFINITY;
        for budget in [1_000, 3_000, 30_000] {
            let (blocked, points, met) = plates_blocked(1e-14, (budget, MAX_DEPTH));
            let error = (0.199_824_895_698_8 - blocked - reference).abs();
            println!("budget {budget}: {points} points, error {error:.1e}");
            assert!(!met, "1e-14 met in {points} points");
            // Past the budget by one refinement at most (a triangle's four children),
            // and the estimate improves with the budget.
            let refinement = 4 * LAURIE.len() as u32;
            assert!(
                points >= budget && points <= budget + refinement,
                "{points}"
            );
            assert!(error < 1e-4 && error < last, "{error:e} after {last:e}");
            last = error;
        }
    }

    /// With refinement capped shallow, the triangles kept at the cap carry their error:
    /// the rule refines the others until the two together meet the tolerance (it
    /// stopped when the others alone did, and said unmet with points to spare), and
    /// says unmet only when they cannot. The box between two squares, its triangles
    /// one by one, 1.15e-9 of F⁰: met at depth 3 (within the tolerance of the rule run
    /// to 1e-12 without the cap), unmet at depth 2. At depth 3 the capped triangles
    /// hold about 1e-9 (the rule meets 1.03e-9 there, not 1e-9): a rule that stopped
    /// when the open errors alone met 1.15e-9 says unmet, and fails this test.
    #[test]
    fn a_rule_at_its_depth_limit_refines_the_rest_until_the_sum_meets_the_tolerance() {
        let (_, _, one_by_one) = box_between_squares();
        let pj = square_facing(0.6, 1.4, 0.6, 1.4, 3.0, false);
        let pi = square_facing(-1.0, 3.0, -1.0, 3.0, 0.0, true);
        let f0 = area_form_factor(&pi, &pj, gauss_table(), ContourParams::default());
        let pair = Pair {
            pi: &pi,
            ni: DVec3::Y,
            pj: &pj,
            casters: &one_by_one,
            solids: &[],
            tol: 1e-12,
            params: ContourParams::default(),
        };
        let run = |tol: f64, depth: u32| match blocked_integral_within(
            &pair,
            tol * f0,
            (MAX_POINTS, depth),
            &mut ShadowScratch::default(),
        ) {
            Some(Blocked::Part { blocked, met, .. }) => (blocked, met),
            other => panic!("{other:?}"),
        };
        let (converged, met) = run(1e-12, MAX_DEPTH);
        assert!(met);
        let (capped, met) = run(1.15e-9, 3);
        assert!(met, "depth 3: the rest refined until the sum met 1.15e-9");
        assert!(
            (capped - converged).abs() <= 1.151e-9 * f0,
            "{capped} vs {converged}"
        );
        assert!(
            !run(1.15e-9, 2).1,
            "depth 2: the cap alone holds more than 1.15e-9"
        );
    }

    #[test]
    fn obstructed_plates_come_out_exact() {
        let reference = obstructed_reference();
        assert!((reference - 0.0995063).abs() < 5e-8, "{reference}");
        for tol in [1e-6, 1e-9] {
            let (blocked, points, met) = plates_blocked(tol, (MAX_POINTS, MAX_DEPTH));
            assert!(met, "tolerance {tol:e} unmet after {points} points");
            let f = 0.199_824_895_698_8 - blocked;
            println!(
                "tolerance {tol:e}: F = {f:.12}, error {:.1e}, {points} points",
                f - reference
            );
            assert!((f - reference).abs() <= 2.0 * tol, "{f} vs {reference}");
        }
    }
}
