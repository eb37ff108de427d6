//! Gathering and shooting through the links of sparse rows (spec §5.7).
//!
//! A link of row i carries the form factor F_iL from patch i to the patches of a range
//! [a, b) of the file's cluster order, less the row's kept columns and i itself (the
//! link's *patches*). The solver treats it as the patch entries
//!
//!   F_ij = F_iL · A_j / A_L   for each of the link's patches j,   A_L = Σ A_j over them,
//!
//! which keep the link's mass and reciprocity's form (A_i F_ij ∝ A_j). Gathering
//! through a link therefore needs the area-weighted mean radiosity of its patches,
//! read in O(1) from prefix sums over the cluster order (made once per sweep, O(n m)),
//! less the few kept columns and the row patch that lie inside its range (found by
//! binary search over the row's links). Shooting and every other reader that visits
//! entries one by one expands the link into its patches instead (O(b − a)).
//!
//! Gauss–Seidel reads the prefix sums made at the start of its sweep, so the links
//! part of its update is a Jacobi step (the kept entries still see the newest values).

use crate::rows::Link;

/// The cluster order of a source, with what the gather through links needs.
#[derive(Debug)]
pub(crate) struct LinkSpace {
    /// Patch at each position.
    order: Vec<u32>,
    /// Position of each patch.
    pos: Vec<u32>,
    /// Σ A over positions < p, for p in 0..=n.
    area: Vec<f64>,
}

impl LinkSpace {
    /// The space of cluster order `order` (a permutation of the n patches, checked by
    /// the reader) for patch areas `area`.
    pub(crate) fn new(order: &[u32], area: &[f64]) -> Self {
        let mut pos = vec![0u32; order.len()];
        let mut prefix = Vec::with_capacity(order.len() + 1);
        let mut sum = 0.0;
        prefix.push(0.0);
        for (p, &j) in order.iter().enumerate() {
            pos[j as usize] = p as u32;
            sum += area[j as usize];
            prefix.push(sum);
        }
        LinkSpace {
            order: order.to_vec(),
            pos,
            area: prefix,
        }
    }

    /// Σ A_j b_j per column over positions < p, for p in 0..=n (`m` columns a patch).
    pub(crate) fn prefix(&self, b: &[f64], area: &[f64], m: usize) -> Vec<f64> {
        let mut out = vec![0.0; (self.order.len() + 1) * m];
        for (p, &j) in self.order.iter().enumerate() {
            let j = j as usize;
            for c in 0..m {
                out[(p + 1) * m + c] = out[p * m + c] + area[j] * b[j * m + c];
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

    /// `acc[c] += Σ_L F_iL · (mean of b over L's patches)` for row i with kept columns
    /// `cols`; `prefix` from [`LinkSpace::prefix`] of b. Returns Σ F_iL.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn gather(
        &self,
        links: &[Link],
        i: u32,
        cols: &[u32],
        b: &[f64],
        area: &[f64],
        prefix: &[f64],
        acc: &mut [f64],
    ) -> f64 {
        let m = acc.len();
        // The patches in the links' ranges that are not theirs (few: at most the kept
        // columns and the row patch), by link.
        let out: Vec<(usize, usize)> = self
            .excluded(links, i, cols)
            .map(|(k, j)| (k, j as usize))
            .collect();
        let mut sum = 0.0;
        for (k, l) in links.iter().enumerate() {
            let f = f64::from(l.value);
            sum += f;
            let (s, e) = (l.start as usize, l.end() as usize);
            let mine = || out.iter().filter(move |x| x.0 == k).map(|x| x.1);
            let w = self.area[e] - self.area[s] - mine().map(|j| area[j]).sum::<f64>();
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            for c in 0..m {
                let ab = prefix[e * m + c]
                    - prefix[s * m + c]
                    - mine().map(|j| area[j] * b[j * m + c]).sum::<f64>();
                acc[c] += f * ab / w;
            }
        }
        sum
    }

    /// Call `f(j, F_ij)` for every patch j of row i's links (module docs), link by link
    /// in order of position.
    pub(crate) fn expand(
        &self,
        links: &[Link],
        i: u32,
        cols: &[u32],
        area: &[f64],
        mut f: impl FnMut(usize, f64),
    ) {
        let mine = |j: u32| j != i && cols.binary_search(&j).is_err();
        for l in links {
            let range = &self.order[l.start as usize..l.end() as usize];
            let w: f64 = range
                .iter()
                .filter(|&&j| mine(j))
                .map(|&j| area[j as usize])
                .sum();
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let per_area = f64::from(l.value) / w;
            for &j in range.iter().filter(|&&j| mine(j)) {
                f(j as usize, per_area * area[j as usize]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four patches of areas 1, 2, 3, 4 in the order 3, 1, 0, 2; row 0 keeps column 1
    /// and links positions [0, 3) (patches 3, 1, 0: its own patches are 3 alone).
    #[test]
    fn gather_and_expand_agree_and_leave_out_kept_columns_and_the_row_patch() {
        let area = [1.0, 2.0, 3.0, 4.0];
        let space = LinkSpace::new(&[3, 1, 0, 2], &area);
        let links = [Link {
            start: 0,
            len: 3,
            value: 0.5,
        }];
        let b: Vec<f64> = (0..4)
            .flat_map(|j| [j as f64, 10.0 * j as f64, 1.0])
            .collect();
        let prefix = space.prefix(&b, &area, 3);
        let mut acc = [0.0; 3];
        let sum = space.gather(&links, 0, &[1], &b, &area, &prefix, &mut acc);
        assert_eq!(sum, 0.5);
        // Only patch 3 is the link's: the gather is 0.5 · b_3.
        assert!(
            (acc[0] - 1.5).abs() < 1e-12 && (acc[1] - 15.0).abs() < 1e-12,
            "{acc:?}"
        );
        let mut entries = Vec::new();
        space.expand(&links, 0, &[1], &area, |j, f| entries.push((j, f)));
        assert_eq!(entries, vec![(3, 0.5)]);
        // Without kept columns: patches 3 and 1 (areas 4 and 2), the row patch left out.
        let mut acc = [0.0; 3];
        space.gather(&links, 0, &[], &b, &area, &prefix, &mut acc);
        let want = 0.5 * (4.0 * 3.0 + 2.0 * 1.0) / 6.0;
        assert!((acc[0] - want).abs() < 1e-12, "{acc:?} vs {want}");
        let mut entries = Vec::new();
        space.expand(&links, 0, &[], &area, |j, f| entries.push((j, f)));
        assert_eq!(entries, vec![(3, 0.5 * 4.0 / 6.0), (1, 0.5 * 2.0 / 6.0)]);
    }
}
