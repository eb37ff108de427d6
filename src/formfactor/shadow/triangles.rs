//! The outer rule's triangles: a [`Cell`] with its degree-8 estimate and that
//! estimate's error, and an [`Open`] one, not refined yet, ordered for the open list
//! (the largest error first; among equal ones the older, so that the order of
//! refinement never depends on the heap's layout).

use glam::DVec3;

/// One triangle of the outer rule with its degree-8 estimate and that estimate's error.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cell {
    pub(super) t: [DVec3; 3],
    pub(super) area: f64,
    /// [`crate::formfactor::quadrature::LAURIE`]'s estimate of the integral over the triangle.
    pub(super) value: f64,
    /// Its error estimate: how far the embedded [`crate::formfactor::quadrature::RADON`] rule lies from it.
    pub(super) err: f64,
    /// Every sample saw no shadow.
    pub(super) dark_free: bool,
}

/// A triangle of the outer rule not refined further (yet).
#[derive(Debug)]
pub(super) struct Open {
    /// Its error estimate.
    pub(super) err: f64,
    /// Order of creation: among equal errors the older is refined first, so the order
    /// of refinement, and with it the sum, never depends on the heap's layout.
    pub(super) seq: u64,
    pub(super) cell: Cell,
    pub(super) depth: u32,
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
