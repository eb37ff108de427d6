//! The eight-wide hierarchy the [`Occluders`](super::occluders::Occluders) traverse, laid
//! out for SIMD, with its two walks: a shadow segment looking for any blocker
//! ([`Bvh8::any_hit`]) and the box of a pair query ([`Bvh8::for_each_in_box`]).
//!
//! Why not obvhs' own traversal: obvhs builds very good trees (PLOC, then an
//! SAH-optimal collapse to eight-wide nodes, Ylitie et al. 2017), but its compressed
//! nodes are made for GPUs: on a CPU one ray decodes the quantized box of one child at
//! a time. Here the topology of obvhs' tree is kept and laid out again, as Embree lays
//! out its BVH8 (Wald et al., "Embree: a kernel framework for efficient CPU ray
//! tracing", 2014):
//!
//! - a node holds the exact boxes of its eight children as six rows of eight f32 (all
//!   min x, all min y, ..., all max z), rounded outward and padded by [`BOX_PAD`], so a
//!   ray meets all eight children in six fused multiply-adds and four min/max of one
//!   AVX register each;
//! - the triangles are stored in the tree's primitive order, four to a [`Block`], as
//!   lanes of planes (the triangle's plane and its three edge planes). A leaf is a
//!   range of lanes: one of obvhs' leaves (at most three triangles, consecutive in
//!   that order), or a whole node of obvhs' tree whose children are all leaves with at
//!   most [`WIDE`] triangles together (the leaves of one node are next to each other),
//!   which spares every path one node level. Unused lanes pad the blocks so that a
//!   leaf of up to four triangles lies in one block and a larger one in two (on the
//!   94.5k-triangle room 8 % more lanes, block SAH 4.14 → 3.70, single rays 10 %
//!   faster; bench/PERF.md §12); queries name triangles by their index all the same. A
//!   conservative f32 test ([`Block::classify`]) sorts the lanes into triangles the
//!   segment misses for sure, crosses for sure, and may meet; the exact f64 test of the
//!   caller decides only the last kind. So answers are those of the exact test alone:
//!   the f32 parts have error allowances many times their rounding errors (worked out
//!   at [`Block::classify`]).
//!
//! A node's children sit in its slots by the number of triangles below them, most
//! first, and every walk visits the children a segment meets in slot order, as Embree
//! orders the children of its BVH8 for shadow rays: the child with most triangles is
//! the likeliest to hold a blocker, and a shadow segment stops at its first. Measured
//! against visiting the near children first (obvhs' slot assignment per ray octant),
//! single incoherent rays 22–35 % faster through 94.5k triangles and 13–15 % through
//! 9.5k, pair packets 17–24 % and 7–8 % (bench/PERF.md §13).
//!
//! The rays of one pair of patches can also walk together, sixteen to a
//! [`SegmentPacket`] ([`Bvh8::any_hit_packet`]): lanes are rays, each node is fetched
//! once and its eight boxes tested against all of them, each triangle is filtered
//! against all of them. A ray leaves the walk once a blocker is certain (at once for a
//! sure crossing, or when its put-off exact tests are run). Its answer is the one it
//! gets alone, since either walk visits every leaf the segment passes through
//! and answers are decided by the same filter and exact test. A packet can also be
//! tested against a pair's candidate list instead of the hierarchy
//! ([`Bvh8::any_hit_list`]): the same filter, triangle by triangle.
//!
//! Everything is in the normalized frame of the occluders (coordinates within ±0.5).

use glam::DVec3;
use obvhs::cwbvh::CwBvh;

use super::triangle::OccluderTriangle as Tri;

mod rays;
mod walk;

pub(crate) use rays::{SegmentPacket, SegmentRay, PACKET};

/// Padding of every box (normalized units, i.e. a fraction of the scene diagonal):
/// about 50 times the largest f32 rounding error of a slab test on the clipped
/// segments of [`SegmentRay`], so that no box a segment passes through is missed.
pub(crate) const BOX_PAD: f64 = 1e-5;

