//! Patch clusters: the occluder query of a pair, answered once per pair of clusters.
//!
//! Deciding which occluder triangles may come between two patches (the hull query of
//! `Occluders::collect_between`) walks the hierarchy once per pair, and was the largest
//! single cost of a `contour` row (bench/PERF.md §7). Neighbouring patches of one face
//! ask almost the same question. So the patches of each face are grouped into clusters
//! of about [`CLUSTER_PATCHES`] (cells of a grid in the face's plane), each with a
//! rectangle in that plane that contains all its patches. The query runs once between
//! two clusters' rectangles; a triangle that cannot come between the rectangles cannot
//! come between any patch of one and any patch of the other (every such segment lies
//! in the rectangles' hull, and the planes are the same), so each pair then only
//! narrows that short list (`Occluders::filter_between`). The result is within the set
//! the pair's own query would find (sometimes smaller: the clusters' hull axes can
//! separate a triangle the pair's axes do not) and holds every triangle that can block
//! one of the pair's segments, so rays get the same answers.
//!
//! A cluster pair's list depends on the two clusters only (it is always computed with
//! the lower cluster id first), so what a thread has cached changes the time, never a
//! value: rows stay bitwise equal on any thread or rank.

use std::collections::HashMap;

use glam::DVec3;

use super::geom::PatchGeom;
use crate::geometry::occluders::{Between, Occluders};

/// Patches per cluster the grid aims at (4 × 4 on a quad grid).
pub(crate) const CLUSTER_PATCHES: f64 = 16.0;

/// Clustering is used only when clusters hold at least this many patches on average
/// (scenes whose faces are single patches would only pay for a second query).
const MIN_MEAN_CLUSTER: f64 = 4.0;

/// Most triangles a cluster pair's list holds; with more, the pairs of the two clusters
/// query the hierarchy themselves.
pub(crate) const MAX_CLUSTER_CANDIDATES: usize = 48;

/// Work bound of a cluster pair's query (triangles examined in detail).
const MAX_CLUSTER_REJECTED: usize = 256;

/// Cluster pairs' lists a thread keeps, by the cluster of one side: the rows of a
/// thread come in index order, which walks a face's grid row by row, so the clusters
/// of a few grid rows are in use at a time.
const CACHED_CLUSTERS: usize = 32;

/// The cluster of each patch and each cluster's rectangle.
#[derive(Debug)]
pub(crate) struct Clusters {
    of: Vec<u32>,
    rects: Vec<ClusterRect>,
}

/// A planar convex quadrilateral containing every patch of a cluster.
#[derive(Clone, Copy, Debug)]
struct ClusterRect {
    corners: [DVec3; 4],
    normal: DVec3,
    face: u32,
}

/// No cluster (the patch's pairs query the hierarchy themselves).
const NONE: u32 = u32::MAX;

impl Clusters {
    /// Clusters the valid patches face by face, or with `by_plane` plane by plane
    /// (the patches of one plane facing the same way, whatever their face: a mesh
    /// delivered split into facets has one patch per face, so clusters by face would
    /// hold one patch each); `None` when clusters would be too small to pay off
    /// ([`MIN_MEAN_CLUSTER`]). `diag`: the patches' bounding-box diagonal (faces must
    /// be planar to 1e-12 of it). Clusters by plane are for foreign occluders only,
    /// whose queries ignore triangles by plane: the face ids of native ones would
    /// name one face of the cluster.
    pub(crate) fn new(
        geom: &[PatchGeom],
        valid: &[bool],
        diag: f64,
        by_plane: bool,
    ) -> Option<Self> {
        let mut groups: HashMap<(u32, [i64; 4]), Vec<usize>> = HashMap::new();
        for (i, g) in geom.iter().enumerate() {
            if valid[i] {
                let key = if by_plane {
                    let n = g.normal.normalize_or_zero();
                    let q = |x: f64, step: f64| (x / step).round() as i64;
                    let o = n.dot(g.centroid);
                    (
                        0,
                        [q(n.x, 1e-9), q(n.y, 1e-9), q(n.z, 1e-9), q(o, 1e-9 * diag)],
                    )
                } else {
                    (g.face, [0; 4])
                };
                groups.entry(key).or_default().push(i);
            }
        }
        let mut groups: Vec<Vec<usize>> = groups.into_values().collect();
        // Members are in patch order: order the groups by their first patch.
        groups.sort_unstable_by_key(|m| m[0]);
        let mut c = Clusters {
            of: vec![NONE; geom.len()],
            rects: Vec::new(),
        };
        let mut clustered = 0usize;
        for members in &groups {
            let face = geom[members[0]].face;
            clustered += c.add_face(face, members, geom, 1e-12 * diag, by_plane);
        }
        let mean = clustered as f64 / c.rects.len().max(1) as f64;
        (mean >= MIN_MEAN_CLUSTER).then_some(c)
    }

