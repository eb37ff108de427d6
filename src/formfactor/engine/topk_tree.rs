//! Top-k rows of the `contour` method by best-first search over the patch tree
//! ([`crate::formfactor::TopKSearch::Tree`]): a row evaluates the columns of the nodes
//! whose bound can still enter its top k, not every column.
//!
//! 1. Nodes wait in a max-heap by their bound on one entry's F⁰ ([`super::super::tree`];
//!    ties: the smaller node id). The top node is opened (its children's bounds
//!    computed and pushed; a leaf's columns evaluated) until the k best final values
//!    are found and the top bound is below the worst of them: every column still in the
//!    heap has F ≤ F⁰ ≤ its node's bound < the worst kept value, so none can enter.
//! 2. A leaf's column j gets its F⁰_ij; it enters the kept set (with its visibility)
//!    unless k are kept and F⁰ is below the worst of them, as in the exhaustive search.
//!    Final values are the same function of (i, j) as there, and the kept set is the k
//!    largest of them with ties to the smaller column either way, so the kept entries
//!    are bitwise those of the exhaustive search.
//! 3. dropped = entries pushed out of the kept set (exact) + evaluated tail columns that
//!    need no rays (exact, F = F⁰) + the rest, evaluated in full when it holds at most
//!    2t patches, else estimated: the evaluated tail columns
//!    that need rays (weight F⁰_ij, as in the exhaustive search) and the nodes never
//!    opened (weight: a guess at their F⁰ sum, never 0 where their bound is not; see
//!    `Bound::guess`), from `t` points of systematic sampling over these weights. A
//!    point on a node walks down from it, choosing a child with probability ∝ the
//!    children's guesses and a leaf's column ∝ that column's own, and reports F_ij / (p_j · weight), p_j the probability of
//!    reaching j: unbiased, since every column with F⁰ > 0 has a positive bound on the
//!    way (the bounds are never below the truth). This is the light-tree sampling of
//!    many-light rendering (Conty Estevez and Kulla 2018) applied to form factors; the
//!    tree's bounds are tight for far nodes, where the unopened mass lies, so the
//!    weights follow the mass and the estimate's error is of order (tail mass)/√t.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::topk_bounded::{systematic, Kept};
use super::{RowEngine, Scratch};
use crate::formfactor::geom::PatchBound;
use crate::formfactor::sampling::SplitMix64;
use crate::formfactor::tree::{Kids, PatchTree};
use crate::rows::Row;

/// A tail of at most this many times `t` patches is evaluated in full rather than
/// sampled (a walk costs about as much as an evaluation, and small scenes, where the
/// tail is most of a short row, get the dense row's dropped mass).
const EXACT_TAIL_FACTOR: usize = 2;

/// A tail item of the estimate: an evaluated column that needs rays, or an unopened
/// node.
#[derive(Clone, Copy, Debug)]
enum Tail {
    Column(u32, f64),
    Node(u32, f64),
}

impl RowEngine {
    /// Top-k row i into `kept` (empty, with its k and threshold) by best-first search
    /// over `tree`, with a tail sampled from `t` points (module docs).
    pub(super) fn top_k_row_tree(
        &self,
        tree: &PatchTree,
        i: u32,
        mut kept: Kept,
        t: usize,
        scratch: &mut Scratch,
    ) -> Row {
        scratch.start_row(i);
        let Some(root) = tree.root().filter(|_| self.valid[i as usize]) else {
            return kept.into_row(i, 0.0);
        };
        let row = self.bounds[i as usize];
        // (bound on one entry, Reverse(node)): the largest bound first, then the
        // smaller id.
        let mut open: BinaryHeap<(u64, Reverse<u32>)> = BinaryHeap::new();
        let push = |open: &mut BinaryHeap<(u64, Reverse<u32>)>, id: u32| {
            let b = tree.bound(id, &row);
            if b.max > 0.0 {
                open.push((b.max.to_bits(), Reverse(id)));
            }
        };
        push(&mut open, root);
        let mut tail: Vec<Tail> = Vec::new();
        let mut exact_tail = 0.0f64;
        while let Some(&(bits, Reverse(id))) = open.peek() {
            if f64::from_bits(bits) < kept.floor() {
                break;
            }
            open.pop();
            scratch.pair.counters.tree_nodes_opened += 1;
            match tree.node(id).kids {
                Kids::Inner(left, right) => {
                    push(&mut open, left);
                    push(&mut open, right);
                }
                Kids::Leaf => {
                    for &j in tree.patches_under(id) {
                        if j == i {
                            continue;
                        }
                        let Some(u) = self.column_unoccluded(i, j, scratch) else {
                            continue;
                        };
                        if u.f < kept.floor() {
                            if u.needs_rays {
                                tail.push(Tail::Column(j, u.f));
                            } else {
                                exact_tail += u.f;
                            }
                            continue;
                        }
                        kept.offer(j, self.candidate_value(i, j, u.f, u.needs_rays, scratch));
                    }
                }
            }
        }
        // The unopened nodes, by id (the heap's order is not a sort).
        let mut unopened: Vec<u32> = open.into_iter().map(|(_, Reverse(id))| id).collect();
        unopened.sort_unstable();
        tail.extend(
            unopened
                .into_iter()
                .map(|id| Tail::Node(id, tree.bound(id, &row).guess)),
        );
        let tail_mass = exact_tail + self.tree_tail_mass(tree, i, &row, t, &tail, scratch);
        kept.into_row(i, tail_mass)
    }

