//! The `city` built-in: city blocks open to the sky, for the urban view-factor case
//! (facets of buildings and streets exchanging long-wave radiation, most of each
//! hemisphere being sky).
//!
//! Layout (units m, y up): a square grid of blocks, PARAM per side (default 4); each
//! block is a 20 m cell holding one building of 10–14 m × 10–14 m footprint placed
//! anywhere in it with at least 3 m of street around it, its height 6–30 m, all from a
//! hash of the block's index (so the scene is the same on every machine). Buildings
//! have four walls and a roof, no bottom: they stand on the ground, one face over the
//! whole grid (the ground under a building sees nothing, as under the Cornell blocks).
//! Nothing closes the scene: rows sum to the share of the hemisphere that sees a
//! surface. The ground emits 1 (a warm street), so `run` has light to show; walls and
//! roofs reflect 0.3–0.5.

use glam::DVec3;

use super::builder::Builder;
use super::Scene;
use crate::random::SplitMix64;

/// Blocks per side in `builtin("city", None)`.
pub(crate) const DEFAULT_BLOCKS: usize = 4;

const CELL: f64 = 20.0;
const STREET: f64 = 3.0;

/// A grid of `blocks` × `blocks` city blocks (see the module docs).
pub(super) fn builtin_city(blocks: usize) -> Scene {
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    let side = blocks as f64 * CELL;
    let mut b = Builder::new("city");
    let ground = b.material("ground", [0.2, 0.2, 0.2], [1.0, 1.0, 1.0]);
    let facades = [
        b.material("concrete", [0.45, 0.45, 0.42], [0.0; 3]),
        b.material("brick", [0.45, 0.30, 0.25], [0.0; 3]),
        b.material("glass", [0.30, 0.33, 0.35], [0.0; 3]),
    ];
    let roof = b.material("roof", [0.35, 0.35, 0.35], [0.0; 3]);
    // Facing up: normal u × v = z × x = +y.
    b.quad("ground", ground, DVec3::ZERO, z * side, x * side);
    for i in 0..blocks * blocks {
        let (r, c) = (i / blocks, i % blocks);
        let mut rng = SplitMix64::new(0x0C17_B10C ^ i as u64);
        let w = 10.0 + 4.0 * rng.next_f64();
        let d = 10.0 + 4.0 * rng.next_f64();
        let h = 6.0 + 24.0 * rng.next_f64();
        let ox = c as f64 * CELL + STREET + (CELL - 2.0 * STREET - w) * rng.next_f64();
        let oz = r as f64 * CELL + STREET + (CELL - 2.0 * STREET - d) * rng.next_f64();
        let facade = facades[rng.below(facades.len())];
        let q = [
            DVec3::new(ox, 0.0, oz),
            DVec3::new(ox + w, 0.0, oz),
            DVec3::new(ox + w, 0.0, oz + d),
            DVec3::new(ox, 0.0, oz + d),
        ];
        let name = format!("building_{i}");
        for k in 0..4 {
            // Wall k runs q[k] → q[k+1] (counter-clockwise seen from above): y × that
            // edge points out of the building.
            b.quad(&name, facade, q[k], y * h, q[(k + 1) % 4] - q[k]);
        }
        b.quad(&name, roof, q[0] + y * h, q[3] - q[0], q[1] - q[0]);
    }
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn city_is_valid_deterministic_and_faces_point_out() {
        let s = builtin_city(3);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s, builtin_city(3));
        assert_eq!(s.faces.len(), 1 + 9 * 5);
        let (lo, hi) = s.bounds();
        assert!(lo.min_element() >= 0.0 && hi.x <= 60.0 && hi.z <= 60.0 && hi.y <= 30.0);
        // Every building face points away from its building's centre, the ground up.
        for f in &s.faces {
            let group = &s.groups[f.group as usize];
            let n = f.normal();
            if group == "ground" {
                assert!((n - DVec3::Y).length() < 1e-12);
                continue;
            }
            let mine: Vec<_> = s.faces.iter().filter(|g| g.group == f.group).collect();
            let mean =
                |g: &crate::scene::Face| g.corners.iter().sum::<DVec3>() / g.corners.len() as f64;
            let centre = mine.iter().map(|g| mean(g)).sum::<DVec3>() / mine.len() as f64;
            assert!(n.dot(mean(f) - centre) > 0.0, "{group}: inward face");
        }
    }
}
