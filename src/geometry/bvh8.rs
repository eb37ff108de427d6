//! The eight-wide hierarchy the [`Occluders`](super::bvh::Occluders) traverse, laid
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

use glam::{DVec3, Vec3A};
use obvhs::cwbvh::CwBvh;

use super::bvh::OccluderTriangle as Tri;
use wide::{f32x16 as Lanes16, f32x4, f32x8};

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

/// Segments are clipped to the box ±`CLIP` (the triangles lie within ±0.5) before
/// their f32 set-up, which bounds the coordinates, and so the rounding errors, of
/// every traversal.
const CLIP: f64 = 1.0;

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
/// (triangle, lanes) for the packet walks ([`Pending`]).
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

/// A shadow segment prepared for the traversal, f32: its end points (clipped to
/// ±[`CLIP`]) for the triangle filter, and its inverse direction with origin ×
/// inverse direction for the slab tests (t ∈ [0, 1] over the clipped segment).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SegmentRay {
    p0: [f32; 3],
    p1: [f32; 3],
    inv: [f32; 3],
    oi: [f32; 3],
}

impl SegmentRay {
    /// The segment from `f` to `f + d` (normalized frame), clipped to ±[`CLIP`];
    /// `None` when nothing of it lies in that box (then no triangle can meet it).
    pub(crate) fn new(f: DVec3, d: DVec3) -> Option<Self> {
        let [p0, p1, dd] = clipped_f32(f, d)?;
        let inv = inverse(Vec3A::from_array(dd));
        Some(SegmentRay {
            p0,
            p1,
            inv: inv.to_array(),
            oi: (Vec3A::from_array(p0) * inv).to_array(),
        })
    }
}

/// [`clip`] in f32: the clipped start, end, and end − start (taken in f64).
#[inline(always)]
fn clipped_f32(f: DVec3, d: DVec3) -> Option<[[f32; 3]; 3]> {
    let (p0, p1) = clip(f, d)?;
    Some([p0, p1, p1 - p0].map(|p| p.as_vec3().to_array()))
}

