//! Top-k rows of the `contour` method with a sampled tail ([`crate::formfactor::TopKTail::Sampled`]):
//! the k largest entries found without the rays of the pairs that cannot enter them.
//!
//! 1. F⁰_ij for every j, and whether the pair needs rays ([`RowEngine::candidates`]);
//! 2. candidates in decreasing F⁰ (ties: smaller column first); each gets its
//!    visibility and enters a min-heap of the k best final values (those at or above
//!    the `--min-ff` threshold, if any), until F⁰ falls below the heap's worst value or
//!    the threshold: F ≤ F⁰, so no later candidate can enter ([`RowEngine::best_k`]);
//! 3. dropped = entries pushed out of the heap or below the threshold (exact) + tail pairs that need no rays
//!    (exact, F = F⁰) + the estimate of Σ F⁰_j V_j over the tail pairs that need rays,
//!    from `t` of them drawn by systematic sampling ∝ F⁰_j, all of them when there are
//!    at most `t` ([`RowEngine::tail_mass`]).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::{RowEngine, Scratch, Unoccluded};
use crate::formfactor::sampling::{pair_seed, SplitMix64, Stream};
use crate::rows::{Row, RowValues};

/// Min-heap of (final value bits, Reverse(column)): the top is the worst kept entry
/// (smallest value; among equal values the larger column). Bit patterns of
/// non-negative f64 order like the values.
type KeptHeap = BinaryHeap<Reverse<(u64, Reverse<u32>)>>;

impl RowEngine {
    /// Top-k row i into `kept` (empty, with its k and threshold), with a sampled tail
    /// of `t` pairs (module docs).
    pub(super) fn top_k_row_bounded(
        &self,
        i: u32,
        kept: Kept,
        t: usize,
        scratch: &mut Scratch,
    ) -> Row {
        scratch.start_row(i);
        let mut f0 = std::mem::take(&mut scratch.values);
        let mut order = std::mem::take(&mut scratch.order);
        let mut rays = std::mem::take(&mut scratch.flags);
        self.candidates(i, scratch, &mut f0, &mut rays, &mut order);
        order.sort_unstable_by(|a, b| f0[*b as usize].total_cmp(&f0[*a as usize]).then(a.cmp(b)));
        let (kept, next) = self.best_k(i, kept, &f0, &rays, &order, scratch);
        // The tail, in column order.
        let tail = &mut order[next..];
        tail.sort_unstable();
        let tail_mass = self.tail_mass(i, t, &f0, &rays, tail, scratch);
        scratch.values = f0;
        scratch.order = order;
        scratch.flags = rays;
        kept.into_row(i, tail_mass)
    }

    /// Step 1: `f0[j]` = F⁰_ij, `rays[j]` whether the pair needs rays, `order` the
    /// columns with F⁰ > 0.
    fn candidates(
        &self,
        i: u32,
        scratch: &mut Scratch,
        f0: &mut Vec<f64>,
        rays: &mut Vec<bool>,
        order: &mut Vec<u32>,
    ) {
        let n = self.n();
        f0.clear();
        f0.resize(n, 0.0);
        rays.clear();
        rays.resize(n, false);
        order.clear();
        let iu = i as usize;
        if !self.valid[iu] {
            return;
        }
        for j in 0..n {
            if j == iu || !self.valid[j] {
                continue;
            }
            if let Some(u) = self.column_unoccluded(i, j as u32, scratch) {
                f0[j] = u.f;
                rays[j] = u.needs_rays;
                order.push(j as u32);
            }
        }
    }

    /// The unoccluded part of column j ≠ i of a top-k row (valid patches), None when
    /// they face away or it is not positive; a pair that needs no rays is counted.
    pub(super) fn column_unoccluded(
        &self,
        i: u32,
        j: u32,
        scratch: &mut Scratch,
    ) -> Option<Unoccluded> {
        let (iu, ju) = (i as usize, j as usize);
        let extent = self.facing(iu, ju, scratch)?;
        let (gi, gj) = (&self.geom[iu], &self.geom[ju]);
        let u = self.contour_unoccluded((i, j), gi, gj, extent, scratch)?;
        if !u.needs_rays {
            scratch.pair.counters.pairs_unoccludable += 1;
            scratch.pair.counters.rays_skipped += self.cfg.samples as u64;
        }
        Some(u)
    }

