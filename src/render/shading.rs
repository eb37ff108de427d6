//! Colours at patch corners: what the rasterizer interpolates.
//!
//! Gouraud shading (the default) gives every corner the area-weighted average radiosity
//! of the patches that share that vertex: the usual way radiosity results are smoothed
//! for display (nodal values from the adjacent elements, as in Cohen and Wallace,
//! "Radiosity and Realistic Image Synthesis", 1993, chapter on rendering), and how the
//! paper's renderer interpolated its per-face results. Departure, to keep wall colours clean: vertices
//! are welded only within one group (OBJ group/object), so the red wall's corner does
//! not take in the white floor's radiosity, and within a group only across creases
//! gentler than [`CREASE_DEG`], so the faces of a box do not bleed into each other
//! while a finely tessellated curved surface still shades smoothly.
//!
//! Positions are welded by quantising them to `WELD_FRACTION` of the scene's bounding
//! box diagonal. Two copies of one vertex that differ only by round-off (far below the
//! quantum) fall in different cells only when they straddle a cell boundary, which at
//! that ratio is vanishingly rare; the cost of a miss is a faint seam, not an error.
//!
//! Negative radiosity (solver round-off) is clamped to zero here.

use std::collections::HashMap;

use glam::DVec3;

use crate::patch::PatchSet;

/// Creases sharper than this (angle between patch normals, degrees) are not smoothed.
pub(crate) const CREASE_DEG: f64 = 60.0;

/// Weld quantum as a fraction of the bounding box diagonal.
const WELD_FRACTION: f64 = 1e-6;

/// Per-corner linear RGB colour, one entry per patch (only `n_corners` entries used).
pub(crate) type CornerColours = Vec<[[f32; 3]; 4]>;

fn clamp_colour(b: [f32; 3]) -> [f32; 3] {
    b.map(|x| x.max(0.0))
}

/// Flat shading: every corner of patch `i` has patch `i`'s radiosity.
pub(crate) fn flat_colours(radiosity: &[[f32; 3]]) -> CornerColours {
    radiosity.iter().map(|&b| [clamp_colour(b); 4]).collect()
}

/// Gouraud shading: area-weighted average radiosity at each vertex, welded per group
/// and split at creases (see the module docs). `radiosity.len()` must equal
/// `patches.len()`.
pub(crate) fn vertex_colours(patches: &PatchSet, radiosity: &[[f32; 3]]) -> CornerColours {
    debug_assert_eq!(patches.len(), radiosity.len());
    let quantum = weld_quantum(patches);
    let cos_crease = CREASE_DEG.to_radians().cos();

    // Bucket every corner by (group, quantised position), in patch order.
    type Key = (u32, [i64; 3]);
    let mut buckets: HashMap<Key, Vec<(usize, usize)>> = HashMap::new();
    for (i, p) in patches.patches.iter().enumerate() {
        for (k, c) in p.corners().iter().enumerate() {
            let q = (*c / quantum).round();
            let key = (p.group, [q.x as i64, q.y as i64, q.z as i64]);
            buckets.entry(key).or_default().push((i, k));
        }
    }

    let mut out: CornerColours = radiosity.iter().map(|&b| [clamp_colour(b); 4]).collect();
    for members in buckets.values() {
        // Greedy clustering by normal: a corner joins the first cluster whose first
        // member's normal is within the crease angle. Members are in patch order, so
        // the result does not depend on the hash map's iteration order.
        let mut clusters: Vec<(DVec3, Vec<(usize, usize)>)> = Vec::new();
        for &(i, k) in members {
            let n = patches.patches[i].normal;
            match clusters.iter_mut().find(|(n0, _)| n0.dot(n) >= cos_crease) {
                Some((_, list)) => list.push((i, k)),
                None => clusters.push((n, vec![(i, k)])),
            }
        }
        for (_, list) in &clusters {
            let mut sum = [0.0f64; 3];
            let mut area = 0.0f64;
            for &(i, _) in list {
                let a = patches.patches[i].area;
                let b = clamp_colour(radiosity[i]);
                for (s, x) in sum.iter_mut().zip(b) {
                    *s += a * f64::from(x);
                }
                area += a;
            }
            if area > 0.0 {
                let avg = sum.map(|s| (s / area) as f32);
                for &(i, k) in list {
                    out[i][k] = avg;
                }
            }
        }
    }
    out
}

/// Weld quantum: a fixed fraction of the bounding box diagonal (1 for an empty or
/// degenerate scene).
fn weld_quantum(patches: &PatchSet) -> f64 {
    let diag = patches.diagonal();
    if diag > 0.0 {
        diag * WELD_FRACTION
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::patch::Patch;

    fn quad(c: [DVec3; 4], group: u32) -> Patch {
        let normal = (c[1] - c[0]).cross(c[2] - c[0]).normalize();
        let area = 0.5 * (c[2] - c[0]).cross(c[3] - c[1]).length();
        Patch {
            corners: c,
            n_corners: 4,
            normal,
            area,
            group,
            face: 0,
            rho: [0.5; 3],
            emission: [0.0; 3],
        }
    }

    fn v(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    #[test]
    fn shared_vertex_is_area_weighted_within_a_group() {
        // Two coplanar quads side by side in group 0, areas 1 and 3, sharing the edge
        // x = 1; a third quad of group 1 sharing the same edge must not count.
        let a = quad(
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
            0,
        );
        let b = quad(
            [v(1., 0., 0.), v(4., 0., 0.), v(4., 1., 0.), v(1., 1., 0.)],
            0,
        );
        let c = quad(
            [v(1., 0., 0.), v(1., 0., -1.), v(1., 1., -1.), v(1., 1., 0.)],
            1,
        );
        let set = PatchSet {
            patches: vec![a, b, c],
            groups: vec!["wall".into(), "other".into()],
        };
        let rad = [[1.0, 0.0, 0.0], [5.0, 4.0, -1.0], [100.0, 100.0, 100.0]];
        let col = vertex_colours(&set, &rad);
        // Shared corner: (1·1 + 3·5)/4 = 4 red, (3·4)/4 = 3 green, negative blue → 0.
        assert_eq!(col[0][1], [4.0, 3.0, 0.0]);
        assert_eq!(col[1][0], [4.0, 3.0, 0.0]);
        // Unshared corners keep their own patch's value.
        assert_eq!(col[0][0], [1.0, 0.0, 0.0]);
        assert_eq!(col[1][1], [5.0, 4.0, 0.0]);
        // The other group's patch is untouched by the wall.
        assert_eq!(col[2][0], [100.0; 3]);
    }

    #[test]
    fn crease_within_a_group_is_not_smoothed() {
        // Two faces of one box (same group) at 90°.
        let a = quad(
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
            0,
        );
        let b = quad(
            [v(1., 0., 0.), v(1., 0., 1.), v(1., 1., 1.), v(1., 1., 0.)],
            0,
        );
        let set = PatchSet {
            patches: vec![a, b],
            groups: vec!["box".into()],
        };
        let col = vertex_colours(&set, &[[1.0; 3], [3.0; 3]]);
        assert_eq!(col[0][1], [1.0; 3]);
        assert_eq!(col[1][0], [3.0; 3]);
    }
}
