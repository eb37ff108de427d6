//! Casters and their cones. A [`Caster`] is an occluder triangle prepared for one pair;
//! its [`Cone`] from a point x is the intersection of half-spaces holding the points y
//! whose segment from x crosses it: the three planes through x and an edge, and the
//! far side of its plane (the shadow of a triangle, clipped, in [`super`]). A convex
//! solid seen from x gives one cone for all its triangles: its silhouette's planes and
//! the far sides of the faces x sees ([`super::solids`]). A receiver
//! [`Piece`] is P_j clipped by such planes.

use glam::DVec3;

use super::caster::Caster;
use super::solids::{Solid, MAX_FACES};
use crate::formfactor::clip::PolygonN;

/// A receiver piece: `P_j` (at most 8 vertices) clipped by the four planes of a cone
/// (one vertex more per plane).
pub(crate) type Piece = PolygonN<16>;

/// A half-space `normal · y ≥ offset`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Half {
    pub(super) normal: DVec3,
    pub(super) offset: f64,
}

/// Most half-spaces of a cone: a triangle's four, a solid's silhouette planes and the
/// planes of the faces x sees (a box: at most six and three).
const MAX_HALVES: usize = 12;

/// The points y whose segment from x crosses a caster: an intersection of half-spaces.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cone {
    h: [Half; MAX_HALVES],
    n: usize,
}

/// What a convex solid hides from one point.
pub(super) enum SolidShadow {
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
    pub(super) const EMPTY: Cone = Cone {
        h: [Half {
            normal: DVec3::ZERO,
            offset: 0.0,
        }; MAX_HALVES],
        n: 0,
    };

    pub(super) fn halves(&self) -> &[Half] {
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
    pub(super) fn set_triangle(&mut self, x: DVec3, t: &Caster, tol: f64) -> bool {
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
    pub(super) fn of_solid(
        x: DVec3,
        k: &Solid,
        receiver: &Piece,
        tol: f64,
        c: &mut Cone,
    ) -> SolidShadow {
        let mut side = [0.0; MAX_FACES];
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
    pub(super) fn misses(&self, p: &Piece, tol: f64) -> bool {
        self.halves()
            .iter()
            .any(|h| p.verts().iter().all(|v| h.normal.dot(*v) - h.offset <= tol))
    }
}

/// A piece worth keeping: three vertices or more (slivers of area 0 add nothing).
pub(super) fn usable(p: &Piece) -> bool {
    p.n >= 3
}
