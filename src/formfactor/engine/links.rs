//! Links of a sparse row to clusters of patches (spec §5.7): where the mass that the
//! row does not keep as patch entries goes.
//!
//! A top-k (or `--min-ff`) row keeps its largest entries. Before links, the rest was one
//! number, the dropped mass, which a solver could only share out by a global rule (the
//! pool, `solve/pool.rs`): that misplaces light, badly so in scenes whose rooms see
//! different things (docs/numerics.md §8). Here the rest is split over clusters of
//! patches, nodes of the patch tree the search already walks, each link carrying the
//! form factor from the row patch to the cluster's patches that the row does not keep.
//! A solver gathers through a link the area-weighted mean radiosity of those patches.
//!
//! This is the link of hierarchical radiosity (Hanrahan, Salzman and Aupperle,
//! "A rapid hierarchical radiosity algorithm", SIGGRAPH 1991), there between patches
//! and refined where the form factor's estimate is poor, and its extension to clusters
//! (Smits, Arvo and Greenberg, "A clustering algorithm for radiosity in complex
//! environments", SIGGRAPH 1994). Departures from them: a row links one patch (the
//! row's) to clusters, not cluster to cluster, so that a file stays a matrix of rows that
//! any solver can read and rows stay independent (computed in any order, on any rank);
//! and the links sit beside the exact patch entries a top-k row already keeps.
//!
//! 1. **The cut.** Starting from the tree's root, the cluster with the largest
//!    *spread* is split into its two halves until no spread exceeds `link_tol` times
//!    the row's total or the row has `links` clusters. The spread of a cluster is its
//!    bound on Σ F⁰_ij less its guess of that sum (`tree::Bound`): 0 where the kernel is
//!    the same over the cluster (a link then places the light exactly, whatever the
//!    radiosity), large near the row patch, where the kernel varies and the bound is
//!    loose. It is the kernel-variation oracle of hierarchical radiosity with the
//!    tree's cheap bounds in place of sampled kernel values. A leaf is not split; a
//!    cluster that holds nothing the row dropped gets no link.
//! 2. **The mass.** Each link's value is the exact mass of the columns the search
//!    evaluated and did not keep (pushed out of the top k, below `--min-ff`, or
//!    unoccludable tail columns) plus an estimate of the rest: tail columns that need
//!    visibility and nodes the search never opened, sampled as the dropped mass is
//!    without links (`topk_tree.rs` step 3, the same walks and the same unbiased
//!    weights), but per link, with the row's `t` points shared out over the links in
//!    proportion to their weights and at least one point a link, so that every link's
//!    estimate is unbiased on its own, not only their sum. When the whole tail holds at
//!    most 2t patches every value is evaluated instead.
//!
//! The kept entries are those of the row without links, bit for bit; the dropped mass
//! stored is the sum of the links (spec §5.7), so a reader that ignores links reads the
//! same kind of row as before.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::topk_bounded::systematic;
use super::topk_tree::Tail;
use super::{RowEngine, Scratch};
use crate::formfactor::geom::PatchBound;
use crate::formfactor::tree::{Kids, PatchTree};
use crate::rows::Link;

/// A tail of at most this many times `t` patches is evaluated in full (as without
/// links, `topk_tree.rs`).
const EXACT_TAIL_FACTOR: usize = 2;

/// A link of at most this many patches to evaluate is evaluated in full, not sampled.
const FULL_LINK_PATCHES: usize = 4;

/// What a row did not keep, located in the cluster order.
struct Dropped {
    /// Columns with known values (position, value > 0), by position.
    exact: Vec<(u32, f64)>,
    /// Tail columns that need visibility (position, j, F⁰), by position.
    columns: Vec<(u32, u32, f64)>,
    /// Unopened nodes (start, end, id, guess), by start; disjoint.
    nodes: Vec<(u32, u32, u32, f64)>,
}

impl Dropped {
    /// Whether positions [a, b) hold anything dropped.
    fn holds(&self, a: u32, b: u32) -> bool {
        let k = self.nodes.partition_point(|n| n.1 <= a);
        (k < self.nodes.len() && self.nodes[k].0 < b)
            || any_of(&self.exact, |x| x.0, a, b)
            || any_of(&self.columns, |x| x.0, a, b)
    }

    /// The unopened node whose range holds [a, b) whole, if any.
    fn inside(&self, a: u32, b: u32) -> Option<(u32, u32, u32, f64)> {
        let k = self.nodes.partition_point(|n| n.1 <= a);
        self.nodes.get(k).copied().filter(|n| n.0 <= a && b <= n.1)
    }
}

