//! The discontinuity cells: P_i cut into convex cells along the lines where the
//! integrand is not smooth, so that the rule sees a smooth integrand on each. It jumps
//! where a caster touching P_i's plane crosses it; it has kinks where a caster vertex
//! lines up with an edge of P_j, or a vertex of P_j with a caster edge (for a convex
//! solid, the edges of its silhouette).

use glam::DVec3;

use super::caster::Caster;
use super::cone::{usable, Piece};
use super::hidden::segments_may_cross;
use super::pair::Pair;
use crate::formfactor::shadow::solids::{Solid, NO_SOLID};

/// Most cells [`split_at_events`] cuts P_i into. A kink left uncut can fool the rule:
/// a triangle that barely crosses it may have all its samples on one side, so that its
/// two rules agree to rounding while the sliver beyond differs. With 64
/// cells a box between two squares came out 1.8e-8 of F⁰ off with its estimate at
/// 1e-11; it needs 88 (bench/PERF.md §30). 256 cost nothing measurable on the Cornell
/// box and 3 % on the room at 1e-3.
pub(super) const MAX_CELLS: usize = 256;

/// Cuts P_i into convex cells along the lines where the shadows change shape (where
/// the integrand has kinks), so that the rule sees a smooth integrand on each: the
/// points x at which a caster vertex v lines up with an edge p→q of P_j (x in the plane
/// of p, q, v), or a vertex p of P_j with a caster edge v→w (the plane of p, v, w), and
/// the caster's own plane (where the integrand jumps: a caster touching P_i's plane
/// hides much from one side of its plane and nothing from the plane itself).
/// (Where two casters' shadow edges cross, and where three edges line up, kinks
/// remain; the adaptive rule handles those.) At most [`MAX_CELLS`] cells.
///
/// Returns false when the jumps could not all be cut (too many cells): the rule would
/// then converge only slowly across them, and the pair goes to rays.
pub(super) fn split_at_events(
    pair: &Pair<'_>,
    loose: &[Caster],
    solids: &[&Solid],
    cells: &mut Vec<Piece>,
) -> bool {
    cells.clear();
    cells.push(Piece::new(pair.pi.verts()));
    let q = pair.pj.verts();
    let tol = pair.tol;
    let ni = pair.ni;
    let oi = ni.dot(pair.pi.v[0]);
    // Where x crosses the caster's own plane, what it hides jumps when the caster
    // touches P_i's plane (a wall standing on P_i hides much from one side of it,
    // nothing from its plane). Jumps first: the rule converges far more slowly across
    // a jump than across a kink, so they get the cells when there are not enough.
    // A caster whose plane does not cross P_i cuts nothing (`cut` would find no cell
    // on both sides): asked first, as it is cheaper than the separating axes. The half
    // tolerance leaves the planes `cut` computes from the corners a margin.
    let crosses_pi = |c: &Caster| {
        let d = |p: &DVec3| c.normal.dot(*p) - c.offset;
        let pv = pair.pi.verts();
        pv.iter().any(|p| d(p) < -0.5 * tol) && pv.iter().any(|p| d(p) > 0.5 * tol)
    };
    for c in pair.casters {
        if c.v.iter().any(|v| (ni.dot(*v) - oi).abs() <= tol)
            && crosses_pi(c)
            && (c.solid == NO_SOLID || segments_may_cross(pair.pi.verts(), q, &c.v, tol))
            && !cut(cells, MAX_CELLS, c.v[0], c.v[1], c.v[2], tol, &|_| true)
        {
            return false;
        }
    }
    for (k, c) in loose.iter().enumerate() {
        let edges = (0..3)
            .filter(|&e| !inner_edge(loose, k, e, tol))
            .map(|e| (c.v[e], c.v[(e + 1) % 3]));
        cut_at_kinks(cells, q, &c.v, edges, tol);
    }
    // A convex solid's shadow is bounded by its silhouette: only edges that are on it
    // from some point of P_i (between a face that some point sees and one that it does
    // not) and their ends make kinks.
    let pv = pair.pi.verts();
    for k in solids {
        // Per face: how many vertices of P_i see it (a point sees a face when it lies
        // in front of its plane by more than the tolerance, affine in the point).
        let seen_by: Vec<usize> = k
            .faces
            .iter()
            .map(|f| {
                pv.iter()
                    .filter(|x| f.normal.dot(**x) - f.offset > tol)
                    .count()
            })
            .collect();
        let edges: Vec<(DVec3, DVec3)> = k
            .edges
            .iter()
            .filter(|e| {
                // On the silhouette from no point of P_i when every point sees both
                // faces, or none sees either.
                let [f, g] = e.faces.map(|f| seen_by[f as usize]);
                !(f == g && (f == 0 || f == pv.len()))
            })
            .map(|e| (e.a, e.b))
            .collect();
        let mut ends: Vec<DVec3> = edges.iter().flat_map(|&(a, b)| [a, b]).collect();
        ends.sort_by(|a, b| {
            (a.x.total_cmp(&b.x))
                .then(a.y.total_cmp(&b.y))
                .then(a.z.total_cmp(&b.z))
        });
        ends.dedup();
        cut_at_kinks(cells, q, &ends, edges.into_iter(), tol);
    }
    true
}

