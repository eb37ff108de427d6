//! The row engine: computes row i of the form-factor matrix, F_ij for every j.
//!
//! One [`RowEngine`] is shared (it is `Send + Sync`) by all threads of a process; each
//! thread brings its own [`Scratch`] (buffers and counters). Per-patch data (plane,
//! edges, sampling map, centroid) is computed once in [`RowEngine::new`].
//!
//! Per pair (i, j), cheapest test first:
//! 1. j = i → 0 (planar patches do not see themselves);
//! 2. facing away → 0 without any kernel work: every corner of j on or behind the plane
//!    of i, or every corner of i on or behind the plane of j (this includes coplanar
//!    pairs);
//! 3. the method's kernel ([`super::contour`], [`super::mc`], [`super::point`]),
//!    with rays only when [`Occluders::any_between`] says something can come between.
//!
//! Determinism: a row depends only on (i, patches, occluders, config). Random streams
//! are seeded by (i, j, seed), every sum runs in a fixed order, and nothing is shared
//! between threads except read-only data, so the same row comes out bitwise equal on
//! any thread, in any order, on any rank.
//!
//! Counters live in the [`Scratch`] (no atomics in the hot loop); a caller that uses
//! several scratches sums them with [`Counters::add`].

use std::borrow::Cow;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use glam::DVec3;

use super::clip::{EdgeSet, Polygon};
use super::clusters::{ClusterCache, Clusters};
use super::contour::{area_form_factor_edges, ContourParams};
use super::farfield::{self, FarOrders};
use super::geom::{PatchBound, PatchGeom};
use super::quadrature::{gauss_table, GaussTable};
use super::scratch::{Counters, PairScratch};
use super::shadow::solids::{Solids, NO_SOLID};
use super::shadow::{Caster, ShadowScratch};
use super::tree::PatchTree;
use super::{
    mc, point, topk, visibility, DroppedMassRoute, FormFactorConfig, Method, RowTotal, TopKSearch,
    TopKTail, Visibility,
};
use crate::geometry::occluders::{
    Between, Occluders, MAX_PAIR_CANDIDATES, MAX_REJECTED_CANDIDATES, RAY_EPSILON,
};
use crate::patch::PatchSet;
use crate::rows::Row;
use exact::EXACT_MAX_CANDIDATES;

/// Plane tolerance of the facing and clipping tests, relative to the diagonal of the
/// patches' bounding box (so it scales with the scene).
const PLANE_RELATIVE_TOLERANCE: f64 = 1e-10;

/// Per-thread working memory of [`RowEngine::compute_row`].
#[derive(Debug, Default)]
pub struct Scratch {
    values: Vec<f64>,
    order: Vec<u32>,
    flags: Vec<bool>,
    /// What the pair kernels write into.
    pair: PairScratch,
    /// Occluder triangles that may come between the current pair
    /// (`Occluders::collect_between`): its rays test only these.
    candidates: Vec<u32>,
    /// Occluder lists of cluster pairs ([`super::clusters`]).
    clusters: ClusterCache,
    /// Exact visibility: the pair's candidates as casters, the shadow clipping's
    /// pieces.
    casters: Vec<Caster>,
    /// The top-k tree search's blocker polygons and enclosing cell of the current row.
    hidden: topk_tree::HiddenRow,
    /// The row total's hemisphere rays: their sample points, and the patch tree's walk.
    closure: closure::ClosureScratch,
    shadow: ShadowScratch,
    /// The row being computed (a hint for what the cluster lists keep; no value
    /// depends on it).
    row: Option<u32>,
    /// Far pairs' Gauss points ([`farfield::FarScratch`]).
    far: farfield::FarScratch,
}

impl Scratch {
    pub fn new() -> Self {
        Self::default()
    }

    /// Counters accumulated since creation or the last [`Scratch::take_counters`].
    pub fn counters(&self) -> Counters {
        self.pair.counters
    }

    /// Counts row `i` and notes it as the row being computed.
    fn start_row(&mut self, i: u32) {
        self.pair.counters.rows += 1;
        self.row = Some(i);
    }

    /// Returns the counters and resets them.
    pub fn take_counters(&mut self) -> Counters {
        std::mem::take(&mut self.pair.counters)
    }
}

