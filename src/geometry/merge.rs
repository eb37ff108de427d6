//! Coplanar occluders merged into fewer, larger triangles.
//!
//! A mesh that arrives already split into facets (a city meshed for an urban climate
//! model, a CAD export) gives the occluders thousands of small triangles where a few
//! large ones would block the same segments: a wall split into a 3 m grid is a hundred
//! triangles, one rectangle as an occluder. The exact visibility route clips one shadow
//! per candidate triangle and sends a pair with more than 32 candidates to rays, so
//! split occluders cost it an order of magnitude in time and some accuracy
//! (bench/PERF.md §19–20); the hierarchy and the rays gain a little too.
//!
//! Triangles are grouped by plane (unit normal up to sign and offset, within
//! [`PLANE_TOLERANCE`] of the scene's diagonal); each group's triangles are mapped to
//! the plane's 2D frame, oriented counter-clockwise, and their union is taken by a
//! polygon boolean (`i_overlay`, through `i_triangle`'s re-export; non-zero fill, so
//! overlapping or T-junctioned facets merge as well as edge-sharing ones), with the
//! points that lie on a straight edge removed, then triangulated again (`i_triangle`,
//! holes kept). The output vertices are snapped back to the group's input vertices
//! (a union of facets without overlaps has no other vertices), so merged triangles
//! keep the input coordinates bit for bit and share edges exactly, as the watertight
//! ray test needs. A group is replaced only when that gives fewer triangles and the
//! merged area equals the input's within [`AREA_TOLERANCE`] when no input triangles
//! overlap: otherwise it stays as it was. Faces block from both sides, so a face's
//! orientation does not matter here.
//!
//! The merged triangles no longer belong to one scene face each, so the occluders they
//! build are foreign ([`super::occluders::Occluders::new_foreign`]): self-occlusion is
//! told apart by the patches' planes, as with `--occluders`. That is exact: a segment
//! between two patches meets the plane of either only at its own end.

use std::collections::HashMap;

use glam::{DVec2, DVec3};
use i_triangle::float::triangulator::Triangulator;
use i_triangle::i_overlay::core::fill_rule::FillRule;
use i_triangle::i_overlay::float::simplify::SimplifyShape;
use i_triangle::int::validation::Validation;

use super::occluders::Occluders;

/// Plane tolerance of the grouping, relative to the diagonal of the triangles'
/// bounding box: a vertex this close to a group's plane is on it.
pub const PLANE_TOLERANCE: f64 = 1e-9;

/// Largest relative difference between a group's input and merged areas accepted (the
/// merged triangles come from an integer grid of about 2⁻⁶⁰ of the group's extent, and
/// are then snapped back to the input vertices).
pub const AREA_TOLERANCE: f64 = 1e-9;

/// Most triangles of a group whose union came out smaller than its parts that are
/// checked for overlaps (quadratic); a larger such group stays as it was.
const MAX_OVERLAP_CHECK: usize = 4096;

/// What [`merge_coplanar`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Merged {
    /// The occluder triangles: merged groups, then the triangles left as they were.
    pub triangles: Vec<[DVec3; 3]>,
    /// Input triangles that are finite and not degenerate.
    pub input: usize,
    /// Planes whose triangles were merged.
    pub groups: usize,
}

/// The occluder triangles of a job as [`OccluderMesh::prepare`] makes them: as given, or
/// with each plane's triangles merged ([`merge_coplanar`]). Every job builds its
/// occluders through it (`job::build_job`, which the row benchmark uses too), and the
/// header records its counts (`occluder_triangles=`, `occluders_merged=`).
#[derive(Clone, Debug)]
pub struct OccluderMesh {
    /// The triangles the hierarchy is built over, each with its scene face (merged
    /// triangles are numbered from 0 and belong to no face: `foreign` is then set).
    pub triangles: Vec<(u32, [DVec3; 3])>,
    /// How many of the triangles as given the occluders keep (the header's
    /// `occluder_triangles=`; `occluders_merged=` is the second of `merged`).
    pub given: usize,
    /// Planes merged and the triangles left after merging, when any plane was merged.
    pub merged: Option<(usize, usize)>,
    /// Whether the face ids mean nothing to the patches (another mesh, or merged).
    pub foreign: bool,
    /// Whether the triangles come from another mesh than the patches' scene.
    pub other_mesh: bool,
}