/// The end points of the segment from `f` to `f + d` clipped to ±[`CLIP`] (the
/// segment itself when it lies inside); `None` when nothing of it is inside.
#[inline(always)]
fn clip(f: DVec3, d: DVec3) -> Option<(DVec3, DVec3)> {
    let (mut a, mut b) = (0.0f64, 1.0f64);
    if f.abs().max_element() > CLIP || (f + d).abs().max_element() > CLIP {
        for k in 0..3 {
            if d[k] == 0.0 {
                if f[k].abs() > CLIP {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d[k];
            let (t0, t1) = ((-CLIP - f[k]) * inv, (CLIP - f[k]) * inv);
            a = a.max(t0.min(t1));
            b = b.min(t0.max(t1));
        }
        if a.is_nan() || b.is_nan() || a > b {
            return None;
        }
    }
    Some((f + d * a, f + d * b))
}

/// 1/dd per component; a zero (or vanishing) component gets a large finite inverse
/// of the same sign instead, which keeps the slab products free of ∞ − ∞.
#[inline(always)]
fn inverse(dd: Vec3A) -> Vec3A {
    let i = Vec3A::ONE / dd;
    let big = Vec3A::splat(INV_MAX).copysign(dd);
    Vec3A::select(i.abs().cmplt(Vec3A::splat(INV_MAX)), i, big)
}

/// Largest inverse direction component (see [`inverse`]).
const INV_MAX: f32 = 1e30;

/// Slab parameters the boxes must overlap: a little beyond [0, 1], since the boxes
/// are padded ([`BOX_PAD`]) and the segment's ends may lie on them.
const T_MIN: f32 = -1e-3;
const T_MAX: f32 = 1.0 + 1e-3;

/// One [`SegmentRay`] as lanes: its slab terms over the eight children of a node,
/// its end points over the four triangles of a block.
struct RayLanes {
    inv: [f32x8; 3],
    oi: [f32x8; 3],
    /// Row of [`Node::b`] holding the near / far side of the boxes along each axis.
    near: [usize; 3],
    far: [usize; 3],
    p0: [f32x4; 3],
    p1: [f32x4; 3],
}

impl RayLanes {
    fn new(r: &SegmentRay) -> Self {
        let near = [0, 1, 2].map(|k| if r.inv[k] >= 0.0 { k } else { k + 3 });
        RayLanes {
            inv: r.inv.map(f32x8::splat),
            oi: r.oi.map(f32x8::splat),
            near,
            far: near.map(|row| (row + 3) % 6),
            p0: r.p0.map(f32x4::splat),
            p1: r.p1.map(f32x4::splat),
        }
    }
}

/// Most segments a [`SegmentPacket`] holds, one per lane of its vectors (sixteen
/// f32: two AVX registers, or one AVX-512 register when built for it).
pub(crate) const PACKET: usize = 16;

/// Up to [`PACKET`] shadow segments walked together ([`Bvh8::any_hit_packet`]), one
/// per lane: the rays of one pair of patches start and end close to each other, so
/// they pass through mostly the same nodes, and a node is then fetched and tested once
/// for all of them, with no chain of dependent steps per ray.
pub(crate) struct SegmentPacket {
    inv: [Lanes16; 3],
    oi: [Lanes16; 3],
    p0: [Lanes16; 3],
    p1: [Lanes16; 3],
    /// Lanes that hold a segment.
    lanes: u32,
}

impl SegmentPacket {
    /// The segments from `f` to `f + d` (normalized frame), in lanes `0..ends.len()`;
    /// the set-up of [`SegmentRay::new`] for all of them at once. A segment with
    /// nothing inside ±[`CLIP`] leaves its lane empty (never blocked).
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    pub(crate) fn new(ends: &[(DVec3, DVec3)]) -> Self {
        assert!(ends.len() <= PACKET, "{} segments in a packet", ends.len());
        // p0, p1, p1 − p0; per axis; per lane.
        let mut v = [[[0f32; PACKET]; 3]; 3];
        let mut lanes = 0;
        for (l, &(f, d)) in ends.iter().enumerate() {
            let Some(ends) = clipped_f32(f, d) else {
                continue;
            };
            lanes |= 1 << l;
            for (rows, x) in v.iter_mut().zip(ends) {
                for k in 0..3 {
                    rows[k][l] = x[k];
                }
            }
        }
        let [p0, p1, dd] = v.map(|rows| rows.map(Lanes16::from));
        // `inverse`, lane by lane (an empty lane has dd = 0, so 1e30; whatever it
        // meets is masked out by `lanes`).
        let inv = dd.map(|dd| {
            let i = Lanes16::ONE / dd;
            let keep = i.abs().simd_lt(Lanes16::splat(INV_MAX));
            let big = (dd & Lanes16::splat(-0.0)) | Lanes16::splat(INV_MAX);
            (keep & i) | (!keep & big)
        });
        SegmentPacket {
            inv,
            oi: [0, 1, 2].map(|k| p0[k] * inv[k]),
            p0,
            p1,
            lanes,
        }
    }
}

/// The slots of `mask` in the order a walk pushes them: the last first, so that the
/// first (the child with most triangles) is popped next.
#[inline(always)]
fn last_first(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let s = 31 - mask.leading_zeros();
            mask &= !(1 << s);
            s as usize
        })
    })
}

impl Node {
    #[inline(always)]
    fn row(&self, r: usize) -> f32x8 {
        f32x8::from(self.b[r])
    }

