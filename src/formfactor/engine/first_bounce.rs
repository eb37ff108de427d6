//! A first estimate of the radiosity, to steer where rows open their links (spec §5.7,
//! `links.rs` step 1).
//!
//! A link gathers a weighted mean of the radiosity over its cluster; what it gets
//! wrong is at most its mass times how much the radiosity varies over the cluster
//! (times the spread of its weights when a slope takes some below zero, `links.rs`
//! step 3). Where the radiosity is flat the link is exact,
//! however the row's form factor is spread inside the cluster; where a lamp makes a
//! bright spot the cluster must be small. Hierarchical radiosity refines links by
//! this product, form factor times radiosity ("BF refinement", Hanrahan, Salzman and
//! Aupperle 1991, §5), using the radiosity of the solution in progress. Rows here are
//! computed once, independently, so the radiosity is estimated before any row: the
//! emitted light plus its first bounce,
//!
//!   B¹_j = E_j + ρ_j Σ_e F_je E_e    (per channel; the mean of the three is used),
//!
//! with F_je the form factor from patch j to emitter e (visibility included, by the
//! engine's own pair rule). That is where most of the radiosity's variation is in a
//! lit scene (the pool of light under a lamp, shadows); later bounces are smoother.
//! With at most [`ALL_EMITTERS`] emitters every F_je is evaluated; with more, that
//! many are drawn per patch, systematically in proportion to their power, with
//! weights that keep the sum unbiased. Each patch's draw is seeded by its index, so
//! the estimate is the same on every rank and thread.
//!
//! Departure from the paper: there the refinement uses the current solution and
//! iterates with the solve; here one estimate, made before the rows, misses the
//! variation of the later bounces. Links to clusters where B¹ is flat are still
//! opened by the kernel's spread (`links.rs`).
//!
//! The second bounce B²_j = ρ_j Σ_k F_jk B¹_k is estimated as well, from
//! [`SECOND_BOUNCE_POINTS`] points a patch drawn down the tree, for the rows' link
//! error only (spec §5.7): where a scene's light is mostly indirect (the far end of a
//! corridor lit at one end) B¹ is nearly flat and an error measured with it alone
//! understates. Its noise would make every cluster look uneven, so the cut does not
//! use it (docs/numerics.md §8).

use super::{RowEngine, Scratch};
use crate::formfactor::sampling::{pair_seed, SplitMix64, Stream};
use glam::DVec3;

use crate::formfactor::geom::PatchGeom;
use crate::formfactor::tree::{Kids, PatchTree};
use crate::patch::PatchSet;

/// Emitters evaluated for every patch; more are sampled, this many a patch.
const ALL_EMITTERS: usize = 16;

/// Points a patch's second bounce is estimated from.
const SECOND_BOUNCE_POINTS: usize = 16;

/// How much the first-bounce radiosity varies over each node of the patch tree.
#[derive(Debug, Default)]
pub(super) struct Contrast {
    /// Per node id: the largest less the smallest B¹ over the node's patches.
    pub(super) range: Vec<f32>,
    /// The area-weighted mean of B¹ over the valid patches (the scale the link
    /// tolerance is relative to).
    pub(super) scale: f64,
    /// Per patch: B¹.
    pub(super) bounce: Vec<f32>,
    /// Per node id: Σ A_j B¹_j and Σ A_j (x_j − x̄) B¹_j over its patches (x̄ the
    /// node's area-weighted mean centroid).
    pub(super) moments: Vec<(f64, DVec3)>,
    /// Per patch: B¹ + B², the first two bounces (the link error's radiosity).
    pub(super) both: Vec<f32>,
    /// Per node id: the range and the area mean of B¹ + B² over its patches.
    pub(super) both_range: Vec<f32>,
    pub(super) both_mean: Vec<f64>,
}

impl RowEngine {
    /// The first-bounce radiosity B¹ of every patch (module docs), the mean of the
    /// three channels; `None` when nothing emits.
    pub(super) fn first_bounce(&self, patches: &PatchSet) -> Option<Vec<f32>> {
        let grey = |c: [f32; 3]| (c[0] as f64 + c[1] as f64 + c[2] as f64) / 3.0;
        let emitters: Vec<(u32, f64)> = patches
            .patches
            .iter()
            .enumerate()
            .filter(|&(e, p)| self.valid[e] && grey(p.emission) > 0.0)
            .map(|(e, p)| (e as u32, p.area * grey(p.emission)))
            .collect();
        if emitters.is_empty() {
            return None;
        }
        let power: f64 = emitters.iter().map(|e| e.1).sum();
        Some(self.per_patch(|j, scratch| self.bounce_at(patches, j, &emitters, power, scratch)))
    }