impl OccluderMesh {
    /// `tris` (from the patches' own scene, or from another mesh when `foreign`), merged
    /// when `merge` is set and some plane gains from it.
    pub fn prepare(tris: Vec<(u32, [DVec3; 3])>, foreign: bool, merge: bool) -> Self {
        let given = Occluders::count_kept(tris.clone());
        let merged = merge
            .then(|| merge_coplanar(tris.iter().map(|t| t.1)))
            .filter(|m| m.groups > 0);
        match merged {
            Some(m) => {
                let triangles: Vec<_> = (0u32..).zip(m.triangles).collect();
                let kept = Occluders::count_kept(triangles.clone());
                OccluderMesh {
                    triangles,
                    given,
                    merged: Some((m.groups, kept)),
                    foreign: true,
                    other_mesh: foreign,
                }
            }
            None => OccluderMesh {
                triangles: tris,
                given,
                merged: None,
                foreign,
                other_mesh: foreign,
            },
        }
    }

    /// The hierarchy over the triangles.
    pub fn build(self) -> Occluders {
        let mut o = match self.foreign {
            true => Occluders::new_foreign(self.triangles),
            false => Occluders::new(self.triangles),
        };
        o.surfaces_are_patches = !self.other_mesh;
        o
    }
}

/// The triangles of `tris` (any order; degenerate and non-finite ones are dropped, as
/// the occluders would drop them) with each plane's triangles merged where that makes
/// fewer. Deterministic: the same input gives the same output on every rank.
pub fn merge_coplanar(tris: impl IntoIterator<Item = [DVec3; 3]>) -> Merged {
    let tris: Vec<Plane> = tris.into_iter().filter_map(Plane::of).collect();
    let input = tris.len();
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for p in tris.iter().flat_map(|p| p.v) {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let diag = (hi - lo).length();
    if input < 2 || diag.is_nan() || diag <= 0.0 {
        return Merged {
            triangles: tris.into_iter().map(|p| p.v).collect(),
            input,
            groups: 0,
        };
    }
    let tol = PLANE_TOLERANCE * diag;
    // Group by a rounded plane key, then check every vertex against the group's first
    // plane: a rounding boundary can only split a group (less merging), never join two
    // planes.
    let key = |p: &Plane| {
        let q = |x: f64, step: f64| (x / step).round() as i64;
        (
            q(p.normal.x, 1e-8),
            q(p.normal.y, 1e-8),
            q(p.normal.z, 1e-8),
            q(p.offset, 64.0 * tol),
        )
    };
    let mut order: Vec<usize> = (0..input).collect();
    order.sort_by_key(|&k| (key(&tris[k]), k));
    let mut out = Merged {
        triangles: Vec::with_capacity(input),
        input,
        groups: 0,
    };
    let mut rest = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let k0 = key(&tris[order[start]]);
        let end = start
            + order[start..]
                .iter()
                .take_while(|&&k| key(&tris[k]) == k0)
                .count();
        let rep = tris[order[start]];
        let (members, strays): (Vec<usize>, Vec<usize>) =
            order[start..end].iter().partition(|&&k| {
                tris[k]
                    .v
                    .iter()
                    .all(|&p| (rep.normal.dot(p) - rep.offset).abs() <= tol)
            });
        rest.extend(strays);
        match (members.len() >= 2)
            .then(|| merge_group(&rep, members.iter().map(|&k| tris[k].v), tol))
            .flatten()
        {
            Some(merged) if merged.len() < members.len() => {
                out.groups += 1;
                out.triangles.extend(merged);
            }
            _ => rest.extend(members),
        }
        start = end;
    }
    rest.sort_unstable();
    out.triangles.extend(rest.into_iter().map(|k| tris[k].v));
    out
}

