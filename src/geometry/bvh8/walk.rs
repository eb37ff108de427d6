//! The walks of the tree: the eight-box test of a node and the triangle filter of a
//! block, the put-off exact tests, and the traversals of one ray, of a packet, of a
//! candidate list and of a box.

use glam::DVec3;
use wide::{f32x16 as Lanes16, f32x4, f32x8};

use super::rays::*;
use super::*;

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

    pub(crate) fn child_box(&self, s: usize) -> (DVec3, DVec3) {
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
    ///   than [`crate::geometry::occluders::RAY_EPSILON`]) from either end point along the segment,
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
pub(crate) struct Stack<'a> {
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

impl Bvh8 {
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