/// Error allowance of the f32 triangle filter ([`Block::classify`]), normalized units:
/// at least 50 times the f32 rounding of its inputs and products, plus
/// [`TRUST`] for the planes' own f64 error.
const FILTER_SLACK: f32 = 1e-5;

/// How far (normalized units) a triangle's vertices may sit off its f64 plane or
/// outside its f64 edge planes before the triangle is left to the exact test alone
/// (a lane of zeros, which [`Block::classify`] never decides). Thin slivers, whose cross
/// products lose digits, are the ones this catches.
const TRUST: f64 = 1e-7;

/// Child reference: a leaf when this bit is set; then bits 3–30 hold its first lane
/// position (see [`Bvh8::from_cwbvh`]) and bits 0–2 its triangle count minus one.
const LEAF_BIT: u32 = 1 << 31;
/// Child reference of an empty slot; face of an unused lane.
const NONE: u32 = u32::MAX;

/// The (first lane position, count) of a leaf reference.
#[inline(always)]
fn leaf_range(r: u32) -> (usize, usize) {
    (((r & !LEAF_BIT) >> 3) as usize, (r & 7) as usize + 1)
}

/// Triangles [`Bvh8::any_hit`] puts off before it runs their exact tests; entries
/// (triangle, lanes) for the packet walks (`walk::Pending`).
const DEFERRED: usize = 16;

/// Stack entries kept on the machine stack; deeper trees allocate one per walk.
const INLINE_STACK: usize = 128;

/// Eight children: their boxes as rows of lanes (min x, min y, min z, max x, max y,
/// max z), and what each slot holds. An empty slot has the box +∞..−∞, which no ray
/// or box meets.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Node {
    b: [[f32; 8]; 6],
    child: [u32; 8],
}

/// Four consecutive triangles, one per lane: rows 0–3 the plane (n, o) with n·x = o
/// on it, rows 4–15 the three edge planes (m, c) with m·x ≥ c inside the triangle (n,
/// m unit), and the scene face of each. An unused lane has n = 0, o = 1 (missed by
/// every segment); a lane of zeros is never decided ([`TRUST`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Block {
    p: [[f32; 4]; 16],
    face: [u32; 4],
}

/// The shape of a hierarchy, for benchmarks (bench/perf_rays.rs prints it; compare
/// Embree's own statistics, bench/embree/shadow.c with EMBREE_VERBOSE=1). The two
/// costs are the surface area heuristic's sums over the tree, with each box's area
/// relative to the root's: the nodes a random line through the root's box is expected
/// to test, and the four-triangle blocks it is expected to filter.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TreeStats {
    /// Nodes (eight-wide).
    pub nodes: usize,
    /// Leaves.
    pub leaves: usize,
    /// Levels of nodes on the longest path from the root.
    pub depth: usize,
    /// Blocks of four triangle lanes (272 bytes each), padding lanes included.
    pub blocks: usize,
    /// Σ over the nodes of area(node) / area(root): the root counts 1.
    pub node_sah: f64,
    /// Σ over the leaves of area(leaf) / area(root) × blocks the leaf spans.
    pub block_sah: f64,
}

/// The hierarchy: nodes, leaves and the root reference.
#[derive(Clone, Debug)]
pub(crate) struct Bvh8 {
    nodes: Vec<Node>,
    blocks: Vec<Block>,
    /// Per lane position: its triangle (index into the `tris` given to
    /// [`Bvh8::from_cwbvh`]), [`NONE`] for padding; and the position of each triangle.
    tri_at: Vec<u32>,
    pos_of: Vec<u32>,
    root: u32,
    /// Most stack entries a walk needs (7 per level below the root, plus one).
    stack_len: usize,
}

fn round_down(x: f64) -> f32 {
    let y = x as f32;
    if y as f64 > x {
        y.next_down()
    } else {
        y
    }
}

fn round_up(x: f64) -> f32 {
    let y = x as f32;
    if (y as f64) < x {
        y.next_up()
    } else {
        y
    }
}