/// Computes form-factor rows; shared by all threads of a process.
#[derive(Debug)]
pub struct RowEngine {
    /// Process-unique id, so a [`Scratch`] moved between engines never reuses
    /// cached per-row data.
    id: u64,
    occluders: Arc<Occluders>,
    cfg: FormFactorConfig,
    geom: Vec<PatchGeom>,
    bounds: Vec<PatchBound>,
    /// Rounding allowance of the sphere tests of [`RowEngine::facing`].
    bound_slack: f64,
    valid: Vec<bool>,
    gauss: &'static GaussTable,
    params: ContourParams,
    far_orders: FarOrders,
    tol: f64,
    /// Most candidate triangles a pair's list holds (0: no lists, rays walk the Bvh;
    /// see [`PAIR_LISTS_MAX_OCCLUDERS`]; [`EXACT_MAX_CANDIDATES`] with exact
    /// visibility, which needs them).
    list_max: usize,
    /// Candidates examined in detail before a list gives up.
    list_rejected: usize,
    /// Patch clusters whose pairs share one occluder query (None: every pair queries
    /// the hierarchy).
    clusters: Option<Clusters>,
    /// A pair's rays through the hierarchy go as packets (see `visibility::Blockers`).
    packets: bool,
    /// The hierarchy over the patches of the top-k tree search (None unless the
    /// configuration asks for it).
    tree: Option<PatchTree>,
    /// Margin (world units) by which a polygon must hide a node from a row patch for
    /// the tree search to skip the node: four times the distance within which a ray
    /// ignores hits near its ends, so every ray the skipped pairs would cast is surely
    /// blocked. (100 times was too much: a floor cell 0.15 mm inside a box's wall at 1M
    /// patches could not use the wall.)
    hide_margin: f64,
    /// The larger of the patches' and the occluders' diagonals (world units).
    span: f64,
    /// The convex solids among the occluders (exact visibility only; empty otherwise).
    solids: Solids,
    /// Whether the tree search skips the nodes a blocker polygon or an enclosing cell
    /// hides (`topk_tree` step 4; off only in tests, which check that it changes no
    /// kept entry).
    cull_hidden: bool,
    /// With links: how much the first-bounce radiosity varies over each tree node
    /// (`first_bounce.rs`; `None` when nothing emits), which steers the links' cut.
    contrast: Option<first_bounce::Contrast>,
    /// With links: what the links' one-ray points read of each patch, in cluster
    /// order (`points.rs`).
    points: Vec<points::PointPatch>,
    /// With links: the pseudo-inverse of each tree node's second moments, by id (the
    /// links' slopes, `links.rs`).
    inverses: Vec<links::PseudoInverse>,
    /// With links: the seconds of the links' set-up ([`RowEngine::links_setup_seconds`]).
    links_setup: Option<f64>,
    /// Threads of the engine's own set-up work ([`RowEngine::with_threads`]).
    setup_threads: usize,
}

/// Pair candidate lists (`Occluders::collect_between`) pay off only with few occluder
/// triangles: measured (bench/PERF.md §7, 2-core machine, x86-64-v3), the 16-box room
/// (188 triangles) at 8.5k patches 45.1 → 39.8 CPU-s, but rooms of 64, 200 and 900 boxes
/// (780, 2120, 9470 triangles) 9-21 % slower, because finding every candidate of a
/// cluttered pair costs more than the rays save. Both ways give the same answers.
pub(crate) const PAIR_LISTS_MAX_OCCLUDERS: usize = 256;

impl RowEngine {
    /// With exact visibility, how many convex solids the occluders hold and how many
    /// triangles they are made of ([`super::shadow::solids`]); None otherwise.
    pub fn solids_found(&self) -> Option<(usize, usize)> {
        (self.cfg.visibility == Visibility::Exact).then(|| {
            let s = &self.solids;
            (
                s.solids.len(),
                s.of.iter().filter(|&&k| k != NO_SOLID).count(),
            )
        })
    }

    /// Precomputes per-patch data. Patches with zero area (or no proper normal) get
    /// zero rows and columns. The configuration should have passed
    /// [`FormFactorConfig::validate`]; out-of-range values are clamped.
    pub fn new(patches: &PatchSet, occluders: Arc<Occluders>, cfg: FormFactorConfig) -> Self {
        let threads = std::thread::available_parallelism().map_or(1, |t| t.get());
        Self::with_threads(patches, occluders, cfg, threads)
    }

