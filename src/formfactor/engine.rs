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

use std::sync::Arc;

use glam::DVec3;

use super::contour::{area_form_factor_edges, ContourParams};
use super::polygon::{EdgeSet, Polygon};
use super::quadrature::{gauss_table, GaussTable};
use super::sampling::PatchMap;
use super::{mc, point, topk, visibility, FormFactorConfig, Method};
use crate::geometry::bvh::Occluders;
use crate::patch::PatchSet;
use crate::rows::Row;

/// Plane tolerance of the facing and clipping tests, relative to the diagonal of the
/// patches' bounding box (so it scales with the scene).
const PLANE_RELATIVE_TOLERANCE: f64 = 1e-10;

/// Work done, for reports and benchmarks. Summed over scratches by the caller.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Rows computed.
    pub rows: u64,
    /// Pairs (i ≠ j) whose kernel was evaluated.
    pub pairs_evaluated: u64,
    /// Pairs skipped without kernel work because one faces away from the other
    /// (including coplanar pairs).
    pub pairs_facing_away: u64,
    /// Evaluated pairs between which no occluder can come (no rays needed).
    pub pairs_unoccludable: u64,
    /// Shadow rays cast.
    pub rays_cast: u64,
    /// Rays the per-pair budget allowed but that were not cast: all of them for pairs
    /// no occluder can come between, the rest of the budget when the adaptive
    /// estimate stopped after its first batch (`contour`), samples with a
    /// non-positive kernel (`mc`).
    pub rays_skipped: u64,
}

impl Counters {
    pub fn add(&mut self, o: &Counters) {
        self.rows += o.rows;
        self.pairs_evaluated += o.pairs_evaluated;
        self.pairs_facing_away += o.pairs_facing_away;
        self.pairs_unoccludable += o.pairs_unoccludable;
        self.rays_cast += o.rays_cast;
        self.rays_skipped += o.rays_skipped;
    }
}

/// Per-thread working memory of [`RowEngine::compute_row`].
#[derive(Debug, Default)]
pub struct Scratch {
    pub(crate) values: Vec<f64>,
    pub(crate) order: Vec<u32>,
    pub(crate) perms: Vec<u32>,
    pub(crate) samples: Vec<[f64; 4]>,
    pub(crate) counters: Counters,
}

impl Scratch {
    pub fn new() -> Self {
        Self::default()
    }

    /// Counters accumulated since creation or the last [`Scratch::take_counters`].
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Returns the counters and resets them.
    pub fn take_counters(&mut self) -> Counters {
        std::mem::take(&mut self.counters)
    }
}

/// Everything the kernels need about one patch, computed once.
#[derive(Clone, Debug)]
pub(crate) struct PatchGeom {
    pub poly: Polygon,
    pub edges: EdgeSet,
    pub normal: DVec3,
    /// normal · x for x on the patch's plane.
    pub offset: f64,
    pub centroid: DVec3,
    pub area: f64,
    /// Longest edge.
    pub size: f64,
    pub face: u32,
    pub map: PatchMap,
}

impl PatchGeom {
    fn new(p: &crate::patch::Patch) -> Self {
        let poly = Polygon::new(p.corners());
        let edges = EdgeSet::from_polygon(&poly);
        let size = edges.edges().iter().map(|e| e.len).fold(0.0, f64::max);
        let centroid = p.centroid();
        PatchGeom {
            poly,
            edges,
            normal: p.normal,
            offset: p.normal.dot(centroid),
            centroid,
            area: p.area,
            size,
            face: p.face,
            map: PatchMap::new(p.corners(), p.area),
        }
    }

    /// Largest and smallest signed distance of this patch's corners to `other`'s plane.
    #[inline]
    fn extent_wrt(&self, other: &PatchGeom) -> (f64, f64) {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for c in self.poly.verts() {
            let d = other.normal.dot(*c) - other.offset;
            lo = lo.min(d);
            hi = hi.max(d);
        }
        (lo, hi)
    }

