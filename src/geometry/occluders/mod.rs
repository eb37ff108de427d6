//! Occluders: a bounding volume hierarchy over the scene triangles, answering the two
//! visibility questions the form-factor kernels ask.
//!
//! - [`Occluders::occluded`]: does any triangle (other than those of two given scene
//!   faces) cut the open segment between two points? Every face is opaque from both
//!   sides (docs/known-answers.md §7, Cornell box: the blocks have no bottom faces, and the floor
//!   under them must stay dark, so rays from the floor hit the blocks from inside).
//! - [`Occluders::any_between`]: can any triangle come between two given polygons at
//!   all? When not, the pair needs no rays (docs/numerics.md §9, "pairs with no possible
//!   occluder cast no rays"), decided from the hierarchy, not from a flag.
//!
//! The hierarchy is built by obvhs (PLOC, then its collapse to an eight-wide tree,
//! Ylitie et al. 2017) and laid out for SIMD traversal by `geometry/bvh8/`; it works in
//! f32. To make results independent of the scene's units and position, everything is
//! mapped to a normalized frame first: x ↦ (x − centre) / d with d the diagonal of the
//! triangles' bounding box. The exact triangle tests run in f64 on the normalized
//! triangles; the f32 hierarchy and its triangle filter only cull. Ray offsets are
//! fractions of d ([`RAY_EPSILON`]), so scaling a scene by 10⁻³ or 10³ changes no
//! visibility decision.
//!
//! Traversal takes closures (`Bvh8::any_hit`, `Bvh8::for_each_in_box`), so the
//! geometry tests stay out of the hierarchy and the accelerator can be swapped
//! (docs/conventions.md §7).

use std::time::Duration;

use glam::DVec3;
use obvhs::{cwbvh::builder::build_cwbvh_from_tris, triangle::Triangle, BvhBuildParams};

pub(crate) use super::bvh8::TreeStats;
use super::bvh8::{Bvh8, SegmentPacket, SegmentRay};
pub(crate) use super::triangle::OccluderTriangle;
pub use super::triangle::RAY_EPSILON;
use super::triangle::{Scan, Segment};
use between::{HullAxes, PairHull};

/// Most segments [`Occluders::occluded_packet`] takes at once.
pub const PACKET: usize = super::bvh8::PACKET;

/// Tolerance (normalized units) of the plane-side tests of [`Occluders::any_between`]:
/// a triangle that only touches the pair's hull within it cannot block a ray.
pub(crate) const PLANE_TOLERANCE: f64 = 1e-9;

/// Most candidate triangles [`Occluders::collect_between`] hands out for one pair; with
/// more, the pair's rays use the hierarchy.
pub(crate) const MAX_PAIR_CANDIDATES: usize = 16;

/// Work bound of [`Occluders::any_between`]: candidate triangles examined in detail
/// before it gives up and answers "rays needed".
pub(crate) const MAX_REJECTED_CANDIDATES: usize = 32;

/// obvhs' build of the occluder hierarchy: its slowest preset (PLOC over pre-split
/// triangles) with four times that preset's reinsertion passes (Meister and Bittner,
/// "Parallel reinsertion for bounding volume hierarchy optimization", 2018). Measured
/// (bench/PERF.md §12), 94.5k triangles: the SAH cost of the nodes falls from 10.3
/// (`slow_build`, used before) to 7.1, Embree's being 7.4 ([`Occluders::stats`]);
/// nodes tested per incoherent ray 9.2 → 7.7; single rays 17 % faster at 9.5k and at
/// 94.5k triangles, packets 7 % (9.5k) to 23 % (94.5k). The price is build time: 0.15 → 0.55 s
/// at 94.5k triangles, 2.2 → 12 s at 945k, once per process.
const BUILD_PARAMS: BvhBuildParams = BvhBuildParams {
    reinsertion_batch_ratio: 4.0,
    ..BvhBuildParams::very_slow_build()
};