    /// [`RowEngine::new`], whose own set-up work (with links, the first-bounce
    /// estimate) runs on `threads` threads: a process's `--threads`, so that ranks
    /// sharing a node do not each take every core.
    pub fn with_threads(
        patches: &PatchSet,
        occluders: Arc<Occluders>,
        cfg: FormFactorConfig,
        threads: usize,
    ) -> Self {
        let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
        let valid: Vec<bool> = geom.iter().map(PatchGeom::is_valid).collect();
        let (diag, magnitude) = extent(&geom);
        let clusters = if occluders.is_empty() {
            None
        } else {
            Clusters::new(&geom, &valid, diag, occluders.is_foreign())
        };
        let params = cfg.contour_params();
        let occluders_len = occluders.len();
        let cfg_visibility = cfg.visibility;
        let bounds = geom.iter().map(PatchBound::of).collect();
        let tol = PLANE_RELATIVE_TOLERANCE * diag;
        let span = diag.max(occluders.diagonal());
        let hide_margin = 4.0 * RAY_EPSILON * span;
        let bound_slack = 1e-12 * diag + 1e-14 * magnitude;
        let tree = cfg
            .searches_tree()
            .then(|| PatchTree::with_kinds(&geom, &valid, &kinds(patches), tol, bound_slack));
        let solids = if cfg_visibility == Visibility::Exact {
            let tris: Vec<[DVec3; 3]> = (0..occluders_len as u32)
                .map(|k| occluders.world_triangle(k))
                .collect();
            Solids::find(&tris, tol)
        } else {
            Solids::default()
        };
        static NEXT_ID: AtomicU64 = AtomicU64::new(0);
        let mut engine = RowEngine {
            solids,
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            occluders,
            cfg,
            geom,
            bounds,
            bound_slack,
            valid,
            gauss: gauss_table(),
            far_orders: FarOrders::new(params.tol),
            params,
            tol,
            list_max: match cfg_visibility {
                Visibility::Exact => EXACT_MAX_CANDIDATES,
                Visibility::Rays if occluders_len <= PAIR_LISTS_MAX_OCCLUDERS => {
                    MAX_PAIR_CANDIDATES
                }
                Visibility::Rays => 0,
            },
            list_rejected: match cfg_visibility {
                Visibility::Exact => 2 * EXACT_MAX_CANDIDATES,
                Visibility::Rays => MAX_REJECTED_CANDIDATES,
            },
            clusters,
            packets: true,
            tree,
            hide_margin,
            span,
            cull_hidden: true,
            contrast: None,
            points: Vec::new(),
            inverses: Vec::new(),
            links_setup: None,
            setup_threads: threads.max(1),
        };
        if engine.cfg.links_rows() {
            let started = std::time::Instant::now();
            if let (Some(b), Some(tree)) = (engine.first_bounce(patches), &engine.tree) {
                let second = engine.second_bounce(patches, tree, &b);
                engine.contrast = Some(first_bounce::Contrast::new(tree, b, &second, &engine.geom));
            }
            if let Some(tree) = &engine.tree {
                let bounce = engine.contrast.as_ref().map_or(&[][..], |c| &c.bounce[..]);
                engine.points = points::PointPatch::table(tree, &engine.geom, bounce);
                engine.inverses = links::PseudoInverse::of_nodes(tree);
            }
            engine.links_setup = Some(started.elapsed().as_secs_f64());
        }
        engine
    }

    /// With links: the seconds this engine spent on what its links need before any
    /// row (the first-bounce radiosity that steers their cut, `first_bounce.rs`, the
    /// points' table, `points.rs`, and the nodes' pseudo-inverses); `None` without
    /// links.
    pub fn links_setup_seconds(&self) -> Option<f64> {
        self.links_setup
    }

    /// The same engine without the hidden rows' node skipping (for tests: it must
    /// change no row).
    #[cfg(test)]
    pub(crate) fn without_hidden_culling(mut self) -> Self {
        self.cull_hidden = false;
        self
    }

    /// The same engine casting every ray on its own instead of in packets (for tests:
    /// packets must change no value).
    #[cfg(test)]
    pub(crate) fn one_ray_at_a_time(mut self) -> Self {
        self.packets = false;
        self
    }

    /// The same engine with every pair querying the hierarchy itself (for tests:
    /// cluster lists must change no value).
    #[cfg(test)]
    pub(crate) fn without_clusters(mut self) -> Self {
        self.clusters = None;
        self
    }