    /// Grid cells over one face's (or plane's) patches; returns the number of patches
    /// clustered. The group is left out (its pairs query the hierarchy themselves)
    /// unless all its patches have the same normal (with `by_plane`, unit normals
    /// within 1e-12: facets of one plane have their normals computed apart) and every
    /// corner lies within `flat` of the plane through the first corner: the cluster
    /// queries use that plane (an OBJ face may be planar only to 1e-6 of its size, far
    /// more than the occluder tests' tolerance).
    fn add_face(
        &mut self,
        face: u32,
        members: &[usize],
        geom: &[PatchGeom],
        flat: f64,
        by_plane: bool,
    ) -> usize {
        let g0 = &geom[members[0]];
        let normal = g0.normal;
        let unit = normal.normalize_or_zero();
        let same = |n: DVec3| match by_plane {
            true => (n.normalize_or_zero() - unit).length() <= 1e-12,
            false => n == normal,
        };
        if members.iter().any(|&i| !same(geom[i].normal)) {
            return 0;
        }
        let v = g0.poly.verts();
        let origin = v[0];
        let on_plane = members
            .iter()
            .flat_map(|&i| geom[i].poly.verts())
            .all(|p| unit.dot(*p - origin).abs() <= flat);
        if unit == DVec3::ZERO || !on_plane {
            return 0;
        }
        // A frame in the plane: eu along the first patch's first edge.
        let eu = (v[1] - v[0]).reject_from(unit).normalize_or_zero();
        if eu == DVec3::ZERO {
            return 0;
        }
        let ev = unit.cross(eu);
        let uv = |p: DVec3| ((p - origin).dot(eu), (p - origin).dot(ev));
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        let mut area = 0.0;
        for &i in members {
            let (u, v) = uv(geom[i].centroid);
            lo = (lo.0.min(u), lo.1.min(v));
            hi = (hi.0.max(u), hi.1.max(v));
            area += geom[i].area;
        }
        let cell = (CLUSTER_PATCHES * area / members.len() as f64).sqrt();
        if !(cell.is_finite() && cell > 0.0) {
            return 0;
        }
        let cells = |lo: f64, hi: f64| (((hi - lo) / cell).floor() as usize + 1).min(1 << 16);
        let (nu, nv) = (cells(lo.0, hi.0), cells(lo.1, hi.1));
        let cell_of = |p: DVec3| {
            let (u, v) = uv(p);
            let ku = (((u - lo.0) / cell).floor().max(0.0) as usize).min(nu - 1);
            let kv = (((v - lo.1) / cell).floor().max(0.0) as usize).min(nv - 1);
            kv * nu + ku
        };
        // Cells in order of first use, so cluster ids follow patch order.
        let mut id_of_cell: HashMap<usize, u32> = HashMap::new();
        let mut bounds: Vec<((f64, f64), (f64, f64))> = Vec::new();
        let first = self.rects.len() as u32;
        for &i in members {
            let next = first + id_of_cell.len() as u32;
            let id = *id_of_cell.entry(cell_of(geom[i].centroid)).or_insert(next);
            let k = (id - first) as usize;
            if k == bounds.len() {
                bounds.push((
                    (f64::INFINITY, f64::INFINITY),
                    (f64::NEG_INFINITY, f64::NEG_INFINITY),
                ));
            }
            let b = &mut bounds[k];
            for p in geom[i].poly.verts() {
                let (u, v) = uv(*p);
                b.0 = (b.0 .0.min(u), b.0 .1.min(v));
                b.1 = (b.1 .0.max(u), b.1 .1.max(v));
            }
            self.of[i] = id;
        }
        for (lo, hi) in bounds {
            // Widened by a hair so that rounding in the frame (relative to the
            // coordinates' magnitude) cannot put a patch corner outside.
            let pad = 1e-12 * ((hi.0 - lo.0) + (hi.1 - lo.1))
                + 1e-14 * origin.abs().max_element()
                + 1e-300;
            let at = |u: f64, v: f64| origin + eu * u + ev * v;
            self.rects.push(ClusterRect {
                corners: [
                    at(lo.0 - pad, lo.1 - pad),
                    at(hi.0 + pad, lo.1 - pad),
                    at(hi.0 + pad, hi.1 + pad),
                    at(lo.0 - pad, hi.1 + pad),
                ],
                normal,
                face,
            });
        }
        members.len()
    }