    /// The final value of a top-k candidate whose unoccluded value is `f0`: `f0` itself
    /// when nothing can come between, else what the occluders leave of it.
    pub(super) fn candidate_value(
        &self,
        i: u32,
        j: u32,
        f0: f64,
        needs_rays: bool,
        scratch: &mut Scratch,
    ) -> f64 {
        if needs_rays {
            self.occluded_unlisted(i, j, f0, scratch)
        } else {
            f0
        }
    }

    /// Step 2: the k best final values among the candidates in `order` (decreasing
    /// F⁰) with the mass pushed out, and where in `order` the tail starts.
    fn best_k(
        &self,
        i: u32,
        mut kept: Kept,
        f0: &[f64],
        rays: &[bool],
        order: &[u32],
        scratch: &mut Scratch,
    ) -> (Kept, usize) {
        for (pos, &j) in order.iter().enumerate() {
            let ju = j as usize;
            if f0[ju] < kept.floor() {
                return (kept, pos);
            }
            kept.offer(j, self.candidate_value(i, j, f0[ju], rays[ju], scratch));
        }
        (kept, order.len())
    }

    /// Step 3: the mass of the tail (columns ascending): exact for pairs without rays,
    /// and for at most `t` pairs with rays; else estimated from `t` of them by
    /// systematic sampling with probability ∝ F⁰ (points u0 + s·step on the cumulative
    /// F⁰ axis, step = mass / t; the estimate step · Σ V is unbiased).
    fn tail_mass(
        &self,
        i: u32,
        t: usize,
        f0: &[f64],
        rays: &[bool],
        tail: &[u32],
        scratch: &mut Scratch,
    ) -> f64 {
        let mut exact = 0.0;
        let mut with_rays_mass = 0.0;
        let mut with_rays = 0usize;
        for &j in tail {
            if rays[j as usize] {
                with_rays_mass += f0[j as usize];
                with_rays += 1;
            } else {
                exact += f0[j as usize];
            }
        }
        if with_rays <= t {
            for &j in tail {
                if rays[j as usize] {
                    exact += self.occluded_unlisted(i, j, f0[j as usize], scratch);
                }
            }
            return exact;
        }
        let items = tail
            .iter()
            .filter(|&&j| rays[j as usize])
            .map(|&j| (j, f0[j as usize]));
        let mut rng = self.tail_rng(i);
        exact
            + systematic(
                items,
                with_rays_mass,
                t,
                &mut rng,
                |j, hits, _| match hits {
                    0 => {
                        scratch.pair.counters.pairs_topk_tail_skipped += 1;
                        scratch.pair.counters.rays_skipped += self.cfg.samples as u64;
                        0.0
                    }
                    _ => hits as f64 * self.visibility_fraction(i, j, f0[j as usize], scratch),
                },
            )
    }

    /// The random stream of row i's tail estimate.
    pub(super) fn tail_rng(&self, i: u32) -> SplitMix64 {
        SplitMix64::new(pair_seed(self.cfg.seed, i, u32::MAX, Stream::TopKTail))
    }
}

/// Systematic sampling of `t` points over `items` with weights w (their sum `total`
/// is positive): the points u0 + s·step on the cumulative weight axis, step = total / t, u0
/// uniform in [0, step). `hit(item, hits, rng)` gets every item, with the number of
/// points that fell on it, and returns Σ over those points of Y / w, Y an unbiased
/// estimate of the item's mass (0 for none); the result step · Σ is unbiased for the
/// items' total mass.
pub(super) fn systematic<T>(
    items: impl Iterator<Item = (T, f64)>,
    total: f64,
    t: usize,
    rng: &mut SplitMix64,
    mut hit: impl FnMut(T, u32, &mut SplitMix64) -> f64,
) -> f64 {
    let step = total / t as f64;
    let mut point = rng.next_f64() * step;
    let mut cumulative = 0.0;
    let mut estimate = 0.0;
    for (item, w) in items {
        cumulative += w;
        let mut hits = 0u32;
        while point < cumulative && hits < t as u32 {
            hits += 1;
            point += step;
        }
        estimate += hit(item, hits, rng);
    }
    estimate * step
}