    /// The cluster order of the file when the rows link to clusters (spec §4.3): the
    /// patches in the order of the tree the rows' links name ranges of. The same for
    /// every engine of the same patches and settings, and what
    /// [`RowEngine::cluster_order_of`] gives without building one.
    pub fn cluster_order(&self) -> Option<Vec<u32>> {
        match (&self.tree, self.cfg.links) {
            (Some(tree), Some(_)) => Some(tree.cluster_order(self.n())),
            _ => None,
        }
    }

    /// [`RowEngine::cluster_order`] of an engine with `cfg` over `patches`, without
    /// building the engine (rank 0 writes it into the header and computes no row).
    pub fn cluster_order_of(patches: &PatchSet, cfg: &FormFactorConfig) -> Option<Vec<u32>> {
        if !(cfg.searches_tree() && cfg.links.is_some()) {
            return None;
        }
        let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
        let valid: Vec<bool> = geom.iter().map(PatchGeom::is_valid).collect();
        let (diag, magnitude) = extent(&geom);
        let tree = PatchTree::with_kinds(
            &geom,
            &valid,
            &kinds(patches),
            PLANE_RELATIVE_TOLERANCE * diag,
            1e-12 * diag + 1e-14 * magnitude,
        );
        Some(tree.cluster_order(geom.len()))
    }

    /// Number of patches (rows and columns).
    pub fn n(&self) -> usize {
        self.geom.len()
    }

    /// The settings, the number of occluder triangles and whether they come from
    /// another mesh than the patches': what the file header's run parameters say of
    /// this engine (`job::EngineParams::of_engine`).
    pub fn header_inputs(&self) -> (&FormFactorConfig, usize, bool) {
        (
            &self.cfg,
            self.occluders.len(),
            !self.occluders.surfaces_are_patches,
        )
    }

    /// How an engine with `cfg` and that many occluder triangles, from another mesh
    /// than the patches' (`other_mesh`) or not, finds the dropped mass of its sparse
    /// rows, without building it; None for dense rows. The header records it
    /// (`dropped_mass=`, `links=`, `link_tol=`).
    pub fn dropped_mass(
        cfg: &FormFactorConfig,
        occluder_triangles: usize,
        other_mesh: bool,
    ) -> Option<DroppedMassRoute> {
        match (cfg.sparse_rows(), cfg.method, cfg.top_k_tail) {
            (false, ..) => None,
            (true, Method::Contour, TopKTail::Sampled(points)) => {
                let hemisphere = closure::hemisphere_totals(occluder_triangles, other_mesh);
                let total = match (cfg.top_k_search, hemisphere) {
                    (TopKSearch::Tree, true) => RowTotal::Hemisphere,
                    (TopKSearch::Tree, false) => RowTotal::TreeWalk,
                    (TopKSearch::Exhaustive, _) => RowTotal::Sampled,
                };
                // With links, `total` still says where the row's total comes from (the
                // links' sampled parts are scaled to hemisphere totals, `links.rs`).
                let links = match (cfg.links, cfg.top_k_search) {
                    (Some(m), TopKSearch::Tree) => Some((m, cfg.link_tol)),
                    _ => None,
                };
                Some(DroppedMassRoute::Estimated {
                    total,
                    points,
                    links,
                })
            }
            (true, ..) => Some(DroppedMassRoute::Exact),
        }
    }

    /// Row i: dense, or the k largest entries when `top_k` is set, only those ≥
    /// `min_ff` when that is set. Values are accumulated in f64 and stored as f32.
    ///
    /// # Panics
    /// If `i` is not a patch index (a caller bug, not an input error).
    pub fn compute_row(&self, i: u32, scratch: &mut Scratch) -> Row {
        assert!(
            (i as usize) < self.n(),
            "row {i} out of range (n = {})",
            self.n()
        );
        let n = self.n();
        let k = self.cfg.top_k.map_or(n, |k| k as usize);
        let eps = self.cfg.min_ff.unwrap_or(0.0);
        if let (true, Method::Contour, TopKTail::Sampled(t)) =
            (self.cfg.sparse_rows(), self.cfg.method, self.cfg.top_k_tail)
        {
            let kept = topk_bounded::Kept::new(k, eps);
            return match &self.tree {
                Some(tree) => self.top_k_row_tree(tree, i, kept, t as usize, scratch),
                None => self.top_k_row_bounded(i, kept, t as usize, scratch),
            };
        }
        let mut values = std::mem::take(&mut scratch.values);
        self.row_values(i, scratch, &mut values);
        let row = match self.cfg.sparse_rows() {
            true => topk::top_k_row(i, &values, k, eps, &mut scratch.order),
            false => Row::dense(i, values.iter().map(|&v| v as f32).collect()),
        };
        scratch.values = values;
        row
    }

