//! An occluder triangle prepared for one pair ([`Caster`]), the unit of every shadow
//! in this folder, and [`NO_SOLID`], the mark of a caster that belongs to no convex
//! solid ([`super::solids`]).

use glam::DVec3;

/// No solid: the triangle casts its own shadow.
pub(crate) const NO_SOLID: u32 = u32::MAX;

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
