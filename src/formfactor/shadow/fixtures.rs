//! Shapes the tests of the shadow modules share: squares, their casters, a box between
//! two squares, and Howell's corner formula for a differential element.

use glam::dvec3;

use super::caster::Caster;
use crate::formfactor::clip::Polygon;
use crate::formfactor::shadow::solids::Solids;

/// Howell's differential element to a parallel rectangle with a corner above
/// it (a × b at height c), written out independently of [`point_polygon`].
pub(super) fn corner_rectangle(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

pub(super) fn square(x0: f64, x1: f64, z0: f64, z1: f64, y: f64) -> Polygon {
    // Seen from below (y smaller), counter-clockwise about −y.
    Polygon::new(&[
        dvec3(x0, y, z0),
        dvec3(x0, y, z1),
        dvec3(x1, y, z1),
        dvec3(x1, y, z0),
    ])
}

/// A closed box between a floor square and a smaller ceiling square, as one solid
/// and as its twelve triangles each on its own.
pub(super) fn box_between_squares() -> (Solids, Vec<Caster>, Vec<Caster>) {
    use crate::formfactor::shadow::solids::tests::box_triangles;
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
pub(super) fn square_facing(x0: f64, x1: f64, z0: f64, z1: f64, y: f64, up: bool) -> Polygon {
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

pub(super) fn casters_of_square(x0: f64, x1: f64, z0: f64, z1: f64, y: f64) -> Vec<Caster> {
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
