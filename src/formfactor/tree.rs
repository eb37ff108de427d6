//! A hierarchy over the patches as receivers, with bounds on the unoccluded form factor
//! of a whole node, so a top-k row does not evaluate every column.
//!
//! Each node holds a box around its patches' corners, their total and largest area,
//! and a cone containing their normals (axis and half-angle). For a row patch i (its
//! bounding sphere and plane) [`PatchTree::bound`] gives two numbers that no patch j of
//! the node can exceed, without any per-patch work:
//!
//! ```text
//! F⁰_ij = (1/A_i) ∫∫ cos⁺θ_i cos⁺θ_j / (π r²) dA_j dA_i  ≤  A_j · c_i c_j / (π d²)
//! ```
//!
//! with d the distance from i's sphere to the node's box (r ≥ d), c_i the largest cos θ_i
//! (the least angle between n_i and a direction from i's sphere to the node's bounding
//! sphere, and at most h/d where h is how far the box reaches in front of i's plane),
//! and c_j the largest cos θ_j over the normal cone and the same directions. The node's
//! bound on one entry uses its largest area, on the sum of its entries its total area;
//! both are at most what a patch can have (F⁰ ≤ 1 per entry). The bounding of cosines by
//! normal cones and direction cones is that of light hierarchies for many-light
//! rendering (Conty Estevez and Kulla, "Importance sampling of many lights with
//! adaptive tree splitting", 2018); hierarchical radiosity (Hanrahan, Salzman and
//! Aupperle, 1991) and clustering (Smits, Arvo and Greenberg, 1994) bound form factors
//! between clusters in the same spirit, to decide where to refine a link. Here the
//! bounds decide which nodes a row opens (`engine/topk_tree.rs`), so they must never
//! be below the truth: `tests` checks them against computed F⁰ over many random pairs.
//!
//! The tree is built top-down. A node whose normal cone is wider than
//! [`SPLIT_ON_NORMALS_ABOVE`] is split at the middle of the normal component that
//! varies most (a room's six walls part first, so that nodes face one way), any other
//! at the median of the longest axis of its centroids' box; ties go by patch index, so
//! the tree is a function of the patches alone: the same on every rank and thread.

use std::f64::consts::PI;

use glam::DVec3;

use super::clip::convex_holds;
use super::geom::{PatchBound, PatchGeom};

/// Patches a leaf holds at most.
const LEAF_PATCHES: usize = 4;

/// Nodes whose normal cone has a half-angle above this (radians, 30°) are split by
/// their normals rather than by position.
const SPLIT_ON_NORMALS_ABOVE: f64 = PI / 6.0;

/// Relative margin on every bound: F⁰ itself is computed to `quad_tol` (at most 0.1 of a
/// percent in any preset, far less by default), and the bound must stay above the
/// computed value, not only above the exact one.
const MARGIN: f64 = 1.0 + 1e-3;

/// A node's children, or none: a leaf, whose patches are [`PatchTree::patches_under`].
#[derive(Clone, Copy, Debug)]
pub(crate) enum Kids {
    Inner(u32, u32),
    Leaf,
}

/// One node: what the bounds need of its patches.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Centre and radius of a sphere around the box.
    centre: DVec3,
    radius: f64,
    /// Normal cone: unit axis and half-angle (radians, π when the normals span more
    /// than a hemisphere around any axis tried).
    axis: DVec3,
    spread: f64,
    area_sum: f64,
    area_max: f64,
    /// Area-weighted centroid of the patches.
    mean: DVec3,
    /// Σ A_j (x_j − mean)(x_j − mean)ᵀ over the patches' centroids x_j, as xx, yy, zz,
    /// xy, xz, yz (tree nodes only: zero in the node of a single patch's bound).
    second: [f64; 6],
    /// Box of the patches' centroids.
    spots: (DVec3, DVec3),
    count: u32,
    /// The node's patches: `PatchTree::order[range.0..range.1]`.
    range: (u32, u32),
    pub(crate) kids: Kids,
}

impl Node {
    /// The eight corners of the node's box.
    pub(crate) fn corners(&self) -> [DVec3; 8] {
        let (l, h) = (self.lo, self.hi);
        std::array::from_fn(|k| {
            DVec3::new(
                if k & 1 == 0 { l.x } else { h.x },
                if k & 2 == 0 { l.y } else { h.y },
                if k & 4 == 0 { l.z } else { h.z },
            )
        })
    }

    /// Whether `x` lies in the node's box widened by `tol`.
    fn holds(&self, x: DVec3, tol: f64) -> bool {
        (x - self.lo).min_element() >= -tol && (self.hi - x).min_element() >= -tol
    }