    /// The second bounce of `first` (B¹ per patch): ρ_j Σ_k F_jk B¹_k for every patch
    /// j, from [`SECOND_BOUNCE_POINTS`] points drawn over the tree in proportion to
    /// the kernel's estimate (the tail sampler of `topk_tree.rs`, visibility
    /// included), seeded by j.
    pub(super) fn second_bounce(
        &self,
        patches: &PatchSet,
        tree: &PatchTree,
        first: &[f32],
    ) -> Vec<f32> {
        let Some(root) = tree.root() else {
            return vec![0.0; self.n()];
        };
        self.per_patch(|j, scratch| {
            let p = &patches.patches[j as usize];
            let rho = p.rho.iter().map(|&r| r as f64).sum::<f64>() / 3.0;
            if !self.valid[j as usize] || rho <= 0.0 {
                return 0.0;
            }
            let row = self.bounds[j as usize];
            let mut rng =
                SplitMix64::new(pair_seed(self.cfg.seed, j, u32::MAX, Stream::SecondBounce));
            let sum: f64 = (0..SECOND_BOUNCE_POINTS)
                .map(
                    |_| match self.bounce_sample(tree, root, j, &row, &mut rng, scratch) {
                        Some((v, k)) => v * first[k as usize] as f64,
                        None => 0.0,
                    },
                )
                .sum();
            rho * sum / SECOND_BOUNCE_POINTS as f64
        })
    }

    /// One point for patch j's second bounce: a patch k drawn down the tree from `id`,
    /// each step in proportion to the kernel's estimate for the halves (by area where
    /// an estimate is not finite: near j), and F_jk over the probability of drawing
    /// it (an unbiased estimate of Σ_k F_jk); `None` when nothing can be drawn.
    fn bounce_sample(
        &self,
        tree: &PatchTree,
        mut id: u32,
        j: u32,
        row: &crate::formfactor::geom::PatchBound,
        rng: &mut SplitMix64,
        scratch: &mut Scratch,
    ) -> Option<(f64, u32)> {
        let mut p = 1.0;
        loop {
            match tree.node(id).kids {
                Kids::Inner(left, right) => {
                    let w =
                        [left, right].map(|c| (tree.bound(c, row).guess, tree.node(c).moments().0));
                    let mut weights = [0.0; 2];
                    weigh(&w, &mut weights);
                    let k = draw(&weights, &mut p, rng)?;
                    id = [left, right][k];
                }
                Kids::Leaf => {
                    let patches: Vec<u32> = tree
                        .patches_under(id)
                        .iter()
                        .copied()
                        .filter(|&k| k != j)
                        .collect();
                    let w: Vec<(f64, f64)> = patches
                        .iter()
                        .map(|&k| {
                            let g = &self.geom[k as usize];
                            (tree.patch_bound(g, row).guess, g.area)
                        })
                        .collect();
                    let mut weights = vec![0.0; w.len()];
                    weigh(&w, &mut weights);
                    let k = draw(&weights, &mut p, rng)?;
                    let v = self.pair_value(j, patches[k], scratch) / p;
                    return v.is_finite().then_some((v, patches[k]));
                }
            }
        }
    }

    /// `f(j)` for every patch j, on the engine's set-up threads (each patch's
    /// value depends on j alone, so not on how they are shared out).
    fn per_patch(&self, f: impl Fn(u32, &mut Scratch) -> f64 + Sync) -> Vec<f32> {
        let n = self.n();
        let threads = self.setup_threads;
        let chunk = n.div_ceil(threads).max(1);
        let mut out = vec![0.0f32; n];
        std::thread::scope(|s| {
            for (c, part) in out.chunks_mut(chunk).enumerate() {
                let f = &f;
                s.spawn(move || {
                    let mut scratch = Scratch::new();
                    for (k, b) in part.iter_mut().enumerate() {
                        *b = f((c * chunk + k) as u32, &mut scratch) as f32;
                    }
                });
            }
        });
        out
    }