/// Runs `$body` with `$kx`, `$ky`, `$kz` bound (as constants, usable as const generic
/// arguments) to the axis permutation `$axes` of a [`super::triangle::ShearedRay`]: one copy of a ray's
/// hot loop per permutation.
macro_rules! by_axes {
    ($axes:expr, |$kx:ident, $ky:ident, $kz:ident| $body:expr) => {
        match $axes {
            [1, 2, 0] => by_axes!(@arm 1, 2, 0, $kx, $ky, $kz, $body),
            [2, 1, 0] => by_axes!(@arm 2, 1, 0, $kx, $ky, $kz, $body),
            [2, 0, 1] => by_axes!(@arm 2, 0, 1, $kx, $ky, $kz, $body),
            [0, 2, 1] => by_axes!(@arm 0, 2, 1, $kx, $ky, $kz, $body),
            [0, 1, 2] => by_axes!(@arm 0, 1, 2, $kx, $ky, $kz, $body),
            [1, 0, 2] => by_axes!(@arm 1, 0, 2, $kx, $ky, $kz, $body),
            axes => unreachable!("not a permutation: {axes:?}"),
        }
    };
    (@arm $x:literal, $y:literal, $z:literal, $kx:ident, $ky:ident, $kz:ident, $body:expr) => {{
        const $kx: usize = $x;
        const $ky: usize = $y;
        const $kz: usize = $z;
        $body
    }};
}

mod between;
#[cfg(test)]
mod tests;

pub use between::Between;

/// Triangles that block light, in a hierarchy. Immutable after [`Occluders::new`], so
/// it is `Send + Sync` and shared by all threads.
#[derive(Clone, Debug)]
pub struct Occluders {
    bvh: Option<Bvh8>,
    /// Triangles in hierarchy primitive order (so no index indirection at traversal).
    tris: Vec<OccluderTriangle>,
    center: DVec3,
    /// 1 / the scene diagonal (world units): normalized = (world − center) · inv_scale.
    inv_scale: f64,
    /// Built from another mesh than the patches' (`--occluders`): face ids of the
    /// patches mean nothing here, so self-occlusion is told apart by planes instead
    /// (see [`Occluders::occluded_between_planes`]).
    foreign: bool,
    /// The triangles cover the same surfaces as the patches (their own scene's faces,
    /// merged or not), so the first surface a ray meets is a patch's
    /// ([`Occluders::first_hit`]); false for another mesh (`--occluders`).
    pub(crate) surfaces_are_patches: bool,
}

impl Occluders {
    /// As [`Occluders::new`] for a mesh other than the one the patches come from (a
    /// coarser occluder mesh of the same geometry): the `ignore` face ids of every
    /// query are disregarded; [`Occluders::occluded_between_planes`] ignores hits on
    /// the planes of the two patches instead, and [`Occluders::any_between`] already
    /// rejects triangles lying on (or behind) them.
    ///
    /// The face ids of `tris` must not be `u32::MAX`, which foreign queries ignore.
    pub fn new_foreign(tris: Vec<(u32, [DVec3; 3])>) -> Self {
        debug_assert!(tris.iter().all(|t| t.0 != u32::MAX), "face id u32::MAX");
        let mut o = Occluders::new(tris);
        o.foreign = true;
        o.surfaces_are_patches = false;
        o
    }

    /// Whether the triangles come from another mesh than the patches.
    pub(crate) fn is_foreign(&self) -> bool {
        self.foreign
    }

    /// Builds the hierarchy over `(scene face, triangle)` pairs. Degenerate (zero
    /// area) or non-finite triangles are dropped: they cannot block anything.
    pub fn new(tris: Vec<(u32, [DVec3; 3])>) -> Self {
        let Some((norm, center, diag)) = Self::normalized(tris) else {
            return Occluders::empty();
        };
        let f32_tris: Vec<Triangle> = norm
            .iter()
            .map(|t| {
                let [a, b, c] = t.vertices();
                Triangle {
                    v0: a.as_vec3a(),
                    v1: b.as_vec3a(),
                    v2: c.as_vec3a(),
                }
            })
            .collect();
        let bvh = build_cwbvh_from_tris(&f32_tris, BUILD_PARAMS, &mut Duration::default());
        let ordered: Vec<OccluderTriangle> = bvh
            .primitive_indices
            .iter()
            .map(|&k| norm[k as usize])
            .collect();
        Occluders {
            bvh: Bvh8::from_cwbvh(&bvh, &ordered),
            tris: ordered,
            center,
            inv_scale: 1.0 / diag,
            foreign: false,
            surfaces_are_patches: true,
        }
    }