    /// The compute side of `--symmetric` (reciprocity half, bench/PERF.md section 6):
    /// each unordered pair {a < b} is evaluated once, as `pair_value(a, b)` = F_ab, and
    /// its other direction follows from reciprocity A_a F_ab = A_b F_ba (docs/numerics.md §6):
    /// F_ba = F_ab · A_a / A_b.
    ///
    /// `in_run[j]` says whether row j is computed in this run. Row i owns the pairs
    /// {i, j} with j > i, and also those with j < i when row j is not in the run (it is
    /// already in the file, or skipped on purpose), since no other row will evaluate
    /// them. Out: `own` = (j, F_ij) for every owned column j; `mirrored` = (j, F_ji) for
    /// the owned j > i that are in the run. Row j of the matrix is its own entries
    /// plus the mirrored entries of the rows i < j. Entries that are 0 are left out.
    ///
    /// Whatever `in_run` is, the value of a pair is the same function of (a, b), so a
    /// resumed or `--rows needed` run gives rows bitwise equal to a full one.
    ///
    /// Meant for `contour`, whose two directions agree (exact unoccluded part, a
    /// visibility estimate symmetric in expectation). `point` and `mc` clamp each
    /// direction to 1, so their mirrored value can exceed 1: the CLI refuses them.
    ///
    /// # Panics
    /// If `i` is not a patch index, `in_run.len() != n` or `in_run[i]` is false.
    pub fn half_row(
        &self,
        i: u32,
        in_run: &[bool],
        scratch: &mut Scratch,
        own: &mut Vec<(u32, f64)>,
        mirrored: &mut Vec<(u32, f64)>,
    ) {
        let n = self.n();
        assert!((i as usize) < n, "row {i} out of range (n = {n})");
        assert!(
            in_run.len() == n && in_run[i as usize],
            "row {i} must be one of the n = {n} rows of the run"
        );
        own.clear();
        mirrored.clear();
        scratch.start_row(i);
        let ai = self.geom[i as usize].area;
        for (j, &computed) in in_run.iter().enumerate().take(i as usize) {
            if !computed {
                let f = self.pair_value(j as u32, i, scratch);
                if f > 0.0 {
                    own.push((j as u32, f * self.geom[j].area / ai));
                }
            }
        }
        for j in i + 1..n as u32 {
            let f = self.pair_value(i, j, scratch);
            if f > 0.0 {
                own.push((j, f));
                if in_run[j as usize] {
                    mirrored.push((j, f * ai / self.geom[j as usize].area));
                }
            }
        }
    }

    /// Row i in f64 (dense, before the f32 conversion and top-k), into `out`.
    ///
    /// # Panics
    /// If `i` is not a patch index.
    pub fn row_values(&self, i: u32, scratch: &mut Scratch, out: &mut Vec<f64>) {
        let n = self.n();
        assert!((i as usize) < n, "row {i} out of range (n = {n})");
        out.clear();
        out.resize(n, 0.0);
        scratch.start_row(i);
        if !self.valid[i as usize] {
            return;
        }
        for (j, v) in out.iter_mut().enumerate() {
            *v = self.pair_value(i, j as u32, scratch);
        }
    }

    /// F_ij in f64.
    ///
    /// # Panics
    /// If `i` or `j` is not a patch index.
    pub fn pair_value(&self, i: u32, j: u32, scratch: &mut Scratch) -> f64 {
        let (iu, ju) = (i as usize, j as usize);
        if iu == ju || !self.valid[iu] || !self.valid[ju] {
            return 0.0;
        }
        let gi = &self.geom[iu];
        let gj = &self.geom[ju];
        if self.cfg.method == Method::Point {
            return point::pair(gi, gj, &self.occluders, &mut scratch.pair.counters);
        }
        let Some(extent) = self.facing(iu, ju, scratch) else {
            return 0.0;
        };
        match self.cfg.method {
            Method::Mc => mc::pair(i, j, gi, gj, &self.occluders, &self.cfg, &mut scratch.pair),
            _ => match self.contour_unoccluded((i, j), gi, gj, extent, scratch) {
                Some(u) => self.contour_occluded(i, j, &u, scratch),
                None => 0.0,
            },
        }
    }