    /// Number of patches under the node.
    pub(crate) fn count(&self) -> u32 {
        self.count
    }

    /// The box of the node's patches' centroids.
    pub(crate) fn centroid_bounds(&self) -> (DVec3, DVec3) {
        self.spots
    }

    /// Total area, area-weighted mean centroid and second moments about it (see
    /// `second`) of the node's patches.
    pub(crate) fn moments(&self) -> (f64, DVec3, [f64; 6]) {
        (self.area_sum, self.mean, self.second)
    }

    /// Whether the node's sphere is `ratio` times the two radii away from row patch i.
    #[cfg(test)]
    pub(crate) fn is_far_from(&self, i: &PatchBound, ratio: f64) -> bool {
        (self.centre - i.centre).length() > ratio * (self.radius + i.radius)
    }
}

/// Upper bounds on the unoccluded form factors F⁰_ij of one node's patches j.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bound {
    /// No F⁰_ij of the node exceeds this (infinite when i's sphere touches the box).
    pub(crate) max: f64,
    /// Their sum does not exceed this (infinite when i's sphere touches the box).
    pub(crate) sum: f64,
    /// A guess at their sum, in (0, sum] when sum > 0: the kernel at the patches'
    /// mean point and mean normal times their area, but at least a tenth of `sum`.
    /// The weight of the tail's sampling, which needs it positive wherever F⁰ can be.
    pub(crate) guess: f64,
}

impl Bound {
    const ZERO: Bound = Bound {
        max: 0.0,
        sum: 0.0,
        guess: 0.0,
    };
    const OPEN: Bound = Bound {
        max: f64::INFINITY,
        sum: f64::INFINITY,
        guess: f64::INFINITY,
    };
}

/// The hierarchy over the valid patches (module docs).
#[derive(Debug)]
pub(crate) struct PatchTree {
    nodes: Vec<Node>,
    /// Patch indices, each leaf's ascending.
    order: Vec<u32>,
    /// The inverse of `order` (u32::MAX for patches outside the tree).
    pos: Vec<u32>,
    /// `area_before[k]`: the area of the patches at positions 0..k of `order`
    /// (`order.len() + 1` entries).
    area_before: Vec<f64>,
    /// The engine's plane tolerance (a patch whose corners are all within it of i's
    /// plane, or behind, faces away) and the rounding allowance of plane distances,
    /// in length units.
    plane_tol: f64,
    slack: f64,
}

impl PatchTree {
    /// Builds the tree over the patches with `valid[j]`; `plane_tol`: the engine's
    /// facing tolerance, `slack`: the rounding allowance of plane distances.
    #[cfg(test)]
    pub(crate) fn new(geom: &[PatchGeom], valid: &[bool], plane_tol: f64, slack: f64) -> Self {
        Self::with_kinds(geom, valid, &[], plane_tol, slack)
    }

    /// The tree of `PatchTree::new` (tests) whose nodes first part patches of different `kinds` (one per
    /// patch, or none): ffstream gives emitters one kind and the other patches another,
    /// so that no cluster mixes a lamp with the ceiling around it (a link to such a
    /// cluster would spread the lamp's radiosity over the ceiling's area).
    pub(crate) fn with_kinds(
        geom: &[PatchGeom],
        valid: &[bool],
        kinds: &[u8],
        plane_tol: f64,
        slack: f64,
    ) -> Self {
        let mut order: Vec<u32> = (0..geom.len() as u32)
            .filter(|&j| valid[j as usize])
            .collect();
        let mut tree = PatchTree {
            nodes: Vec::with_capacity(2 * order.len() / LEAF_PATCHES + 1),
            order: Vec::new(),
            pos: Vec::new(),
            area_before: Vec::new(),
            plane_tol,
            slack,
        };
        if !order.is_empty() {
            let n = order.len();
            tree.build(geom, kinds, &mut order, 0, n);
        }
        tree.pos = vec![u32::MAX; geom.len()];
        for (k, &j) in order.iter().enumerate() {
            tree.pos[j as usize] = k as u32;
        }
        tree.area_before = std::iter::once(0.0)
            .chain(order.iter().scan(0.0, |sum, &j| {
                *sum += geom[j as usize].area;
                Some(*sum)
            }))
            .collect();
        tree.order = order;
        tree
    }

    /// One (node, u) of [`PatchTree::positions_at_area`], by `partition_point`: the
    /// tests' reference.
    #[cfg(test)]
    pub(crate) fn position_at_area(&self, id: u32, u: f64) -> u32 {
        let (a, b) = self.range(id);
        let before = &self.area_before[a as usize..=b as usize];
        let target = before[0] + u;
        let k = before[1..].partition_point(|&x| x <= target);
        a + k.min((b - a - 1) as usize) as u32
    }