/// Whether edge `e` (from corner e to e + 1) of `casters[k]` is no edge of the shadows:
/// another caster in the same plane shares it from the other side (an inner edge of
/// merged triangles, a box face's diagonal). A coplanar caster on the same side (the
/// same triangle given facing the other way) leaves it an edge.
fn inner_edge(casters: &[Caster], k: usize, e: usize, tol: f64) -> bool {
    let c = &casters[k];
    let (v, w, r) = (c.v[e], c.v[(e + 1) % 3], c.v[(e + 2) % 3]);
    let side = |p: DVec3| (w - v).cross(p - v).dot(c.normal);
    casters.iter().enumerate().any(|(l, d)| {
        l != k
            && d.normal.dot(c.normal).abs() > 1.0 - 1e-12
            && (d.normal.dot(v) - d.offset).abs() <= tol
            && (0..3).any(|f| {
                let (a, b, o) = (d.v[f], d.v[(f + 1) % 3], d.v[(f + 2) % 3]);
                ((a == v && b == w) || (a == w && b == v)) && side(o) * side(r) < 0.0
            })
    })
}

/// Cuts `cells` where a vertex of `vertices` lines up with an edge of `q` (P_j), and a
/// vertex of `q` with an edge of `edges`.
fn cut_at_kinks(
    cells: &mut Vec<Piece>,
    q: &[DVec3],
    vertices: &[DVec3],
    edges: impl Iterator<Item = (DVec3, DVec3)> + Clone,
    tol: f64,
) {
    for m in 0..q.len() {
        let (p0, p1) = (q[m], q[(m + 1) % q.len()]);
        // A caster vertex v seen on the edge p0 → p1 of P_j: from x, the ray through v
        // meets the edge itself, beyond v.
        for &v in vertices {
            cut(cells, MAX_CELLS, p0, p1, v, tol, &|x| {
                ray_meets_segment(x, v, p0, p1)
            });
        }
        // A vertex p0 of P_j seen on a caster edge v → w: the segment from x to p0
        // crosses the edge itself.
        for (v, w) in edges.clone() {
            cut(cells, MAX_CELLS, p0, v, w, tol, &|x| {
                segment_meets_segment(x, p0, v, w)
            });
        }
    }
}

/// True when the line from `x` through `v` meets the segment `a`–`b` (x, v, a, b
/// coplanar) with v between x and the meeting point, give or take a margin.
fn ray_meets_segment(x: DVec3, v: DVec3, a: DVec3, b: DVec3) -> bool {
    line_meets_segment(x, v, a, b).is_some_and(|lambda| lambda >= 1.0 - 1e-9)
}

/// True when the segment `x`–`y` meets the segment `a`–`b` (all four coplanar), give
/// or take a margin.
fn segment_meets_segment(x: DVec3, y: DVec3, a: DVec3, b: DVec3) -> bool {
    line_meets_segment(x, y, a, b).is_some_and(|lambda| (-1e-6..=1.0 + 1e-6).contains(&lambda))
}

/// Where the line x + λ (v − x) meets the segment `a`–`b` (all four coplanar), as λ;
/// None when it misses the segment (by more than a margin) or runs parallel to it.
fn line_meets_segment(x: DVec3, v: DVec3, a: DVec3, b: DVec3) -> Option<f64> {
    let (d, e) = (v - x, b - a);
    let c = d.cross(e);
    let cc = c.length_squared();
    if cc.is_nan() || cc <= 0.0 {
        return None;
    }
    // x + λ d = a + t e.
    let w = a - x;
    let t = w.cross(d).dot(c) / cc;
    (-1e-6..=1.0 + 1e-6)
        .contains(&t)
        .then(|| w.cross(e).dot(c) / cc)
}