    /// None when one patch faces away from the other (every corner on or behind the
    /// other's plane; coplanar pairs included), else the lowest signed distance of
    /// i's corners to j's plane and of j's corners to i's plane (or, when every corner
    /// is clearly in front, a lower bound above the tolerance: callers only compare it
    /// with −tolerance). Counts the pair.
    ///
    /// Decided from the bounding spheres when they are clear of the planes by a margin
    /// (the answer of the corners then cannot differ): they sit in a compact array,
    /// while the corners are in the large per-patch records, and most pairs of a row
    /// are decided here.
    #[inline]
    fn facing(&self, i: usize, j: usize, scratch: &mut Scratch) -> Option<(f64, f64)> {
        let (bi, bj) = (&self.bounds[i], &self.bounds[j]);
        // Signed distance of each centre to the other's plane.
        let dj = bi.normal.dot(bj.centre) - bi.offset;
        let di = bj.normal.dot(bi.centre) - bj.offset;
        let margin = self.tol + self.bound_slack;
        if dj + bj.radius < self.tol - self.bound_slack
            || di + bi.radius < self.tol - self.bound_slack
        {
            scratch.pair.counters.pairs_facing_away += 1;
            return None;
        }
        if dj - bj.radius > margin && di - bi.radius > margin {
            scratch.pair.counters.pairs_evaluated += 1;
            return Some((di - bi.radius, dj - bj.radius));
        }
        let (gi, gj) = (&self.geom[i], &self.geom[j]);
        let (j_lo, j_hi) = gj.extent_wrt(gi);
        let (i_lo, i_hi) = gi.extent_wrt(gj);
        if j_hi <= self.tol || i_hi <= self.tol {
            scratch.pair.counters.pairs_facing_away += 1;
            return None;
        }
        scratch.pair.counters.pairs_evaluated += 1;
        Some((i_lo, j_lo))
    }

