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
//! Positions are welded ([`weld`]) when they lie within `WELD_FRACTION` of the scene's
//! bounding box diagonal of each other: positions are hashed by cells of that size and
//! each corner is compared with the vertices of its cell and the 26 cells around it,
//! so two copies of one vertex that differ by round-off meet even when they straddle a
//! cell boundary. The PLY writer ([`super::lit_ply`]) uses the same vertices and colours,
//! so the mesh shows what the picture shows.
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

/// Welded, smoothed vertices: corners of one group that coincide (within the weld
/// quantum) and whose patches meet at a crease gentler than [`CREASE_DEG`] share one
/// vertex, whose colour is the area-weighted average radiosity of those patches.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SmoothVertices {
    /// Per patch: the vertex of each corner (only `n_corners` entries used).
    pub(crate) corner_vertex: Vec<[u32; 4]>,
    pub(crate) positions: Vec<DVec3>,
    /// Linear RGB, clamped to ≥ 0.
    pub(crate) colours: Vec<[f32; 3]>,
}

/// Gouraud shading: area-weighted average radiosity at each vertex, welded per group
/// and split at creases (see the module docs). `radiosity.len()` must equal
/// `patches.len()`.
pub(crate) fn vertex_colours(patches: &PatchSet, radiosity: &[[f32; 3]]) -> CornerColours {
    let v = smooth_vertices(patches, radiosity);
    v.corner_vertex
        .iter()
        .map(|ids| ids.map(|id| v.colours.get(id as usize).copied().unwrap_or([0.0; 3])))
        .collect()
}

/// The vertices of Gouraud shading (see [`SmoothVertices`] and the module docs).
pub(crate) fn smooth_vertices(patches: &PatchSet, radiosity: &[[f32; 3]]) -> SmoothVertices {
    debug_assert_eq!(patches.len(), radiosity.len());
    let cos_crease = CREASE_DEG.to_radians().cos();
    let (points, corner_point) = weld(patches);
    // Corners by (group, welded point), in patch order.
    let mut buckets: HashMap<(u32, u32), Vec<(usize, usize)>> = HashMap::new();
    for (i, p) in patches.patches.iter().enumerate() {
        for (k, &pt) in corner_point[i][..p.n_corners as usize].iter().enumerate() {
            buckets.entry((p.group, pt)).or_default().push((i, k));
        }
    }
    // Vertices numbered in order of their first corner, so the result does not depend
    // on the hash map's iteration order.
    let mut keys: Vec<(u32, u32)> = buckets.keys().copied().collect();
    keys.sort_unstable_by_key(|key| buckets[key][0]);
    let mut out = SmoothVertices {
        corner_vertex: vec![[u32::MAX; 4]; patches.len()],
        positions: Vec::new(),
        colours: Vec::new(),
    };
    for key in keys {
        // Greedy clustering by normal: a corner joins the first cluster whose first
        // member's normal is within the crease angle (members in patch order).
        let mut clusters: Vec<(DVec3, Vec<(usize, usize)>)> = Vec::new();
        for &(i, k) in &buckets[&key] {
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
                for (s, x) in sum.iter_mut().zip(clamp_colour(radiosity[i])) {
                    *s += a * f64::from(x);
                }
                area += a;
            }
            let colour = if area > 0.0 {
                sum.map(|s| (s / area) as f32)
            } else {
                clamp_colour(radiosity[list[0].0])
            };
            let id = out.positions.len() as u32;
            out.positions.push(points[key.1 as usize]);
            out.colours.push(colour);
            for &(i, k) in list {
                out.corner_vertex[i][k] = id;
            }
        }
    }
    out
}

/// Welds the corners of all patches: returns the distinct points and, per patch, the
/// point of each corner (only `n_corners` entries used). Two corners within the weld
/// quantum (`WELD_FRACTION` of the bounding box diagonal) of a point found first
/// become that point (module docs).
pub(crate) fn weld(patches: &PatchSet) -> (Vec<DVec3>, Vec<[u32; 4]>) {
    let quantum = weld_quantum(patches);
    let origin = patches.bounds().map_or(DVec3::ZERO, |(lo, _)| lo);
    let cell = |c: DVec3| {
        let q = ((c - origin) / quantum).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    };
    let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut points: Vec<DVec3> = Vec::new();
    let mut corner_point = vec![[u32::MAX; 4]; patches.len()];
    for (i, p) in patches.patches.iter().enumerate() {
        for (k, &c) in p.corners().iter().enumerate() {
            let key = cell(c);
            let near = neighbours(key).find_map(|k| {
                cells.get(&k).and_then(|ids| {
                    ids.iter()
                        .copied()
                        .find(|&id| (points[id as usize] - c).length() <= quantum)
                })
            });
            corner_point[i][k] = near.unwrap_or_else(|| {
                let id = points.len() as u32;
                points.push(c);
                cells.entry(key).or_default().push(id);
                id
            });
        }
    }
    (points, corner_point)
}

/// The 27 cells around and including `key`.
fn neighbours(key: [i64; 3]) -> impl Iterator<Item = [i64; 3]> {
    (-1..=1).flat_map(move |dx| {
        (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| [key[0] + dx, key[1] + dy, key[2] + dz]))
    })
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
    fn shared_vertices_average_by_area_across_a_round_off_straddle() {
        // Two quads of one group sharing the edge x = 1: [0,1]x[0,1] (area 1, B = 1)
        // and [1,3]x[0,1] (area 2, B = 4). Shared vertices: (1·1 + 2·4) / 3 = 3. The
        // second quad's copies of the shared corners are off by round-off across the
        // cell boundary x = 1 (the cells are 1e-6 × diagonal from the origin).
        let eps = 1e-13;
        let a = quad(
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
            0,
        );
        let b = quad(
            [
                v(1. - eps, 0., 0.),
                v(3., 0., 0.),
                v(3., 1., 0.),
                v(1. + eps, 1., 0.),
            ],
            0,
        );
        let ps = PatchSet {
            patches: vec![a, b],
            groups: vec!["g".into()],
        };
        let m = smooth_vertices(&ps, &[[1.0; 3], [4.0; 3]]);
        assert_eq!(m.positions.len(), 6);
        assert_eq!(m.corner_vertex[0], [0, 1, 2, 3]);
        assert_eq!(m.corner_vertex[1], [1, 4, 5, 2]);
        assert_eq!(m.colours[0], [1.0; 3]);
        assert_eq!(m.colours[1], [3.0; 3]);
        assert_eq!(m.colours[2], [3.0; 3]);
        assert_eq!(m.colours[4], [4.0; 3]);
        // The same corners in two groups are two vertices each.
        let mut ps2 = ps.clone();
        ps2.patches[1].group = 1;
        ps2.groups.push("h".into());
        assert_eq!(
            smooth_vertices(&ps2, &[[1.0; 3], [4.0; 3]]).positions.len(),
            8
        );
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