    /// For each (node `id`, `u`) of `at`, into `out`: the position (in
    /// [`PatchTree::cluster_order`]) of the patch under node `id` at `u` along its
    /// area, `u` in [0, the node's area), patches taken in tree order, each as long as
    /// its area, so that a uniform `u` draws a patch in proportion to its area (the
    /// last patch when rounding carries `u` past the end). The binary searches advance
    /// in step, so that their cache misses overlap instead of following one another
    /// (the links' points, `engine/points.rs`); the tests check the positions against
    /// one search at a time (a monotone predicate has one partition point).
    pub(crate) fn positions_at_area<const B: usize>(&self, at: &[(u32, f64)], out: &mut [u32; B]) {
        assert!(at.len() <= B, "{} searches for {B} places", at.len());
        let (mut from, mut base, mut size, mut target) = ([0; B], [0; B], [0; B], [0.0; B]);
        for (t, &(id, u)) in at.iter().enumerate() {
            let (a, b) = self.range(id);
            // The search is over area_before[a + 1..=b], for the last entry <= target.
            from[t] = a as usize + 1;
            size[t] = (b - a) as usize;
            target[t] = self.area_before[a as usize] + u;
        }
        let m = at.len();
        loop {
            let mut more = false;
            for t in 0..m {
                if size[t] > 1 {
                    let half = size[t] / 2;
                    if self.area_before[from[t] + base[t] + half] <= target[t] {
                        base[t] += half;
                    }
                    size[t] -= half;
                    more = true;
                }
            }
            if !more {
                break;
            }
        }
        for t in 0..m {
            let k = base[t] + usize::from(self.area_before[from[t] + base[t]] <= target[t]);
            let (a, b) = self.range(at[t].0);
            out[t] = a + k.min((b - a - 1) as usize) as u32;
        }
    }

    /// Where patch `j` stands in [`PatchTree::cluster_order`] (`None` for a patch
    /// outside the tree).
    pub(crate) fn position(&self, j: u32) -> Option<u32> {
        self.pos.get(j as usize).copied().filter(|&p| p != u32::MAX)
    }

    /// The root (node 0), if any patch is valid.
    pub(crate) fn root(&self) -> Option<u32> {
        (!self.nodes.is_empty()).then_some(0)
    }

    pub(crate) fn node(&self, id: u32) -> &Node {
        &self.nodes[id as usize]
    }

    /// Number of nodes (ids 0..len).
    pub(crate) fn len(&self) -> usize {
        self.nodes.len()
    }

    /// The cluster order of a linked file (spec §4.3): the valid patches in tree order,
    /// so that node `id`'s patches are positions `range(id)`, then the others ascending.
    pub(crate) fn cluster_order(&self, n: usize) -> Vec<u32> {
        let mut in_tree = vec![false; n];
        for &j in &self.order {
            in_tree[j as usize] = true;
        }
        let rest = (0..n as u32).filter(|&j| !in_tree[j as usize]);
        self.order.iter().copied().chain(rest).collect()
    }

    /// The positions of node `id`'s patches in [`PatchTree::cluster_order`].
    pub(crate) fn range(&self, id: u32) -> (u32, u32) {
        self.node(id).range
    }

    /// Every patch under node `id` (in tree order; a leaf's ascending).
    pub(crate) fn patches_under(&self, id: u32) -> &[u32] {
        let (start, end) = self.node(id).range;
        &self.order[start as usize..end as usize]
    }