    /// The triangles [`Occluders::new`] keeps, in its normalized frame, with that
    /// frame's centre and scale (None when none is kept).
    fn normalized(tris: Vec<(u32, [DVec3; 3])>) -> Option<(Vec<OccluderTriangle>, DVec3, f64)> {
        let finite: Vec<(u32, [DVec3; 3])> = tris
            .into_iter()
            .filter(|(_, t)| t.iter().all(|p| p.is_finite()))
            .collect();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for (_, t) in &finite {
            for p in t {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        let diag = (hi - lo).length();
        if finite.is_empty() || !diag.is_finite() || diag <= 0.0 {
            return None;
        }
        let center = 0.5 * (lo + hi);
        let inv_scale = 1.0 / diag;
        let norm: Vec<OccluderTriangle> = finite
            .iter()
            .filter_map(|(f, t)| {
                OccluderTriangle::new(
                    *f,
                    [
                        (t[0] - center) * inv_scale,
                        (t[1] - center) * inv_scale,
                        (t[2] - center) * inv_scale,
                    ],
                )
            })
            .collect();
        (!norm.is_empty()).then_some((norm, center, diag))
    }

    /// How many of `tris` [`Occluders::new`] would keep, without building anything
    /// (what a rank that casts no rays needs to describe the job).
    pub fn count_kept(tris: Vec<(u32, [DVec3; 3])>) -> usize {
        Self::normalized(tris).map_or(0, |(kept, _, _)| kept.len())
    }

    /// No occluders at all: nothing is ever occluded.
    pub(crate) fn empty() -> Self {
        Occluders {
            bvh: None,
            tris: Vec::new(),
            center: DVec3::ZERO,
            inv_scale: 1.0,
            foreign: false,
            surfaces_are_patches: true,
        }
    }

    /// The diagonal (world units) that [`RAY_EPSILON`] is relative to.
    pub(crate) fn diagonal(&self) -> f64 {
        1.0 / self.inv_scale
    }

    /// Number of triangles in the hierarchy.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Triangle `k` (an index of the candidate lists, [`Occluders::collect_between`])
    /// in world units.
    pub(crate) fn world_triangle(&self, k: u32) -> [DVec3; 3] {
        self.tris[k as usize]
            .v
            .map(|p| self.center + p / self.inv_scale)
    }

    /// The shape of the hierarchy (`None` without triangles), for benchmarks.
    pub fn stats(&self) -> Option<TreeStats> {
        self.bvh.as_ref().map(Bvh8::stats)
    }

    #[inline]
    fn to_norm(&self, p: DVec3) -> DVec3 {
        (p - self.center) * self.inv_scale
    }

    /// The segment `from` → `to` (world units) in the normalized frame, as its start
    /// and its end minus its start.
    #[inline]
    fn norm_segment(&self, from: DVec3, to: DVec3) -> (DVec3, DVec3) {
        let f = self.to_norm(from);
        (f, self.to_norm(to) - f)
    }

    /// True when a triangle of a face other than `ignore.0` and `ignore.1` cuts the
    /// segment from `from` to `to`, ignoring hits within [`RAY_EPSILON`] × diagonal of
    /// either end.
    pub fn occluded(&self, from: DVec3, to: DVec3, ignore: (u32, u32)) -> bool {
        self.occluded_between_planes(from, to, ignore, None)
    }

    /// As [`Occluders::occluded`] for a segment between two patches with planes
    /// `planes` = ((normal, offset) of the source, of the target), world units, used
    /// when the occluders are foreign ([`Occluders::new_foreign`]): a hit counts only
    /// on a triangle that does not lie in either plane (within [`RAY_EPSILON`] ×
    /// diagonal: a coarse or merged mesh of the same flat faces has triangles on those
    /// planes, which the face ids of the patches cannot name). For native occluders the planes are
    /// not needed and `ignore` works as in [`Occluders::occluded`].
    pub(crate) fn occluded_between_planes(
        &self,
        from: DVec3,
        to: DVec3,
        ignore: (u32, u32),
        planes: Option<[(DVec3, f64); 2]>,
    ) -> bool {
        let Some(bvh) = &self.bvh else { return false };
        let ignore = self.ignored_faces(ignore);
        let planes = self.normalized_planes(planes);
        let (f, d) = self.norm_segment(from, to);
        let Some(ray) = SegmentRay::new(f, d) else {
            return false;
        };
        // The exact test runs only for the few triangles the f32 filter cannot
        // decide, and most rays need none: its set-up waits for the first one. A
        // segment too short for `Segment::new` answers "not blocked" all the same:
        // the filter is never sure of a crossing within FILTER_SLACK (> RAY_EPSILON)
        // of either end. One dispatch per test keeps a single copy of the walk.
        let mut setup = None;
        bvh.any_hit(&ray, ignore, planes.is_none(), |id| {
            self.exact_blocks(&mut setup, (f, d), id, &planes)
        })
    }

    /// The exact test: does triangle `id` block the segment from `f` to `f + d`
    /// (normalized frame; with foreign occluders, by a hit off the end patches'
    /// `planes`)? The segment's set-up is made into `setup` on the first call for it
    /// (`Some(None)`: too short to be blocked).
    fn exact_blocks(
        &self,
        setup: &mut Option<Option<Segment>>,
        (f, d): (DVec3, DVec3),
        id: usize,
        planes: &Option<[(DVec3, f64); 2]>,
    ) -> bool {
        let Some(seg) = setup.get_or_insert_with(|| Segment::new(f, d)) else {
            return false;
        };
        by_axes!(seg.sheared.axes, |KX, KY, KZ| {
            let tri = &self.tris[id];
            tri.hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                .is_some()
                && Segment::counts(tri, planes)
        })
    }

    /// The first point where the ray from `from` along `dir` (world units, any length)
    /// meets a triangle within twice the scene's diagonal (from distance 0 on), ignoring
    /// triangles of face `ignore` (native occluders) and those lying in `plane` =
    /// (unit normal, offset), world units: the ray's own surface. `None` when it meets nothing. Every
    /// triangle the ray may meet is tested exactly (no early exit), keeping the nearest.
    pub(crate) fn first_hit(
        &self,
        from: DVec3,
        dir: DVec3,
        ignore: u32,
        plane: (DVec3, f64),
    ) -> Option<DVec3> {
        let bvh = self.bvh.as_ref()?;
        let planes = self.normalized_planes(Some([plane, plane]));
        let ignore = self.ignored_faces((ignore, ignore));
        let f = self.to_norm(from);
        let unit = dir.normalize_or_zero();
        let d = unit * 2.0;
        let ray = SegmentRay::new(f, d)?;
        let mut seg = Segment::new(f, d)?;
        // Hits from the start on: the ray's own surface is left out by its plane, and
        // a surface standing next to the start point (a box's wall a few ray
        // tolerances away) must stop it, or it passes into the box and the start
        // point seems to see nothing (one ray lost in 2 of 60 rows beside boxes at 25k).
        seg.t0 = 0.0;
        let mut nearest = f64::INFINITY;
        by_axes!(seg.sheared.axes, |KX, KY, KZ| {
            bvh.any_hit(&ray, ignore, false, |id| {
                let tri = &self.tris[id];
                if let Some(t) = tri.hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1.min(nearest)) {
                    if Segment::counts(tri, &planes) {
                        nearest = nearest.min(t);
                    }
                }
                false
            })
        });
        // `t` of the exact test is a distance along the unit direction.
        nearest
            .is_finite()
            .then(|| self.center + (f + unit * nearest) / self.inv_scale)
    }

    /// Calls `visit` with every triangle (world units) that stands on the plane
    /// `plane` = (unit normal, offset, world units) near the box [lo, hi] (world
    /// units): its own box overlaps [lo, hi] widened by `tol`, and one or two of its
    /// corners, not three, lie within `tol` of the plane (a wall of a box standing on
    /// a floor; a triangle lying in the plane is left out).
    pub(crate) fn standing_on(
        &self,
        lo: DVec3,
        hi: DVec3,
        plane: (DVec3, f64),
        tol: f64,
        mut visit: impl FnMut([DVec3; 3]),
    ) {
        let Some(bvh) = &self.bvh else { return };
        let (lo, hi) = (lo - DVec3::splat(tol), hi + DVec3::splat(tol));
        let (nlo, nhi) = (self.to_norm(lo), self.to_norm(hi));
        bvh.for_each_in_box(
            nlo,
            nhi,
            |_, _| true,
            |k| {
                let v = self.world_triangle(k as u32);
                let (tlo, thi) = (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]));
                let on = v
                    .iter()
                    .filter(|p| (plane.0.dot(**p) - plane.1).abs() <= tol)
                    .count();
                if (1..3).contains(&on) && tlo.cmple(hi).all() && thi.cmpge(lo).all() {
                    visit(v);
                }
                false
            },
        );
    }

    /// [`Occluders::occluded_between_planes`] for up to [`PACKET`] segments at once:
    /// bit l of the answer is set when segment l is blocked, with the same answer as
    /// alone. The segments are walked through the hierarchy together, which pays when
    /// they are close to each other (the rays of one pair of patches).
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    pub fn occluded_packet(
        &self,
        segs: &[(DVec3, DVec3)],
        ignore: (u32, u32),
        planes: Option<[(DVec3, f64); 2]>,
    ) -> u32 {
        let ignore = self.ignored_faces(ignore);
        self.with_packet(segs, planes, |bvh, pk, trust_sure, exact| {
            bvh.any_hit_packet(pk, ignore, trust_sure, exact)
        })
    }

    /// [`Occluders::occluded_by`] for up to [`PACKET`] segments at once, against the
    /// same candidate list `ids`: bit l of the answer is set when segment l is blocked,
    /// with the same answer as alone. Each candidate's f32 filter runs for all the
    /// segments together; the exact test only for what it cannot decide.
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    pub fn occluded_packet_by(
        &self,
        segs: &[(DVec3, DVec3)],
        ids: &[u32],
        planes: Option<[(DVec3, f64); 2]>,
        first: &mut usize,
    ) -> u32 {
        self.with_packet(segs, planes, |bvh, pk, trust_sure, exact| {
            bvh.any_hit_list(pk, ids, trust_sure, first, exact)
        })
    }

    /// The set-up both packet queries share: `segs` (world units) as a packet in the
    /// normalized frame, handed to `walk` with whether sure crossings block (native
    /// occluders) and the exact test of (lane, triangle).
    ///
    /// # Panics
    /// With more than [`PACKET`] segments.
    fn with_packet(
        &self,
        segs: &[(DVec3, DVec3)],
        planes: Option<[(DVec3, f64); 2]>,
        walk: impl FnOnce(&Bvh8, &SegmentPacket, bool, &mut dyn FnMut(usize, usize) -> bool) -> u32,
    ) -> u32 {
        assert!(segs.len() <= PACKET, "{} segments in a packet", segs.len());
        let Some(bvh) = &self.bvh else { return 0 };
        let planes = self.normalized_planes(planes);
        let mut ends = [(DVec3::ZERO, DVec3::ZERO); PACKET];
        for (l, &(from, to)) in segs.iter().enumerate() {
            ends[l] = self.norm_segment(from, to);
        }
        let packet = SegmentPacket::new(&ends[..segs.len()]);
        // As in `occluded_between_planes`: each lane's exact set-up waits for its
        // first undecided triangle.
        let mut setups: [Option<Option<Segment>>; PACKET] = Default::default();
        walk(bvh, &packet, planes.is_none(), &mut |lane, id| {
            self.exact_blocks(&mut setups[lane], ends[lane], id, &planes)
        })
    }

    /// The faces whose triangles a query ignores: `ignore` for native occluders, none
    /// for foreign ones (their face ids mean nothing to the patches; planes decide).
    fn ignored_faces(&self, ignore: (u32, u32)) -> (u32, u32) {
        if self.foreign {
            (u32::MAX, u32::MAX)
        } else {
            ignore
        }
    }

    /// For foreign occluders, the planes of the two end patches in the normalized frame
    /// (n·x' = (n·x − n·c) / d); `None` for native occluders, which use face ids.
    fn normalized_planes(&self, planes: Option<[(DVec3, f64); 2]>) -> Option<[(DVec3, f64); 2]> {
        if !self.foreign {
            return None;
        }
        planes.map(|ps| ps.map(|(n, o)| (n, (o - n.dot(self.center)) * self.inv_scale)))
    }

    /// The segment `from` → `to` (world units) as a ray in the normalized frame, hits
    /// counted between [`RAY_EPSILON`] of either end; `None` when it is too short.
    fn segment(&self, from: DVec3, to: DVec3) -> Option<Segment> {
        let (f, d) = self.norm_segment(from, to);
        Segment::new(f, d)
    }

    /// Calls `visit` with the index of every triangle whose hierarchy leaf box
    /// overlaps the box [lo, hi] (normalized units) and is not separated from `hull`
    /// by one of its axes, until `visit` returns `true` ("stop"). Returns whether a
    /// visit stopped the traversal.
    fn for_each_in_hull(
        &self,
        lo: DVec3,
        hi: DVec3,
        hull: &HullAxes,
        visit: impl FnMut(usize) -> bool,
    ) -> bool {
        let Some(bvh) = &self.bvh else { return false };
        bvh.for_each_in_box(lo, hi, |blo, bhi| !hull.separates_box(blo, bhi), visit)
    }

    /// Can any triangle (other than those of faces `ignore.0`, `ignore.1`) come between
    /// polygon `a` (front normal `na`) and polygon `b` (front normal `nb`)? Both are
    /// given in world units and should already be clipped to each other's front
    /// half-space. Conservative: `false` means that no segment from a point of `a` to
    /// a point of `b` can be blocked, so the pair needs no rays; `true` means rays are
    /// needed.
    ///
    /// A triangle cannot block when one of the tests of the pair's hull (`PairHull`)
    /// rejects it (its box, its plane, the planes of `a` and `b`, the hull's side axes;
    /// all with [`PLANE_TOLERANCE`]).
    ///
    /// The work is bounded: after [`MAX_REJECTED_CANDIDATES`] triangles that pass the
    /// cheap tests 1–2 (face, box), the answer is `true` (rays will decide), so a pair
    /// in a cluttered region costs a short traversal, never a scan.
    pub fn any_between(&self, q: &Between<'_>) -> bool {
        self.scan_between(q, MAX_REJECTED_CANDIDATES, |_| true) != Scan::Done
    }

    /// The triangles that may come between polygons `a` and `b` (the candidates of
    /// [`Occluders::any_between`], all of them), into `out`. Returns `false` (and
    /// `out` is then of no use) when there are more than [`MAX_PAIR_CANDIDATES`] or
    /// the search gave up ([`MAX_REJECTED_CANDIDATES`]); rays must then use the
    /// hierarchy. An empty `out` with `true` means no segment between the polygons
    /// can be blocked. A triangle left out cannot block any segment from a point of
    /// `a` to a point of `b`, so [`Occluders::occluded_by`] with these candidates
    /// answers as the hierarchy would for such segments (up to rays grazing a
    /// triangle that only touches the pair's hull, which `any_between` ignores too).
    pub fn collect_between(&self, q: &Between<'_>, out: &mut Vec<u32>) -> bool {
        self.collect_between_up_to(q, MAX_PAIR_CANDIDATES, MAX_REJECTED_CANDIDATES, out)
    }

    /// The search behind [`Occluders::any_between`] and
    /// [`Occluders::collect_between`]: calls `found` with every triangle that may come
    /// between the polygons, until it returns `true`; gives up after `max_rejected`
    /// triangles examined in detail.
    fn scan_between(
        &self,
        q: &Between<'_>,
        max_rejected: usize,
        mut found: impl FnMut(usize) -> bool,
    ) -> Scan {
        let Some(pair) = PairHull::new(self, q) else {
            return Scan::Done;
        };
        let hull = pair.hull_axes();
        let tris = &self.tris;
        let mut rejected = 0usize;
        let mut gave_up = false;
        let stopped = self.for_each_in_hull(pair.qlo, pair.qhi, &hull, |k| {
            let t = &tris[k];
            if !pair.near(t) {
                return false;
            }
            rejected += 1;
            if rejected > max_rejected {
                gave_up = true;
                return true;
            }
            pair.crosses(t) && !hull.separates(&t.v) && found(k)
        });
        match (stopped, gave_up) {
            (_, true) => Scan::GaveUp,
            (true, false) => Scan::Stopped,
            (false, false) => Scan::Done,
        }
    }

    /// As [`Occluders::collect_between`] with the limits given (`max_found`
    /// candidates, `max_rejected` triangles examined in detail), for queries between
    /// larger polygons whose lists are then narrowed pair by pair with
    /// [`Occluders::filter_between`].
    pub(crate) fn collect_between_up_to(
        &self,
        q: &Between<'_>,
        max_found: usize,
        max_rejected: usize,
        out: &mut Vec<u32>,
    ) -> bool {
        out.clear();
        let scan = self.scan_between(q, max_rejected, |k| {
            out.push(k as u32);
            out.len() > max_found
        });
        scan == Scan::Done
    }

    /// The triangles of `list` that may come between polygons `a` and `b`, into `out`
    /// (in the order of `list`). When `list` holds every triangle that may come
    /// between two polygons containing `a` and `b` (a [`Occluders::collect_between_up_to`]
    /// answer for them, with the same planes and ignored faces), `out` is within the
    /// set [`Occluders::collect_between`] finds for `a` and `b` and holds every
    /// triangle that can block a segment between them (up to triangles that only touch
    /// the hull within [`PLANE_TOLERANCE`], as every test here), without walking the
    /// hierarchy:
    /// a triangle that cannot come between the larger polygons cannot come between the
    /// smaller ones. Stops once `out` holds more than `max_found` (0: "is there any").
    pub(crate) fn filter_between(
        &self,
        q: &Between<'_>,
        list: &[u32],
        max_found: usize,
        out: &mut Vec<u32>,
    ) {
        out.clear();
        if list.is_empty() {
            return;
        }
        let Some(pair) = PairHull::new(self, q) else {
            return;
        };
        // Test 5's axes cost more than the other tests: built on first need.
        let mut hull = None;
        for &k in list {
            let t = &self.tris[k as usize];
            if pair.near(t)
                && pair.crosses(t)
                && !hull.get_or_insert_with(|| pair.hull_axes()).separates(&t.v)
            {
                out.push(k);
                if out.len() > max_found {
                    return;
                }
            }
        }
    }

    /// Is the segment `from` → `to` (world units) blocked by one of the triangles
    /// `ids` (from [`Occluders::collect_between`])? The same ray set-up and exact test
    /// as [`Occluders::occluded_between_planes`], without the hierarchy.
    ///
    /// `first` is tested first (the pair's last blocker: its rays are coherent, so it
    /// likely blocks the next one too) and is set to the blocker found. The answer does
    /// not depend on it.
    pub fn occluded_by(
        &self,
        from: DVec3,
        to: DVec3,
        ids: &[u32],
        planes: Option<[(DVec3, f64); 2]>,
        first: &mut usize,
    ) -> bool {
        let Some(seg) = self.segment(from, to) else {
            return false;
        };
        let planes = self.normalized_planes(planes);
        by_axes!(seg.sheared.axes, |KX, KY, KZ| {
            self.first_blocker::<KX, KY, KZ>(&seg, ids, &planes, first)
        })
    }

    /// [`Occluders::occluded_by`] for a segment whose axes are (KX, KY, KZ).
    #[inline(always)]
    fn first_blocker<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        seg: &Segment,
        ids: &[u32],
        planes: &Option<[(DVec3, f64); 2]>,
        first: &mut usize,
    ) -> bool {
        let blocks = |k: usize| {
            let tri = &self.tris[ids[k] as usize];
            tri.hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                .is_some()
                && Segment::counts(tri, planes)
        };
        if *first < ids.len() && blocks(*first) {
            return true;
        }
        match (0..ids.len()).find(|&k| k != *first && blocks(k)) {
            Some(k) => {
                *first = k;
                true
            }
            None => false,
        }
    }

    /// Checks internal invariants (for tests): every triangle is finite with a unit
    /// normal, lies inside the normalized unit-diagonal box, and the hierarchy holds
    /// each triangle exactly once.
    #[cfg(test)]
    pub(crate) fn validate(&self) {
        for t in &self.tris {
            assert!((t.normal.length() - 1.0).abs() < 1e-12);
            for v in t.vertices() {
                assert!(v.is_finite() && v.abs().max_element() <= 0.5 + 1e-12);
            }
        }
        if let Some(bvh) = &self.bvh {
            bvh.validate(&self.tris);
        }
    }
}
