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
//! 4. Hidden columns by the node. A patch that sees fewer than k others (a floor cell
//!    under a box, the ground under a building) never fills its kept set with positive
//!    values, so its floor stays 0 and step 1 would evaluate every column in front of
//!    it, each with rays, to find them all 0: at 1M patches in the 16-box room 1.75 %
//!    of the rows did 94 % of the evaluations (bench/PERF.md §23). A cell under a
//!    floating box is alike: it sees a few far walls, so its floor is tiny, and every
//!    column above the box has a larger F⁰ and gets rays. Once a row has found
//!    [`CULL_AFTER`] hidden columns, a hidden column that the row's blockers do not
//!    already explain teaches it the occluder polygons (a triangle, or two coplanar
//!    ones sharing an edge that make a convex quad) that hide the column whole: every
//!    segment from the row patch to the column crosses the polygon, with a margin of
//!    four times the rays' tolerance (`shadow::polygon_hides`; one lesson per leaf). The
//!    blockers may also close a convex cell around the row patch (a box over a floor
//!    cell: each face of the cell, but the one in the patch's own plane, lies within
//!    one blocker), and a segment from the patch to a point outside the cell leaves it
//!    through a blocker. A node that one blocker hides whole (the same test against the
//!    node's box), or whose box lies beyond a plane of the cell, is not opened. Its
//!    columns would all come out exactly 0, every ray blocked: they add nothing to the
//!    kept entries (the same, bit for bit) nor to the dropped mass. A row that never
//!    skips a node is the same row bit for bit; one that does may find fewer unopened
//!    nodes and tail columns for its sampled tail, whose estimate stays unbiased (what
//!    it leaves out holds nothing).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::DVec3;

use super::topk_bounded::{systematic, Kept};
use super::{between, RowEngine, Scratch};
use crate::formfactor::clip::{convex_holds, PolygonN};
use crate::formfactor::geom::{PatchBound, PatchGeom};
use crate::formfactor::sampling::SplitMix64;
use crate::formfactor::shadow::{polygon_hides, Caster};
use crate::formfactor::tree::{Kids, PatchTree};
use crate::rows::Row;

/// A tail of at most this many times `t` patches is evaluated in full rather than
/// sampled (a walk costs about as much as an evaluation, and small scenes, where the
/// tail is most of a short row, get the dense row's dropped mass).
const EXACT_TAIL_FACTOR: usize = 2;

/// Hidden columns a row finds before it looks for the polygons that hide them (step 4):
/// rows that see most of what lies in front of them rarely get here.
const CULL_AFTER: usize = 64;

/// Most blocker polygons a row keeps (step 4).
const MAX_BLOCKERS: usize = 32;

/// The occluder polygons that hide whole columns from a row's patch, and the cell they
/// may close around it (step 4).
#[derive(Debug, Default)]
pub(super) struct HiddenRow {
    blockers: Vec<Shade>,
    /// Candidate ids of a query.
    found: Vec<u32>,
    /// The row patch's enclosing cell, as half-spaces n · y ≤ o that hold the patch
    /// (empty: none known).
    cell: Vec<(DVec3, f64)>,
}

/// Most vertices of a face of an enclosing cell: a square cut by at most
/// [`MAX_BLOCKERS`] planes and the row patch's own.
type CellFace = PolygonN<{ MAX_BLOCKERS + 8 }>;

/// A convex occluder polygon: one occluder triangle, or two coplanar ones sharing an
/// edge whose union is convex (a box face cut along its diagonal hides what neither
/// half hides alone).
#[derive(Clone, Copy, Debug)]
struct Shade {
    /// The triangles' ids (the second = the first for a triangle).
    ids: [u32; 2],
    v: [DVec3; 4],
    len: usize,
    normal: DVec3,
    offset: f64,
}

impl Shade {
    fn triangle(id: u32, t: [DVec3; 3]) -> Option<Self> {
        let c = Caster::new(t)?;
        Some(Shade {
            ids: [id, id],
            v: [t[0], t[1], t[2], t[2]],
            len: 3,
            normal: c.normal,
            offset: c.offset,
        })
    }

