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
//!    tree's cheap bounds in place of sampled kernel values. When something emits,
//!    the spread also counts the radiosity: it is then the kernel's spread times the
//!    scene's mean first-bounce radiosity B¹ plus the bound on Σ F⁰_ij times how much
//!    B¹ varies over the cluster (`first_bounce.rs`), and the tolerance is scaled by
//!    that mean. The second term is hierarchical radiosity's BF refinement with B¹ in
//!    place of the solution: a link to a cluster whose radiosity is flat gathers it
//!    exactly however the row's form factor lies inside, while a cluster holding the
//!    pool of light under a lamp or a shadow's edge is opened (`builtin:room`, 256
//!    links: worst surface 2.1 → 1.3 % at 3k patches, bench/LINKS.md). A leaf is not
//!    split; a cluster that holds nothing the row dropped gets no link.
//! 2. **The mass.** Each link's value is the exact mass of the columns the search
//!    evaluated and did not keep (pushed out of the top k, below `--min-ff`, or
//!    unoccludable tail columns) plus an estimate of the rest: tail columns that need
//!    visibility and nodes the search never opened. [`LINK_POINT_FACTOR`] times the
//!    row's `t` points are shared out over the links in proportion to the kernel's
//!    estimate of their tail, at least [`LINK_POINTS`] a link, so that every link's
//!    estimate is unbiased on its own, not only their sum; inside a link they fall systematically on its items
//!    by the same weights (`topk_tree.rs` step 3). A point on a tail column takes the
//!    pair's visibility by its own rule. Points on an unopened node are spread over
//!    its area and each is one ray between a point of the row patch and a point of
//!    the node ([`RowEngine::plan_node_points`]): a pair evaluation costs its contour or
//!    quadrature and up to 16 rays, a point one ray, so a link gets several points
//!    for less than one pair, and several points are what tell where in the cluster
//!    the mass lies (step 3). A link of at most 4 patches is evaluated in full, and
//!    when the whole tail holds at most 2t patches every value is.
//! 3. **The slope.** Inside a large cluster the row's form factor leans to the parts
//!    it sees and the parts nearer to it; spread by area alone, a link gathers the
//!    cluster's mean radiosity where it should gather that of those parts (the ceiling
//!    of the 16-box room came out 4 % dark at 3k patches). Each value of step 2 comes
//!    from a patch, so the same evaluations give the first moment of the link's mass,
//!    hence where its mass lies (its F-weighted centroid), at no extra visibility
//!    cost. The link stores the slope q of the linear weights A_j (1 + q · (x_j − x̄))
//!    (spec §5.7) whose centroid is that one ([`link_slope`]). This is the linear
//!    term of the link's distribution: from a few points a link it is a noisy
//!    estimate, limited so that no weight falls below [`WEIGHT_FLOOR`] times its
//!    patch's area (the weights are a rule for the gather, like a quadrature's, and
//!    some may be negative). The same samples give the F-weighted
//!    mean of B¹ over the link; the slope is then moved, as little as it can be in the
//!    weights' own metric, until the weights gather that mean of B¹: where the
//!    radiosity is B¹ plus a smooth remainder, the link then gathers what the row's
//!    form factor would. Higher-order variation (a bright patch under the lamp inside
//!    a floor cluster) is left to the cut.
//!
//! 4. **The link error.** The same estimate of the radiosity, its second bounce
//!    added, measures what the row's links may get wrong: their placement (each
//!    link's mass times the range of the radiosity over its cluster, times the
//!    spread of its weights when some are negative) and their
//!    sampling (two standard errors), over what the row gathers ([`LinkSpread`]). It is
//!    stored with the row (spec §5.7) and checked against the true error of rows
//!    against dense rows in `tests/it/links.rs`.
//!
//! The kept entries are those of the row without links, bit for bit; the dropped mass
//! stored is the sum of the links (spec §5.7), so a reader that ignores links reads the
//! same kind of row as before.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::{DVec3, DVec4};