/// Whether some item of `items` (sorted by `pos`) has its position in [a, b).
fn any_of<T>(items: &[T], pos: impl Fn(&T) -> u32, a: u32, b: u32) -> bool {
    let k = items.partition_point(|x| pos(x) < a);
    k < items.len() && pos(&items[k]) < b
}

/// The items of [a, b) (sorted by `pos`).
fn within<T>(items: &[T], pos: impl Fn(&T) -> u32, a: u32, b: u32) -> &[T] {
    let lo = items.partition_point(|x| pos(x) < a);
    let hi = items.partition_point(|x| pos(x) < b);
    &items[lo..hi]
}

/// One sampled item of a link: a tail column or a node.
#[derive(Clone, Copy)]
enum Item {
    Column(u32, f64),
    Node(u32, f64),
}

impl RowEngine {
    /// The links of row i (module docs): `known` is the mass the row knows exactly
    /// (kept entries and `exact`), `exact` the columns not kept whose values are known,
    /// `tail` the tail columns that need visibility and the unopened nodes, `t` the
    /// row's sample points, `max` the most links.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn row_links(
        &self,
        tree: &PatchTree,
        i: u32,
        row: &PatchBound,
        t: usize,
        max: usize,
        known: f64,
        exact: &[(u32, f64)],
        tail: &[Tail],
        scratch: &mut Scratch,
    ) -> Vec<Link> {
        let Some(root) = tree.root() else {
            return Vec::new();
        };
        let at = |j: u32| {
            tree.position(j)
                .expect("a column of the row is a tree patch")
        };
        let mut d = Dropped {
            exact: exact
                .iter()
                .filter(|x| x.1 > 0.0)
                .map(|&(j, v)| (at(j), v))
                .collect(),
            columns: Vec::new(),
            nodes: Vec::new(),
        };
        for x in tail {
            match *x {
                Tail::Column(j, f0) => d.columns.push((at(j), j, f0)),
                Tail::Node(id, guess) => {
                    let (a, b) = tree.range(id);
                    d.nodes.push((a, b, id, guess));
                }
            }
        }
        d.exact.sort_unstable_by_key(|x| x.0);
        d.columns.sort_unstable_by_key(|x| x.0);
        d.nodes.sort_unstable_by_key(|x| x.0);
        let total = known
            + d.columns.iter().map(|x| x.2).sum::<f64>()
            + d.nodes.iter().map(|x| x.3).sum::<f64>();
        let cut = self.link_cut(tree, root, row, &d, max, self.cfg.link_tol * total);
        let (exact, evaluated, sampled, all) = self.link_values(tree, i, row, t, &d, &cut, scratch);
        // In a closed scene the row's total is known better from hemisphere rays than
        // from the links' samples: what the link phase found (sampled or evaluated) is
        // scaled to that total less the known mass (a ratio estimate), so the row's
        // dropped mass is the one it has without links, bias and all. Not when the
        // whole tail was evaluated: that is exact.
        let mut scale = 1.0;
        let found: f64 = sampled.iter().chain(&evaluated).sum();
        if !all && found > 0.0 {
            if let Some(total) = self.closure_total(tree, i, t, scratch) {
                scale = (total - known).max(0.0) / found;
            }
        }
        let mut links = Vec::with_capacity(cut.len());
        for (((&id, e), v), s) in cut.iter().zip(exact).zip(evaluated).zip(sampled) {
            let value = (e + scale * (v + s)) as f32;
            if value.is_finite() && value > 0.0 {
                let (a, b) = tree.range(id);
                links.push(Link {
                    start: a,
                    len: b - a,
                    value,
                });
            }
        }
        links
    }

    /// Step 1 (module docs): the clusters, as node ids in ascending order of position.
    fn link_cut(
        &self,
        tree: &PatchTree,
        root: u32,
        row: &PatchBound,
        d: &Dropped,
        max: usize,
        tolerance: f64,
    ) -> Vec<u32> {
        let spread = |id: u32| match tree.node(id).kids {
            Kids::Leaf => 0.0,
            Kids::Inner(..) => {
                let b = tree.bound(id, row);
                if b.sum.is_finite() {
                    (b.sum - b.guess).max(0.0)
                } else {
                    f64::INFINITY
                }
            }
        };
        let holds = |id: u32| {
            let (a, b) = tree.range(id);
            d.holds(a, b)
        };
        // (spread bits, Reverse(id)): the largest spread first, then the smaller id.
        let mut open: BinaryHeap<(u64, Reverse<u32>)> = BinaryHeap::new();
        if holds(root) {
            open.push((spread(root).to_bits(), Reverse(root)));
        }
        let mut cut = Vec::new();
        while let Some(&(bits, Reverse(id))) = open.peek() {
            if f64::from_bits(bits) <= tolerance || open.len() + cut.len() >= max {
                break;
            }
            open.pop();
            match tree.node(id).kids {
                Kids::Leaf => cut.push(id),
                Kids::Inner(left, right) => {
                    for kid in [left, right] {
                        if holds(kid) {
                            open.push((spread(kid).to_bits(), Reverse(kid)));
                        }
                    }
                }
            }
        }
        cut.extend(open.into_iter().map(|(_, Reverse(id))| id));
        cut.sort_unstable_by_key(|&id| tree.range(id).0);
        cut
    }

    /// Step 2 (module docs): per cluster of `cut`, the mass known before (columns not
    /// kept), the mass evaluated now (small links, or every link when the whole tail
    /// is small: the last value says so) and the sampled estimate of the rest.
    #[allow(clippy::too_many_arguments)]
    fn link_values(
        &self,
        tree: &PatchTree,
        i: u32,
        row: &PatchBound,
        t: usize,
        d: &Dropped,
        cut: &[u32],
        scratch: &mut Scratch,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>, bool) {
        // Each cluster's exact mass and sampled items.
        let mut exact = Vec::with_capacity(cut.len());
        let mut items: Vec<Vec<(Item, f64)>> = Vec::with_capacity(cut.len());
        for &id in cut {
            let (a, b) = tree.range(id);
            exact.push(
                within(&d.exact, |x| x.0, a, b)
                    .iter()
                    .map(|x| x.1)
                    .sum::<f64>(),
            );
            let mut of: Vec<(Item, f64)> = within(&d.columns, |x| x.0, a, b)
                .iter()
                .map(|&(_, j, f0)| (Item::Column(j, f0), f0))
                .collect();
            match d.inside(a, b) {
                // Inside an unopened node: all of it is tail.
                Some(_) => {
                    let g = tree.bound(id, row).guess;
                    of.push((Item::Node(id, g), g));
                }
                None => of.extend(
                    within(&d.nodes, |x| x.0, a, b)
                        .iter()
                        .map(|&(_, _, n, g)| (Item::Node(n, g), g)),
                ),
            }
            items.push(of);
        }
        let size = |of: &[(Item, f64)]| -> usize {
            of.iter()
                .map(|(x, _)| match *x {
                    Item::Column(..) => 1,
                    Item::Node(id, _) => tree.node(id).count() as usize,
                })
                .sum()
        };
        let evaluate_all = items.iter().map(|of| size(of)).sum::<usize>() <= EXACT_TAIL_FACTOR * t;
        // Small links are evaluated in full: one sample point on a link of a few patches
        // is as costly as they are, and a point on a hidden one would leave out the
        // visible others (bench/LINKS.md).
        let in_full: Vec<bool> = items
            .iter()
            .map(|of| evaluate_all || size(of) <= FULL_LINK_PATCHES)
            .collect();
        let weight: f64 = items
            .iter()
            .zip(&in_full)
            .filter(|x| !*x.1)
            .flat_map(|x| x.0)
            .map(|x| x.1)
            .sum();
        let mut rng = self.tail_rng(i);
        let mut sampled = vec![0.0; cut.len()];
        let mut evaluated = vec![0.0; cut.len()];
        for (k, of) in items.iter().enumerate() {
            if in_full[k] {
                for (x, _) in of {
                    let v = match *x {
                        Item::Column(j, f0) => self.occluded_unlisted(i, j, f0, scratch),
                        Item::Node(n, _) => tree
                            .patches_under(n)
                            .iter()
                            .map(|&j| self.pair_value(i, j, scratch))
                            .sum(),
                    };
                    evaluated[k] += v;
                }
            } else {
                let w: f64 = of.iter().map(|x| x.1).sum();
                if w.is_finite() && w > 0.0 && weight > 0.0 {
                    let points = ((t as f64 * w / weight).round() as usize).max(1);
                    sampled[k] = systematic(
                        of.iter().copied(),
                        w,
                        points,
                        &mut rng,
                        |x, hits, rng| match (x, hits) {
                            (_, 0) => 0.0,
                            (Item::Column(j, f0), _) => {
                                hits as f64 * self.visibility_fraction(i, j, f0, scratch)
                            }
                            (Item::Node(n, g), _) => (0..hits)
                                .map(|_| self.node_sample(tree, n, i, row, rng, scratch) / g)
                                .sum(),
                        },
                    );
                }
            }
        }
        (exact, evaluated, sampled, evaluate_all)
    }
}