    /// The quad of triangles `self` and `o` when they lie in one plane (within `tol`),
    /// share an edge and make a convex quadrilateral.
    fn join(&self, o: &Shade, tol: f64) -> Option<Shade> {
        if self.len != 3 || o.len != 3 || self.normal.dot(o.normal).abs() < 1.0 - 1e-12 {
            return None;
        }
        if o.v[..3]
            .iter()
            .any(|&y| (self.normal.dot(y) - self.offset).abs() > tol)
        {
            return None;
        }
        let same = |a: DVec3, b: DVec3| (a - b).length() <= tol;
        // The vertex of each triangle off the shared edge.
        let lone = |t: &Shade, other: &Shade| {
            let off: Vec<usize> = (0..3)
                .filter(|&k| !other.v[..3].iter().any(|&y| same(t.v[k], y)))
                .collect();
            (off.len() == 1).then(|| off[0])
        };
        let (a, b) = (lone(self, o)?, lone(o, self)?);
        let (u, w) = (self.v[a], o.v[b]);
        let (s1, s2) = (self.v[(a + 1) % 3], self.v[(a + 2) % 3]);
        let v = [u, s1, w, s2];
        let turn = |k: usize| {
            let (p, q, r) = (v[k], v[(k + 1) % 4], v[(k + 2) % 4]);
            self.normal.dot((q - p).cross(r - q))
        };
        let turns = [turn(0), turn(1), turn(2), turn(3)];
        let convex = turns.iter().all(|&t| t > 0.0) || turns.iter().all(|&t| t < 0.0);
        convex.then_some(Shade {
            ids: [self.ids[0], o.ids[0]],
            v,
            len: 4,
            normal: self.normal,
            offset: self.offset,
        })
    }

    fn hides(&self, p: &[DVec3], q: &[DVec3], tol: f64) -> bool {
        polygon_hides(p, q, &self.v[..self.len], self.normal, self.offset, tol)
    }

    /// Whether the points `q` of the polygon's plane lie in it (within `tol`).
    fn contains(&self, q: &[DVec3], tol: f64) -> bool {
        let v = &self.v[..self.len];
        let turn: f64 = (0..v.len())
            .map(|k| self.normal.dot(v[k].cross(v[(k + 1) % v.len()])))
            .sum();
        let normal = turn.signum() * self.normal;
        q.iter().all(|&y| convex_holds(v, normal, y, tol))
    }
}

