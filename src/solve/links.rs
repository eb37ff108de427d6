//! Gathering and shooting through the links of sparse rows (spec §5.7).
//!
//! A link L of row i carries the form factor F_iL from patch i to the patches of a range
//! [a, b) of the file's cluster order, less the row's kept columns and i itself (the
//! link's *patches*), and a slope q_L. The solver treats it as the patch entries
//!
//!   F_ij = F_iL · w_j / Σ w_j',   w_j = A_j (1 + q_L · (x_j − x̄_L)),
//!
//! x_j the patch centroids and x̄_L their area-weighted mean over the whole range: the
//! link's mass lies on its cluster by area, tilted toward the part the row sees most
//! (with q_L = 0, by area alone, which keeps reciprocity's form A_i F_ij ∝ A_j).
//! Gathering through a link needs Σ w_j b_j over its range, which is
//! Σ A_j b_j + q_L · (Σ A_j x_j b_j − x̄_L Σ A_j b_j): read in O(1) from prefix sums over
//! the cluster order (made once per sweep, O(n m)), less the few kept columns and the
//! row patch that lie inside its range (found by binary search over the row's links).
//! What that needs of the row alone (each link's Σ w_j, those patches) is worked out
//! once and kept, within a memory budget ([`LinkSpace::with_cache`]), so that later
//! sweeps read only the prefix sums (docs/numerics.md §8).
//! Shooting and every other reader that visits entries one by one expands the link
//! into its patches instead (O(b − a)).
//!
//! Gauss–Seidel reads the prefix sums made at the start of its sweep, so the links
//! part of its update is a Jacobi step (the kept entries still see the newest values).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

use glam::DVec3;

use crate::formfactor::tree::{second_matrix, second_products};
use crate::rows::Link;

/// The cluster order of a source, with what the gather through links needs.
#[derive(Debug)]
pub(crate) struct LinkSpace {
    /// Patch at each position.
    order: Vec<u32>,
    /// Position of each patch.
    pos: Vec<u32>,
    /// Area and centroid of each patch.
    area: Vec<f64>,
    centroid: Vec<DVec3>,
    /// Σ A, Σ A x and Σ A x xᵀ (xx, yy, zz, xy, xz, yz) over positions < p, for p in
    /// 0..=n.
    prefix_area: Vec<f64>,
    prefix_moment: Vec<DVec3>,
    prefix_second: Vec<[f64; 6]>,
    /// Rows' links made ready to gather, kept while they fit ([`LinkSpace::with_cache`]).
    cache: Option<ReadyCache>,
}

/// A link made ready to gather: its range of positions, g = F_iL / Σ w_j over its own
/// patches, its slope q (zero when the link goes by area) and k = 1 − q · x̄, so that
/// its share of the gather is g (k Σ A b + q · Σ A x b) over its range.
#[derive(Clone, Copy, Debug)]
struct ReadyLink {
    start: u32,
    end: u32,
    slope: [f32; 3],
    g: f64,
    k: f64,
}

/// A patch inside a link's range that is not the link's (a kept column or the row
/// patch): its position and what its A_j b_j weighs in the link's sum, to be taken
/// off it.
#[derive(Clone, Copy, Debug)]
struct Out {
    position: u32,
    factor: f64,
}

/// The range additions of a scatter through links ([`LinkSpace::scatter`]): per
/// position and column, the differences of Σ g k w and Σ g q w over the links whose
/// range starts or ends there.
#[derive(Debug)]
pub(crate) struct Scatter {
    diff: Vec<f64>,
    m: usize,
}

/// Ranges of at most this many positions are scattered into their patches directly:
/// a range addition costs 8 m numbers in an array of n × 4 m, read back once a sweep,
/// and at daylight scales (3,000 patches, 96 sensors) the direct way was twice as fast
/// (bench/LINKS.md).
const DIRECT_SPAN: usize = 64;