    /// B¹ of patch j (module docs); `emitters` are (patch, power), `power` their sum.
    fn bounce_at(
        &self,
        patches: &PatchSet,
        j: u32,
        emitters: &[(u32, f64)],
        power: f64,
        scratch: &mut Scratch,
    ) -> f64 {
        let p = &patches.patches[j as usize];
        let mut b = [0.0f64; 3];
        if self.valid[j as usize] && p.rho.iter().any(|&r| r > 0.0) {
            let mut add = |e: u32, w: f64, scratch: &mut Scratch| {
                let f = self.pair_value(j, e, scratch) * w;
                for (c, x) in b.iter_mut().enumerate() {
                    *x += f * patches.patches[e as usize].emission[c] as f64;
                }
            };
            if emitters.len() <= ALL_EMITTERS {
                for &(e, _) in emitters {
                    add(e, 1.0, scratch);
                }
            } else {
                // Systematic draws over the cumulative power, one offset per patch.
                let step = power / ALL_EMITTERS as f64;
                let mut rng =
                    SplitMix64::new(pair_seed(self.cfg.seed, j, u32::MAX, Stream::FirstBounce));
                let mut u = rng.next_f64() * step;
                let mut cumulative = 0.0;
                for &(e, w) in emitters {
                    cumulative += w;
                    while u < cumulative {
                        add(e, step / w, scratch);
                        u += step;
                    }
                }
            }
            for (c, x) in b.iter_mut().enumerate() {
                *x *= p.rho[c] as f64;
            }
        }
        let own: f64 = p.emission.iter().map(|&e| e as f64).sum();
        (b.iter().sum::<f64>() + own) / 3.0
    }
}

/// The weights of a draw's choices from (the kernel's estimate, area) per choice:
/// the estimates, or the areas where one is not finite (near the row patch).
fn weigh(w: &[(f64, f64)], out: &mut [f64]) {
    let finite = w.iter().all(|x| x.0.is_finite());
    for (o, x) in out.iter_mut().zip(w) {
        *o = match finite {
            true => x.0.max(0.0),
            false if x.0 > 0.0 || x.0.is_nan() => x.1,
            false => 0.0,
        };
    }
}

/// One choice drawn in proportion to `weights` (none when they sum to nothing),
/// its probability multiplied into `p`.
fn draw(weights: &[f64], p: &mut f64, rng: &mut SplitMix64) -> Option<usize> {
    let total: f64 = weights.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let u = rng.next_f64() * total;
    let mut at = 0.0;
    let k = (0..weights.len())
        .find(|&k| {
            at += weights[k];
            u < at && weights[k] > 0.0
        })
        .or_else(|| weights.iter().rposition(|&w| w > 0.0))?;
    *p *= weights[k] / total;
    Some(k)
}

impl RowEngine {
    /// Σ F_ij (B¹_j + B²_j) and Σ F_ij over the kept entries of `row` (0s without B¹).
    pub(super) fn kept_bounce(&self, row: &crate::rows::Row) -> (f64, f64) {
        let Some(c) = &self.contrast else {
            return (0.0, 0.0);
        };
        let (mut sum, mut mass) = (0.0, 0.0);
        row.for_each_nonzero(|j, f| {
            sum += f64::from(f) * c.both[j as usize] as f64;
            mass += f64::from(f);
        });
        (sum, mass)
    }
}

impl Contrast {
    /// The contrast of `b` (per patch) over the nodes of `tree`; `area` per patch.
    /// The contrast over the nodes of `tree` of `first` (B¹ per patch), with `second`
    /// (B² per patch) for the link error.
    pub(super) fn new(
        tree: &PatchTree,
        first: Vec<f32>,
        second: &[f32],
        geom: &[PatchGeom],
    ) -> Contrast {
        let area = |j: u32| geom[j as usize].area;
        let b = &first;
        let moments = (0..tree.len() as u32)
            .map(|id| {
                let (_, mean, _) = tree.node(id).moments();
                tree.patches_under(id)
                    .iter()
                    .fold((0.0, DVec3::ZERO), |(s, g), &j| {
                        let w = area(j) * b[j as usize] as f64;
                        (s + w, g + w * (geom[j as usize].centroid - mean))
                    })
            })
            .collect();
        let both: Vec<f32> = first.iter().zip(second).map(|(x, y)| x + y).collect();
        let both_mean = (0..tree.len() as u32)
            .map(|id| {
                let (a, _, _) = tree.node(id).moments();
                let s: f64 = tree
                    .patches_under(id)
                    .iter()
                    .map(|&j| area(j) * both[j as usize] as f64)
                    .sum();
                s / a
            })
            .collect();
        let (mut sum, mut total) = (0.0, 0.0);
        if let Some(root) = tree.root() {
            for &j in tree.patches_under(root) {
                sum += area(j) * b[j as usize] as f64;
                total += area(j);
            }
        }
        Contrast {
            range: ranges(tree, &first),
            both_range: ranges(tree, &both),
            both_mean,
            both,
            bounce: first,
            moments,
            scale: if total > 0.0 { sum / total } else { 0.0 },
        }
    }
}