    /// Slots whose (padded) box the ray's parameter range [tmin, tmax] passes through.
    #[inline(always)]
    fn hit(&self, r: &RayLanes) -> u32 {
        let slab = |k: usize, row: usize| self.row(row).mul_sub(r.inv[k], r.oi[k]);
        let t_near = slab(0, r.near[0])
            .fast_max(slab(1, r.near[1]))
            .fast_max(slab(2, r.near[2]).fast_max(f32x8::splat(T_MIN)));
        let t_far = slab(0, r.far[0])
            .fast_min(slab(1, r.far[1]))
            .fast_min(slab(2, r.far[2]).fast_min(f32x8::splat(T_MAX)));
        t_near.simd_le(t_far).to_bitmask()
    }

    /// For each slot, the lanes of `pk` whose segment passes through its (padded)
    /// box, as [`Node::hit`] finds for each segment alone (the same slab values; the
    /// near and far sides picked per lane by min and max). Empty slots: 0.
    #[inline(always)]
    fn hit_packet(&self, pk: &SegmentPacket) -> [u32; 8] {
        let mut lanes = [0; 8];
        for (s, out) in lanes.iter_mut().enumerate() {
            if self.child[s] == NONE {
                continue;
            }
            let slab =
                |row: usize, k: usize| Lanes16::splat(self.b[row][s]).mul_sub(pk.inv[k], pk.oi[k]);
            let (a0, b0) = (slab(0, 0), slab(3, 0));
            let (a1, b1) = (slab(1, 1), slab(4, 1));
            let (a2, b2) = (slab(2, 2), slab(5, 2));
            let t_near = a0
                .fast_min(b0)
                .fast_max(a1.fast_min(b1))
                .fast_max(a2.fast_min(b2).fast_max(Lanes16::splat(T_MIN)));
            let t_far = a0
                .fast_max(b0)
                .fast_min(a1.fast_max(b1))
                .fast_min(a2.fast_max(b2).fast_min(Lanes16::splat(T_MAX)));
            *out = t_near.simd_le(t_far).to_bitmask();
        }
        lanes
    }

    /// Slots whose box overlaps the box [lo, hi].
    #[inline(always)]
    fn overlap(&self, lo: &[f32x8; 3], hi: &[f32x8; 3]) -> u32 {
        let axis = |k: usize| self.row(k).simd_le(hi[k]) & self.row(k + 3).simd_ge(lo[k]);
        (axis(0) & axis(1) & axis(2)).to_bitmask()
    }

    fn child_box(&self, s: usize) -> (DVec3, DVec3) {
        let v = |r: usize| self.b[r][s] as f64;
        (DVec3::new(v(0), v(1), v(2)), DVec3::new(v(3), v(4), v(5)))
    }
}

/// The triangle filter of [`Block::classify`] over lanes of type `$v` (f32x4: four
/// triangles and one segment; [`Lanes16`]: one triangle and sixteen segments): `$row(k)` is
/// filter row k of the triangles, `$p0`, `$p1` the end points of the segments, as
/// lanes. Gives (sure, maybe) lane masks.
macro_rules! filter {
    ($v:ident, $row:expr, $p0:expr, $p1:expr) => {{
        let row = $row;
        let (p0, p1): (&[$v; 3], &[$v; 3]) = ($p0, $p1);
        let slack = $v::splat(FILTER_SLACK);
        let plane = |k: usize, p: &[$v; 3]| {
            row(k).mul_add(
                p[0],
                row(k + 1).mul_add(p[1], row(k + 2).mul_sub(p[2], row(k + 3))),
            )
        };
        'filter: {
            let (d0, d1) = (plane(0, p0), plane(0, p1));
            let (above0, below0) = (d0.simd_gt(slack), d0.simd_lt(-slack));
            let (above1, below1) = (d1.simd_gt(slack), d1.simd_lt(-slack));
            let mut live = !((above0 & above1) | (below0 & below1));
            if live.to_bitmask() == 0 {
                break 'filter (0, 0);
            }
            let mut inside = (above0 & below1) | (below0 & above1);
            let sigma = d0 - d1;
            let flat = sigma.abs().simd_le(slack * $v::splat(4.0));
            // The sign bit of σ, to turn N_k into sign(σ)·N_k.
            let sign = sigma & $v::splat(-0.0);
            let dsum = d0.abs() + d1.abs();
            for k in [4, 8, 12] {
                let (e0, e1) = (plane(k, p0), plane(k, p1));
                let n = d0.mul_sub(e1, d1 * e0) ^ sign;
                let bound = slack.mul_add(dsum + e0.abs() + e1.abs(), slack * slack);
                live &= flat | n.simd_ge(-bound);
                inside &= n.simd_gt(bound);
            }
            let sure = inside.to_bitmask();
            (sure, live.to_bitmask() & !sure)
        }
    }};
}