    /// Whether `x` lies on a patch whose front faces a ray arriving along `dir`
    /// (normal · dir < 0): within `tol` of its plane and inside its polygon, edges
    /// widened by `tol`. `stack` is scratch space.
    pub(crate) fn front_patch_at(
        &self,
        geom: &[PatchGeom],
        x: DVec3,
        dir: DVec3,
        tol: f64,
        stack: &mut Vec<u32>,
    ) -> bool {
        stack.clear();
        stack.extend(self.root());
        while let Some(id) = stack.pop() {
            let node = self.node(id);
            if !node.holds(x, tol) {
                continue;
            }
            match node.kids {
                Kids::Inner(left, right) => stack.extend([left, right]),
                Kids::Leaf => {
                    let on = |g: &PatchGeom| {
                        g.normal.dot(dir) < 0.0
                            && (g.normal.dot(x) - g.offset).abs() <= tol
                            && convex_holds(g.poly.verts(), g.normal, x, tol)
                    };
                    if self
                        .patches_under(id)
                        .iter()
                        .any(|&j| on(&geom[j as usize]))
                    {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Builds the node of `order[start..end]` and its subtree; returns its id.
    fn build(
        &mut self,
        geom: &[PatchGeom],
        kinds: &[u8],
        order: &mut [u32],
        start: usize,
        end: usize,
    ) -> u32 {
        let id = self.nodes.len() as u32;
        let patches = &mut order[start..end];
        let mut node = node_of(patches.iter().map(|&j| &geom[j as usize]));
        node.range = (start as u32, end as u32);
        for &j in patches.iter() {
            let g = &geom[j as usize];
            let products = second_products(g.centroid - node.mean);
            for (m, p) in node.second.iter_mut().zip(products) {
                *m += g.area * p;
            }
        }
        self.nodes.push(node);
        if patches.len() <= LEAF_PATCHES {
            patches.sort_unstable();
            return id;
        }
        let kind = |j: u32| kinds.get(j as usize).copied().unwrap_or(0);
        let first = kind(patches[0]);
        let mid = if patches.iter().any(|&j| kind(j) != first) {
            patches.sort_unstable_by_key(|&j| (kind(j), j));
            patches.partition_point(|&j| kind(j) == kind(patches[0]))
        } else {
            SplitKey::of(geom, patches, &node).partition(geom, patches)
        };
        let left = self.build(geom, kinds, order, start, start + mid);
        let right = self.build(geom, kinds, order, start + mid, end);
        self.nodes[id as usize].kids = Kids::Inner(left, right);
        id
    }

    /// Bounds on F⁰_ij over the patches j of node `id`, for row patch `i`.
    pub(crate) fn bound(&self, id: u32, i: &PatchBound) -> Bound {
        bound_of(self.node(id), i, self.plane_tol, self.slack)
    }

    /// The bound of one patch on its own (a node of one patch), for sampling inside a
    /// leaf.
    pub(crate) fn patch_bound(&self, g: &PatchGeom, i: &PatchBound) -> Bound {
        bound_of(&node_of(std::iter::once(g)), i, self.plane_tol, self.slack)
    }
}

/// The node of a set of patches (a leaf; its range left for the caller).
fn node_of<'a>(patches: impl Iterator<Item = &'a PatchGeom> + Clone) -> Node {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let (mut area_sum, mut area_max, mut count) = (0.0f64, 0.0f64, 0u32);
    let mut normals = DVec3::ZERO;
    let mut mean = DVec3::ZERO;
    let mut spots = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for g in patches.clone() {
        mean += g.centroid * g.area;
        spots = (spots.0.min(g.centroid), spots.1.max(g.centroid));
        for c in g.poly.verts() {
            lo = lo.min(*c);
            hi = hi.max(*c);
        }
        area_sum += g.area;
        area_max = area_max.max(g.area);
        normals += g.normal * g.area;
        count += 1;
    }
    // The axis: the area-weighted mean normal (any unit vector when they cancel).
    let axis = normals.try_normalize().unwrap_or(DVec3::Z);
    let spread = patches
        .map(|g| angle_between(axis, g.normal))
        .fold(0.0, f64::max);
    // Rounding of the angles (acos of a dot product near 1 is off by ~1e-8).
    let spread = if spread > 0.0 { spread + 1e-7 } else { 1e-7 };
    Node {
        lo,
        hi,
        centre: 0.5 * (lo + hi),
        radius: 0.5 * (hi - lo).length(),
        axis,
        spread: spread.min(PI),
        area_sum,
        area_max,
        mean: mean / area_sum,
        second: [0.0; 6],
        spots,
        count,
        range: (0, 0),
        kids: Kids::Leaf,
    }
}

/// What a node's patches are split by: a normal component when the cone is wide, else
/// a centroid coordinate (longest axis of the centroids' box).
#[derive(Clone, Copy)]
enum SplitKey {
    Normal(usize),
    Centroid(usize),
}

impl SplitKey {
    fn of(geom: &[PatchGeom], patches: &[u32], node: &Node) -> Self {
        let extent_of = |f: &dyn Fn(&PatchGeom) -> DVec3| {
            let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            for &j in patches {
                let v = f(&geom[j as usize]);
                lo = lo.min(v);
                hi = hi.max(v);
            }
            hi - lo
        };
        let longest = |e: DVec3| -> usize {
            if e.x >= e.y && e.x >= e.z {
                0
            } else if e.y >= e.z {
                1
            } else {
                2
            }
        };
        if node.spread > SPLIT_ON_NORMALS_ABOVE {
            SplitKey::Normal(longest(extent_of(&|g| g.normal)))
        } else {
            SplitKey::Centroid(longest(extent_of(&|g| g.centroid)))
        }
    }

    /// Puts the first half of `patches` first and returns where the second starts: for
    /// normals, those below the middle of the key's range (a median would cut a wall
    /// of 100 patches that shares a node with one of 50), for centroids the lower half
    /// by the key (ties by index). Either way the halves are sets fixed by the patches.
    fn partition(self, geom: &[PatchGeom], patches: &mut [u32]) -> usize {
        let key = |j: u32| self.of_patch(&geom[j as usize]);
        if let SplitKey::Normal(_) = self {
            let (lo, hi) = patches
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &j| {
                    (lo.min(key(j)), hi.max(key(j)))
                });
            let middle = 0.5 * (lo + hi);
            patches.sort_unstable_by(|&a, &b| {
                (key(a) >= middle).cmp(&(key(b) >= middle)).then(a.cmp(&b))
            });
            let mid = patches.partition_point(|&j| key(j) < middle);
            if mid > 0 && mid < patches.len() {
                return mid;
            }
        }
        let mid = patches.len() / 2;
        patches.select_nth_unstable_by(mid, |&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
        mid
    }

    fn of_patch(self, g: &PatchGeom) -> f64 {
        match self {
            SplitKey::Normal(axis) => g.normal[axis],
            SplitKey::Centroid(axis) => g.centroid[axis],
        }
    }
}

/// Angle between two unit vectors, in [0, π].
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    // atan2 of |a × b| and a · b is accurate near 0 and π, where acos is not.
    a.cross(b).length().atan2(a.dot(b))
}

/// The bounds of `node` for row patch `i` (module docs).
fn bound_of(node: &Node, i: &PatchBound, plane_tol: f64, slack: f64) -> Bound {
    // How far the box reaches in front of i's plane; no patch of a box within the
    // plane tolerance of it (or behind) is seen.
    let half = 0.5 * (node.hi - node.lo);
    let h = i.normal.dot(node.centre) + i.normal.abs().dot(half) - i.offset + slack;
    if h <= plane_tol {
        return Bound::ZERO;
    }
    // Distance from i's sphere to the box.
    let gap = (node.lo - i.centre)
        .max(i.centre - node.hi)
        .max(DVec3::ZERO);
    let d = gap.length() - i.radius;
    if d <= 0.0 {
        return Bound::OPEN;
    }
    // Directions from i's sphere into the node's sphere: a cone around u.
    let to = node.centre - i.centre;
    let dist = to.length();
    let reach = i.radius + node.radius;
    let (cos_i, cos_j) = if dist > reach {
        let u = to / dist;
        let beta = (reach / dist).asin();
        let theta_i = angle_between(i.normal, u);
        let theta_j = angle_between(node.axis, -u);
        (
            cos_above(theta_i - beta),
            cos_above(theta_j - node.spread - beta),
        )
    } else {
        (1.0, 1.0)
    };
    let cos_i = cos_i.min(h / d);
    let kernel = cos_i * cos_j / (PI * d * d);
    if kernel <= 0.0 {
        return Bound::ZERO;
    }
    let sum = (node.area_sum * kernel).min(node.count as f64) * MARGIN;
    let r = node.mean - i.centre;
    let r2 = r.length_squared();
    let at_mean =
        i.normal.dot(r).max(0.0) * (-node.axis.dot(r)).max(0.0) * node.area_sum / (PI * r2 * r2);
    Bound {
        max: (node.area_max * kernel).min(1.0) * MARGIN,
        sum,
        guess: at_mean.clamp(0.1 * sum, sum),
    }
}

/// The largest cosine of an angle at least `theta` (1 when theta ≤ 0, 0 past π/2).
fn cos_above(theta: f64) -> f64 {
    if theta <= 0.0 {
        1.0
    } else if theta >= 0.5 * PI {
        0.0
    } else {
        theta.cos()
    }
}

/// Second moments stored as (xx, yy, zz, xy, xz, yz) as the symmetric 3 × 3 matrix.
pub(crate) fn second_matrix(m: [f64; 6]) -> glam::DMat3 {
    glam::DMat3::from_cols_array(&[m[0], m[3], m[4], m[3], m[1], m[5], m[4], m[5], m[2]])
}

/// The products of r's components that second moments sum, in their stored order
/// (xx, yy, zz, xy, xz, yz).
pub(crate) fn second_products(r: DVec3) -> [f64; 6] {
    [
        r.x * r.x,
        r.y * r.y,
        r.z * r.z,
        r.x * r.y,
        r.x * r.z,
        r.y * r.z,
    ]
}

#[cfg(test)]
mod tests;