    /// Number of clusters.
    pub(crate) fn len(&self) -> usize {
        self.rects.len()
    }

    /// The cluster of patch `i`, if it has one.
    #[inline]
    pub(crate) fn of(&self, i: u32) -> Option<u32> {
        let c = self.of[i as usize];
        (c != NONE).then_some(c)
    }

    /// The list of clusters `a` and `b` (lower id first): `false` when it would be
    /// longer than [`MAX_CLUSTER_CANDIDATES`] or the query gave up.
    fn query(&self, occ: &Occluders, a: u32, b: u32, out: &mut Vec<u32>) -> bool {
        let (a, b) = (a.min(b), a.max(b));
        let (ra, rb) = (&self.rects[a as usize], &self.rects[b as usize]);
        let q = Between::new(
            &ra.corners,
            ra.normal,
            &rb.corners,
            rb.normal,
            (ra.face, rb.face),
        );
        occ.collect_between_up_to(&q, MAX_CLUSTER_CANDIDATES, MAX_CLUSTER_REJECTED, out)
    }
}

/// A thread's lists (in its [`super::Scratch`]): those of cluster pairs, and those of
/// the current patch with each cluster.
#[derive(Debug, Default)]
pub(crate) struct ClusterCache {
    /// Engine the lists belong to.
    engine: Option<u64>,
    pairs: PairLists,
    patch: PatchLists,
}

/// Lists of cluster pairs, by the cluster of one side ([`CACHED_CLUSTERS`] of them).
#[derive(Debug, Default)]
struct PairLists {
    /// Most recently used last.
    entries: Vec<CacheEntry>,
    /// Query output buffer.
    found: Vec<u32>,
}

#[derive(Debug)]
struct CacheEntry {
    cluster: u32,
    /// Per other cluster.
    slots: Vec<Slot>,
    pool: ListPool,
}

/// Where a list is in a [`ListPool`], or that it is not known yet, or that there
/// were too many triangles for a list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Slot {
    start: u32,
    len: u32,
}

impl Slot {
    const UNKNOWN: Slot = Slot {
        start: u32::MAX,
        len: 0,
    };
    const TOO_MANY: Slot = Slot {
        start: u32::MAX,
        len: 1,
    };
}

/// Triangle lists stored back to back.
#[derive(Debug, Default)]
struct ListPool {
    ids: Vec<u32>,
}

impl ListPool {
    fn clear(&mut self) {
        self.ids.clear();
    }

    fn store(&mut self, list: &[u32]) -> Slot {
        let start = self.ids.len() as u32;
        self.ids.extend_from_slice(list);
        Slot {
            start,
            len: list.len() as u32,
        }
    }

    /// The list of a stored slot; `None` for [`Slot::TOO_MANY`].
    fn get(&self, slot: Slot) -> Option<&[u32]> {
        (slot != Slot::TOO_MANY)
            .then(|| &self.ids[slot.start as usize..(slot.start + slot.len) as usize])
    }
}

/// Lists of one patch (the first patch of the pairs asked about, the row's patch in a
/// row) with each cluster: the cluster pair's list narrowed to that patch, so that
/// each pair narrows a shorter list.
#[derive(Debug, Default)]
struct PatchLists {
    patch: Option<u32>,
    /// Generation of the current patch: a slot is valid when it carries it.
    generation: u32,
    /// Per cluster: (generation, where the list is).
    slots: Vec<(u32, Slot)>,
    pool: ListPool,
    found: Vec<u32>,
}

