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
//! 1 − known, whatever the tail holds. With the total comes a scale of its error,
//! √(p̃(1 − p̃)/t) with p̃ = (hits + 1)/(t + 2) (Laplace's rule, so that a patch whose
//! rays all met a front, or none did, still admits an error of about 1/t: a few rays
//! can miss a sliver that sees the room), summed over the cells below; the link error
//! of a row (spec §5.7) counts it. The tree walk's estimate it replaces (light-tree
//! sampling over the unopened nodes, `tree_tail_mass`) has an error that grows with the
//! tail: at 1M patches in the closed 16-box room, rows summed to up to 4.96
//! (bench/PERF.md §23).
//!
//! **Patches that something stands on** (a floor cell partly under a box) see the
//! closed room from one part and nothing from the other; rays spread over the whole
//! patch estimate that split only to about 1/t per grid cell the box's wall crosses
//! (errors up to 1.3e-2 at t = 256 on the 16-box room, bench/PERF.md §24). Such a
//! patch is cut into convex cells along the planes of the triangles standing on it
//! (one or two corners on its plane), and each cell gets rays in proportion to its
//! area, at least one: still unbiased, and exact in a closed scene, where each cell
//! sees all or nothing. Rays start meeting surfaces at distance 0
//! ([`crate::geometry::occluders::Occluders::first_hit`]), so a start point a hair from such a wall does
//! not slip past it into the box.
//!
//! It needs the occluders to be the patches' own surfaces (the scene's faces, merged or
//! not): the first surface a ray meets is then located among the patches by the patch
//! tree. With another occluder mesh (`--occluders`) the walk's estimate is kept.

use glam::DVec3;

use super::{RowEngine, Scratch};
use crate::formfactor::geom::PatchGeom;
use crate::formfactor::sampling::{latin_pairs, SplitMix64};
use crate::formfactor::shadow::{self, Piece};
use crate::formfactor::tree::PatchTree;

/// Most cells a patch's row total is cut into (each gets one ray at least; more
/// cells: the plain estimate).
const MAX_CELLS: usize = 64;

/// Whether the row totals come from hemisphere rays with these occluders (that many
/// triangles, from another mesh than the patches' or not): what the file header says
/// ([`RowEngine::dropped_mass`]) and what [`RowEngine::closure_total`] does.
pub(super) fn hemisphere_totals(occluder_triangles: usize, other_mesh: bool) -> bool {
    occluder_triangles > 0 && !other_mesh
}

/// Scratch space of [`RowEngine::closure_total`].
#[derive(Debug, Default)]
pub(super) struct ClosureScratch {
    perms: Vec<u32>,
    points: Vec<[f64; 4]>,
    stack: Vec<u32>,
    cells: Vec<Piece>,
}

/// The variance of the share of `rays` rays that met a front, `hits` of them met
/// one, with Laplace's rule of succession (module docs).
fn ray_error(hits: usize, rays: usize) -> f64 {
    let p = (hits as f64 + 1.0) / (rays as f64 + 2.0);
    p * (1.0 - p) / rays.max(1) as f64
}

/// A cosine-distributed direction about `n` (`u`, `v`, `n` orthonormal) from two
/// uniform numbers.
fn cosine_direction(u: DVec3, v: DVec3, n: DVec3, c: f64, d: f64) -> DVec3 {
    let (r, phi) = (c.sqrt(), std::f64::consts::TAU * d);
    u * (r * phi.cos()) + v * (r * phi.sin()) + n * (1.0 - c).max(0.0).sqrt()
}

/// The point of the convex polygon `v` for (p, q) uniform in the unit square: a
/// uniform point of it (p picks a triangle of the fan from `v[0]` by area and, rescaled,
/// the distance from `v[0]`; q the place across).
fn point_in_fan(v: &[DVec3], area: f64, p: f64, q: f64) -> DVec3 {
    let mut left = p * area;
    let last = v.len() - 2;
    for k in 1..=last {
        let (b, c) = (v[k], v[k + 1]);
        let a = 0.5 * (b - v[0]).cross(c - v[0]).length();
        if left < a || k == last {
            let s = (left / a).clamp(0.0, 1.0).sqrt();
            return v[0] + s * ((b - v[0]) + q * (c - b));
        }
        left -= a;
    }
    v[0]
}

