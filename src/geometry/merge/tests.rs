//! Tests of the coplanar merge: what it merges, that the merged triangles cover
//! exactly what the input covers, and that it leaves alone what it should.

use super::*;
use glam::dvec3;

/// The rectangle [x0, x1] × [y0, y1] at height z split into nx × ny cells, two
/// triangles each, with the vertices shared between cells.
fn grid(x: (f64, f64), y: (f64, f64), z: f64, nx: usize, ny: usize) -> Vec<[DVec3; 3]> {
    let p = |i: usize, j: usize| {
        dvec3(
            x.0 + (x.1 - x.0) * i as f64 / nx as f64,
            y.0 + (y.1 - y.0) * j as f64 / ny as f64,
            z,
        )
    };
    let mut t = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            t.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            t.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    t
}

fn area(t: &[DVec3; 3]) -> f64 {
    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()
}

fn total_area(t: &[[DVec3; 3]]) -> f64 {
    t.iter().map(area).sum()
}

/// Whether the point p of the plane z = const lies in triangle t (closed), in x, y.
fn covers(t: &[DVec3; 3], p: DVec2) -> bool {
    let e = |a: DVec3, b: DVec3| (b.truncate() - a.truncate()).perp_dot(p - a.truncate());
    let s = [e(t[0], t[1]), e(t[1], t[2]), e(t[2], t[0])];
    s.iter().all(|&x| x >= 0.0) || s.iter().all(|&x| x <= 0.0)
}