impl Scatter {
    /// Add what the links sent to `next` (n × m): patch j at position p gets
    /// A_j (α + β · x_j) in column c, α and β the sums of g k w and g q w over the links
    /// whose range holds p.
    pub(crate) fn add_to(&self, space: &LinkSpace, next: &mut [f64]) {
        let m = self.m;
        if self.diff.is_empty() {
            return;
        }
        let mut running = vec![0.0; 4 * m];
        for (p, &j) in space.order.iter().enumerate() {
            for (r, d) in running
                .iter_mut()
                .zip(&self.diff[p * 4 * m..(p + 1) * 4 * m])
            {
                *r += d;
            }
            let (j, x) = (j as usize, space.centroid[j as usize]);
            for c in 0..m {
                let r = &running[4 * c..4 * c + 4];
                next[j * m + c] += space.area[j] * (r[0] + r[1] * x.x + r[2] * x.y + r[3] * x.z);
            }
        }
    }
}

/// One row's links made ready to gather, and a bound on Σ |F_ij| over their patches
/// (Σ F_iL when no weight is negative).
#[derive(Debug)]
struct Ready {
    links: Vec<ReadyLink>,
    out: Vec<Out>,
    sum: f64,
}

impl Ready {
    /// Bytes it holds.
    fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.links.capacity() * std::mem::size_of::<ReadyLink>()
            + self.out.capacity() * std::mem::size_of::<Out>()
    }
}

/// The rows' ready links, by row, and the bytes they may take.
#[derive(Debug)]
struct ReadyCache {
    rows: Vec<OnceLock<Ready>>,
    budget: usize,
    used: AtomicUsize,
}

/// A link whose weights sum to at most this fraction of its range's area is spread by
/// area (spec §5.7): such a sum is what is left after prefix sums cancel, mostly
/// rounding, and the link's mass would be divided by it.
const FLAT_WEIGHT: f64 = 1e-6;

/// `acc[c] +=` each ready link's share of the gather, less the patches inside link
/// ranges that are not the links', for `acc.len()` columns a patch (4 numbers of the
/// prefix sums a column and position); returns the bound on Σ |F_ij| of
/// [`Ready::sum`].
fn gather_ready(ready: &Ready, prefix: &[f64], acc: &mut [f64]) -> f64 {
    if let Ok(acc) = <&mut [f64; 3]>::try_from(&mut *acc) {
        // The common single-case path: the length known, the three sums in registers.
        let mut sums = [0.0; 3];
        add_shares(ready, prefix, &mut sums);
        for (a, s) in acc.iter_mut().zip(sums) {
            *a += s;
        }
    } else {
        add_shares(ready, prefix, acc);
    }
    ready.sum
}

/// The body of [`gather_ready`], adding into `sums` directly.
#[inline(always)]
fn add_shares(ready: &Ready, prefix: &[f64], sums: &mut [f64]) {
    let stride = 4 * sums.len();
    let record = |p: usize| &prefix[p * stride..(p + 1) * stride];
    for l in &ready.links {
        let (rs, re) = (record(l.start as usize), record(l.end as usize));
        let (g, q) = (l.g, l.slope.map(f64::from));
        for (c, sum) in sums.iter_mut().enumerate() {
            let d = |t: usize| re[4 * c + t] - rs[4 * c + t];
            *sum += g * (l.k * d(0) + q[0] * d(1) + q[1] * d(2) + q[2] * d(3));
        }
    }
    for x in &ready.out {
        // A_j b_j as the prefix sums hold it (b as it was when they were made, not as
        // a Gauss–Seidel sweep has since changed it: the two parts of the sum must
        // see the same b).
        let p = x.position as usize;
        let (rs, re) = (record(p), record(p + 1));
        for (c, sum) in sums.iter_mut().enumerate() {
            *sum -= x.factor * (re[4 * c] - rs[4 * c]);
        }
    }
}

