//! A top-k row's total from rays over the hemisphere (`topk_tree.rs` step 3).
//!
//! Σ_j F_ij is the probability that a ray leaving a uniform point of patch i in a
//! cosine-distributed direction first meets the front of a patch (form factors are one
//! sided: a ray that meets a back face, or nothing, carries light to no patch). So
//!
//!   T̂_i = (1/t) Σ_r w_r [ray r's first surface is a patch's front],
//!
//! w_r the area weight of its start point (1 but on bilinear quads), is an unbiased
//! estimate of the row total, and the row's dropped tail is T̂_i less the mass known
//! exactly (kept entries, entries pushed out, columns needing no rays). Its error is
//! √(T(1 − T)/t) at most, less with the stratified points and directions used here
//! (start points on a jittered grid, directions from a Latin hypercube), and **zero in
//! a closed scene**,
//! where every ray meets a front face: there the row total is 1 and the dropped mass
//! 1 − known, whatever the tail holds. The tree walk's estimate it replaces (light-tree
//! sampling over the unopened nodes, `tree_tail_mass`) has an error that grows with the
//! tail: at 1M patches in the closed 16-box room, rows summed to up to 4.96
//! (bench/PERF.md §23).
//!
//! It needs the occluders to be the patches' own surfaces (the scene's faces, merged or
//! not): the first surface a ray meets is then located among the patches by the patch
//! tree. With another occluder mesh (`--occluders`) the walk's estimate is kept.

use super::{RowEngine, Scratch};
use crate::formfactor::sampling::latin_pairs;
use crate::formfactor::tree::PatchTree;

/// Whether the row totals come from hemisphere rays with these occluders (that many
/// triangles, from another mesh than the patches' or not): what the file header says
/// (`RowEngine::description`) and what [`RowEngine::closure_total`] does.
pub(super) fn hemisphere_totals(occluder_triangles: usize, other_mesh: bool) -> bool {
    occluder_triangles > 0 && !other_mesh
}

/// Scratch space of [`RowEngine::closure_total`].
#[derive(Debug, Default)]
pub(super) struct ClosureScratch {
    perms: Vec<u32>,
    points: Vec<[f64; 4]>,
    stack: Vec<u32>,
}

impl RowEngine {
    /// T̂_i from `t` rays (module docs); `None` when the occluders are another mesh or
    /// there are none, or patch i is not valid.
    pub(super) fn closure_total(
        &self,
        tree: &PatchTree,
        i: u32,
        t: usize,
        scratch: &mut Scratch,
    ) -> Option<f64> {
        if !hemisphere_totals(self.occluders.len(), !self.occluders.surfaces_are_patches) || t == 0
        {
            return None;
        }
        let g = self
            .geom
            .get(i as usize)
            .filter(|_| self.valid[i as usize])?;
        let s = &mut scratch.closure;
        let mut rng = self.tail_rng(i);
        latin_pairs(&mut rng, t, &mut s.perms, &mut s.points);
        let n = g.normal;
        let (u, v) = n.any_orthonormal_pair();
        // Start points on a jittered s × s grid when t is a square (a shadow edge
        // across the patch is then sampled in both directions), directions from the
        // Latin hypercube's other two coordinates.
        let side = (t as f64).sqrt().round() as usize;
        let grid = side * side == t;
        let mut sum = 0.0;
        for (k, &[p, q, c, d]) in s.points.iter().enumerate() {
            let (p, q) = match grid {
                true => (
                    ((k % side) as f64 + rng.next_f64()) / side as f64,
                    ((k / side) as f64 + rng.next_f64()) / side as f64,
                ),
                false => (p, q),
            };
            let (x, jacobian) = g.map.eval(p, q);
            let (r, phi) = (c.sqrt(), std::f64::consts::TAU * d);
            let dir = u * (r * phi.cos()) + v * (r * phi.sin()) + n * (1.0 - c).max(0.0).sqrt();
            let Some(y) = self.occluders.first_hit(x, dir, g.face, (n, g.offset)) else {
                continue;
            };
            if tree.front_patch_at(&self.geom, y, dir, self.hide_margin, &mut s.stack) {
                sum += jacobian / g.area;
            }
        }
        scratch.pair.counters.closure_rays += t as u64;
        Some(sum / t as f64)
    }
}