use super::first_bounce::Contrast;
use super::topk_bounded::systematic;
use super::topk_tree::Tail;
use super::{RowEngine, Scratch};
use crate::formfactor::geom::{PatchBound, PatchGeom};
use crate::formfactor::tree::{second_matrix, Kids, PatchTree};
use crate::rows::Link;

/// A tail of at most this many times `t` patches is evaluated in full (as without
/// links, `topk_tree.rs`).
const EXACT_TAIL_FACTOR: usize = 2;

/// A link of at most this many patches to evaluate is evaluated in full, not sampled.
const FULL_LINK_PATCHES: usize = 4;

/// The points a row's sampled links share, in proportion to their weights, are this
/// many times the row's `t` (step 2): a point costs one ray, not a pair evaluation.
/// On the room at 10k patches, 4 (at least 2 a link) gave the same compute as a floor
/// of 4 points a link with t shared out, the same worst surface, and half the noise of
/// single patches (bench/LINKS.md).
const LINK_POINT_FACTOR: usize = 4;

/// The fewest points a sampled link gets (step 2): two, so that its slope has more
/// than one place to lean toward.
const LINK_POINTS: usize = 2;

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
    /// What row i dropped, by position in the cluster order: the columns not kept
    /// whose values are known (`exact`, those > 0) and the search's `tail`.
    fn new(tree: &PatchTree, exact: &[(u32, f64)], tail: &[Tail]) -> Dropped {
        let mut d = Dropped {
            exact: exact
                .iter()
                .filter(|x| x.1 > 0.0)
                .map(|&(j, v)| (position(tree, j), v))
                .collect(),
            columns: Vec::new(),
            nodes: Vec::new(),
        };
        for x in tail {
            match *x {
                Tail::Column(j, f0) => d.columns.push((position(tree, j), j, f0)),
                Tail::Node(id, guess) => {
                    let (a, b) = tree.range(id);
                    d.nodes.push((a, b, id, guess));
                }
            }
        }
        d.exact.sort_unstable_by_key(|x| x.0);
        d.columns.sort_unstable_by_key(|x| x.0);
        d.nodes.sort_unstable_by_key(|x| x.0);
        d
    }

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

/// Patch j's position in the cluster order: a row's columns are all tree patches.
fn position(tree: &PatchTree, j: u32) -> u32 {
    tree.position(j)
        .expect("a column of the row is a tree patch")
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

/// What one item of a sampled link gave ([`RowEngine::link_values`]): nothing (no
/// point fell on it), a tail column's value and moment point, or a node's weight
/// and the range of its points in the row's plan.
enum Event {
    Nothing,
    Column(f64, DVec4),
    Node(f64, std::ops::Range<usize>),
}

impl Event {
    /// Over one link's `events`, in order, with its points' (Y, moment point) in
    /// `values`: Σ value / weight of its samples and Σ (value / weight) x, which
    /// times the sampling step are the link's estimate and the first moment of it.
    fn sums(events: &[Event], values: &[(f64, DVec4)]) -> (f64, DVec4) {
        let mut moment = DVec4::ZERO;
        let mut estimate = 0.0;
        for e in events {
            estimate += match e {
                Event::Nothing => 0.0,
                Event::Column(v, x) => {
                    moment += *v * *x;
                    *v
                }
                Event::Node(g, points) => {
                    let mut sum = 0.0;
                    for &(v, x) in &values[points.clone()] {
                        moment += (v / g) * x;
                        sum += v / g;
                    }
                    sum
                }
            };
        }
        (estimate, moment)
    }
}

/// The items of each link of a cut, in one allocation: link k's are
/// `all[starts[k]..starts[k + 1]]`, with their weights.
struct Items {
    all: Vec<(Item, f64)>,
    starts: Vec<usize>,
}

impl Items {
    fn iter(&self) -> impl Iterator<Item = &[(Item, f64)]> + '_ {
        self.starts.windows(2).map(|w| &self.all[w[0]..w[1]])
    }
}

