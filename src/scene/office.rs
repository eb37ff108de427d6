//! The `office` built-in: a daylit room for `ffstream annual`, the only built-in with
//! z up (x east, y north, z up: the axes `annual` assumes by default).
//!
//! A room 4 m wide (x), 6 m deep (y) and 3 m high, every face facing in, with one
//! window opening (a hole: the sky is what a ray through it reaches) in the south wall
//! (y = 0), centred, sill 0.9 m, head 2.1 m, its width the scene's parameter (2 m by
//! default, at most 3.8 m). Reflectances: floor 0.2, walls 0.5, ceiling 0.8 (the usual
//! values of daylight studies). No light source: the light comes through the window.
//! `annual --rotate DEG` turns the window to face other directions.

use glam::DVec3;

use super::builder::Builder;
use super::Scene;

/// Width, depth, height (m).
pub(crate) const SIZE: [f64; 3] = [4.0, 6.0, 3.0];
/// Sill and head of the window (m).
pub(crate) const SILL: f64 = 0.9;
pub(crate) const HEAD: f64 = 2.1;
/// Default window width (m).
pub(crate) const DEFAULT_WINDOW: f64 = 2.0;

/// The office with a window `width` m wide (0 < width ≤ 3.8).
pub(crate) fn builtin_office(width: f64) -> Scene {
    let [w, d, h] = SIZE;
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    let mut b = Builder::new("office");
    let floor = b.material("floor", [0.2, 0.2, 0.2], [0.0; 3]);
    let wall = b.material("wall", [0.5, 0.5, 0.5], [0.0; 3]);
    let ceiling = b.material("ceiling", [0.8, 0.8, 0.8], [0.0; 3]);
    // Each quad's normal u × v points into the room.
    b.quad("floor", floor, DVec3::ZERO, x * w, y * d);
    b.quad("ceiling", ceiling, z * h, y * d, x * w);
    b.quad("wall_north", wall, y * d, x * w, z * h);
    b.quad("wall_west", wall, DVec3::ZERO, y * d, z * h);
    b.quad("wall_east", wall, x * w, z * h, y * d);
    let (x0, x1) = (0.5 * (w - width), 0.5 * (w + width));
    b.quad("wall_south", wall, DVec3::ZERO, z * SILL, x * w);
    b.quad("wall_south", wall, z * HEAD, z * (h - HEAD), x * w);
    b.quad("wall_south", wall, z * SILL, z * (HEAD - SILL), x * x0);
    b.quad(
        "wall_south",
        wall,
        x * x1 + z * SILL,
        z * (HEAD - SILL),
        x * (w - x1),
    );
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faces_look_into_the_room_and_the_window_is_a_hole() {
        let s = builtin_office(2.0);
        let centre = DVec3::new(2.0, 3.0, 1.5);
        for f in &s.faces {
            let c = f.corners.iter().copied().sum::<DVec3>() / f.corners.len() as f64;
            assert!(f.normal().dot(centre - c) > 0.0, "face at {c} faces out");
        }
        let south: f64 = s
            .faces
            .iter()
            .filter(|f| s.groups[f.group as usize] == "wall_south")
            .map(|f| f.area())
            .sum();
        assert!(
            (south - (4.0 * 3.0 - 2.0 * (HEAD - SILL))).abs() < 1e-12,
            "{south}"
        );
    }
}