/// A tail item of the estimate: an evaluated column that needs rays, or an unopened
/// node.
#[derive(Clone, Copy, Debug)]
pub(super) enum Tail {
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
        kept: Kept,
        t: usize,
        scratch: &mut Scratch,
    ) -> Row {
        scratch.start_row(i);
        let links = self.cfg.links.map(|m| m as usize);
        let mut kept = match links {
            Some(_) => kept.recording(),
            None => kept,
        };
        // With links: the tail columns that need no visibility, with their values.
        let mut exact_columns: Vec<(u32, f64)> = Vec::new();
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
        // Step 4: the hidden columns found so far, and the row's blockers.
        let mut hidden = 0usize;
        let ready = |hidden: usize| self.cull_hidden && hidden >= CULL_AFTER;
        scratch.hidden.blockers.clear();
        scratch.hidden.cell.clear();
        while let Some(&(bits, Reverse(id))) = open.peek() {
            if f64::from_bits(bits) < kept.floor() {
                break;
            }
            open.pop();
            if ready(hidden) && self.node_hidden(i, &tree.node(id).corners(), scratch) {
                scratch.pair.counters.tree_nodes_hidden += 1;
                continue;
            }
            scratch.pair.counters.tree_nodes_opened += 1;
            match tree.node(id).kids {
                Kids::Inner(left, right) => {
                    push(&mut open, left);
                    push(&mut open, right);
                }
                Kids::Leaf => {
                    let mut learnt = false;
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
                                if links.is_some() {
                                    exact_columns.push((j, u.f));
                                }
                            }
                            continue;
                        }
                        let value = self.candidate_value(i, j, u.f, u.needs_rays, scratch);
                        if value == 0.0 && u.needs_rays {
                            hidden += 1;
                            // One lesson per leaf: its columns lie close together.
                            if ready(hidden) && !learnt {
                                learnt = self.learn_blockers(i, j, scratch);
                            }
                        }
                        kept.offer(j, value);
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
        let known = kept.known_mass() + exact_tail;
        if let Some(max) = links {
            let mut exact = kept.out.take().unwrap_or_default();
            exact.extend(exact_columns);
            let stored = kept.columns();
            let (links, spread) = self.row_links(
                tree, i, &row, t, max, known, &stored, &exact, &tail, scratch,
            );
            let mut out = kept.into_linked_row(i, 0.0, links);
            if !out.links.is_empty() {
                let (gather, mass) = self.kept_bounce(&out);
                out.link_error = spread.error(gather, mass);
            }
            return out;
        }
        let tail_mass = exact_tail + self.tree_tail_mass(tree, i, &row, t, &tail, known, scratch);
        kept.into_row(i, tail_mass)
    }

    /// Step 4: whether the box with corners `q` is hidden whole from row patch i: one
    /// blocker hides it, or it lies outside the patch's enclosing cell.
    fn node_hidden(&self, i: u32, q: &[DVec3; 8], scratch: &Scratch) -> bool {
        let m = self.hide_margin;
        let outside = |&(n, o): &(DVec3, f64)| q.iter().all(|&y| n.dot(y) - o > m);
        scratch.hidden.cell.iter().any(outside) || self.hidden_from(i, q, scratch)
    }

    /// Step 4: the convex cell around row patch i whose faces, all but the one in the
    /// patch's own plane, each lie within one blocker (empty when the blockers do not
    /// close one). The patch lies inside every plane of the cell by the margin. A
    /// segment from the patch to a point y outside the cell leaves it through a face
    /// (not the patch's own plane: y is in front of it, or its column is 0 anyway),
    /// so it crosses the blocker holding that face; when y is beyond one of the cell's
    /// planes by the margin, it is that far from the crossing.
    fn enclosing_cell(&self, i: u32, blockers: &[Shade]) -> Vec<(DVec3, f64)> {
        let g = &self.geom[i as usize];
        let (p, m) = (g.poly.verts(), self.hide_margin);
        let same_plane = |b: &Shade, n: DVec3, o: f64| {
            b.normal.dot(n).abs() > 1.0 - 1e-12
                && (b.normal.dot(n) * b.offset - o).abs() <= self.tol
        };
        // Each blocker's plane once, turned so the patch lies inside by the margin. (A
        // plane twice would cut its own face away and pass for redundant.)
        let mut planes: Vec<(DVec3, f64, usize)> = Vec::new();
        for (k, b) in blockers.iter().enumerate() {
            let d: Vec<f64> = p.iter().map(|&x| b.normal.dot(x) - b.offset).collect();
            let turned = if d.iter().all(|&d| d < -m) {
                (b.normal, b.offset, k)
            } else if d.iter().all(|&d| d > m) {
                (-b.normal, -b.offset, k)
            } else {
                continue;
            };
            if !planes.iter().any(|&(n, o, _)| same_plane(b, n, o)) {
                planes.push(turned);
            }
        }
        // Drop planes whose face no blocker holds until every face is held.
        'cells: loop {
            for (k, &(n, o, _)) in planes.iter().enumerate() {
                let face = self.cell_face(g, &planes, k);
                if face.n < 3 {
                    continue;
                }
                let held = blockers
                    .iter()
                    .any(|b| same_plane(b, n, o) && b.contains(face.verts(), self.tol));
                if !held {
                    planes.remove(k);
                    continue 'cells;
                }
            }
            return planes.into_iter().map(|(n, o, _)| (n, o)).collect();
        }
    }

    /// The face of the cell `planes` in plane k: a square far larger than the scene
    /// in that plane, cut by the other planes and by the front of row patch `g`'s plane.
    fn cell_face(&self, g: &PatchGeom, planes: &[(DVec3, f64, usize)], k: usize) -> CellFace {
        let (n, o, _) = planes[k];
        let centre = g.centroid - n * (n.dot(g.centroid) - o);
        let u = n.any_orthonormal_vector();
        let (u, v) = (u * self.span * 4.0, n.cross(u) * self.span * 4.0);
        let mut face = CellFace::new(&[
            centre - u - v,
            centre + u - v,
            centre + u + v,
            centre - u + v,
        ]);
        let mut cut = CellFace::EMPTY;
        for (l, &(nl, ol, _)) in planes.iter().enumerate() {
            if l != k {
                face.clip_front_into(-nl, -ol, 0.0, &mut cut);
                std::mem::swap(&mut face, &mut cut);
            }
        }
        face.clip_front_into(g.normal, g.offset, 0.0, &mut cut);
        cut
    }

    /// Step 4: whether one of the row's blockers hides the points `q` (a column's
    /// corners, a node's box) whole from row patch i.
    fn hidden_from(&self, i: u32, q: &[DVec3], scratch: &Scratch) -> bool {
        let p = self.geom[i as usize].poly.verts();
        scratch
            .hidden
            .blockers
            .iter()
            .any(|b| b.hides(p, q, self.hide_margin))
    }

    /// Step 4: column j came out hidden from row i. Unless a blocker of the row already
    /// hides it whole, the occluder triangles that may come between the two patches
    /// are asked, and those that hide it whole become blockers of the row. True when
    /// the occluders were asked.
    fn learn_blockers(&self, i: u32, j: u32, scratch: &mut Scratch) -> bool {
        let (gi, gj) = (&self.geom[i as usize], &self.geom[j as usize]);
        if scratch.hidden.blockers.len() >= MAX_BLOCKERS
            || self.hidden_from(i, gj.poly.verts(), scratch)
        {
            return false;
        }
        let before = scratch.hidden.blockers.len();
        let q = between(gi, gj, &gi.poly, &gj.poly);
        let mut found = std::mem::take(&mut scratch.hidden.found);
        self.occluders
            .collect_between_up_to(&q, MAX_BLOCKERS, 2 * MAX_BLOCKERS, &mut found);
        let shades: Vec<Shade> = found
            .iter()
            .filter_map(|&k| Shade::triangle(k, self.occluders.world_triangle(k)))
            .collect();
        // Quads first: a triangle of a quad that hides adds nothing.
        let mut fresh: Vec<Shade> = Vec::new();
        for (a, s) in shades.iter().enumerate() {
            for t in &shades[a + 1..] {
                if let Some(quad) = s.join(t, self.tol) {
                    fresh.push(quad);
                }
            }
        }
        fresh.extend(shades);
        let (pi, pj) = (gi.poly.verts(), gj.poly.verts());
        for shade in fresh {
            let h = &mut scratch.hidden;
            let known = |b: &Shade| shade.ids.iter().all(|id| b.ids.contains(id));
            if h.blockers.len() >= MAX_BLOCKERS || h.blockers.iter().any(known) {
                continue;
            }
            if shade.hides(pi, pj, self.hide_margin) {
                h.blockers.push(shade);
            }
        }
        scratch.hidden.found = found;
        if scratch.hidden.blockers.len() > before {
            scratch.hidden.cell = self.enclosing_cell(i, &scratch.hidden.blockers);
        }
        true
    }

    /// Step 3: the mass of the tail items (module docs): exact when they hold at most
    /// [`EXACT_TAIL_FACTOR`] · `t` patches; else the row total from `t` hemisphere rays
    /// less the `known` mass (kept entries, pushed out, exact tail), when the occluders
    /// are the patches' own surfaces (`closure.rs`); else sampled from `t` points.
    #[allow(clippy::too_many_arguments)]
    fn tree_tail_mass(
        &self,
        tree: &PatchTree,
        i: u32,
        row: &PatchBound,
        t: usize,
        tail: &[Tail],
        known: f64,
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
        if let Some((total, _)) = self.closure_total(tree, i, t, scratch) {
            return (total - known).max(0.0);
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
    pub(super) fn node_sample(
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