impl LinkSpace {
    /// The space of cluster order `order` (a permutation of the n patches, checked by
    /// the reader) for patch areas `area` and centroids `centroid` (spec §5.7).
    pub(crate) fn new(order: &[u32], area: &[f64], centroid: &[DVec3]) -> Self {
        let mut pos = vec![0u32; order.len()];
        let mut prefix_area = Vec::with_capacity(order.len() + 1);
        let mut prefix_moment = Vec::with_capacity(order.len() + 1);
        let mut prefix_second = Vec::with_capacity(order.len() + 1);
        let (mut a, mut x, mut xx) = (0.0, DVec3::ZERO, [0.0; 6]);
        prefix_area.push(a);
        prefix_moment.push(x);
        prefix_second.push(xx);
        for (p, &j) in order.iter().enumerate() {
            let j = j as usize;
            pos[j] = p as u32;
            let c = centroid[j];
            a += area[j];
            x += area[j] * c;
            for (s, v) in xx.iter_mut().zip(second_products(c)) {
                *s += area[j] * v;
            }
            prefix_area.push(a);
            prefix_moment.push(x);
            prefix_second.push(xx);
        }
        LinkSpace {
            order: order.to_vec(),
            pos,
            area: area.to_vec(),
            centroid: centroid.to_vec(),
            prefix_area,
            prefix_moment,
            prefix_second,
            cache: None,
        }
    }

    /// The same space keeping each row's links ready to gather (made once, the first
    /// time the row is gathered) while they take at most `budget` bytes; rows beyond
    /// are made ready again at every gather. For sources whose rows do not change
    /// between gathers (a file): row i must always come with the same links and
    /// kept columns.
    pub(crate) fn with_cache(mut self, budget: usize) -> Self {
        self.cache = Some(ReadyCache {
            rows: (0..self.order.len()).map(|_| OnceLock::new()).collect(),
            budget,
            used: AtomicUsize::new(0),
        });
        self
    }

    /// Per position p in 0..=n and column c of the `m` columns a patch: Σ A_j b_j over
    /// positions < p, then the three components of Σ A_j x_j b_j (4 m numbers a
    /// position, so that a link's gather reads two runs of them).
    pub(crate) fn prefix(&self, b: &[f64], m: usize) -> Vec<f64> {
        let stride = 4 * m;
        let mut out = vec![0.0; (self.order.len() + 1) * stride];
        for (p, &j) in self.order.iter().enumerate() {
            let j = j as usize;
            let (a, x) = (self.area[j], self.centroid[j]);
            let (done, next) = out.split_at_mut((p + 1) * stride);
            let (last, next) = (&done[p * stride..], &mut next[..stride]);
            for c in 0..m {
                let ab = a * b[j * m + c];
                next[4 * c] = last[4 * c] + ab;
                for k in 0..3 {
                    next[4 * c + 1 + k] = last[4 * c + 1 + k] + ab * x[k];
                }
            }
        }
        out
    }

    /// Which of `links` (ascending, disjoint) holds patch j, if any.
    fn link_of(&self, links: &[Link], j: u32) -> Option<usize> {
        let p = *self.pos.get(j as usize)?;
        let k = links.partition_point(|l| l.start <= p).checked_sub(1)?;
        (u64::from(p) < links[k].end()).then_some(k)
    }