impl Block {
    /// Sorts the lanes by what the segment p0 → p1 does to their triangle: (`sure`,
    /// `maybe`), the lanes it certainly crosses in their interior, away from both end
    /// points, and those it may meet; it misses the other lanes for sure.
    ///
    /// With D = n·x − o (signed distance to the plane) and E_k = m_k·x − c_k (to edge
    /// plane k) at the two end points, the segment crosses the plane at
    /// x = (D0 p1 − D1 p0)/(D0 − D1), where E_k(x) = N_k/σ with N_k = D0 E_k(p1) −
    /// D1 E_k(p0) and σ = D0 − D1 (no division needed). With the slack δ and
    /// B_k = δ·(|D0| + |D1| + |E_k(p0)| + |E_k(p1)|) + δ², a lane is
    /// - missed when both end points lie beyond δ on the same side of the plane, or
    ///   σ is clear of zero (|σ| > 4δ) and sign(σ)·N_k < −B_k for some edge k;
    /// - certainly crossed when the end points lie beyond δ on opposite sides and
    ///   sign(σ)·N_k > B_k for every edge k. The crossing is then more than δ (more
    ///   than [`super::bvh::RAY_EPSILON`]) from either end point along the segment,
    ///   so the exact test would count it.
    ///
    /// B_k covers the f32 errors of the four factors (each at most a few 1e-7 for
    /// coordinates within ±[`CLIP`]) and the triangle's own thickness ([`TRUST`]): a
    /// point of the segment within that thickness of the plane lies where |D| ≤ η, and
    /// there σ·E_k = N_k ∓ η (E_k(p1) − E_k(p0)), which B_k bounds. Segments in (or
    /// nearly in) the plane (|σ| ≤ 4δ) are never missed by the edges.
    #[inline(always)]
    fn classify(&self, r: &RayLanes) -> (u32, u32) {
        filter!(f32x4, |k: usize| f32x4::from(self.p[k]), &r.p0, &r.p1)
    }

    /// [`Block::classify`] of the triangle in `lane` for each segment of a packet:
    /// (`sure`, `maybe`) as masks of the packet's lanes.
    #[inline(always)]
    fn classify_packet(&self, lane: usize, pk: &SegmentPacket) -> (u32, u32) {
        filter!(
            Lanes16,
            |k: usize| Lanes16::splat(self.p[k][lane]),
            &pk.p0,
            &pk.p1
        )
    }
}

/// The put-off exact tests of a packet walk: (triangle, lanes that may meet it).
struct Pending {
    later: [(u32, u32); DEFERRED],
    len: usize,
}

impl Pending {
    fn new() -> Self {
        Pending {
            later: [(0, 0); DEFERRED],
            len: 0,
        }
    }

    /// Filters triangle `id` of `blocks` for the segments of `pk` in `lanes` that are
    /// still `open`: the lanes it certainly blocks (when `trust_sure`) leave `open` and
    /// are returned; those it may block are put off, their exact tests run when the
    /// list is full or at [`Pending::settle`].
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn filter(
        &mut self,
        blocks: &[Block],
        id: usize,
        pk: &SegmentPacket,
        lanes: u32,
        trust_sure: bool,
        open: &mut u32,
        exact: &mut impl FnMut(usize, usize) -> bool,
    ) -> u32 {
        let (sure, maybe) = blocks[id / 4].classify_packet(id % 4, pk);
        let lanes = lanes & *open;
        let (mut sure, mut maybe) = (sure & lanes, maybe & lanes);
        if !trust_sure {
            maybe |= sure;
            sure = 0;
        }
        *open &= !sure;
        if maybe != 0 {
            if self.len == DEFERRED {
                self.settle(open, exact);
            }
            self.later[self.len] = (id as u32, maybe);
            self.len += 1;
        }
        sure
    }