impl ClusterCache {
    /// The triangles that may come between patch `i` (unclipped, `gi`) and any patch
    /// of cluster `b`, computed on first use from the list of `i`'s cluster and `b`;
    /// `None` when that list would be too long. `row`: the cluster of the row being
    /// computed, if known: the cluster pairs' lists are kept by it, so that a half row
    /// asking about pairs (j, i) with j from many clusters does not churn the cache
    /// (only the time depends on it, never a list).
    pub(crate) fn list(
        &mut self,
        engine: u64,
        clusters: &Clusters,
        occ: &Occluders,
        (i, gi): (u32, &PatchGeom),
        b: u32,
        row: Option<u32>,
    ) -> Option<&[u32]> {
        if self.engine != Some(engine) {
            *self = ClusterCache {
                engine: Some(engine),
                ..ClusterCache::default()
            };
        }
        let p = &mut self.patch;
        if p.patch != Some(i) {
            p.patch = Some(i);
            p.pool.clear();
            p.generation = p.generation.wrapping_add(1);
            if p.generation == 0 || p.slots.len() != clusters.len() {
                p.generation = 1;
                p.slots.clear();
                p.slots.resize(clusters.len(), (0, Slot::UNKNOWN));
            }
        }
        let (generation, mut slot) = p.slots[b as usize];
        if generation != p.generation {
            let a = clusters.of(i)?;
            let keep = if row == Some(b) { b } else { a };
            slot = match self.pairs.list(clusters, occ, a, b, keep) {
                Some(list) => {
                    let rb = &clusters.rects[b as usize];
                    let q = Between::new(
                        gi.poly.verts(),
                        gi.normal,
                        &rb.corners,
                        rb.normal,
                        (gi.face, rb.face),
                    );
                    occ.filter_between(&q, list, usize::MAX, &mut p.found);
                    p.pool.store(&p.found)
                }
                None => Slot::TOO_MANY,
            };
            p.slots[b as usize] = (p.generation, slot);
        }
        p.pool.get(slot)
    }
}