    /// A usable patch: positive finite area and a unit normal.
    fn is_valid(&self) -> bool {
        self.area > 0.0
            && self.area.is_finite()
            && (self.normal.length() - 1.0).abs() < 1e-6
            && self.poly.n >= 3
    }
}

/// Computes form-factor rows; shared by all threads of a process.
#[derive(Debug)]
pub struct RowEngine {
    patches: Arc<PatchSet>,
    occluders: Arc<Occluders>,
    cfg: FormFactorConfig,
    geom: Vec<PatchGeom>,
    valid: Vec<bool>,
    gauss: &'static GaussTable,
    params: ContourParams,
    tol: f64,
}

impl RowEngine {
    /// Precomputes per-patch data. Patches with zero area (or no proper normal) get
    /// zero rows and columns. The configuration should have passed
    /// [`FormFactorConfig::validate`]; out-of-range values are clamped.
    pub fn new(patches: Arc<PatchSet>, occluders: Arc<Occluders>, cfg: FormFactorConfig) -> Self {
        let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
        let valid = geom.iter().map(PatchGeom::is_valid).collect();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for g in &geom {
            for c in g.poly.verts() {
                lo = lo.min(*c);
                hi = hi.max(*c);
            }
        }
        let diag = if geom.is_empty() {
            1.0
        } else {
            (hi - lo).length()
        };
        let params = cfg.contour_params();
        RowEngine {
            patches,
            occluders,
            cfg,
            geom,
            valid,
            gauss: gauss_table(),
            params,
            tol: PLANE_RELATIVE_TOLERANCE * diag,
        }
    }

    pub fn patches(&self) -> &Arc<PatchSet> {
        &self.patches
    }

    pub fn occluders(&self) -> &Arc<Occluders> {
        &self.occluders
    }

    pub fn config(&self) -> &FormFactorConfig {
        &self.cfg
    }

    /// Number of patches (rows and columns).
    pub fn n(&self) -> usize {
        self.geom.len()
    }

    /// The parameters that determine the numbers, for the file header.
    pub fn describe(&self) -> String {
        format!(
            "{} occluder_triangles={}",
            self.cfg.describe(),
            self.occluders.len()
        )
    }

    /// Row i: dense, or the k largest entries when `top_k` is set. Values are
    /// accumulated in f64 and stored as f32.
    ///
    /// # Panics
    /// If `i` is not a patch index (a caller bug, not an input error).
    pub fn compute_row(&self, i: u32, scratch: &mut Scratch) -> Row {
        assert!(
            (i as usize) < self.n(),
            "row {i} out of range (n = {})",
            self.n()
        );
        let mut values = std::mem::take(&mut scratch.values);
        self.row_values(i, scratch, &mut values);
        let row = match self.cfg.top_k {
            Some(k) => topk::top_k_row(i, &values, k as usize, &mut scratch.order),
            None => Row::dense(i, values.iter().map(|&v| v as f32).collect()),
        };
        scratch.values = values;
        row
    }