/// Distance in x, y from p to the nearest edge of any of the triangles.
fn edge_distance(tris: &[[DVec3; 3]], p: DVec2) -> f64 {
    let seg = |a: DVec2, b: DVec2| {
        let t = ((p - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
        (a + t * (b - a)).distance(p)
    };
    tris.iter()
        .flat_map(|t| (0..3).map(move |k| seg(t[k].truncate(), t[(k + 1) % 3].truncate())))
        .fold(f64::INFINITY, f64::min)
}

/// Deterministic points in [lo, hi]² (a Weyl sequence).
fn points(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = DVec2> {
    let (a, b) = (0.754_877_666_246_692_7, 0.569_840_290_998_053_3);
    (1..=n).map(move |k| {
        let (u, v) = ((k as f64 * a).fract(), (k as f64 * b).fract());
        DVec2::new(lo + (hi - lo) * u, lo + (hi - lo) * v)
    })
}

/// The merged triangles cover the same points as the input, away from the input's
/// edges (on them either may or may not count).
fn assert_same_cover(input: &[[DVec3; 3]], merged: &[[DVec3; 3]], lo: f64, hi: f64) {
    let mut checked = 0;
    for p in points(lo, hi, 20_000) {
        if edge_distance(input, p) < 1e-9 || edge_distance(merged, p) < 1e-9 {
            continue;
        }
        let a = input.iter().any(|t| covers(t, p));
        let b = merged.iter().any(|t| covers(t, p));
        assert_eq!(a, b, "point {p}: input covers it: {a}, merged: {b}");
        checked += 1;
    }
    assert!(
        checked > 19_000,
        "only {checked} points away from the edges"
    );
}

#[test]
fn a_split_wall_with_t_junctions_becomes_two_triangles() {
    // [0, 10] × [0, 3] in 1 m cells, and above it [0, 10] × [3, 5] in 7 columns: the
    // seam at y = 3 has T-junctions (no shared edges across it).
    let mut input = grid((0.0, 10.0), (0.0, 3.0), 2.0, 10, 3);
    input.extend(grid((0.0, 10.0), (3.0, 5.0), 2.0, 7, 2));
    let m = merge_coplanar(input.iter().copied());
    assert_eq!(m.input, input.len());
    assert_eq!(m.groups, 1);
    assert_eq!(m.triangles.len(), 2, "{:?}", m.triangles);
    assert!((total_area(&m.triangles) - 50.0).abs() < 1e-12);
    // The corners are input vertices bit for bit.
    for v in m.triangles.iter().flatten() {
        assert!(
            input.iter().flatten().any(|w| w == v),
            "{v} is not an input vertex"
        );
    }
    assert_same_cover(&input, &m.triangles, -1.0, 11.0);
}

#[test]
fn a_ground_cut_around_a_footprint_keeps_its_hole() {
    // Ground [0, 30]² cut into four rectangles around the footprint [10, 20]², each
    // split into cells of its own size, with the two faces given in both
    // orientations (the merge must not care).
    let mut input = grid((0.0, 30.0), (0.0, 10.0), 0.0, 6, 2);
    input.extend(grid((0.0, 30.0), (20.0, 30.0), 0.0, 5, 3));
    input.extend(grid((0.0, 10.0), (10.0, 20.0), 0.0, 3, 4));
    let mut right = grid((20.0, 30.0), (10.0, 20.0), 0.0, 2, 2);
    for t in &mut right {
        t.swap(1, 2);
    }
    input.extend(right);
    let m = merge_coplanar(input.iter().copied());
    assert_eq!(m.groups, 1);
    assert!(m.triangles.len() < 12, "{} triangles", m.triangles.len());
    assert!((total_area(&m.triangles) - 800.0).abs() < 1e-9);
    assert!(!m
        .triangles
        .iter()
        .any(|t| covers(t, DVec2::new(15.0, 15.0))));
    assert_same_cover(&input, &m.triangles, -1.0, 31.0);
}

#[test]
fn overlapping_facets_merge_into_their_union() {
    // Two unit squares overlapping by half, each two triangles: union area 1.5.
    let mut input = grid((0.0, 1.0), (0.0, 1.0), 0.0, 1, 1);
    input.extend(grid((0.5, 1.5), (0.0, 1.0), 0.0, 1, 1));
    let m = merge_coplanar(input.iter().copied());
    assert_eq!(m.groups, 1);
    assert_eq!(m.triangles.len(), 2);
    assert!((total_area(&m.triangles) - 1.5).abs() < 1e-12);
    assert_same_cover(&input, &m.triangles, -0.5, 2.0);
}

#[test]
fn a_tilted_split_plane_merges_and_keeps_its_vertices() {
    // A 4 × 4 grid of a 2 × 3 rectangle on a plane of general orientation, far from
    // the origin.
    let (o, a, b) = (
        dvec3(120.0, -40.0, 7.0),
        dvec3(0.6, 0.8, 0.0) * 2.0,
        dvec3(-0.48, 0.36, 0.8) * 3.0,
    );
    let p = |i: usize, j: usize| o + a * (i as f64 / 4.0) + b * (j as f64 / 4.0);
    let mut input = Vec::new();
    for i in 0..4 {
        for j in 0..4 {
            input.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            input.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    let m = merge_coplanar(input.iter().copied());
    assert_eq!(m.groups, 1);
    assert_eq!(m.triangles.len(), 2);
    assert!((total_area(&m.triangles) - 6.0).abs() < 1e-9);
    let corners = [p(0, 0), p(4, 0), p(4, 4), p(0, 4)];
    for v in m.triangles.iter().flatten() {
        assert!(corners.contains(v), "{v} is not a corner");
    }
}

#[test]
fn what_is_not_coplanar_stays_as_it_was() {
    // Two squares 1e-6 apart (far beyond the plane tolerance of a 10 m scene), a
    // single triangle on its own plane, a box's six faces: nothing to merge.
    let mut input = grid((0.0, 1.0), (0.0, 1.0), 0.0, 1, 1);
    input.extend(grid((2.0, 3.0), (0.0, 1.0), 1e-6, 1, 1));
    input.push([
        dvec3(0.0, 0.0, 5.0),
        dvec3(1.0, 0.0, 5.0),
        dvec3(0.0, 1.0, 6.0),
    ]);
    input.push([
        dvec3(10.0, 10.0, 0.0),
        dvec3(0.0, 0.0, 0.0),
        dvec3(0.0, 0.0, 0.0),
    ]);
    input.push([
        dvec3(f64::NAN, 0.0, 0.0),
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
    ]);
    let m = merge_coplanar(input.iter().copied());
    assert_eq!(
        m.input, 5,
        "the degenerate and the NaN triangle are dropped"
    );
    assert_eq!(m.groups, 0);
    assert_eq!(m.triangles.len(), 5);
    for t in &m.triangles {
        assert!(input.contains(t), "{t:?} changed");
    }
}

#[test]
fn a_plane_whose_merge_makes_no_fewer_triangles_is_kept_whole() {
    // Two disjoint coplanar squares: their union is the same four triangles.
    let mut input = grid((0.0, 1.0), (0.0, 1.0), 0.0, 1, 1);
    input.extend(grid((3.0, 4.0), (0.0, 1.0), 0.0, 1, 1));
    let m = merge_coplanar(input.iter().copied());
    assert_eq!(m.groups, 0);
    assert_eq!(m.triangles, input);
}
