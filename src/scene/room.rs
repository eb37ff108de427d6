//! The `room` built-in: a closed, cluttered room whose size grows with the number of
//! boxes, for benchmarks that need many occluders and 100k+ patches.
//!
//! Layout (units m, y up): the floor is a grid of 2 m cells, one box per cell, so boxes
//! never intersect; a 1 m margin runs along the walls; the ceiling (3 m) has a light
//! cut into its centre, a quarter of the room's width and depth, facing down. Each box
//! gets its size, rotation about y (half of them axis-aligned), colour and height from
//! a hash of its index (SplitMix64), so the scene is the same on every machine. Every
//! fourth box floats (base 0.4 to 1 m up) and so has a bottom face; the others stand on
//! the floor without one, like the Cornell blocks.

use glam::DVec3;

use super::builder::Builder;
use super::Scene;
use crate::random::SplitMix64;

/// Boxes in `builtin("room", None)`.
pub(crate) const DEFAULT_BOXES: usize = 16;

const CELL: f64 = 2.0;
const MARGIN: f64 = 1.0;
const HEIGHT: f64 = 3.0;

/// Uniform value in [0, 1) for box `i`, property `k`: the first draw of the generator
/// seeded with both (a hash of them, the same on every machine).
fn unit(i: usize, k: u64) -> f64 {
    SplitMix64::new((i as u64) << 8 | k).next_f64()
}

/// A room with `boxes` boxes (see the module docs).
pub fn builtin_room(boxes: usize) -> Scene {
    let cols = ((boxes as f64).sqrt().ceil() as usize).max(1);
    let rows = boxes.div_ceil(cols).max(1);
    let (wx, wz) = (
        cols as f64 * CELL + 2.0 * MARGIN,
        rows as f64 * CELL + 2.0 * MARGIN,
    );
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);

    let mut b = Builder::new("room");
    let wall = b.material("wall", [0.75, 0.75, 0.75], [0.0; 3]);
    let floor = b.material("floor", [0.45, 0.42, 0.40], [0.0; 3]);
    let light = b.material("light", [0.78, 0.78, 0.78], [10.0, 10.0, 10.0]);
    let colours = [
        b.material("red", [0.70, 0.15, 0.12], [0.0; 3]),
        b.material("green", [0.15, 0.60, 0.20], [0.0; 3]),
        b.material("blue", [0.15, 0.20, 0.65], [0.0; 3]),
        b.material("grey", [0.50, 0.50, 0.50], [0.0; 3]),
    ];

    // Shell, every face inward (normal u × v).
    b.quad("floor", floor, DVec3::ZERO, z * wz, x * wx);
    b.quad("wall_x0", wall, DVec3::ZERO, y * HEIGHT, z * wz);
    b.quad("wall_x1", wall, x * wx, z * wz, y * HEIGHT);
    b.quad("wall_z0", wall, DVec3::ZERO, x * wx, y * HEIGHT);
    b.quad("wall_z1", wall, z * wz, y * HEIGHT, x * wx);
    // Ceiling around the light's hole: front and back strips, then left and right.
    let (x0, x1) = (wx * 0.375, wx * 0.625);
    let (z0, z1) = (wz * 0.375, wz * 0.625);
    let top = y * HEIGHT;
    b.quad("ceiling", wall, top, x * wx, z * z0);
    b.quad("ceiling", wall, top + z * z1, x * wx, z * (wz - z1));
    b.quad("ceiling", wall, top + z * z0, x * x0, z * (z1 - z0));
    b.quad(
        "ceiling",
        wall,
        top + x * x1 + z * z0,
        x * (wx - x1),
        z * (z1 - z0),
    );
    b.quad(
        "light",
        light,
        top + x * x0 + z * z0,
        x * (x1 - x0),
        z * (z1 - z0),
    );

    for i in 0..boxes {
        let (r, c) = (i / cols, i % cols);
        let w = 0.4 + 0.8 * unit(i, 0);
        let d = 0.4 + 0.8 * unit(i, 1);
        let theta = if unit(i, 2) < 0.5 {
            0.0
        } else {
            unit(i, 3) * std::f64::consts::FRAC_PI_2
        };
        // Keep the rotated footprint (radius ≤ 0.85) inside the cell (half-width 1).
        let slack = CELL * 0.5 - 0.5 * (w * w + d * d).sqrt();
        let centre = DVec3::new(
            MARGIN + (c as f64 + 0.5) * CELL + slack * (2.0 * unit(i, 4) - 1.0),
            0.0,
            MARGIN + (r as f64 + 0.5) * CELL + slack * (2.0 * unit(i, 5) - 1.0),
        );
        let floating = i % 4 == 3;
        let base = if floating {
            0.4 + 0.6 * unit(i, 6)
        } else {
            0.0
        };
        let h = 0.3 + (HEIGHT - 0.3 - base - 0.3) * unit(i, 7);
        let material = colours[(unit(i, 8) * colours.len() as f64) as usize % colours.len()];
        let (ux, uz) = (
            DVec3::new(theta.cos(), 0.0, theta.sin()),
            DVec3::new(-theta.sin(), 0.0, theta.cos()),
        );
        let (a, e) = (ux * (w * 0.5), uz * (d * 0.5));
        let lift = y * base + centre;
        let q = [lift - a - e, lift + a - e, lift + a + e, lift - a + e];
        let name = format!("box_{i}");
        for k in 0..4 {
            // Side k runs q[k] → q[k+1]; y × that edge points out of the box.
            b.quad(&name, material, q[k], y * h, q[(k + 1) % 4] - q[k]);
        }
        b.quad(&name, material, q[0] + y * h, q[3] - q[0], q[1] - q[0]);
        if floating {
            b.quad(&name, material, q[0], q[1] - q[0], q[3] - q[0]);
        }
    }
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_is_valid_closed_and_deterministic() {
        let s = builtin_room(10);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s, builtin_room(10));
        // 5 walls/floor + 4 ceiling pieces + light, 5 faces per box, 6 for floating ones.
        let floating = (0..10).filter(|i| i % 4 == 3).count();
        assert_eq!(s.faces.len(), 10 + 10 * 5 + floating);
        // The shell: ceiling pieces + light cover exactly the floor area.
        let (lo, hi) = s.bounds();
        let floor = (hi.x - lo.x) * (hi.z - lo.z);
        let top: f64 = s
            .faces
            .iter()
            .filter(|f| matches!(s.groups[f.group as usize].as_str(), "ceiling" | "light"))
            .map(|f| f.area())
            .sum();
        assert!((top - floor).abs() < 1e-9 * floor);
        // Boxes stay inside the room, below the ceiling.
        assert!(lo.min_element() >= 0.0 && hi.y <= HEIGHT);
    }

    #[test]
    fn box_faces_point_outward() {
        let s = builtin_room(8);
        for f in &s.faces {
            let g = &s.groups[f.group as usize];
            if !g.starts_with("box_") {
                continue;
            }
            let same: Vec<DVec3> = s
                .faces
                .iter()
                .filter(|o| o.group == f.group)
                .flat_map(|o| o.corners.iter().copied())
                .collect();
            let centre = same.iter().copied().sum::<DVec3>() / same.len() as f64;
            let c = f.corners.iter().copied().sum::<DVec3>() / 4.0;
            assert!(f.normal().dot(c - centre) > 0.0, "{g}");
        }
    }
}