    /// Row i in f64 (before the f32 conversion and top-k), into `out`.
    ///
    /// # Panics
    /// If `i` is not a patch index.
    pub fn row_values(&self, i: u32, scratch: &mut Scratch, out: &mut Vec<f64>) {
        let n = self.n();
        assert!((i as usize) < n, "row {i} out of range (n = {n})");
        out.clear();
        out.resize(n, 0.0);
        scratch.counters.rows += 1;
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
            return point::pair(gi, gj, &self.occluders, &mut scratch.counters);
        }
        let (j_lo, j_hi) = gj.extent_wrt(gi);
        let (i_lo, i_hi) = gi.extent_wrt(gj);
        if j_hi <= self.tol || i_hi <= self.tol {
            scratch.counters.pairs_facing_away += 1;
            return 0.0;
        }
        scratch.counters.pairs_evaluated += 1;
        match self.cfg.method {
            Method::Mc => mc::pair(i, j, gi, gj, &self.occluders, &self.cfg, scratch),
            _ => self.contour_pair(i, j, gi, gj, (i_lo, j_lo), scratch),
        }
    }

    /// `contour`: exact unoccluded F_ij on the mutually clipped polygons, times the
    /// visibility fraction.
    fn contour_pair(
        &self,
        i: u32,
        j: u32,
        gi: &PatchGeom,
        gj: &PatchGeom,
        (i_lo, j_lo): (f64, f64),
        scratch: &mut Scratch,
    ) -> f64 {
        // Clip only when part of a polygon is behind the other's plane.
        let clip_i = i_lo < -self.tol;
        let clip_j = j_lo < -self.tol;
        let pi = if clip_i {
            gi.poly.clip_front(gj.normal, gj.offset, self.tol)
        } else {
            gi.poly
        };
        let pj = if clip_j {
            gj.poly.clip_front(gi.normal, gi.offset, self.tol)
        } else {
            gj.poly
        };
        let ei = if clip_i {
            EdgeSet::from_polygon(&pi)
        } else {
            gi.edges
        };
        let ej = if clip_j {
            EdgeSet::from_polygon(&pj)
        } else {
            gj.edges
        };
        let r_ref = (gi.centroid - gj.centroid)
            .length()
            .max(gi.size)
            .max(gj.size);
        let af = area_form_factor_edges(&ei, &ej, r_ref, self.gauss, self.params);
        let f = af / gi.area;
        if f.is_nan() || f <= 0.0 {
            return 0.0;
        }
        let (ni, nj) = (gi.normal, gj.normal);
        if !self
            .occluders
            .any_between(pi.verts(), ni, pj.verts(), nj, (gi.face, gj.face))
        {
            scratch.counters.pairs_unoccludable += 1;
            scratch.counters.rays_skipped += self.cfg.samples as u64;
            return f;
        }
        let v = visibility::fraction(i, j, gi, gj, &pi, &pj, &self.occluders, &self.cfg, scratch);
        f * v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::patch::Patch;
    use glam::dvec3;

    fn square(origin: DVec3, u: DVec3, v: DVec3, face: u32) -> Patch {
        let n = u.cross(v);
        Patch {
            corners: [origin, origin + u, origin + u + v, origin + v],
            n_corners: 4,
            normal: n.normalize(),
            area: n.length(),
            group: 0,
            face,
            rho: [0.5; 3],
            emission: [0.0; 3],
        }
    }

    /// Two unit squares facing each other at distance 1 (Howell C-11, X = Y = 1).
    fn facing_pair() -> PatchSet {
        PatchSet {
            patches: vec![
                square(
                    dvec3(0.0, 0.0, 0.0),
                    dvec3(1.0, 0.0, 0.0),
                    dvec3(0.0, 1.0, 0.0),
                    0,
                ),
                square(
                    dvec3(0.0, 0.0, 1.0),
                    dvec3(0.0, 1.0, 0.0),
                    dvec3(1.0, 0.0, 0.0),
                    1,
                ),
            ],
            groups: vec!["g".into()],
        }
    }

    #[test]
    fn contour_single_pair_matches_howell() {
        let e = RowEngine::new(
            Arc::new(facing_pair()),
            Arc::new(Occluders::empty()),
            FormFactorConfig::accurate(),
        );
        let mut s = Scratch::new();
        let f = e.pair_value(0, 1, &mut s);
        assert!((f - 0.19982489570).abs() < 1e-10, "{f}");
        assert_eq!(e.pair_value(0, 0, &mut s), 0.0);
        let c = s.counters();
        assert_eq!(c.pairs_evaluated, 1);
        assert_eq!(c.rays_cast, 0);
    }

    #[test]
    fn facing_away_costs_nothing() {
        let mut ps = facing_pair();
        // Turn the upper square around: it now faces up, away from the lower one.
        ps.patches[1] = square(
            dvec3(0.0, 0.0, 1.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
            1,
        );
        let e = RowEngine::new(
            Arc::new(ps),
            Arc::new(Occluders::empty()),
            FormFactorConfig::accurate(),
        );
        let mut s = Scratch::new();
        assert_eq!(e.pair_value(0, 1, &mut s), 0.0);
        assert_eq!(s.counters().pairs_facing_away, 1);
        assert_eq!(s.counters().pairs_evaluated, 0);
    }
}