/// The filter rows of one triangle ([`Block`]), or zeros when its f64 planes do not
/// hold its own vertices within [`TRUST`].
fn lane_rows(t: &Tri) -> [f32; 16] {
    let mut rows = [0f64; 16];
    let (n, v) = (t.normal, t.v);
    rows[..3].copy_from_slice(&n.to_array());
    rows[3] = t.offset;
    let mut trusted = v.iter().all(|p| (n.dot(*p) - t.offset).abs() <= TRUST);
    for k in 0..3 {
        let m = n.cross(v[(k + 1) % 3] - v[k]).normalize_or_zero();
        let c = m.dot(v[k]);
        trusted &= m != DVec3::ZERO && v.iter().all(|p| m.dot(*p) - c >= -TRUST);
        rows[4 + 4 * k..7 + 4 * k].copy_from_slice(&m.to_array());
        rows[7 + 4 * k] = c;
    }
    trusted &= rows.iter().all(|x| x.is_finite());
    if trusted {
        rows.map(|x| x as f32)
    } else {
        [0.0; 16]
    }
}

/// Node `i` of `cw` as one leaf, (first triangle, count), when all its children are
/// leaves that hold at most [`WIDE`] triangles together, in a row.
fn wide_leaf(cw: &CwBvh, i: usize) -> Option<(u32, u32)> {
    let src = &cw.nodes[i];
    let (mut ranges, mut n) = ([(0, 0); 8], 0);
    for s in 0..8 {
        if src.is_child_empty(s) {
            continue;
        }
        if !src.is_leaf(s) {
            return None;
        }
        ranges[n] = src.child_primitives(s);
        n += 1;
    }
    let ranges = &mut ranges[..n];
    ranges.sort_unstable();
    let start = ranges.first()?.0;
    let mut end = start;
    for &(a, n) in ranges.iter() {
        if a != end {
            return None;
        }
        end += n;
    }
    (end - start <= WIDE).then_some((start, end - start))
}

/// Most triangles of a leaf made of a whole node ([`wide_leaf`]). Measured (bench/PERF.md
/// §10): single rays through 94.5k triangles ~25 % faster, 9.5k and packets unchanged.
const WIDE: u32 = 8;

impl Bvh8 {
    /// Lays out `cw` (built over `tris`, which must be in `cw`'s primitive order, so
    /// that a leaf's triangles are `tris[start..start + count]`). `None` for an empty
    /// tree.
    ///
    /// # Panics
    /// With 2²⁸ lane positions or more, padding included (a leaf reference holds its
    /// first position in 28 bits); such a mesh would need some 25 GB or more for its
    /// f64 triangles alone.
    pub(crate) fn from_cwbvh(cw: &CwBvh, tris: &[Tri]) -> Option<Self> {
        assert!(
            tris.len() < 1 << 28,
            "{} occluder triangles: fewer than 2^28 are supported",
            tris.len()
        );
        if cw.nodes.is_empty() || tris.is_empty() {
            return None;
        }
        let mut b = Bvh8 {
            nodes: Vec::with_capacity(cw.nodes.len()),
            blocks: Vec::new(),
            tri_at: Vec::with_capacity(tris.len() + tris.len() / 4),
            pos_of: Vec::new(),
            root: 0,
            stack_len: 1,
        };
        let (_, depth, _) = b.lay_out(cw, 0, tris);
        b.stack_len = 7 * depth + 2;
        b.tri_at.resize(b.tri_at.len().next_multiple_of(4), NONE);
        assert!(
            b.tri_at.len() < 1 << 28,
            "{} occluder triangles take {} lane positions: fewer than 2^28 are supported",
            tris.len(),
            b.tri_at.len()
        );
        b.pos_of = vec![NONE; tris.len()];
        for (pos, &id) in b.tri_at.iter().enumerate() {
            if id != NONE {
                b.pos_of[id as usize] = pos as u32;
            }
        }
        b.blocks = b
            .tri_at
            .chunks(4)
            .map(|four| {
                let mut block = Block {
                    p: [[0.0; 4]; 16],
                    face: [NONE; 4],
                };
                block.p[3] = [1.0; 4];
                for (lane, &id) in four.iter().enumerate() {
                    let Some(t) = tris.get(id as usize) else {
                        continue;
                    };
                    for (row, x) in lane_rows(t).into_iter().enumerate() {
                        block.p[row][lane] = x;
                    }
                    block.face[lane] = t.face;
                }
                block
            })
            .collect();
        Some(b)
    }