/// A triangle with its plane, the normal's sign fixed (largest component positive) so
/// that the two sides of a face fall in one group.
#[derive(Clone, Copy, Debug)]
struct Plane {
    v: [DVec3; 3],
    normal: DVec3,
    offset: f64,
}

impl Plane {
    fn of(v: [DVec3; 3]) -> Option<Plane> {
        if !v.iter().all(|p| p.is_finite()) {
            return None;
        }
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let len = n.length();
        if !(len.is_finite() && len > 0.0) {
            return None;
        }
        let mut normal = n / len;
        let a = normal.abs();
        let big = if a.x >= a.y && a.x >= a.z {
            normal.x
        } else if a.y >= a.z {
            normal.y
        } else {
            normal.z
        };
        if big < 0.0 {
            normal = -normal;
        }
        let offset = normal.dot((v[0] + v[1] + v[2]) / 3.0);
        Some(Plane { v, normal, offset })
    }
}

/// The union of coplanar triangles, triangulated again; None when the polygon boolean
/// gives something that does not check out (then the triangles stay as they were).
fn merge_group(
    rep: &Plane,
    tris: impl Iterator<Item = [DVec3; 3]>,
    tol: f64,
) -> Option<Vec<[DVec3; 3]>> {
    let u = rep.normal.any_orthonormal_vector();
    let w = rep.normal.cross(u);
    let origin = rep.v[0];
    let flat = |p: DVec3| DVec2::new((p - origin).dot(u), (p - origin).dot(w));
    let mut contours: Vec<Vec<[f64; 2]>> = Vec::new();
    let mut vertices: Vec<(DVec2, DVec3)> = Vec::new();
    let mut input_area = 0.0;
    for mut t in tris {
        let mut c = t.map(flat);
        let area = 0.5 * (c[1] - c[0]).perp_dot(c[2] - c[0]);
        if area < 0.0 {
            c.swap(1, 2);
            t.swap(1, 2);
        }
        input_area += area.abs();
        contours.push(c.iter().map(|p| [p.x, p.y]).collect());
        vertices.extend(c.iter().zip(t).map(|(&p2, p3)| (p2, p3)));
    }
    let mut shapes = contours.simplify_shape_as::<i64>(FillRule::NonZero);
    // The boolean removes points on a straight edge only when they are exactly on it
    // in its integer grid; rounding leaves the points of a tilted edge a hair off.
    for contour in shapes.iter_mut().flatten() {
        drop_straight_points(contour, tol);
    }
    // Delaunay: of the triangulations with these vertices, the one with the fewest
    // slivers, which keeps the tree's boxes small.
    let mut triangulator = Triangulator::<u32, i64>::new(
        64,
        Validation::with_fill_rule(FillRule::NonZero),
        Default::default(),
    );
    triangulator.delaunay(true);
    let mesh = triangulator.triangulate(&shapes);
    let snap = Snap::new(&vertices, tol);
    let points: Vec<DVec3> = mesh
        .points
        .iter()
        .map(|p| {
            let q = DVec2::new(p[0], p[1]);
            snap.nearest(q).unwrap_or(origin + q.x * u + q.y * w)
        })
        .collect();
    let mut merged = Vec::with_capacity(mesh.indices.len() / 3);
    let mut merged_area = 0.0;
    for t in mesh.indices.chunks_exact(3) {
        let v = [0, 1, 2].map(|k| points[t[k] as usize]);
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let area = 0.5 * n.length();
        if !(area.is_finite() && area > 0.0) {
            continue;
        }
        merged_area += area;
        merged.push(v);
    }
    // The union is never larger than the parts, and equal to them when the facets do
    // not overlap (the usual mesh): a larger union, or one that lost area while every
    // input vertex is a merged vertex too (no overlap made new ones), means the boolean
    // went wrong.
    let rel = (merged_area - input_area) / input_area;
    if rel.is_nan() || rel > AREA_TOLERANCE || merged.is_empty() {
        return None;
    }
    if rel < -AREA_TOLERANCE && (contours.len() > MAX_OVERLAP_CHECK || !overlapping(&contours)) {
        return None;
    }
    Some(merged)
}