    /// The patches of row `i`'s links that are not the link's (its kept columns `cols`
    /// and i itself), as (link, patch).
    fn excluded<'a>(
        &'a self,
        links: &'a [Link],
        i: u32,
        cols: &'a [u32],
    ) -> impl Iterator<Item = (usize, u32)> + 'a {
        cols.iter()
            .copied()
            .chain(std::iter::once(i))
            .filter_map(move |j| self.link_of(links, j).map(|k| (k, j)))
    }

    /// Area-weighted mean centroid x̄_L of the positions [s, e) and the link's slope.
    fn lean(&self, l: &Link) -> (DVec3, DVec3) {
        let (s, e) = (l.start as usize, l.end() as usize);
        let a = self.prefix_area[e] - self.prefix_area[s];
        let mean = (self.prefix_moment[e] - self.prefix_moment[s]) / a;
        let q = DVec3::from_array(l.slope.map(f64::from));
        if q == DVec3::ZERO || !mean.is_finite() {
            return (DVec3::ZERO, DVec3::ZERO);
        }
        (mean, q)
    }

    /// The link's mean and slope (as [`LinkSpace::lean`]) and the sum of its patches'
    /// weights, `sum_w` of them; when that sum is at most [`FLAT_WEIGHT`] times the
    /// range's area (kept columns holding all, or all but a rounding error, of the
    /// weight), no slope and the sum of the areas instead (spec §5.7).
    fn tilt(&self, l: &Link, sum_w: impl Fn((DVec3, DVec3)) -> f64) -> (DVec3, DVec3, f64) {
        let (mean, q) = self.lean(l);
        let w = sum_w((mean, q));
        let whole = self.prefix_area[l.end() as usize] - self.prefix_area[l.start as usize];
        let weighs = w > FLAT_WEIGHT * whole; // false for NaN too
        if !weighs && q != DVec3::ZERO {
            return (DVec3::ZERO, DVec3::ZERO, sum_w((DVec3::ZERO, DVec3::ZERO)));
        }
        (mean, q, w)
    }

    /// √(A Σ A_j (q · (x_j − x̄))²) over positions [s, e) of area A and mean `mean`: it
    /// bounds Σ |q · (x_j − x̄)| A_j (Cauchy–Schwarz), so twice what the weights
    /// A_j (1 + q · (x_j − x̄)) of the range can hold below zero.
    fn tilt_size(&self, s: usize, e: usize, mean: DVec3, q: DVec3) -> f64 {
        let a = self.prefix_area[e] - self.prefix_area[s];
        let m = std::array::from_fn(|k| self.prefix_second[e][k] - self.prefix_second[s][k]);
        // qᵀ (Σ A x xᵀ) q − A (q · x̄)²: the second moments about the mean.
        let about_origin = q.dot(second_matrix(m) * q);
        (a * (about_origin - a * q.dot(mean).powi(2)).max(0.0)).sqrt()
    }

    /// Weight w_j of patch j in a link with mean `mean` and slope `q` (module docs).
    fn weight(&self, j: usize, mean: DVec3, q: DVec3) -> f64 {
        self.area[j] * (1.0 + q.dot(self.centroid[j] - mean))
    }

    /// `acc[c] += Σ_L F_iL · (Σ w_j b_j / Σ w_j over L's patches)` for row i with kept
    /// columns `cols`, against the radiosity `prefix` was made of ([`LinkSpace::prefix`]).
    /// Returns a bound on Σ |F_ij| over the links' patches, Σ F_iL when no weight is
    /// negative (the Gauss–Seidel bound's). With a cache ([`LinkSpace::with_cache`])
    /// a row's links are made ready once, the first time it is gathered, while the
    /// cache has room.
    pub(crate) fn gather(
        &self,
        links: &[Link],
        i: u32,
        cols: &[u32],
        prefix: &[f64],
        acc: &mut [f64],
    ) -> f64 {
        self.with_ready(links, i, cols, |ready| gather_ready(ready, prefix, acc))
    }

    /// `f` of row i's links made ready: those kept, or made now (and kept while the
    /// cache has room).
    fn with_ready<T>(
        &self,
        links: &[Link],
        i: u32,
        cols: &[u32],
        f: impl FnOnce(&Ready) -> T,
    ) -> T {
        let slot = self.cache.as_ref().and_then(|c| c.rows.get(i as usize));
        if let Some(ready) = slot.and_then(|s| s.get()) {
            return f(ready);
        }
        let ready = self.ready(links, i, cols);
        let out = f(&ready);
        if let (Some(cache), Some(slot)) = (&self.cache, slot) {
            let bytes = ready.bytes();
            let used = cache.used.fetch_add(bytes, Ordering::Relaxed);
            if used + bytes <= cache.budget {
                let _ = slot.set(ready);
            } else {
                cache.used.fetch_sub(bytes, Ordering::Relaxed);
            }
        }
        out
    }

    /// The transpose of [`LinkSpace::gather`], for a solve that scatters rows into
    /// columns (`adjoint.rs`): row i with kept columns `cols` sends `w` (`m`
    /// columns) through its links, F_ij · w_c into column j of every patch j of every
    /// link. A link's range of more than [`DIRECT_SPAN`] positions goes into `into` as
    /// a range addition, O(1) a link (apply them with [`Scatter::add_to`]); a smaller
    /// one, and the patches inside a range that are not the link's (taken off), go to
    /// `next` (n × m) at once.
    pub(crate) fn scatter(
        &self,
        links: &[Link],
        i: u32,
        cols: &[u32],
        w: &[f64],
        into: &mut Scatter,
        next: &mut [f64],
    ) {
        self.scatter_spans(links, (i, cols), w, into, next, DIRECT_SPAN);
    }

    /// [`LinkSpace::scatter`] with ranges of at most `direct` positions sent directly.
    fn scatter_spans(
        &self,
        links: &[Link],
        (i, cols): (u32, &[u32]),
        w: &[f64],
        into: &mut Scatter,
        next: &mut [f64],
        direct: usize,
    ) {
        let m = w.len();
        let stride = 4 * m;
        self.with_ready(links, i, cols, |ready| {
            for l in &ready.links {
                let part = [l.k, l.slope[0].into(), l.slope[1].into(), l.slope[2].into()];
                let (s, e) = (l.start as usize, l.end as usize);
                if e - s <= direct {
                    // A small range: straight into its patches.
                    for &j in &self.order[s..e] {
                        let (j, x) = (j as usize, self.centroid[j as usize]);
                        let q = DVec3::from_array(l.slope.map(f64::from));
                        let f = l.g * self.area[j] * (l.k + q.dot(x));
                        for (o, &wc) in next[j * m..(j + 1) * m].iter_mut().zip(w) {
                            *o += f * wc;
                        }
                    }
                    continue;
                }
                if into.diff.is_empty() {
                    into.diff = vec![0.0; (self.order.len() + 1) * stride];
                }
                for (c, &wc) in w.iter().enumerate() {
                    for (t, x) in part.into_iter().enumerate() {
                        into.diff[s * stride + 4 * c + t] += l.g * x * wc;
                        into.diff[e * stride + 4 * c + t] -= l.g * x * wc;
                    }
                }
            }
            for x in &ready.out {
                let j = self.order[x.position as usize] as usize;
                for (c, &wc) in w.iter().enumerate() {
                    next[j * m + c] -= x.factor * self.area[j] * wc;
                }
            }
        });
    }

    /// An empty [`Scatter`] for `m` columns a patch.
    pub(crate) fn scatter_start(&self, m: usize) -> Scatter {
        Scatter {
            diff: Vec::new(),
            m,
        }
    }

    /// Row i's links with kept columns `cols`, made ready to gather: each link's weight
    /// sum found once (with the patches in its range that are not its own taken out),
    /// so that a gather reads only prefix sums.
    fn ready(&self, links: &[Link], i: u32, cols: &[u32]) -> Ready {
        // The patches in the links' ranges that are not theirs (few: at most the kept
        // columns and the row patch), in order of link, each link's a slice of them.
        let mut out: Vec<(usize, usize)> = self
            .excluded(links, i, cols)
            .map(|(k, j)| (k, j as usize))
            .collect();
        out.sort_unstable();
        let mut ready = Ready {
            links: Vec::with_capacity(links.len()),
            out: Vec::with_capacity(out.len()),
            sum: 0.0,
        };
        let mut next = 0;
        for (k, l) in links.iter().enumerate() {
            let (s, e) = (l.start as usize, l.end() as usize);
            let first = next;
            while out.get(next).is_some_and(|x| x.0 == k) {
                next += 1;
            }
            let theirs = &out[first..next];
            // Σ w over the range is its area (the slope's part sums to zero).
            let sum_w = |(mean, q)| {
                self.prefix_area[e]
                    - self.prefix_area[s]
                    - theirs
                        .iter()
                        .map(|x| self.weight(x.1, mean, q))
                        .sum::<f64>()
            };
            let (mean, q, w) = self.tilt(l, sum_w);
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let g = f64::from(l.value) / w;
            // Σ |F_ij| over the link's patches: F_iL when no weight is negative; a
            // slope's negative weights (spec §5.7) add at most g times the range's
            // tilt (what the range holds below zero, twice; 0 without a slope).
            ready.sum += f64::from(l.value) + g * self.tilt_size(s, e, mean, q);
            let slope = if q == DVec3::ZERO { [0.0; 3] } else { l.slope };
            ready.links.push(ReadyLink {
                start: l.start,
                end: l.end() as u32,
                g,
                slope,
                k: 1.0 - q.dot(mean),
            });
            for &(_, j) in theirs {
                ready.out.push(Out {
                    position: self.pos[j],
                    factor: g * (1.0 + q.dot(self.centroid[j] - mean)),
                });
            }
        }
        ready
    }

    /// Call `f(j, F_ij)` for every patch j of row i's links (module docs), link by link
    /// in order of position.
    pub(crate) fn expand(
        &self,
        links: &[Link],
        i: u32,
        cols: &[u32],
        mut f: impl FnMut(usize, f64),
    ) {
        let mine = |j: u32| j != i && cols.binary_search(&j).is_err();
        for l in links {
            let range = &self.order[l.start as usize..l.end() as usize];
            let sum_w = |(mean, q)| -> f64 {
                range
                    .iter()
                    .filter(|&&j| mine(j))
                    .map(|&j| self.weight(j as usize, mean, q))
                    .sum()
            };
            let (mean, q, w) = self.tilt(l, sum_w);
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let per_weight = f64::from(l.value) / w;
            for &j in range.iter().filter(|&&j| mine(j)) {
                f(j as usize, per_weight * self.weight(j as usize, mean, q));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four patches of areas 1, 2, 3, 4 on the x axis at x = 0, 1, 2, 3, in the order
    /// 3, 1, 0, 2.
    fn space() -> LinkSpace {
        let centroid: Vec<DVec3> = (0..4).map(|j| DVec3::new(j as f64, 0.0, 0.0)).collect();
        LinkSpace::new(&[3, 1, 0, 2], &[1.0, 2.0, 3.0, 4.0], &centroid)
    }

    /// Three columns a patch: b_j = (j, 10 j, 1).
    fn radiosity() -> Vec<f64> {
        (0..4)
            .flat_map(|j| [j as f64, 10.0 * j as f64, 1.0])
            .collect()
    }

    fn link(slope: [f32; 3]) -> [Link; 1] {
        [Link {
            start: 0,
            len: 3,
            value: 0.5,
            slope,
        }]
    }

    /// Row 0 keeps column 1 and links positions [0, 3) (patches 3, 1, 0: its own
    /// patches are 3 alone).
    #[test]
    fn gather_and_expand_agree_and_leave_out_kept_columns_and_the_row_patch() {
        let (space, b) = (space(), radiosity());
        let links = link([0.0; 3]);
        let prefix = space.prefix(&b, 3);
        let mut acc = [0.0; 3];
        let sum = space.gather(&links, 0, &[1], &prefix, &mut acc);
        assert_eq!(sum, 0.5);
        // Only patch 3 is the link's: the gather is 0.5 · b_3.
        assert!(
            (acc[0] - 1.5).abs() < 1e-12 && (acc[1] - 15.0).abs() < 1e-12,
            "{acc:?}"
        );
        let mut entries = Vec::new();
        space.expand(&links, 0, &[1], |j, f| entries.push((j, f)));
        assert_eq!(entries, vec![(3, 0.5)]);
        // Without kept columns: patches 3 and 1 (areas 4 and 2), the row patch left out.
        let mut acc = [0.0; 3];
        space.gather(&links, 0, &[], &prefix, &mut acc);
        let want = 0.5 * (4.0 * 3.0 + 2.0 * 1.0) / 6.0;
        assert!((acc[0] - want).abs() < 1e-12, "{acc:?} vs {want}");
        let mut entries = Vec::new();
        space.expand(&links, 0, &[], |j, f| entries.push((j, f)));
        assert_eq!(entries, vec![(3, 0.5 * 4.0 / 6.0), (1, 0.5 * 2.0 / 6.0)]);
    }

    /// A slope that takes a weight below zero (q = 1: w_0 = 1 · (1 + (0 − 2)) = −1):
    /// what gather returns for the stopping rule is still at least Σ |F_ij| of the
    /// expanded entries, and exactly F_iL without a slope. The bound must fail if the
    /// negative entries are counted by their sign.
    #[test]
    fn the_gathers_absolute_sum_bounds_negative_entries_of_a_steep_slope() {
        let (space, b) = (space(), radiosity());
        let prefix = space.prefix(&b, 3);
        for (q, kept) in [
            (1.0f32, &[][..]),
            (1.0, &[1][..]),
            (-0.6, &[][..]),
            (0.0, &[][..]),
        ] {
            let links = link([q, 0.0, 0.0]);
            let mut entries = Vec::new();
            space.expand(&links, 2, kept, |_, f| entries.push(f));
            let signed: f64 = entries.iter().sum();
            let abs: f64 = entries.iter().map(|f| f.abs()).sum();
            let mut acc = [0.0; 3];
            let bound = space.gather(&links, 2, kept, &prefix, &mut acc);
            assert!(
                (signed - 0.5).abs() < 1e-12,
                "q {q}: entries sum to {signed}"
            );
            assert!(
                bound >= abs - 1e-12,
                "q {q}, kept {kept:?}: {bound} < {abs}"
            );
            if q == 0.0 {
                assert_eq!(bound, 0.5);
            } else if q == 1.0 && kept.is_empty() {
                assert!(
                    abs > 0.5 + 1e-3,
                    "the case must hold a negative entry: {entries:?}"
                );
            }
        }
    }

    /// With a slope the weights are w_j = A_j (1 + q · (x_j − x̄)), x̄ the area mean of
    /// the whole range (patches 3, 1, 0: (4·3 + 2·1 + 1·0) / 7 = 2), worked by hand.
    #[test]
    fn a_slope_tilts_the_link_by_the_spec_rule_in_gather_and_expand_alike() {
        let (space, b) = (space(), radiosity());
        let links = link([0.25, 0.0, 0.0]);
        let prefix = space.prefix(&b, 3);
        // Row 2 (not in the range) keeps nothing: all three patches are the link's.
        let w = |a: f64, x: f64| a * (1.0 + 0.25 * (x - 2.0));
        let (w3, w1, w0) = (w(4.0, 3.0), w(2.0, 1.0), w(1.0, 0.0));
        let total = w3 + w1 + w0;
        let mut entries = Vec::new();
        space.expand(&links, 2, &[], |j, f| entries.push((j, f)));
        let want = [
            (3, 0.5 * w3 / total),
            (1, 0.5 * w1 / total),
            (0, 0.5 * w0 / total),
        ];
        assert_eq!(entries.len(), 3);
        for ((j, f), (wj, wf)) in entries.iter().zip(want) {
            assert_eq!(*j, wj);
            assert!((f - wf).abs() < 1e-15, "{entries:?} vs {want:?}");
        }
        assert!((entries.iter().map(|e| e.1).sum::<f64>() - 0.5).abs() < 1e-15);
        // The gather through prefix sums equals Σ F_ij b_j of the expansion, with and
        // without kept columns inside the range.
        for (row, cols) in [(2u32, vec![]), (2, vec![1u32]), (0, vec![]), (1, vec![3])] {
            let mut acc = [0.0; 3];
            space.gather(&links, row, &cols, &prefix, &mut acc);
            let mut want = [0.0; 3];
            space.expand(&links, row, &cols, |j, f| {
                for c in 0..3 {
                    want[c] += f * b[j * 3 + c];
                }
            });
            for c in 0..3 {
                assert!(
                    (acc[c] - want[c]).abs() < 1e-12,
                    "row {row} {cols:?}: {acc:?} vs {want:?}"
                );
            }
        }
    }

    /// A slope that leaves the link's own patches (here patch 0 alone, the others kept)
    /// with a weight of rounding size: the link goes by area (spec §5.7), so its whole
    /// mass lands on patch 0, in gather and expand alike. (The gather once took the
    /// kept columns' radiosity from the current b of a Gauss–Seidel sweep and the rest
    /// from the prefix sums made at its start, and divided the difference by such a
    /// weight: a 10k-patch room solved to NaN. It now reads both from the prefix sums.)
    #[test]
    fn a_link_whose_own_patches_weigh_next_to_nothing_goes_by_area() {
        let (space, b) = (space(), radiosity());
        // x̄ = 2 over patches 3, 1, 0 (module test above): 1 + q (0 − 2) is 6e-8 at patch 0.
        let links = link([0.499_999_97, 0.0, 0.0]);
        let prefix = space.prefix(&b, 3);
        let mut acc = [0.0; 3];
        space.gather(&links, 2, &[1, 3], &prefix, &mut acc);
        assert_eq!(acc, [0.0, 0.0, 0.5]);
        let mut entries = Vec::new();
        space.expand(&links, 2, &[1, 3], |j, f| entries.push((j, f)));
        assert_eq!(entries, vec![(0, 0.5)]);
    }

    /// A space with a cache gives, row by row, what the space without one gives: the
    /// first gather of a row (which makes its links ready and keeps them), the later
    /// ones (which read them back), and rows the budget leaves out (made ready again
    /// each time).
    #[test]
    fn links_kept_ready_gather_what_links_made_ready_each_time_gather() {
        let b = radiosity();
        let links = [
            Link {
                start: 0,
                len: 2,
                value: 0.25,
                slope: [0.25, 0.0, 0.0],
            },
            Link {
                start: 2,
                len: 2,
                value: 0.125,
                slope: [0.0; 3],
            },
        ];
        let rows: [(u32, Vec<u32>); 3] = [(0, vec![]), (1, vec![3]), (2, vec![1, 0])];
        let plain = space();
        let prefix = plain.prefix(&b, 3);
        for budget in [0, 200, 1 << 20] {
            let kept = space().with_cache(budget);
            for _ in 0..3 {
                for (row, cols) in &rows {
                    let (mut want, mut got) = ([0.0; 3], [0.0; 3]);
                    let s0 = plain.gather(&links, *row, cols, &prefix, &mut want);
                    let s1 = kept.gather(&links, *row, cols, &prefix, &mut got);
                    assert_eq!(s0, s1);
                    for c in 0..3 {
                        assert!(
                            (want[c] - got[c]).abs() <= 1e-15 * want[c].abs().max(1.0),
                            "budget {budget}, row {row}: {got:?} vs {want:?}"
                        );
                    }
                }
            }
            let held = kept.cache.as_ref().unwrap().rows.iter();
            let n_held = held.filter(|r| r.get().is_some()).count();
            match budget {
                0 => assert_eq!(n_held, 0),
                200 => assert!(n_held < 3, "a 200-byte budget held {n_held} rows"),
                _ => assert_eq!(n_held, 3),
            }
        }
    }

    /// The scatter through links (range additions) sends into each column what the
    /// expansion of the links says, F_ij w, kept columns and the row patch left out,
    /// with and without a slope, for rows with and without kept columns in the range.
    #[test]
    fn the_scatter_through_links_is_the_transpose_of_their_expansion() {
        let space = space();
        let w = [2.0, -1.0, 0.5];
        for slope in [[0.0; 3], [0.25, 0.0, 0.0]] {
            let links = link(slope);
            for (row, cols) in [(2u32, vec![]), (2, vec![1u32]), (0, vec![]), (1, vec![3])] {
                let mut want = vec![0.0; 4 * 3];
                space.expand(&links, row, &cols, |j, f| {
                    for c in 0..3 {
                        want[j * 3 + c] += f * w[c];
                    }
                });
                // Ranges as range additions (0), and straight into their patches.
                for direct in [0, DIRECT_SPAN] {
                    let mut got = vec![0.0; 4 * 3];
                    let mut into = space.scatter_start(3);
                    space.scatter_spans(&links, (row, &cols), &w, &mut into, &mut got, direct);
                    into.add_to(&space, &mut got);
                    assert_eq!(into.diff.is_empty(), direct > 0);
                    for (k, (g, x)) in got.iter().zip(&want).enumerate() {
                        assert!(
                            (g - x).abs() < 1e-12,
                            "slope {slope:?}, row {row} {cols:?}, direct {direct}, entry {k}: \
                             {got:?} vs {want:?}"
                        );
                    }
                }
            }
        }
    }
}