impl RowEngine {
    /// The links of row i (module docs): `known` is the mass the row knows exactly
    /// (kept entries and `exact`), `kept` the columns the row stores, `exact` the
    /// columns not kept whose values are known,
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
        kept: &[u32],
        exact: &[(u32, f64)],
        tail: &[Tail],
        scratch: &mut Scratch,
    ) -> (Vec<Link>, LinkSpread) {
        let Some(root) = tree.root() else {
            return (Vec::new(), LinkSpread::default());
        };
        let d = Dropped::new(tree, exact, tail);
        // The patches of a range that are not its link's: the kept columns and i.
        let mut others: Vec<(u32, u32)> = kept
            .iter()
            .chain(std::iter::once(&i))
            .map(|&j| (position(tree, j), j))
            .collect();
        others.sort_unstable();
        let total = known
            + d.columns.iter().map(|x| x.2).sum::<f64>()
            + d.nodes.iter().map(|x| x.3).sum::<f64>();
        let cut = self.link_cut(tree, root, row, &d, max, self.cfg.link_tol * total);
        let LinkValues {
            exact,
            evaluated,
            sampled,
            points,
            unoccluded,
            all,
            lean,
        } = self.link_values(tree, i, row, t, &d, &cut, scratch);
        // In a closed scene the row's total is known better from hemisphere rays than
        // from the links' samples: what the link phase found (sampled or evaluated) is
        // scaled to that total less the known mass (a ratio estimate), so the row's
        // dropped mass is the one it has without links, bias and all. Not when the
        // whole tail was evaluated: that is exact.
        let (mut scale, mut total_error) = (1.0, 0.0);
        let found: f64 = sampled.iter().chain(&evaluated).sum();
        if !all && found > 0.0 {
            if let Some((total, sigma)) = self.closure_total(tree, i, t, scratch) {
                scale = (total - known).max(0.0) / found;
                total_error = sigma;
            }
        }
        let mut links = Vec::with_capacity(cut.len());
        // Per link of the cut, stored or not: (value, the scale of its sampled part's
        // error, node id, the spread of its weights). That scale is the sampled part's
        // mass without occluders over √points: one point's estimate can be 0 (a hidden
        // patch) for a cluster that holds much visible mass, or a large multiple of a
        // small visible part, so the realized value says little of its own error.
        let mut spread = Vec::with_capacity(cut.len());
        for (k, (&id, (known_x, found_x))) in cut.iter().zip(lean).enumerate() {
            let mass = exact[k] + scale * (evaluated[k] + sampled[k]);
            let value = mass as f32;
            let error = scale * unoccluded[k] / (points[k].max(1) as f64).sqrt();
            let stored = value.is_finite() && value > 0.0;
            let mut weights = 1.0;
            if stored {
                let (a, b) = tree.range(id);
                let centre = (known_x + scale * found_x) / mass;
                let slope = link_slope(
                    tree,
                    &self.geom,
                    self.contrast.as_ref(),
                    (id, &self.inverses[id as usize]),
                    centre,
                    within(&others, |x| x.0, a, b),
                );
                weights = slope.spread;
                links.push(Link {
                    start: a,
                    len: b - a,
                    value,
                    slope: slope.q,
                });
            }
            spread.push((
                if stored { f64::from(value) } else { 0.0 },
                error,
                id,
                weights,
            ));
        }
        let spread = self
            .contrast
            .as_ref()
            .map_or_else(LinkSpread::default, |c| {
                LinkSpread::of(c, &spread, total_error)
            });
        (links, spread)
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
        let contrast = self.contrast.as_ref();
        let tolerance = tolerance * contrast.map_or(1.0, |c| c.scale);
        let spread = |id: u32| match tree.node(id).kids {
            Kids::Leaf => 0.0,
            Kids::Inner(..) => {
                let b = tree.bound(id, row);
                if b.sum.is_finite() {
                    let kernel = (b.sum - b.guess).max(0.0);
                    match contrast {
                        None => kernel,
                        Some(c) => kernel * c.scale + b.sum * c.range[id as usize] as f64,
                    }
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

    /// A patch's centroid and, as the fourth coordinate, its first-bounce radiosity (0
    /// without): the point of the first moments of step 3.
    fn moment_point(&self, j: u32) -> DVec4 {
        let b = self
            .contrast
            .as_ref()
            .map_or(0.0, |c| c.bounce[j as usize] as f64);
        self.geom[j as usize].centroid.extend(b)
    }

    /// Per cluster of `cut`: the exact mass known before (columns not kept), its first
    /// moment (with a zero moment for the rest, filled in by [`Self::link_values`]),
    /// and the items of its tail (columns and unopened nodes) with their weights.
    #[allow(clippy::type_complexity)]
    fn cluster_items(
        &self,
        tree: &PatchTree,
        row: &PatchBound,
        d: &Dropped,
        cut: &[u32],
    ) -> (Vec<f64>, Vec<(DVec4, DVec4)>, Items) {
        let mut exact = Vec::with_capacity(cut.len());
        let mut lean = Vec::with_capacity(cut.len());
        let mut items = Items {
            all: Vec::new(),
            starts: Vec::with_capacity(cut.len() + 1),
        };
        items.starts.push(0);
        // The whole cluster order: the known columns are given by position in it.
        let order = tree.root().map_or(&[][..], |root| tree.patches_under(root));
        for &id in cut {
            let (a, b) = tree.range(id);
            let known = within(&d.exact, |x| x.0, a, b);
            exact.push(known.iter().map(|x| x.1).sum::<f64>());
            let moment = known
                .iter()
                .map(|&(p, v)| v * self.moment_point(order[p as usize]))
                .sum::<DVec4>();
            lean.push((moment, DVec4::ZERO));
            let of = &mut items.all;
            of.extend(
                within(&d.columns, |x| x.0, a, b)
                    .iter()
                    .map(|&(_, j, f0)| (Item::Column(j, f0), f0)),
            );
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
            items.starts.push(of.len());
        }
        (exact, lean, items)
    }

    /// Step 2 (module docs): per cluster of `cut`, the mass known before (columns not
    /// kept), the mass evaluated now (small links, or every link when the whole tail
    /// is small: the fourth value says so), the sampled estimate of the rest, and the
    /// first moments Σ F x of the known mass and of the rest (evaluated and sampled),
    /// x the centroid of the patch each value came from (step 3).
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
    ) -> LinkValues {
        let at = |j: u32| self.moment_point(j);
        // Each cluster's exact mass and sampled items.
        let (exact, mut lean, items) = self.cluster_items(tree, row, d, cut);
        let size = |of: &[(Item, f64)]| -> usize {
            of.iter()
                .map(|(x, _)| match *x {
                    Item::Column(..) => 1,
                    Item::Node(id, _) => tree.node(id).count() as usize,
                })
                .sum()
        };
        let evaluate_all = items.iter().map(size).sum::<usize>() <= EXACT_TAIL_FACTOR * t;
        // Small links are evaluated in full: a few points on a link of a few patches
        // are noisier than its pairs, for about their cost (bench/LINKS.md).
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
        let mut points = vec![0; cut.len()];
        let mut unoccluded = vec![0.0; cut.len()];
        let mut sampled = vec![0.0; cut.len()];
        let mut evaluated = vec![0.0; cut.len()];
        // The sampled links' items in order, the points their nodes drew, and which
        // items are whose link.
        let (mut events, mut plan, mut replay) = (Vec::new(), Vec::new(), Vec::new());
        for (k, of) in items.iter().enumerate() {
            if in_full[k] {
                for (x, _) in of {
                    match *x {
                        Item::Column(j, f0) => {
                            let v = self.occluded_unlisted(i, j, f0, scratch);
                            evaluated[k] += v;
                            lean[k].1 += v * at(j);
                        }
                        Item::Node(n, _) => {
                            for &j in tree.patches_under(n) {
                                let v = self.pair_value(i, j, scratch);
                                evaluated[k] += v;
                                lean[k].1 += v * at(j);
                            }
                        }
                    }
                }
            } else {
                let w: f64 = of.iter().map(|x| x.1).sum();
                if w.is_finite() && w > 0.0 && weight > 0.0 {
                    let share = (LINK_POINT_FACTOR * t) as f64 * w / weight;
                    let p = (share.round() as usize).max(LINK_POINTS);
                    points[k] = p;
                    unoccluded[k] = w;
                    // The points of unopened nodes are drawn now and evaluated
                    // with the row's others below (`points.rs`); what each item
                    // gives is kept in order, so that the sums come out as they
                    // would one item at a time.
                    let first = events.len();
                    systematic(of.iter().copied(), w, p, &mut rng, |x, hits, rng| {
                        events.push(match (x, hits) {
                            (_, 0) => Event::Nothing,
                            (Item::Column(j, f0), _) => {
                                let v = hits as f64 * self.visibility_fraction(i, j, f0, scratch);
                                Event::Column(v, at(j))
                            }
                            (Item::Node(n, g), _) => {
                                let start = plan.len();
                                self.plan_node_points(tree, n, i, hits, rng, &mut plan);
                                Event::Node(g, start..plan.len())
                            }
                        });
                        0.0
                    });
                    replay.push((k, first..events.len()));
                }
            }
        }
        let mut values = Vec::with_capacity(plan.len());
        self.eval_points(tree, i, &plan, scratch, &mut values);
        for (k, range) in replay {
            let (estimate, moment) = Event::sums(&events[range], &values);
            let (w, p) = (unoccluded[k], points[k]);
            sampled[k] = estimate * (w / p as f64);
            lean[k].1 += moment * (w / p as f64);
        }
        LinkValues {
            exact,
            evaluated,
            sampled,
            points,
            unoccluded,
            all: evaluate_all,
            lean,
        }
    }
}

/// What [`RowEngine::link_values`] finds, per link of the cut.
struct LinkValues {
    /// The mass known before (columns not kept).
    exact: Vec<f64>,
    /// The mass evaluated now.
    evaluated: Vec<f64>,
    /// The sampled estimate of the rest, and the points it took (0: none sampled).
    sampled: Vec<f64>,
    points: Vec<usize>,
    /// The estimate of the sampled part's mass without occluders (what the points were
    /// shared out by).
    unoccluded: Vec<f64>,
    /// Whether the whole tail was evaluated.
    all: bool,
    /// The first moments (x and B¹, step 3) of the known mass and of the rest.
    lean: Vec<(DVec4, DVec4)>,
}

/// Standard errors of the sampled link masses the link error allows for. The masses of
/// one sample point are far from normal (a point on a visible patch of a mostly hidden
/// cluster weighs the whole cluster's estimate); two are what kept every row of the
/// 16-box room (1.5k and 10k patches), the two rooms and the corridor at or above its
/// true error (`tests/it/links.rs`, bench/LINKS.md), one was not.
const SAMPLING_SIGMAS: f64 = 2.0;

/// A row's links measured against the radiosity of the first two bounces, B = B¹ + B²
/// (`first_bounce.rs`; the row's link error, spec §5.7): see [`LinkSpread::error`].
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct LinkSpread {
    /// Σ_L F_L s_L (max − min of B over L's cluster): the most the links' placement
    /// of their mass can change the gathered B, s_L the spread of L's weights
    /// ([`Slope::spread`], 1 when none is negative).
    placement: f64,
    /// √Σ_L (σ_L (B̄_L − ḡ))²: the standard error that the sampling of the masses
    /// (σ_L for link L, B̄_L its cluster's area mean of B; ḡ the links' mass-weighted
    /// mean) gives the gathered B, the row's total being fixed.
    sampling: f64,
    /// Σ_L F_L B̄_L: what the links gather.
    gathered: f64,
    /// Σ_L F_L: the links' mass.
    mass: f64,
    /// The standard error of the row's total from hemisphere rays, when the links'
    /// mass was scaled to it (`closure.rs`); 0 otherwise.
    total: f64,
    /// Whether B exists (something emits).
    known: bool,
}

impl LinkSpread {
    /// The spread of links given as (value, standard error of its mass, node id, the
    /// spread of its weights), with `total` the standard error of the row total they
    /// were scaled to.
    fn of(c: &Contrast, links: &[(f64, f64, u32, f64)], total: f64) -> LinkSpread {
        let mean = |id: u32| c.both_mean[id as usize];
        let (mass, gathered) = links.iter().fold((0.0, 0.0), |(m, g), &(v, _, id, _)| {
            (m + v, g + v * mean(id))
        });
        let centre = if mass > 0.0 { gathered / mass } else { 0.0 };
        LinkSpread {
            placement: links
                .iter()
                .map(|&(v, _, id, s)| v * s * c.both_range[id as usize] as f64)
                .sum(),
            sampling: links
                .iter()
                .map(|&(_, e, id, _)| (e * (mean(id) - centre)).powi(2))
                .sum::<f64>()
                .sqrt(),
            gathered,
            mass,
            total,
            known: true,
        }
    }

    /// The row's link error: (placement + [`SAMPLING_SIGMAS`] · √(sampling² + (σ_T
    /// B̄)²)) over all the row gathers of B, G; σ_T B̄ is what the error of the row's
    /// total does to G, B̄ = G over the row's mass being its mean B. `kept` is what the
    /// kept entries gather (Σ F_ij B_j), `kept_mass` their Σ F_ij. `None` without B, or
    /// when the row gathers none of it.
    pub(super) fn error(&self, kept: f64, kept_mass: f64) -> Option<f32> {
        let gathered = kept + self.gathered;
        let mean = gathered / (kept_mass + self.mass);
        let random = self.sampling.hypot(self.total * mean);
        (self.known && gathered > 0.0)
            .then(|| ((self.placement + SAMPLING_SIGMAS * random) / gathered) as f32)
            .filter(|e| e.is_finite())
    }
}

/// A link's slope (spec §5.7) and how far its weights may carry the gather outside
/// the range of the radiosity over its patches.
struct Slope {
    q: [f32; 3],
    /// (1 + Σ|u_j|) / 2 for the link's normalised weights u_j = w_j / Σ w: 1 when no
    /// weight is negative, else an upper bound. The gathered mean of B then lies
    /// within this many ranges of B over the link's patches from the true one.
    spread: f64,
}

/// Step 3 (module docs): the slope q of a link to node `id` whose mass has its
/// centroid at `centre` (spec §5.7), `others` the patches of the node's range
/// that are not the link's (the row's kept columns and the row patch), as (position,
/// patch). The weights
/// A_j (1 + q · (x_j − x̄)) over the node's patches have their centroid at
/// x̄ + M q / A (M the node's second moments, A its area), so q = A M⁺ (centre −
/// x̄), with M⁺ the pseudo-inverse (a planar or straight cluster has no second
/// moment across itself, and no slope there).
///
/// With a first-bounce estimate, `centre.w` is the F-weighted mean of B¹ over the
/// link, and q then moves by δ = M⁺g (t − g · q) / (gᵀM⁺g), with g = Σ A_j (x_j −
/// x̄) B¹_j and t = A centre.w − Σ A_j B¹_j: the least change, in the metric δᵀMδ =
/// Σ A_j (δ · (x_j − x̄))² of the weights it moves, after which the weights' mean
/// of B¹ is that target.
///
/// The weights are a rule for the gather, not form factors of single patches, and
/// may be negative (as a quadrature's may), but not without limit: q is shrunk
/// until 1 + q · (x − x̄) ≥ [`WEIGHT_FLOOR`] over the box of the node's centroids
/// and the link's own patches keep at least half their area as weight, Σ w ≥ A_L
/// / 2. That bounds what the weights can do to noise in the radiosity
/// ([`Slope::spread`]); a floor of 0, no negative weight, left the ceiling of the
/// 16-box room 2.5 % dark at 10k patches (bench/LINKS.md, "Weights below zero").
fn link_slope(
    tree: &PatchTree,
    geom: &[PatchGeom],
    contrast: Option<&Contrast>,
    (id, inverse): (u32, &PseudoInverse),
    centre: DVec4,
    others: &[(u32, u32)],
) -> Slope {
    let flat = Slope {
        q: [0.0; 3],
        spread: 1.0,
    };
    let node = tree.node(id);
    let (area, mean, m) = node.moments();
    let shift = centre.truncate() - mean;
    if node.count() < 2 || !shift.is_finite() || area.is_nan() || area <= 0.0 {
        return flat;
    }
    let mut q = area * inverse.times(shift);
    if let Some(c) = contrast {
        let (sum, g) = c.moments[id as usize];
        let step = inverse.times(g);
        let gg = g.dot(step);
        let miss = area * centre.w - sum - q.dot(g);
        if gg > 0.0 && (miss / gg).is_finite() {
            q += step * (miss / gg);
        }
    }
    let (lo, hi) = node.centroid_bounds();
    // The least of q · (x − x̄) over the box: each axis at its worse end.
    let least = |q: DVec3| -> f64 {
        (0..3)
            .map(|k| (q[k] * (lo[k] - mean[k])).min(q[k] * (hi[k] - mean[k])))
            .sum()
    };
    // The link's own area, and Σ A_j (x_j − x̄) over the patches that are not its
    // own: Σ w over its own patches is A_L − q · that (the weights of the whole
    // range sum to A).
    let (others_area, others_moment) = others.iter().fold((0.0, DVec3::ZERO), |(a, x), &(_, j)| {
        let g = &geom[j as usize];
        (a + g.area, x + g.area * (g.centroid - mean))
    });
    let link_area = area - others_area;
    let mut shrink: f64 = 1.0;
    let low = least(q);
    if low < WEIGHT_FLOOR - 1.0 {
        shrink = shrink.min((1.0 - WEIGHT_FLOOR) / -low);
    }
    let lost = q.dot(others_moment);
    if lost > 0.5 * link_area {
        shrink = shrink.min(0.5 * link_area / lost);
    }
    let full = q * shrink;
    // Cut to a few bits, unless that moves the weights' centroid (M q / A) by more
    // than an eighth of its shift: across a thin cluster M is nearly singular, q
    // large there, and the cut of that large component would land in the wide
    // directions, where M magnifies it.
    let cut = full.to_array().map(|x| round_slope(x as f32));
    let shift_of = |q: DVec3| second_matrix(m) * q;
    let cut_miss = shift_of(DVec3::from_array(cut.map(f64::from)) - full).length();
    let q = match cut_miss <= shift_of(full).length() / 8.0 {
        true => cut,
        false => full.to_array().map(|x| x as f32),
    };
    let qd = DVec3::from_array(q.map(f64::from));
    let sum = link_area - qd.dot(others_moment);
    let below = -(1.0 + least(qd)).min(0.0);
    let spread = 1.0 + below * link_area / sum;
    if q.iter().all(|x| x.is_finite()) && sum > 0.0 && spread.is_finite() {
        Slope { q, spread }
    } else {
        flat
    }
}

/// `x` cut to [`SLOPE_BITS`] bits of mantissa, toward zero (so a slope the limiter
/// allowed stays allowed): a slope needs no more than a few percent, and cut values
/// compress (their low bytes are zero, and shuffling puts them together). Measured on
/// `builtin:room` at 3k patches: the same radiosity to the printed digits as full f32
/// slopes, in a file a third smaller (bench/LINKS.md).
fn round_slope(x: f32) -> f32 {
    const DROP: u32 = 23 - SLOPE_BITS;
    f32::from_bits((x.to_bits() >> DROP) << DROP)
}

/// The least a link's weight may be, as a multiple of its patch's area (spec §5.7):
/// 1 + q · (x − x̄) ≥ this over the box of the cluster's centroids. On the 16-box room
/// at 10k patches, floors of 0, −1, −2, −4 and none left the ceiling −2.5, −1.3,
/// −0.8, −0.55 and −0.34 % off dense rows (bench/LINKS.md, "Weights below zero").
const WEIGHT_FLOOR: f64 = -4.0;

/// Mantissa bits a stored slope keeps (relative error at most 2^-4).
const SLOPE_BITS: u32 = 4;

/// Eigenvalues of a cluster's second moments below this fraction of the largest count
/// as zero (directions the cluster does not extend in).
const FLAT: f64 = 1e-6;

/// M⁺ v for the symmetric 3 × 3 matrix `m` (xx, yy, zz, xy, xz, yz): see
/// [`PseudoInverse`].
#[cfg(test)]
fn pseudo_solve(m: [f64; 6], v: DVec3) -> DVec3 {
    PseudoInverse::of(m).times(v)
}

/// The pseudo-inverse M⁺ of a symmetric 3 × 3 matrix, as its eigenvectors and
/// eigenvalues, found by Jacobi rotations: eigenvalues below [`FLAT`] times the
/// largest are left out (M⁺ is 0 along their eigenvectors). A link's slope
/// applies one of its node's to two vectors (`link_slope`); the engine finds one
/// for every node before any row (96 bytes a node), not one for every link of
/// every row.
#[derive(Clone, Debug)]
pub(super) struct PseudoInverse {
    /// Per eigenvalue: its unit eigenvector and λ, 0 where it is left out.
    axes: [(DVec3, f64); 3],
}

impl PseudoInverse {
    /// One for each node of `tree`, by id.
    pub(super) fn of_nodes(tree: &PatchTree) -> Vec<PseudoInverse> {
        (0..tree.len() as u32)
            .map(|id| PseudoInverse::of(tree.node(id).moments().2))
            .collect()
    }

    fn of(m: [f64; 6]) -> PseudoInverse {
        let mut a = [[m[0], m[3], m[4]], [m[3], m[1], m[5]], [m[4], m[5], m[2]]];
        let mut e = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for _ in 0..32 {
            let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
            let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
            if off <= 1e-15 * scale || off.is_nan() {
                break;
            }
            for (p, q) in [(0, 1), (0, 2), (1, 2)] {
                if a[p][q] == 0.0 {
                    continue;
                }
                // The rotation that zeroes a[p][q] (Golub and Van Loan, §8.5.2);
                // signum of 0 is 1 here, as the rule wants.
                let tau = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = tau.signum() / (tau.abs() + (1.0 + tau * tau).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = t * c;
                // A ← Jᵀ A J, E ← E J: columns p and q, then rows p and q.
                let turn = |x: f64, y: f64| (c * x - s * y, s * x + c * y);
                for row in a.iter_mut().chain(e.iter_mut()) {
                    (row[p], row[q]) = turn(row[p], row[q]);
                }
                let (rp, rq) = (a[p], a[q]);
                a[p] = std::array::from_fn(|k| turn(rp[k], rq[k]).0);
                a[q] = std::array::from_fn(|k| turn(rp[k], rq[k]).1);
            }
        }
        let largest = (0..3).map(|k| a[k][k].abs()).fold(0.0, f64::max);
        let axes = std::array::from_fn(|k| {
            let lambda = a[k][k];
            let axis = DVec3::new(e[0][k], e[1][k], e[2][k]);
            match lambda > FLAT * largest && lambda > 0.0 {
                true => (axis, lambda),
                false => (axis, 0.0),
            }
        });
        PseudoInverse { axes }
    }

    /// M⁺ v.
    fn times(&self, v: DVec3) -> DVec3 {
        let mut out = DVec3::ZERO;
        for &(axis, lambda) in &self.axes {
            if lambda != 0.0 {
                out += axis * (axis.dot(v) / lambda);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;