impl PairLists {
    /// The triangles that may come between any patch of cluster `a` and any of `b`
    /// (computed on first use); `None` when there are too many for a list. A new
    /// entry is made for `keep` (`a` or `b`) when neither has one.
    fn list(
        &mut self,
        clusters: &Clusters,
        occ: &Occluders,
        a: u32,
        b: u32,
        keep: u32,
    ) -> Option<&[u32]> {
        let found = self
            .entries
            .iter()
            .rposition(|e| e.cluster == a || e.cluster == b);
        let at = match found {
            Some(k) => {
                if k + 1 != self.entries.len() {
                    let e = self.entries.remove(k);
                    self.entries.push(e);
                }
                self.entries.len() - 1
            }
            None => {
                let mut e = if self.entries.len() == CACHED_CLUSTERS {
                    self.entries.remove(0)
                } else {
                    CacheEntry {
                        cluster: keep,
                        slots: Vec::new(),
                        pool: ListPool::default(),
                    }
                };
                e.cluster = keep;
                e.slots.clear();
                e.slots.resize(clusters.len(), Slot::UNKNOWN);
                e.pool.clear();
                self.entries.push(e);
                self.entries.len() - 1
            }
        };
        let e = &mut self.entries[at];
        let other = if e.cluster == a { b } else { a };
        let mut slot = e.slots[other as usize];
        if slot == Slot::UNKNOWN {
            slot = if clusters.query(occ, a, b, &mut self.found) {
                e.pool.store(&self.found)
            } else {
                Slot::TOO_MANY
            };
            e.slots[other as usize] = slot;
        }
        e.pool.get(slot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::sampling::SplitMix64;
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;

    /// A face whose patches are off one plane by more than the flatness allowance
    /// (an OBJ face planar to 1e-7 of its size) gets no clusters: its pairs query the
    /// hierarchy themselves; a planar face next to it does.
    #[test]
    fn faces_not_flat_enough_are_left_out() {
        let quad = |o: DVec3, face: u32, lift: f64| {
            let c = [
                o,
                o + DVec3::X,
                o + DVec3::X + DVec3::Y,
                o + DVec3::Y + DVec3::Z * lift,
            ];
            crate::patch::Patch {
                corners: c,
                n_corners: 4,
                normal: DVec3::Z,
                area: 1.0,
                group: 0,
                face,
                rho: [0.5; 3],
                emission: [0.0; 3],
            }
        };
        let mut patches = Vec::new();
        for k in 0..64 {
            let o = DVec3::new((k % 8) as f64, (k / 8) as f64, 0.0);
            patches.push(quad(o, 0, 0.0));
            patches.push(quad(o + DVec3::Z * 5.0, 1, if k == 9 { 1e-7 } else { 0.0 }));
        }
        let geom: Vec<PatchGeom> = patches.iter().map(PatchGeom::new).collect();
        let valid = vec![true; geom.len()];
        let c = Clusters::new(&geom, &valid, 10.0, false).expect("face 0 is clustered");
        for (i, p) in patches.iter().enumerate() {
            assert_eq!(c.of(i as u32).is_some(), p.face == 0, "patch {i}");
        }
    }

    /// On the 16-box room: every patch lies in its cluster's rectangle (same plane);
    /// a cluster pair's list, narrowed to one patch and then to a pair, is within the set the
    /// hierarchy query finds for that pair and gives every segment between the two
    /// patches the hierarchy's answer; the list is the same from either side and
    /// whatever the cache held before.
    #[test]
    fn narrowed_cluster_lists_answer_like_the_hierarchy() {
        let scene = builtin("room", None).unwrap();
        let patches = subdivide(&scene, default_max_edge(&scene, 2500));
        let occ = Occluders::new(scene.triangles().collect());
        let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
        let valid: Vec<bool> = geom.iter().map(PatchGeom::is_valid).collect();
        let c = Clusters::new(&geom, &valid, 20.0, false).expect("the room's faces are subdivided");
        assert!(c.len() > 2 * CACHED_CLUSTERS && c.len() < geom.len() / 4);
        for (i, g) in geom.iter().enumerate() {
            let r = &c.rects[c.of(i as u32).unwrap() as usize];
            assert_eq!((r.face, r.normal), (g.face, g.normal));
            let (e1, e2) = (r.corners[1] - r.corners[0], r.corners[3] - r.corners[0]);
            for p in g.poly.verts() {
                let d = *p - r.corners[0];
                assert!(
                    d.dot(r.normal).abs() < 1e-9,
                    "patch {i} off its cluster's plane"
                );
                let (u, v) = (
                    d.dot(e1) / e1.length_squared(),
                    d.dot(e2) / e2.length_squared(),
                );
                assert!(
                    (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v),
                    "patch {i} outside"
                );
            }
        }
        let (mut cache, mut pair_lists) = (ClusterCache::default(), PairLists::default());
        let mut rng = SplitMix64::new(11);
        let (mut narrowed, mut reference) = (Vec::new(), Vec::new());
        let (mut pairs, mut empty, mut some, mut tighter, mut blocked) = (0, 0, 0, 0, 0);
        let n = geom.len();
        while pairs < 3000 {
            let (i, j) = (rng.below(n) as u32, rng.below(n) as u32);
            let (gi, gj) = (&geom[i as usize], &geom[j as usize]);
            // Pairs fully in front of each other (the engine clips the others first).
            let front = |a: &PatchGeom, b: &PatchGeom| {
                a.poly
                    .verts()
                    .iter()
                    .all(|p| b.normal.dot(*p - b.centroid) > 1e-9)
            };
            if !(front(gi, gj) && front(gj, gi)) {
                continue;
            }
            pairs += 1;
            let (ci, cj) = (c.of(i).unwrap(), c.of(j).unwrap());
            // Alternate the side first asked, and sometimes forget everything.
            if rng.below(50) == 0 {
                pair_lists = PairLists::default();
            }
            let (a, b) = if rng.below(2) == 0 {
                (ci, cj)
            } else {
                (cj, ci)
            };
            let Some(list) = pair_lists.list(&c, &occ, a, b, a).map(|l| l.to_vec()) else {
                continue;
            };
            let other = pair_lists.list(&c, &occ, b, a, a).map(|l| l.to_vec());
            assert_eq!(Some(&list), other.as_ref(), "clusters {a}, {b}");
            // Narrowed to patch i, then to the pair.
            let of_i = cache
                .list(1, &c, &occ, (i, gi), cj, None)
                .expect("the clusters' list exists");
            assert!(of_i.iter().all(|k| list.contains(k)));
            let q = gi.between(gj);
            occ.filter_between(&q, of_i, usize::MAX, &mut narrowed);
            let all = usize::MAX;
            assert!(occ.collect_between_up_to(&q, all, all, &mut reference));
            narrowed.sort_unstable();
            reference.sort_unstable();
            assert!(
                narrowed.iter().all(|k| reference.binary_search(k).is_ok()),
                "pair ({i}, {j}): {narrowed:?} not within {reference:?}"
            );
            tighter += (narrowed.len() < reference.len()) as usize;
            empty += narrowed.is_empty() as usize;
            some += !narrowed.is_empty() as usize;
            // What the list leaves out blocks nothing: segments between the patches
            // get the hierarchy's answer.
            let mut first = 0;
            for _ in 0..20 {
                let mut r = || rng.next_f64();
                let x = gi.map.eval(r(), r()).0;
                let y = gj.map.eval(r(), r()).0;
                let by_list = occ.occluded_by(x, y, &narrowed, None, &mut first);
                assert_eq!(
                    by_list,
                    occ.occluded(x, y, q.ignore),
                    "pair ({i}, {j}): {x} -> {y}"
                );
                blocked += by_list as usize;
            }
        }
        assert!(
            empty > 300 && some > 300 && blocked > 1000,
            "{empty} pairs with no candidate, {some} with some, {blocked} blocked segments"
        );
        // Tighter than the pair's own query at times: the clusters' hull axes
        // separate some triangles the pair's axes do not.
        assert!(tighter > 0);
    }
}