    /// Step 3: the mass of the tail items (module docs): exact when they hold at most
    /// [`EXACT_TAIL_FACTOR`] · `t` patches, else sampled from `t` points.
    fn tree_tail_mass(
        &self,
        tree: &PatchTree,
        i: u32,
        row: &PatchBound,
        t: usize,
        tail: &[Tail],
        scratch: &mut Scratch,
    ) -> f64 {
        let patches: usize = tail
            .iter()
            .map(|x| match *x {
                Tail::Column(..) => 1,
                Tail::Node(id, _) => tree.node(id).count() as usize,
            })
            .sum();
        if patches <= EXACT_TAIL_FACTOR * t {
            // Few enough to evaluate every one for about the cost of the walks.
            let mut sum = 0.0;
            for x in tail {
                match *x {
                    Tail::Column(j, f0) => sum += self.occluded_unlisted(i, j, f0, scratch),
                    Tail::Node(id, _) => {
                        for &j in tree.patches_under(id) {
                            sum += self.pair_value(i, j, scratch);
                        }
                    }
                }
            }
            return sum;
        }
        let weight = |x: &Tail| match *x {
            Tail::Column(_, w) | Tail::Node(_, w) => w,
        };
        let total: f64 = tail.iter().map(weight).sum();
        if total.is_nan() || total <= 0.0 {
            return 0.0;
        }
        let items = tail.iter().map(|x| (*x, weight(x)));
        let mut rng = self.tail_rng(i);
        systematic(items, total, t, &mut rng, |item, hits, rng| {
            match (item, hits) {
                (_, 0) => {
                    scratch.pair.counters.pairs_topk_tail_skipped += 1;
                    0.0
                }
                (Tail::Column(j, f0), _) => {
                    hits as f64 * self.visibility_fraction(i, j, f0, scratch)
                }
                (Tail::Node(id, w), _) => (0..hits)
                    .map(|_| self.node_sample(tree, id, i, row, rng, scratch) / w)
                    .sum(),
            }
        })
    }

    /// One walk down from node `id` to a column j (module docs): F_ij / p_j, 0 when the
    /// walk finds no column with a positive bound.
    fn node_sample(
        &self,
        tree: &PatchTree,
        mut id: u32,
        i: u32,
        row: &PatchBound,
        rng: &mut SplitMix64,
        scratch: &mut Scratch,
    ) -> f64 {
        let mut p = 1.0f64;
        loop {
            match tree.node(id).kids {
                Kids::Inner(left, right) => {
                    let (l, r) = (tree.bound(left, row).guess, tree.bound(right, row).guess);
                    if (l + r).is_nan() || l + r <= 0.0 {
                        return 0.0;
                    }
                    let u = rng.next_f64() * (l + r);
                    let (next, w) = if u < l { (left, l) } else { (right, r) };
                    p *= w / (l + r);
                    id = next;
                }
                Kids::Leaf => {
                    let patches = tree.patches_under(id);
                    let bound = |j: u32| match j == i {
                        true => 0.0,
                        false => tree.patch_bound(&self.geom[j as usize], row).guess,
                    };
                    let total: f64 = patches.iter().map(|&j| bound(j)).sum();
                    if total.is_nan() || total <= 0.0 {
                        return 0.0;
                    }
                    let u = rng.next_f64() * total;
                    let mut cumulative = 0.0;
                    // The last column with a positive bound, should rounding carry u
                    // past the end.
                    let mut chosen = None;
                    for &j in patches {
                        let b = bound(j);
                        if b > 0.0 {
                            chosen = Some((j, b));
                        }
                        cumulative += b;
                        if u < cumulative && b > 0.0 {
                            break;
                        }
                    }
                    let Some((j, b)) = chosen else {
                        return 0.0;
                    };
                    p *= b / total;
                    scratch.pair.counters.tree_tail_samples += 1;
                    return self.pair_value(i, j, scratch) / p;
                }
            }
        }
    }
}