/// Removes from the closed contour `c` the points within `tol` of the line through
/// their neighbours, pointing on (they lie on a straight edge: T-junctions of the
/// facets, grid points along a wall), until none is left.
fn drop_straight_points(c: &mut Vec<[f64; 2]>, tol: f64) {
    let p = |q: [f64; 2]| DVec2::new(q[0], q[1]);
    let mut k = 0;
    let mut since = 0;
    while c.len() > 3 && since < c.len() {
        let n = c.len();
        let (a, b, d) = (p(c[(k + n - 1) % n]), p(c[k % n]), p(c[(k + 1) % n]));
        let e = d - a;
        let len = e.length();
        let straight = len > 0.0
            && (b - a).perp_dot(e).abs() <= tol * len
            && (b - a).dot(e) > 0.0
            && (d - b).dot(e) > 0.0;
        if straight {
            c.remove(k % n);
            since = 0;
        } else {
            k = (k + 1) % n;
            since += 1;
        }
    }
}

/// Whether some two of the (counter-clockwise) triangles overlap with positive area:
/// their interiors intersect. Quadratic, but only asked when a group lost area.
fn overlapping(tris: &[Vec<[f64; 2]>]) -> bool {
    let tri = |c: &Vec<[f64; 2]>| c.iter().map(|p| DVec2::new(p[0], p[1])).collect::<Vec<_>>();
    // Separating axis test on the edge normals, strict: touching is not overlapping.
    let separated = |a: &[DVec2], b: &[DVec2]| {
        [a, b].iter().any(|poly| {
            (0..3).any(|k| {
                let e = poly[(k + 1) % 3] - poly[k];
                let n = e.perp();
                let scale = e.length() * (a[0].length() + b[0].length() + 1.0);
                let (alo, ahi) = span(a, n);
                let (blo, bhi) = span(b, n);
                ahi <= blo + 1e-12 * scale || bhi <= alo + 1e-12 * scale
            })
        })
    };
    fn span(p: &[DVec2], n: DVec2) -> (f64, f64) {
        p.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                let d = n.dot(*v);
                (lo.min(d), hi.max(d))
            })
    }
    let t: Vec<Vec<DVec2>> = tris.iter().map(tri).collect();
    (0..t.len()).any(|i| (i + 1..t.len()).any(|j| !separated(&t[i], &t[j])))
}

/// The input vertices of a group, found again by their 2D position.
struct Snap<'a> {
    cells: HashMap<(i64, i64), Vec<usize>>,
    vertices: &'a [(DVec2, DVec3)],
    radius: f64,
}

impl<'a> Snap<'a> {
    fn new(vertices: &'a [(DVec2, DVec3)], radius: f64) -> Self {
        let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (k, (p, _)) in vertices.iter().enumerate() {
            cells.entry(Self::cell(*p, radius)).or_default().push(k);
        }
        Snap {
            cells,
            vertices,
            radius,
        }
    }

    fn cell(p: DVec2, radius: f64) -> (i64, i64) {
        ((p.x / radius).floor() as i64, (p.y / radius).floor() as i64)
    }

    /// The input vertex nearest `p` within the radius (the first in input order among
    /// equally near ones), if any.
    fn nearest(&self, p: DVec2) -> Option<DVec3> {
        let (cx, cy) = Self::cell(p, self.radius);
        let mut best: Option<(f64, usize)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for &k in self.cells.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                    let d = self.vertices[k].0.distance(p);
                    if d <= self.radius && best.is_none_or(|(bd, bk)| (d, k) < (bd, bk)) {
                        best = Some((d, k));
                    }
                }
            }
        }
        best.map(|(_, k)| self.vertices[k].1)
    }
}

#[cfg(test)]
mod tests;