/// The k best final values ≥ `eps` of a row so far (ties: the smaller column) and the
/// mass of those pushed out or below `eps`.
pub(super) struct Kept {
    heap: KeptHeap,
    k: usize,
    eps: f64,
    dropped: f64,
    /// With links: the columns pushed out or below `eps`, with their final values.
    pub(super) out: Option<Vec<(u32, f64)>>,
}

impl Kept {
    /// `eps` = 0: no threshold.
    pub(super) fn new(k: usize, eps: f64) -> Self {
        Kept {
            heap: KeptHeap::with_capacity(k.min(1 << 12) + 1),
            k,
            eps,
            dropped: 0.0,
            out: None,
        }
    }

    /// The same, recording the columns that do not stay (for links).
    pub(super) fn recording(mut self) -> Self {
        self.out = Some(Vec::new());
        self
    }

    /// What a final value must reach to enter: `eps`, and once k are kept the smallest
    /// of them. A candidate whose F⁰ (a bound on its final value) is below it cannot
    /// enter.
    pub(super) fn floor(&self) -> f64 {
        match self.heap.peek() {
            Some(Reverse((bits, _))) if self.heap.len() == self.k => {
                f64::from_bits(*bits).max(self.eps)
            }
            _ => self.eps,
        }
    }

    /// The mass known exactly so far: the kept entries as they will be stored (f32)
    /// and what was pushed out or fell below `eps`.
    pub(super) fn known_mass(&self) -> f64 {
        let stored: f64 = self
            .heap
            .iter()
            .map(|Reverse((bits, _))| f64::from(f64::from_bits(*bits) as f32))
            .sum();
        stored + self.dropped
    }

    /// Column j with final value `value`: kept if ≥ `eps` and among the k best, the
    /// value pushed out (or this one, below `eps`) counted as dropped.
    pub(super) fn offer(&mut self, j: u32, value: f64) {
        if value < self.eps {
            self.dropped += value;
            if let Some(out) = &mut self.out {
                out.push((j, value));
            }
            return;
        }
        self.heap.push(Reverse((value.to_bits(), Reverse(j))));
        if self.heap.len() > self.k {
            if let Some(Reverse((bits, Reverse(c)))) = self.heap.pop() {
                self.dropped += f64::from_bits(bits);
                if let Some(out) = &mut self.out {
                    out.push((c, f64::from_bits(bits)));
                }
            }
        }
    }

    /// The columns the row will store (those whose value is > 0 as f32), in no order.
    pub(super) fn columns(&self) -> Vec<u32> {
        self.heap
            .iter()
            .filter(|Reverse((bits, _))| f64::from_bits(*bits) as f32 > 0.0)
            .map(|Reverse((_, Reverse(j)))| *j)
            .collect()
    }

    /// Row i of the kept entries (columns ascending; entries whose visibility came out
    /// 0 carry no mass and stay out), dropped = pushed out + `tail`.
    pub(super) fn into_row(self, i: u32, tail: f64) -> Row {
        self.into_linked_row(i, tail, Vec::new())
    }

    /// As [`Kept::into_row`], with the row's `links`: when there are any, dropped is
    /// the sum of their values (spec §5.7) and `tail` is not used.
    pub(super) fn into_linked_row(self, i: u32, tail: f64, links: Vec<crate::rows::Link>) -> Row {
        let mut kept: Vec<(u32, f32)> = self
            .heap
            .into_iter()
            .map(|Reverse((bits, Reverse(j)))| (j, f64::from_bits(bits) as f32))
            .filter(|&(_, v)| v > 0.0)
            .collect();
        kept.sort_unstable_by_key(|&(j, _)| j);
        Row {
            index: i,
            values: RowValues::Sparse {
                cols: kept.iter().map(|&(j, _)| j).collect(),
                vals: kept.iter().map(|&(_, v)| v).collect(),
            },
            dropped: match links.is_empty() {
                true => (self.dropped + tail) as f32,
                false => links.iter().map(|l| f64::from(l.value)).sum::<f64>() as f32,
            },
            links,
            link_error: None,
        }
    }
}