    /// The polygons clipped to each other's front half-space; borrowed when nothing
    /// of one lies behind the other's plane (copying two polygons per pair showed up
    /// in profiles at 8.5k patches). `(i_lo, j_lo)` as [`RowEngine::facing`] gives.
    fn clipped<'a>(
        &self,
        gi: &'a PatchGeom,
        gj: &'a PatchGeom,
        (i_lo, j_lo): (f64, f64),
    ) -> (Cow<'a, Polygon>, Cow<'a, Polygon>) {
        let clip = |lo: f64, g: &'a PatchGeom, other: &PatchGeom| {
            if lo < -self.tol {
                Cow::Owned(g.poly.clip_front(other.normal, other.offset, self.tol))
            } else {
                Cow::Borrowed(&g.poly)
            }
        };
        (clip(i_lo, gi, gj), clip(j_lo, gj, gi))
    }

    /// Patches `i`, `j` and their polygons clipped to each other's front half-space, for
    /// the visibility of a pair whose unoccluded part was computed before.
    fn clipped_pair(&self, i: u32, j: u32) -> ClippedPair<'_> {
        let (gi, gj) = (&self.geom[i as usize], &self.geom[j as usize]);
        let (j_lo, _) = gj.extent_wrt(gi);
        let (i_lo, _) = gi.extent_wrt(gj);
        let (pi, pj) = self.clipped(gi, gj, (i_lo, j_lo));
        (gi, gj, pi, pj)
    }

    /// `contour`, unoccluded part: F⁰_ij on the mutually clipped polygons, by the
    /// tensor Gauss rule when the pair is far apart and needs no clipping
    /// ([`super::farfield`]), else by the double contour integral. None when ≤ 0.
    fn contour_unoccluded<'a>(
        &self,
        (i, j): (u32, u32),
        gi: &'a PatchGeom,
        gj: &'a PatchGeom,
        extent: (f64, f64),
        scratch: &mut Scratch,
    ) -> Option<Unoccluded> {
        let clip = extent.0 < -self.tol || extent.1 < -self.tol;
        let (pi, pj) = self.clipped(gi, gj, extent);
        let distance = (gi.centroid - gj.centroid).length();
        let gap = distance - gi.radius - gj.radius;
        let far = if clip {
            None
        } else {
            self.far_orders.order(gap, gi.radius.max(gj.radius))
        };
        let af = if let Some(q) = far {
            scratch.pair.counters.pairs_far_field += 1;
            scratch.far.area_form_factor(
                (self.id, i),
                (&gi.map, gi.normal),
                (&gj.map, gj.normal),
                q,
                self.gauss,
            )
        } else {
            // The edges too are recomputed only for a clipped polygon.
            let edges = |p: &Cow<'_, Polygon>, g: &'a PatchGeom| match p {
                Cow::Borrowed(_) => Cow::Borrowed(&g.edges),
                Cow::Owned(p) => Cow::Owned(EdgeSet::from_polygon(p)),
            };
            let (ei, ej) = (edges(&pi, gi), edges(&pj, gj));
            let r_ref = distance.max(gi.size).max(gj.size);
            area_form_factor_edges(&ei, &ej, r_ref, self.gauss, self.params)
        };
        let f = af / gi.area;
        if f.is_nan() || f <= 0.0 {
            return None;
        }
        let (listed, needs_rays) = self.blockers_between(i, j, gi, gj, &pi, &pj, scratch);
        Some(Unoccluded {
            f,
            needs_rays,
            listed,
        })
    }

    /// Which occluder triangles may block pair (i, j), whose polygons clipped to each
    /// other are `pi`, `pj`: returns (listed, needs_rays). `listed`: they are in
    /// `scratch.candidates` (at most [`MAX_PAIR_CANDIDATES`]) and the pair's rays test
    /// only those instead of walking the hierarchy (16 rays per pair in `accurate`).
    /// `needs_rays` false: nothing can come between, no rays.
    ///
    /// From the list of the two patches' clusters when there is one (see
    /// [`super::clusters`]), else from the hierarchy.
    #[allow(clippy::too_many_arguments)]
    fn blockers_between(
        &self,
        i: u32,
        j: u32,
        gi: &PatchGeom,
        gj: &PatchGeom,
        pi: &Polygon,
        pj: &Polygon,
        scratch: &mut Scratch,
    ) -> (bool, bool) {
        let q = between(gi, gj, pi, pj);
        let occ = &self.occluders;
        let shared = self
            .clusters
            .as_ref()
            .and_then(|c| Some((c, c.of(j)?)))
            .and_then(|(c, cj)| {
                let row = scratch.row.and_then(|r| c.of(r));
                scratch.clusters.list(self.id, c, occ, (i, gi), cj, row)
            });
        let max = self.list_max;
        if let Some(list) = shared {
            // With max = 0 (no lists for rays), only whether there is any.
            occ.filter_between(&q, list, max, &mut scratch.candidates);
            let found = scratch.candidates.len();
            return (max > 0 && found <= max, found > 0);
        }
        if max > 0 {
            let listed =
                occ.collect_between_up_to(&q, max, self.list_rejected, &mut scratch.candidates);
            (listed, !listed || !scratch.candidates.is_empty())
        } else {
            (false, occ.any_between(&q))
        }
    }

    /// `contour`: F_ij of a pair from its unoccluded part `u`: F⁰ when nothing can come
    /// between the polygons, else F⁰ minus what the occluders take away, exactly
    /// ([`Visibility::Exact`] with the candidates listed) or by rays.
    fn contour_occluded(&self, i: u32, j: u32, u: &Unoccluded, scratch: &mut Scratch) -> f64 {
        if !u.needs_rays {
            scratch.pair.counters.pairs_unoccludable += 1;
            scratch.pair.counters.rays_skipped += self.cfg.samples as u64;
            return u.f;
        }
        if !u.listed {
            return self.occluded_unlisted(i, j, u.f, scratch);
        }
        let candidates = std::mem::take(&mut scratch.candidates);
        let exact = (self.cfg.visibility == Visibility::Exact)
            .then(|| self.exact_occluded(&self.clipped_pair(i, j), u.f, &candidates, scratch))
            .flatten();
        let f =
            exact.unwrap_or_else(|| u.f * self.visibility_with(i, j, Some(&candidates), scratch));
        scratch.candidates = candidates;
        f
    }

    /// As [`RowEngine::contour_occluded`] for a pair whose candidates are not listed
    /// (the top-k search, or more candidates than the lists hold): exact visibility
    /// lists them first.
    fn occluded_unlisted(&self, i: u32, j: u32, f0: f64, scratch: &mut Scratch) -> f64 {
        if self.cfg.visibility == Visibility::Exact {
            let pair = self.clipped_pair(i, j);
            let (gi, gj, pi, pj) = &pair;
            let q = between(gi, gj, pi, pj);
            let mut candidates = std::mem::take(&mut scratch.candidates);
            let listed = self.occluders.collect_between_up_to(
                &q,
                EXACT_MAX_CANDIDATES,
                self.list_rejected,
                &mut candidates,
            );
            let exact = listed
                .then(|| self.exact_occluded(&pair, f0, &candidates, scratch))
                .flatten();
            let f = exact.unwrap_or_else(|| {
                let listed = listed.then_some(&candidates[..]);
                f0 * self.visibility_with(i, j, listed, scratch)
            });
            scratch.candidates = candidates;
            return f;
        }
        f0 * self.visibility_of(i, j, scratch)
    }

    /// F_ij / F⁰_ij of a pair that may be occluded (unoccluded value `f0` > 0).
    fn visibility_fraction(&self, i: u32, j: u32, f0: f64, scratch: &mut Scratch) -> f64 {
        match self.cfg.visibility {
            Visibility::Exact => self.occluded_unlisted(i, j, f0, scratch) / f0,
            Visibility::Rays => self.visibility_of(i, j, scratch),
        }
    }

    /// Visibility fraction of pair (i, j) from scratch (re-clipping the polygons).
    fn visibility_of(&self, i: u32, j: u32, scratch: &mut Scratch) -> f64 {
        self.visibility_with(i, j, None, scratch)
    }

    /// Visibility fraction of a pair; its rays test only `candidates` when given (the
    /// pair's list from `Occluders::collect_between`), else walk the hierarchy.
    fn visibility_with(
        &self,
        i: u32,
        j: u32,
        candidates: Option<&[u32]>,
        scratch: &mut Scratch,
    ) -> f64 {
        let (gi, gj, pi, pj) = self.clipped_pair(i, j);
        let occ = visibility::Blockers {
            occluders: &self.occluders,
            candidates,
            last: std::cell::Cell::new(0),
            packets: self.packets,
        };
        visibility::fraction(i, j, gi, gj, &pi, &pj, &occ, &self.cfg, &mut scratch.pair)
    }
}