/// Cuts the cells that the plane through `a`, `b`, `c` crosses, where `matters` holds
/// at one of the ends or the middle of the cell's chord on that plane (the event
/// happens along only part of the line: elsewhere the line is no kink), up to
/// `max_cells` cells. Returns whether every cell the plane crosses where it matters
/// was cut.
pub(crate) fn cut(
    cells: &mut Vec<Piece>,
    max_cells: usize,
    a: DVec3,
    b: DVec3,
    c: DVec3,
    tol: f64,
    matters: &dyn Fn(DVec3) -> bool,
) -> bool {
    let n = (b - a).cross(c - a);
    let len = n.length();
    if len.is_nan() || len <= 0.0 {
        return true;
    }
    let (n, o) = (n / len, n.dot(a) / len);
    let mut complete = true;
    let mut k = 0;
    while k < cells.len() {
        let cell = cells[k];
        k += 1;
        let v = cell.verts();
        let d: Vec<f64> = v.iter().map(|p| n.dot(*p) - o).collect();
        if !(d.iter().any(|&x| x < -tol) && d.iter().any(|&x| x > tol)) {
            continue;
        }
        // The chord: where the cell's edges cross the plane.
        let mut ends = [DVec3::ZERO; 2];
        let mut found = 0;
        for m in 0..v.len() {
            let (d0, d1) = (d[m], d[(m + 1) % v.len()]);
            if (d0 < 0.0) != (d1 < 0.0) && found < 2 {
                ends[found] = v[m] + (v[(m + 1) % v.len()] - v[m]) * (d0 / (d0 - d1));
                found += 1;
            }
        }
        if found == 2
            && ![ends[0], ends[1], 0.5 * (ends[0] + ends[1])]
                .into_iter()
                .any(matters)
        {
            continue;
        }
        // A cut adds a vertex to each side: a cell at capacity stays whole, and so
        // does every cell once there are max_cells.
        if cell.n >= cell.v.len() || cells.len() >= max_cells {
            complete = false;
            continue;
        }
        let front = cell.clip_front(n, o, tol);
        let back = cell.clip_front(-n, -o, tol);
        if usable(&front) && usable(&back) {
            cells[k - 1] = front;
            cells.push(back);
        }
    }
    complete
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formfactor::shadow::fixtures::{casters_of_square, square};
    use glam::dvec3;

    /// Only an edge with coplanar triangles on both sides is inner: a square's
    /// diagonal, not its outline, also when the square is given twice, once facing each
    /// way (as `builtin:obstructed` gives its blocker when coplanar occluders are not
    /// merged).
    #[test]
    fn only_edges_between_coplanar_triangles_are_inner() {
        let one = casters_of_square(0.3, 0.8, 0.2, 0.6, 0.5);
        let back: Vec<Caster> = one
            .iter()
            .filter_map(|c| Caster::new([c.v[0], c.v[2], c.v[1]]))
            .collect();
        let both = [one.clone(), back].concat();
        for casters in [&one[..], &both[..]] {
            for (k, c) in casters.iter().enumerate() {
                for e in 0..3 {
                    let (v, w) = (c.v[e], c.v[(e + 1) % 3]);
                    // The diagonal runs corner to opposite corner: x and z both change.
                    let diagonal = v.x != w.x && v.z != w.z;
                    assert_eq!(
                        inner_edge(casters, k, e, 1e-12),
                        diagonal,
                        "{} casters, edge {v} {w}",
                        casters.len()
                    );
                }
            }
        }
    }

    /// A vertex of P_j seen across an occluder edge between the patches is a kink: the
    /// cells are cut where the segment from x to that vertex crosses the edge. (The
    /// test used to look for the edge beyond the vertex or behind x, and never cut.)
    #[test]
    fn a_receiver_corner_behind_an_occluder_edge_cuts_the_cells() {
        // P_i: the unit square at y = 0; P_j: the unit square at y = 2; an occluder
        // edge along x at y = 1, z = 0.25. From x = (·, 0, 0.5) the segment to P_j's
        // corners at z = 0 crosses that edge: the one line where the kink lies.
        let pi = square(0.0, 1.0, 0.0, 1.0, 0.0);
        let pj = square(0.0, 1.0, 0.0, 1.0, 2.0);
        let edge = (dvec3(-5.0, 1.0, 0.25), dvec3(5.0, 1.0, 0.25));
        let mut cells = vec![Piece::new(pi.verts())];
        cut_at_kinks(&mut cells, pj.verts(), &[], [edge].into_iter(), 1e-9);
        assert_eq!(cells.len(), 2, "one cut, at z = 0.5");
        for c in &cells {
            let z: Vec<f64> = c.verts().iter().map(|v| v.z).collect();
            let (lo, hi) = z
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
            assert!(
                (lo.abs() < 1e-12 || (lo - 0.5).abs() < 1e-12)
                    && ((hi - 0.5).abs() < 1e-12 || (hi - 1.0).abs() < 1e-12)
                    && hi - lo > 0.49,
                "cell spans z {lo}..{hi}"
            );
        }
        // An edge beyond P_j (y = 3, z = −0.25) lines up with its corners at z = 0 from
        // the same line of P_i, but behind P_j, where it hides nothing: no cut.
        let beyond = (dvec3(-5.0, 3.0, -0.25), dvec3(5.0, 3.0, -0.25));
        let mut cells = vec![Piece::new(pi.verts())];
        cut_at_kinks(&mut cells, pj.verts(), &[], [beyond].into_iter(), 1e-9);
        assert_eq!(cells.len(), 1);
    }
}
