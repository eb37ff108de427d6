//! The one-ray points of a row's links (`links.rs` step 2), and the table of patches
//! they read.
//!
//! A row's links share 4t points (1,024 with the defaults), and each falls on a patch
//! drawn at random inside a cluster. Reading that patch from the engine's geometry
//! touched several scattered places: its map and normal inside a `PatchGeom` of near a
//! kilobyte (the polygon and edges of the exact routes sit between them), its
//! centroid, its first-bounce radiosity and the tree order. At 100k patches the
//! geometry is about 90 MB, beyond the last-level cache, and on the 16-box room those
//! misses and the area searches that find the patches took about a sixth of a linked
//! compute's CPU (`perf record` on `compute builtin:room --patches 100000 --top-k 64`,
//! bench/LINKS.md "The links' cost"). So:
//!
//! - [`PointPatch`] keeps what a point reads in one place, 192 bytes a patch in
//!   cluster order;
//! - a row's points are drawn first ([`RowEngine::plan_node_points`], in the order of
//!   the random stream) and evaluated together ([`RowEngine::eval_points`]) in batches
//!   whose area searches advance in step and whose patches are read at once, so that
//!   their cache misses overlap.
//!
//! Each point's value is the one it had when evaluated alone, bit for bit (the rows of
//! the 16-box room at 20k patches are identical under `verify --against`).

use glam::{DVec3, DVec4};

use super::{RowEngine, Scratch};
use crate::formfactor::geom::PatchGeom;
use crate::formfactor::sampling::{PatchMap, SplitMix64};
use crate::formfactor::tree::PatchTree;

/// What a one-ray point reads of the patch it falls on (module docs): copies of the
/// patch's geometry, bit for bit, so that points give the values they gave when read
/// from the geometry itself.
#[derive(Clone, Debug)]
#[repr(align(64))]
pub(super) struct PointPatch {
    map: PatchMap,
    normal: DVec3,
    offset: f64,
    centroid: DVec3,
    area: f64,
    face: u32,
    /// The first-bounce radiosity B¹ (0 without one).
    bounce: f32,
}

impl PointPatch {
    /// The table of the patches of `tree`, by position in its cluster order; `bounce`
    /// is B¹ per patch (empty: 0).
    pub(super) fn table(tree: &PatchTree, geom: &[PatchGeom], bounce: &[f32]) -> Vec<PointPatch> {
        let Some(root) = tree.root() else {
            return Vec::new();
        };
        tree.patches_under(root)
            .iter()
            .map(|&j| {
                let g = &geom[j as usize];
                PointPatch {
                    map: g.map,
                    normal: g.normal,
                    offset: g.offset,
                    centroid: g.centroid,
                    area: g.area,
                    face: g.face,
                    bounce: bounce.get(j as usize).copied().unwrap_or(0.0),
                }
            })
            .collect()
    }

    /// The patch's centroid and, as the fourth coordinate, its B¹: the point of the
    /// links' first moments (`links.rs` step 3).
    pub(super) fn moment_point(&self) -> DVec4 {
        self.centroid.extend(self.bounce as f64)
    }
}

/// A one-ray point drawn and not yet evaluated ([`RowEngine::plan_node_points`]):
/// the node, where along its area the point falls, the four unit-square coordinates
/// of its two ends and the node's area.
#[derive(Clone, Copy, Debug)]
pub(super) struct Planned {
    node: u32,
    along: f64,
    q: [f64; 4],
    area: f64,
}

/// Points evaluated together: their patches are found and read first, so that the
/// cache misses of a batch overlap instead of following one another. Their rays go
/// one at a time through the hierarchy: as packets of a batch's points on one face
/// they cost 5 % more CPU on the room at 100k (the rays are not coherent enough), and
/// through the occluder lists of the row's clusters (`clusters.rs`, which spare the
/// rays of clusters nothing can hide) 15 % more (a list for every cluster a point
/// falls in costs more than the rays it spares); bench/LINKS.md "The links' cost".
const BATCH: usize = 8;