impl RowEngine {
    /// T̂_i from `t` rays and the scale of its error (module docs); `None` when the
    /// occluders are another mesh or there are none, or patch i is not valid.
    pub(super) fn closure_total(
        &self,
        tree: &PatchTree,
        i: u32,
        t: usize,
        scratch: &mut Scratch,
    ) -> Option<(f64, f64)> {
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
        if self.standing_cells(g, &mut s.cells) {
            let (total, sigma, cast) = self.cells_total(tree, g, t, &mut rng, s);
            scratch.pair.counters.closure_rays += cast as u64;
            return Some((total, sigma));
        }
        latin_pairs(&mut rng, t, &mut s.perms, &mut s.points);
        let n = g.normal;
        let (u, v) = n.any_orthonormal_pair();
        // Start points on a jittered s × s grid when t is a square (a shadow edge
        // across the patch is then sampled in both directions), directions from the
        // Latin hypercube's other two coordinates.
        let side = (t as f64).sqrt().round() as usize;
        let grid = side * side == t;
        let (mut sum, mut hits) = (0.0, 0);
        for (k, &[p, q, c, d]) in s.points.iter().enumerate() {
            let (p, q) = match grid {
                true => (
                    ((k % side) as f64 + rng.next_f64()) / side as f64,
                    ((k / side) as f64 + rng.next_f64()) / side as f64,
                ),
                false => (p, q),
            };
            let (x, jacobian) = g.map.eval(p, q);
            if self.sees_a_front(tree, g, x, cosine_direction(u, v, n, c, d), &mut s.stack) {
                sum += jacobian / g.area;
                hits += 1;
            }
        }
        scratch.pair.counters.closure_rays += t as u64;
        Some((sum / t as f64, ray_error(hits, t).sqrt()))
    }

    /// Whether the ray from `x` (on patch `g`) along `dir` first meets the front of a
    /// patch.
    fn sees_a_front(
        &self,
        tree: &PatchTree,
        g: &PatchGeom,
        x: DVec3,
        dir: DVec3,
        stack: &mut Vec<u32>,
    ) -> bool {
        self.occluders
            .first_hit(x, dir, g.face, (g.normal, g.offset))
            .is_some_and(|y| tree.front_patch_at(&self.geom, y, dir, self.hide_margin, stack))
    }

    /// Cuts patch `g` into convex cells along the planes of the surfaces standing on
    /// it (a box on a floor patch: what a point sees jumps where its walls meet the
    /// patch, nothing beneath it, everything beside it). False when nothing stands on
    /// the patch or the cuts would need more than [`MAX_CELLS`] cells: the plain
    /// estimate is then used.
    fn standing_cells(&self, g: &PatchGeom, cells: &mut Vec<Piece>) -> bool {
        let verts = g.poly.verts();
        let lo = verts.iter().fold(DVec3::INFINITY, |a, b| a.min(*b));
        let hi = verts.iter().fold(DVec3::NEG_INFINITY, |a, b| a.max(*b));
        cells.clear();
        cells.push(Piece::new(verts));
        let mut complete = true;
        let tol = self.hide_margin;
        self.occluders
            .standing_on(lo, hi, (g.normal, g.offset), tol, |v| {
                complete &= shadow::cut(cells, MAX_CELLS, v[0], v[1], v[2], tol, &|_| true);
            });
        complete && cells.len() > 1
    }

    /// The row total of patch `g` cut into `s.cells`: each cell gets rays in
    /// proportion to its area (at least one), T̂ = Σ_c (A_c / A) · (fraction of the
    /// cell's rays that meet a front). Unbiased as the plain estimate, and exact in a
    /// closed scene where a cell sees either everything or nothing, as the cells of a
    /// floor patch partly under a box do. Returns (T̂, the scale of its error, rays
    /// cast).
    fn cells_total(
        &self,
        tree: &PatchTree,
        g: &PatchGeom,
        t: usize,
        rng: &mut SplitMix64,
        s: &mut ClosureScratch,
    ) -> (f64, f64, usize) {
        let n = g.normal;
        let (u, v) = n.any_orthonormal_pair();
        let areas: Vec<f64> = s.cells.iter().map(|c| c.vector_area().length()).collect();
        let area: f64 = areas.iter().sum();
        let (mut total, mut variance, mut cast) = (0.0, 0.0, 0);
        for (cell, &a) in s.cells.iter().zip(&areas) {
            let rays = ((t as f64 * a / area).round() as usize).max(1);
            latin_pairs(rng, rays, &mut s.perms, &mut s.points);
            let mut hits = 0usize;
            for &[p, q, c, d] in &s.points {
                let x = point_in_fan(cell.verts(), a, p, q);
                let dir = cosine_direction(u, v, n, c, d);
                hits += self.sees_a_front(tree, g, x, dir, &mut s.stack) as usize;
            }
            total += a / area * hits as f64 / rays as f64;
            variance += (a / area).powi(2) * ray_error(hits, rays);
            cast += rays;
        }
        (total, variance.sqrt(), cast)
    }
}