/// Per node of `tree`: the largest less the smallest of `b` over its patches.
fn ranges(tree: &PatchTree, b: &[f32]) -> Vec<f32> {
    (0..tree.len() as u32)
        .map(|id| {
            let (lo, hi) = tree
                .patches_under(id)
                .iter()
                .map(|&j| b[j as usize])
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                });
            if hi >= lo {
                hi - lo
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::dvec3;

    use super::*;
    use crate::formfactor::FormFactorConfig;
    use crate::geometry::occluders::Occluders;
    use crate::patch::Patch;

    /// The unit square at height z, cut into s × s cells, facing +z (up) or −z.
    fn plate(z: f64, s: usize, up: bool, face: u32, emission: f32) -> Vec<Patch> {
        let h = 1.0 / s as f64;
        let mut out = Vec::new();
        for a in 0..s {
            for b in 0..s {
                let o = dvec3(a as f64 * h, b as f64 * h, z);
                let (u, v) = (dvec3(h, 0.0, 0.0), dvec3(0.0, h, 0.0));
                let (u, v) = if up { (u, v) } else { (v, u) };
                let corners = [o, o + u, o + u + v, o + v];
                let n = u.cross(v);
                out.push(Patch {
                    corners,
                    n_corners: 4,
                    normal: n.normalize(),
                    area: n.length(),
                    group: face,
                    face,
                    rho: [0.6, 0.4, 0.2],
                    emission: [emission; 3],
                });
            }
        }
        out
    }

    /// F between parallel unit squares one apart (Howell C-11, X = Y = 1).
    const HOWELL: f64 = 0.199_824_895_70;

    fn bounce(lamp_cells: usize, floor_cells: usize) -> (Vec<f32>, usize) {
        let mut patches = plate(1.0, lamp_cells, false, 0, 2.0);
        let lamp = patches.len();
        patches.extend(plate(0.0, floor_cells, true, 1, 0.0));
        let set = PatchSet {
            patches,
            groups: vec!["lamp".into(), "floor".into()],
        };
        let engine = RowEngine::new(
            &set,
            Arc::new(Occluders::empty()),
            FormFactorConfig::accurate(),
        );
        (engine.first_bounce(&set).expect("the lamp emits"), lamp)
    }

    /// A lamp of one patch over a floor of one: B¹ of the floor is ρ E F (mean of the
    /// channels), with F the analytic form factor; the lamp's is its own emission.
    #[test]
    fn one_emitter_gives_rho_times_the_analytic_form_factor() {
        let (b, _) = bounce(1, 1);
        let want = (0.6 + 0.4 + 0.2) / 3.0 * 2.0 * HOWELL;
        assert!(
            (b[1] as f64 - want).abs() < 1e-6 * want,
            "{} vs {want}",
            b[1]
        );
        assert_eq!(b[0], 2.0);
    }

    /// A lamp of 8 × 8 = 64 patches (more than ALL_EMITTERS: drawn, 16 a patch) over a
    /// floor of 4 × 4: the floor's area-weighted mean B¹ is ρ E F of the plates, which
    /// the draws estimate without bias; and each patch's draw is its own (the same
    /// value when computed again).
    #[test]
    fn drawn_emitters_keep_the_plates_mean() {
        let (b, lamp) = bounce(8, 4);
        let floor: f64 = b[lamp..].iter().map(|&x| x as f64).sum::<f64>() / 16.0;
        let want = (0.6 + 0.4 + 0.2) / 3.0 * 2.0 * HOWELL;
        assert!((floor - want).abs() < 0.03 * want, "{floor} vs {want}");
        assert_eq!(bounce(8, 4).0, b);
        // The floor's corners see less of the lamp than its middle.
        assert!(b[lamp] < b[lamp + 5], "{:?}", &b[lamp..]);
    }
}