impl RowEngine {
    /// Step 2 of `links.rs` for an unopened node `n` that `hits` of a link's points
    /// fell on: draws the points (from `rng`, in the order the row's other draws
    /// expect) and appends them to `plan`, for [`RowEngine::eval_points`], which gives
    /// each point's Y, an unbiased estimate of Σ_j F_ij over the node's patches, and
    /// the moment point ([`PointPatch::moment_point`]) of the patch j it fell on. The
    /// points are spread over the node's area (systematically along the tree order,
    /// which keeps neighbours together, so they stratify the node in space), each with
    /// a uniform point on patch i and one on patch j and one ray between them:
    ///
    ///   Y = (A_N / A_j) · (J_i J_j / A_i) · cos θ_i cos θ_j V / (π r²),
    ///
    /// J the area elements of the two points' parametrisations (A on a triangle), V
    /// the ray's visibility. This is the Monte Carlo form of the form factor's double
    /// area integral (Cohen and Wallace, "Radiosity and Realistic Image Synthesis",
    /// 1993, §4.9); a row's unopened nodes are clear of the row patch's sphere (their
    /// bound is finite), so the kernel is bounded there. One point costs one ray, where
    /// a pair's own rule costs its contour or quadrature and up to 16 rays: the row
    /// can afford several points a link, which is what places its mass
    /// (bench/LINKS.md).
    pub(super) fn plan_node_points(
        &self,
        tree: &PatchTree,
        n: u32,
        i: u32,
        hits: u32,
        rng: &mut SplitMix64,
        plan: &mut Vec<Planned>,
    ) {
        let (area, _, _) = tree.node(n).moments();
        if hits == 0 || area.is_nan() || area <= 0.0 || self.geom[i as usize].area <= 0.0 {
            return;
        }
        let step = area / hits as f64;
        let start = rng.next_f64() * step;
        for s in 0..hits {
            plan.push(Planned {
                node: n,
                along: start + s as f64 * step,
                q: std::array::from_fn(|_| rng.next_f64()),
                area,
            });
        }
    }

    /// The points of `plan` for row i ([`RowEngine::plan_node_points`]), in order:
    /// (Y, moment point) each, appended to `out`.
    pub(super) fn eval_points(
        &self,
        tree: &PatchTree,
        i: u32,
        plan: &[Planned],
        scratch: &mut Scratch,
        out: &mut Vec<(f64, DVec4)>,
    ) {
        let gi = &self.geom[i as usize];
        // Only valid patches are in the tree, so a point is skipped on patch i only.
        let own = tree.position(i);
        let foreign = self.occluders.is_foreign();
        for batch in plan.chunks(BATCH) {
            let m = batch.len();
            let mut at = [0u32; BATCH];
            let queries: [(u32, f64); BATCH] =
                std::array::from_fn(|t| batch.get(t).map_or((0, 0.0), |p| (p.node, p.along)));
            tree.positions_at_area(&queries[..m], &mut at);
            // Copies, not references: the loads are made here, all of them at once.
            let patches: [PointPatch; BATCH] =
                std::array::from_fn(|t| self.points[at[t] as usize].clone());
            for (t, p) in batch.iter().enumerate() {
                let pj = &patches[t];
                let mut v = 0.0;
                if let Some((x, y, w)) = gi
                    .kernel_point_on(&pj.map, pj.normal, p.q)
                    .filter(|_| own != Some(at[t]))
                {
                    let planes =
                        foreign.then_some([(gi.normal, gi.offset), (pj.normal, pj.offset)]);
                    scratch.pair.counters.rays_cast += 1;
                    if !self
                        .occluders
                        .occluded_between_planes(x, y, (gi.face, pj.face), planes)
                    {
                        v = p.area / (pj.area * gi.area * std::f64::consts::PI) * w;
                    }
                }
                out.push((v, pj.moment_point()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::formfactor::engine::tests::linked_room;

    /// Every row of the table is its patch's geometry, bit for bit, in cluster order,
    /// with the patch's B¹ (the 16-box room has a lamp, so B¹ is not all 0).
    #[test]
    fn the_table_copies_each_patch_in_cluster_order() {
        let (_, e) = linked_room(300);
        let tree = e.tree.as_ref().expect("a tree search");
        let bounce = &e.contrast.as_ref().expect("a lamp").bounce;
        assert!(bounce.iter().any(|&b| b > 0.0));
        let order = tree.cluster_order(e.geom.len());
        assert_eq!(e.points.len(), tree.patches_under(0).len());
        for (k, p) in e.points.iter().enumerate() {
            let j = order[k] as usize;
            let g = &e.geom[j];
            assert_eq!(p.map, g.map);
            assert_eq!(p.normal, g.normal);
            assert_eq!(p.offset.to_bits(), g.offset.to_bits());
            assert_eq!(p.centroid, g.centroid);
            assert_eq!(p.area.to_bits(), g.area.to_bits());
            assert_eq!(p.face, g.face);
            assert_eq!(p.bounce.to_bits(), bounce[j].to_bits());
        }
    }
}