    /// Runs the put-off exact tests for the lanes still `open`; a lane leaves `open`
    /// at its first hit.
    fn settle(&mut self, open: &mut u32, exact: &mut impl FnMut(usize, usize) -> bool) {
        for &(id, lanes) in &self.later[..self.len] {
            let mut m = lanes & *open;
            while m != 0 {
                let lane = m.trailing_zeros() as usize;
                m &= m - 1;
                if exact(lane, id as usize) {
                    *open &= !(1 << lane);
                }
            }
        }
        self.len = 0;
    }
}

/// The child references still to visit in a walk ([`Bvh8::walk`]); sized by the
/// tree's depth.
struct Stack<'a> {
    items: &'a mut [u32],
    len: usize,
}

impl Stack<'_> {
    #[inline(always)]
    fn push(&mut self, r: u32) {
        self.items[self.len] = r;
        self.len += 1;
    }
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

    /// Asks the cache for the first line of child `c` (a hint: nothing else).
    #[inline(always)]
    fn prefetch(&self, c: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let p = if c & LEAF_BIT != 0 {
                self.blocks.as_ptr().wrapping_add(leaf_range(c).0 / 4) as *const i8
            } else {
                self.nodes.as_ptr().wrapping_add(c as usize) as *const i8
            };
            // SAFETY: a prefetch reads nothing and cannot fault, whatever the address
            // (and this one lies within `blocks` or `nodes`).
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p) };
        }
    }

    /// Depth-first walk from the root: `leaf(first lane position, count)` for every leaf
    /// popped (true: stop, and the walk returns true), `node` for every node popped,
    /// which pushes the children to visit (the last pushed is popped first).
    #[inline(always)]
    fn walk(
        &self,
        mut leaf: impl FnMut(usize, usize) -> bool,
        mut node: impl FnMut(&Node, &mut Stack<'_>),
    ) -> bool {
        let mut run = |items: &mut [u32]| {
            let mut stack = Stack { items, len: 0 };
            stack.push(self.root);
            while stack.len > 0 {
                stack.len -= 1;
                let r = stack.items[stack.len];
                if r & LEAF_BIT != 0 {
                    let (start, count) = leaf_range(r);
                    if leaf(start, count) {
                        return true;
                    }
                } else {
                    node(&self.nodes[r as usize], &mut stack);
                }
            }
            false
        };
        // Two calls of `run`, each with a stack of fixed length: one slice of either
        // length, as `any_hit_packet` takes, cost this walk 2.4 % more instructions
        // (callgrind on perf_rays), and this form cost the packet walk 3.6 % more.
        if self.stack_len <= INLINE_STACK {
            run(&mut [0u32; INLINE_STACK])
        } else {
            run(&mut vec![0u32; self.stack_len])
        }
    }

    /// Whether a triangle of a face other than `ignore` blocks the segment `ray`.
    /// Triangles the segment certainly crosses ([`Block::classify`]) block when
    /// `trust_sure` (for foreign occluders the caller has more to check); for the
    /// triangles it may meet, `exact` (given the triangle's id) decides. Those are
    /// put off until the walk has found no certain blocker: an occluded segment
    /// usually has one, and then never reads the f64 triangles. Near children are
    /// visited first.
    #[inline(always)]
    pub(crate) fn any_hit(
        &self,
        ray: &SegmentRay,
        ignore: (u32, u32),
        trust_sure: bool,
        mut exact: impl FnMut(usize) -> bool,
    ) -> bool {
        let ray = &RayLanes::new(ray);
        let counts = |face: u32| face != ignore.0 && face != ignore.1;
        let mut later = [0u32; DEFERRED];
        let mut n_later = 0;
        let found = self.walk(
            |start, count| {
                // The leaf's lanes, in one block or two (`place_leaf`).
                let (first, lanes) = (start / 4, ((1u32 << count) - 1) << (start % 4));
                for (k, mask) in [
                    (first, lanes & 0xf),
                    (first + 1, (lanes >> 4) & 0xf),
                    (first + 2, lanes >> 8),
                ] {
                    if mask == 0 {
                        continue;
                    }
                    let block = &self.blocks[k];
                    let (sure, maybe) = block.classify(ray);
                    let (mut sure, mut maybe) = (sure & mask, maybe & mask);
                    if !trust_sure {
                        maybe |= sure;
                        sure = 0;
                    }
                    while sure != 0 {
                        let lane = sure.trailing_zeros() as usize;
                        sure &= sure - 1;
                        if counts(block.face[lane]) {
                            return true;
                        }
                    }
                    while maybe != 0 {
                        let lane = maybe.trailing_zeros() as usize;
                        maybe &= maybe - 1;
                        if !counts(block.face[lane]) {
                            continue;
                        }
                        if n_later == DEFERRED {
                            if later
                                .iter()
                                .any(|&p| exact(self.tri_at[p as usize] as usize))
                            {
                                return true;
                            }
                            n_later = 0;
                        }
                        later[n_later] = (4 * k + lane) as u32;
                        n_later += 1;
                    }
                }
                false
            },
            |node, stack| {
                for s in last_first(node.hit(ray)) {
                    self.prefetch(node.child[s]);
                    stack.push(node.child[s]);
                }
            },
        );
        found
            || later[..n_later]
                .iter()
                .any(|&p| exact(self.tri_at[p as usize] as usize))
    }

    /// [`Bvh8::any_hit`] for the segments of a packet: the lanes blocked by a triangle
    /// of a face other than `ignore`; `exact(lane, id)` is the exact test of triangle
    /// `id` for the segment in `lane`. Each lane gets the answer it gets alone.
    ///
    /// The walk keeps, with every node or leaf to visit, the lanes whose segments pass
    /// through its box; a lane leaves the walk once a blocker is certain (a sure
    /// crossing, or a put-off exact test that hits), and the walk stops when no lane
    /// is left. Triangles a lane may meet are put off, as in
    /// [`Bvh8::any_hit`], with the lanes that may meet them.
    pub(crate) fn any_hit_packet(
        &self,
        pk: &SegmentPacket,
        ignore: (u32, u32),
        trust_sure: bool,
        mut exact: impl FnMut(usize, usize) -> bool,
    ) -> u32 {
        let counts = |face: u32| face != ignore.0 && face != ignore.1;
        let mut exact = |lane, pos: usize| exact(lane, self.tri_at[pos] as usize);
        // Lanes not blocked yet.
        let mut open = pk.lanes;
        let mut pending = Pending::new();
        // Entries: (child reference, lanes that reached it).
        let mut inline = [(0u32, 0u32); INLINE_STACK];
        let mut heap = Vec::new();
        let stack: &mut [(u32, u32)] = if self.stack_len <= INLINE_STACK {
            &mut inline
        } else {
            heap.resize(self.stack_len, (0, 0));
            &mut heap
        };
        stack[0] = (self.root, open);
        let mut len = 1;
        while len > 0 && open != 0 {
            len -= 1;
            let (r, lanes) = stack[len];
            let lanes = lanes & open;
            if lanes == 0 {
                continue;
            }
            if r & LEAF_BIT != 0 {
                let (start, count) = leaf_range(r);
                for id in start..start + count {
                    if counts(self.blocks[id / 4].face[id % 4]) {
                        pending.filter(
                            &self.blocks,
                            id,
                            pk,
                            lanes,
                            trust_sure,
                            &mut open,
                            &mut exact,
                        );
                    }
                }
            } else {
                let node = &self.nodes[r as usize];
                let hits = node.hit_packet(pk).map(|m| m & lanes);
                let mut slots = 0u32;
                for (s, &m) in hits.iter().enumerate() {
                    slots |= ((m != 0) as u32) << s;
                }
                for s in last_first(slots) {
                    self.prefetch(node.child[s]);
                    stack[len] = (node.child[s], hits[s]);
                    len += 1;
                }
            }
        }
        pending.settle(&mut open, &mut exact);
        pk.lanes & !open
    }

    /// [`Bvh8::any_hit_packet`] against the triangles `ids` only (a pair's candidate
    /// list: every one of them counts), without the hierarchy: the lanes blocked by one
    /// of them, each with the answer it gets alone. Candidate `*first` is tested first
    /// (the pair's last blocker: its rays are coherent, so it likely blocks these too)
    /// and `*first` becomes the last candidate found to block for sure; the answer does
    /// not depend on it. Each candidate's filter runs for all open lanes at once;
    /// undecided (lane, triangle) pairs are put off, as in the hierarchy walks.
    pub(crate) fn any_hit_list(
        &self,
        pk: &SegmentPacket,
        ids: &[u32],
        trust_sure: bool,
        first: &mut usize,
        mut exact: impl FnMut(usize, usize) -> bool,
    ) -> u32 {
        let mut exact = |lane, pos: usize| exact(lane, self.tri_at[pos] as usize);
        let mut open = pk.lanes;
        let mut pending = Pending::new();
        let start = (*first < ids.len()).then_some(*first);
        let order = start
            .into_iter()
            .chain((0..ids.len()).filter(|&k| Some(k) != start));
        for k in order {
            if open == 0 {
                break;
            }
            if pending.filter(
                &self.blocks,
                self.pos_of[ids[k] as usize] as usize,
                pk,
                pk.lanes,
                trust_sure,
                &mut open,
                &mut exact,
            ) != 0
            {
                *first = k;
            }
        }
        pending.settle(&mut open, &mut exact);
        pk.lanes & !open
    }

    /// Calls `visit` with every triangle in a leaf whose box overlaps [lo, hi] and
    /// which `keep` (asked about each child box, f64) keeps, until `visit` returns true
    /// ("stop"). Returns whether a visit stopped the walk.
    pub(crate) fn for_each_in_box(
        &self,
        lo: DVec3,
        hi: DVec3,
        mut keep: impl FnMut(DVec3, DVec3) -> bool,
        mut visit: impl FnMut(usize) -> bool,
    ) -> bool {
        let lo8 = lo.to_array().map(|x| f32x8::splat(round_down(x)));
        let hi8 = hi.to_array().map(|x| f32x8::splat(round_up(x)));
        self.walk(
            |start, count| (start..start + count).any(|pos| visit(self.tri_at[pos] as usize)),
            |node, stack| {
                let mut m = node.overlap(&lo8, &hi8);
                while m != 0 {
                    let s = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let (clo, chi) = node.child_box(s);
                    if keep(clo, chi) {
                        stack.push(node.child[s]);
                    }
                }
            },
        )
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

    /// For tests: what [`Block::classify`] says of every triangle for `ray`, as
    /// (sure, maybe) per triangle id (neither: missed for sure).
    #[cfg(test)]
    pub(crate) fn classify_all(&self, ray: &SegmentRay, n: usize) -> Vec<(bool, bool)> {
        let ray = &RayLanes::new(ray);
        (0..n)
            .map(|id| {
                let pos = self.pos_of[id] as usize;
                let (sure, maybe) = self.blocks[pos / 4].classify(ray);
                (sure >> (pos % 4) & 1 == 1, maybe >> (pos % 4) & 1 == 1)
            })
            .collect()
    }
}