/// The occluders' question for a pair: what may come between the polygons `pi`, `pj`
/// (clipped to each other) of patches `gi`, `gj`, their own faces not counting.
fn between<'a>(gi: &PatchGeom, gj: &PatchGeom, pi: &'a Polygon, pj: &'a Polygon) -> Between<'a> {
    Between::new(
        pi.verts(),
        gi.normal,
        pj.verts(),
        gj.normal,
        (gi.face, gj.face),
    )
}

/// A pair's patches and their polygons clipped to each other
/// ([`RowEngine::clipped_pair`]).
type ClippedPair<'a> = (
    &'a PatchGeom,
    &'a PatchGeom,
    Cow<'a, Polygon>,
    Cow<'a, Polygon>,
);

/// Unoccluded part of a `contour` pair.
struct Unoccluded {
    f: f64,
    needs_rays: bool,
    /// `Scratch::candidates` lists every triangle that may block the pair.
    listed: bool,
}

mod closure;
mod exact;
mod first_bounce;
mod links;
mod points;
#[cfg(test)]
mod tests;
mod topk_bounded;
mod topk_tree;

/// The kinds the patch tree keeps apart (`PatchTree::with_kinds`): 1 for an emitter,
/// 0 for the others.
fn kinds(patches: &PatchSet) -> Vec<u8> {
    patches
        .patches
        .iter()
        .map(|p| u8::from(p.emission.iter().any(|&e| e > 0.0)))
        .collect()
}

/// The diagonal of the patches' bounding box (1 without patches) and the largest
/// magnitude of a coordinate (the rounding of plane distances grows with it).
fn extent(geom: &[PatchGeom]) -> (f64, f64) {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for g in geom {
        for c in g.poly.verts() {
            lo = lo.min(*c);
            hi = hi.max(*c);
        }
    }
    if geom.is_empty() {
        return (1.0, 0.0);
    }
    ((hi - lo).length(), lo.abs().max(hi.abs()).max_element())
}