    /// Gives the leaf of triangles `tris[start..start + count]` its lane positions, after
    /// padding that keeps it within one block (up to four triangles) or two: returns
    /// the first.
    fn place_leaf(&mut self, start: u32, count: u32) -> u32 {
        let off = self.tri_at.len() % 4;
        if off + count as usize > count.div_ceil(4) as usize * 4 {
            self.tri_at
                .resize(self.tri_at.len().next_multiple_of(4), NONE);
        }
        let first = self.tri_at.len() as u32;
        self.tri_at.extend(start..start + count);
        first
    }

    /// Lays out node `i` of `cw` and everything below it; returns its bounds (the
    /// union of its children's padded boxes), its height in levels and the number of
    /// triangles below it. Its children take its slots by that number, most first
    /// (ties in obvhs' slot order).
    fn lay_out(&mut self, cw: &CwBvh, i: usize, tris: &[Tri]) -> ((DVec3, DVec3), usize, u32) {
        let at = self.nodes.len();
        self.nodes.push(Node {
            b: [
                [f32::INFINITY; 8],
                [f32::INFINITY; 8],
                [f32::INFINITY; 8],
                [f32::NEG_INFINITY; 8],
                [f32::NEG_INFINITY; 8],
                [f32::NEG_INFINITY; 8],
            ],
            child: [NONE; 8],
        });
        let src = &cw.nodes[i];
        let mut height = 1;
        // (triangles below, reference, padded box) per child.
        let mut children = Vec::with_capacity(8);
        for s in 0..8 {
            if src.is_child_empty(s) {
                continue;
            }
            let wide = (!src.is_leaf(s))
                .then(|| wide_leaf(cw, src.child_node_index(s) as usize))
                .flatten();
            if src.is_leaf(s) || wide.is_some() {
                let (start, count) = wide.unwrap_or_else(|| src.child_primitives(s));
                debug_assert!((1..=8).contains(&count));
                let (mut blo, mut bhi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
                for t in &tris[start as usize..(start + count) as usize] {
                    blo = blo.min(t.min);
                    bhi = bhi.max(t.max);
                }
                let pad = DVec3::splat(BOX_PAD);
                let first = self.place_leaf(start, count);
                let reference = LEAF_BIT | first << 3 | (count - 1);
                children.push((count, reference, (blo - pad, bhi + pad)));
            } else {
                let index = self.nodes.len() as u32;
                let (bounds, h, below) = self.lay_out(cw, src.child_node_index(s) as usize, tris);
                height = height.max(h + 1);
                children.push((below, index, bounds));
            }
        }
        children.sort_by_key(|&(below, _, _)| std::cmp::Reverse(below));
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let node = &mut self.nodes[at];
        for (s, &(_, reference, (clo, chi))) in children.iter().enumerate() {
            let (flo, fhi) = (clo.to_array().map(round_down), chi.to_array().map(round_up));
            for k in 0..3 {
                node.b[k][s] = flo[k];
                node.b[k + 3][s] = fhi[k];
            }
            node.child[s] = reference;
            let (blo, bhi) = node.child_box(s);
            lo = lo.min(blo);
            hi = hi.max(bhi);
        }
        let below = children.iter().map(|&(below, _, _)| below).sum();
        ((lo, hi), height, below)
    }

    /// The shape of the hierarchy ([`TreeStats`]).
    pub(crate) fn stats(&self) -> TreeStats {
        let area = |(lo, hi): (DVec3, DVec3)| {
            let d = (hi - lo).max(DVec3::ZERO);
            2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
        };
        let root = &self.nodes[self.root as usize];
        let bounds = (0..8)
            .filter(|&s| root.child[s] != NONE)
            .map(|s| root.child_box(s))
            .fold(
                (DVec3::INFINITY, DVec3::NEG_INFINITY),
                |(lo, hi), (l, h)| (lo.min(l), hi.max(h)),
            );
        let whole = area(bounds);
        let mut st = TreeStats {
            blocks: self.blocks.len(),
            node_sah: 1.0,
            ..TreeStats::default()
        };
        let mut todo = vec![(self.root, 1)];
        while let Some((r, level)) = todo.pop() {
            st.nodes += 1;
            st.depth = st.depth.max(level);
            let node = &self.nodes[r as usize];
            for s in (0..8).filter(|&s| node.child[s] != NONE) {
                let (c, share) = (node.child[s], area(node.child_box(s)) / whole);
                if c & LEAF_BIT != 0 {
                    let (start, count) = leaf_range(c);
                    st.leaves += 1;
                    st.block_sah += share * (start % 4 + count).div_ceil(4) as f64;
                } else {
                    st.node_sah += share;
                    todo.push((c, level + 1));
                }
            }
        }
        st
    }

    /// Checks the layout (for tests): every triangle of `tris` sits in exactly one leaf
    /// lane, inside the boxes of its leaf and of every node above it; a leaf spans no
    /// more blocks than its size needs; padding lanes are missed; a node's children
    /// fill its first slots, by triangles below them, most first; the stack bound holds.
    #[cfg(test)]
    pub(crate) fn validate(&self, tris: &[Tri]) {
        let mut seen = vec![false; tris.len()];
        let mut levels = 0;
        let mut todo = vec![(self.root, DVec3::NEG_INFINITY, DVec3::INFINITY, 1usize)];
        while let Some((r, lo, hi, level)) = todo.pop() {
            levels = levels.max(level);
            if r & LEAF_BIT != 0 {
                let (start, count) = leaf_range(r);
                assert_eq!(
                    (start % 4 + count).div_ceil(4),
                    count.div_ceil(4),
                    "leaf at lane {start} spans a block more than it needs"
                );
                for pos in start..start + count {
                    let id = self.tri_at[pos] as usize;
                    assert_eq!(self.pos_of[id] as usize, pos);
                    assert!(!seen[id], "triangle {id} in two leaves");
                    seen[id] = true;
                    for p in tris[id].v {
                        assert!(
                            p.cmpge(lo).all() && p.cmple(hi).all(),
                            "triangle {id} outside its box"
                        );
                    }
                    let block = &self.blocks[pos / 4];
                    assert_eq!(block.face[pos % 4], tris[id].face);
                }
                continue;
            }
            let node = &self.nodes[r as usize];
            let used = node.child.iter().take_while(|&&c| c != NONE).count();
            assert!(
                node.child[used..].iter().all(|&c| c == NONE),
                "empty slot before a child"
            );
            let below: Vec<usize> = node.child[..used]
                .iter()
                .map(|&c| self.triangles_below(c))
                .collect();
            assert!(
                below.is_sorted_by(|a, b| a >= b),
                "children not in slots by triangles below them, most first: {below:?}"
            );
            for s in 0..used {
                let (clo, chi) = node.child_box(s);
                assert!(
                    clo.cmpge(lo).all() && chi.cmple(hi).all(),
                    "child box outside its parent"
                );
                todo.push((node.child[s], clo, chi, level + 1));
            }
        }
        assert!(seen.iter().all(|&s| s), "triangle missing from the leaves");
        assert_eq!(self.blocks.len() * 4, self.tri_at.len());
        for (pos, _) in self.tri_at.iter().enumerate().filter(|(_, &id)| id == NONE) {
            assert_eq!(
                self.blocks[pos / 4].p[3][pos % 4],
                1.0,
                "unused lane not missed"
            );
        }
        assert!(
            7 * levels + 2 <= self.stack_len + 7,
            "stack bound too small"
        );
    }

    /// The number of triangles below reference `r`.
    #[cfg(test)]
    fn triangles_below(&self, r: u32) -> usize {
        if r & LEAF_BIT != 0 {
            return leaf_range(r).1;
        }
        let node = &self.nodes[r as usize];
        node.child
            .iter()
            .filter(|&&c| c != NONE)
            .map(|&c| self.triangles_below(c))
            .sum()
    }
}
