//! Tests of the occluders: exact answers on small scenes, the hierarchy against a scan
//! of every triangle, packets against single rays, the candidate lists.

use super::*;
use glam::dvec3;

fn quad(face: u32, p: [DVec3; 4]) -> Vec<(u32, [DVec3; 3])> {
    vec![(face, [p[0], p[1], p[2]]), (face, [p[0], p[2], p[3]])]
}

/// Floor (face `ids.0`, at height `floor_z`) and ceiling (`ids.1`, z = 1) over the
/// unit square, and a blocker (`ids.2`) over [0.25, 0.75]² at z = 0.5, split along
/// its diagonal (0.25, 0.25)–(0.75, 0.75); everything scaled by `s`.
fn blocker_scene(ids: (u32, u32, u32), floor_z: f64, s: f64) -> Vec<(u32, [DVec3; 3])> {
    let mut t = quad(
        ids.2,
        [
            dvec3(0.25, 0.25, 0.5) * s,
            dvec3(0.75, 0.25, 0.5) * s,
            dvec3(0.75, 0.75, 0.5) * s,
            dvec3(0.25, 0.75, 0.5) * s,
        ],
    );
    t.extend(quad(
        ids.0,
        [
            dvec3(0.0, 0.0, floor_z) * s,
            dvec3(1.0, 0.0, floor_z) * s,
            dvec3(1.0, 1.0, floor_z) * s,
            dvec3(0.0, 1.0, floor_z) * s,
        ],
    ));
    t.extend(quad(
        ids.1,
        [
            dvec3(0.0, 0.0, 1.0) * s,
            dvec3(0.0, 1.0, 1.0) * s,
            dvec3(1.0, 1.0, 1.0) * s,
            dvec3(1.0, 0.0, 1.0) * s,
        ],
    ));
    t
}

/// A unit square blocker (face 7) in the plane z = 0.5 over [0.25, 0.75]², between
/// a floor (8) and a ceiling (9) that make the scene box larger than the blocker.
fn blocker(scale: f64) -> Occluders {
    let o = Occluders::new(blocker_scene((8, 9, 7), 0.0, scale));
    o.validate();
    o
}

/// The candidate list of a pair gives every segment between the two polygons the
/// answer the hierarchy gives (random squares facing each other across the
/// blocker, at three scales); an empty list means nothing can block.
#[test]
fn pair_candidates_answer_like_the_hierarchy() {
    let square = |c: DVec3, h: f64, z: f64, up: bool| -> Vec<DVec3> {
        let mut v = vec![
            dvec3(c.x - h, c.y - h, z),
            dvec3(c.x + h, c.y - h, z),
            dvec3(c.x + h, c.y + h, z),
            dvec3(c.x - h, c.y + h, z),
        ];
        if !up {
            v.reverse();
        }
        v
    };
    let point_in = |p: &[DVec3], u: f64, v: f64| {
        p[0] * ((1.0 - u) * (1.0 - v))
            + p[1] * (u * (1.0 - v))
            + p[2] * (u * v)
            + p[3] * ((1.0 - u) * v)
    };
    let mut rng = crate::formfactor::sampling::SplitMix64::new(5);
    let mut ids = Vec::new();
    let (mut listed, mut empty, mut blocked, mut free) = (0, 0, 0, 0);
    for s in [1e-3, 1.0, 1e3] {
        let o = blocker(s);
        for _ in 0..300 {
            let mut r = || rng.next_f64();
            let ca = dvec3(0.1 + 0.8 * r(), 0.1 + 0.8 * r(), 0.0) * s;
            let cb = dvec3(0.1 + 0.8 * r(), 0.1 + 0.8 * r(), 0.0) * s;
            let (ha, hb) = ((0.01 + 0.1 * r()) * s, (0.01 + 0.1 * r()) * s);
            // a below the blocker facing up, b above or below it facing down.
            let za = (0.05 + 0.4 * r()) * s;
            let zb = if r() < 0.7 {
                0.55 + 0.4 * r()
            } else {
                za / s + 0.01 + 0.4 * r()
            } * s;
            let a = square(ca, ha, za, true);
            let b = square(cb, hb, zb, false);
            let (na, nb) = (DVec3::Z, -DVec3::Z);
            if !o.collect_between(&Between::new(&a, na, &b, nb, (8, 9)), &mut ids) {
                continue;
            }
            listed += 1;
            empty += ids.is_empty() as usize;
            let mut first = 0;
            assert_eq!(
                ids.is_empty(),
                !o.any_between(&Between::new(&a, na, &b, nb, (8, 9)))
            );
            for _ in 0..50 {
                let x = point_in(&a, rng.next_f64(), rng.next_f64());
                let y = point_in(&b, rng.next_f64(), rng.next_f64());
                let by_list = o.occluded_by(x, y, &ids, None, &mut first);
                assert_eq!(by_list, o.occluded(x, y, (8, 9)), "scale {s}: {x} -> {y}");
                blocked += by_list as usize;
                free += !by_list as usize;
            }
        }
    }
    assert!(
        listed > 500 && empty > 50 && blocked > 1000 && free > 1000,
        "cases: {listed} listed, {empty} empty, {blocked} blocked, {free} free"
    );
}

#[test]
fn ray_through_blocker_is_occluded_from_both_sides() {
    for s in [1e-3, 1.0, 1e3] {
        let o = blocker(s);
        let a = dvec3(0.5, 0.5, 0.0) * s;
        let b = dvec3(0.5, 0.5, 1.0) * s;
        assert!(o.occluded(a, b, (8, 9)));
        assert!(o.occluded(b, a, (8, 9)));
        // Ignoring the blocker's face lets it through.
        assert!(!o.occluded(a, b, (7, 9)));
        // A ray beside the blocker passes.
        assert!(!o.occluded(dvec3(0.1, 0.1, 0.0) * s, dvec3(0.1, 0.9, 1.0) * s, (8, 9)));
        // Segment ending before the blocker.
        assert!(!o.occluded(a, dvec3(0.5, 0.5, 0.4) * s, (8, 9)));
    }
}

#[test]
fn single_and_degenerate_triangles() {
    let one = Occluders::new(vec![(
        0,
        [
            dvec3(0.0, 0.0, 1.0),
            dvec3(1.0, 0.0, 1.0),
            dvec3(0.0, 1.0, 1.0),
        ],
    )]);
    one.validate();
    assert_eq!(one.len(), 1);
    // One leaf filling the root's box: one node and one block, each met by every
    // line through the root.
    let stats = TreeStats {
        nodes: 1,
        leaves: 1,
        depth: 1,
        blocks: 1,
        node_sah: 1.0,
        block_sah: 1.0,
    };
    assert_eq!(one.stats(), Some(stats));
    assert!(one.occluded(dvec3(0.2, 0.2, 0.0), dvec3(0.2, 0.2, 2.0), (9, 9)));
    let flat = Occluders::new(vec![(
        0,
        [
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(2.0, 0.0, 0.0),
        ],
    )]);
    assert!(flat.is_empty());
    assert_eq!(flat.stats(), None);
    assert!(!flat.occluded(dvec3(0.5, -1.0, 0.0), dvec3(0.5, 1.0, 0.0), (9, 9)));
    assert!(Occluders::new(Vec::new()).is_empty());
}

#[test]
fn ray_through_a_shared_diagonal_is_blocked() {
    // A quad face as two triangles sharing the diagonal (0.25,0.25)–(0.75,0.75) at
    // z = 0.5; rays crossing the plane exactly on the diagonal, in many directions,
    // must all be blocked (a non-watertight test lets some through).
    let o = Occluders::new(blocker_scene((2, 3, 1), 0.0, 1.0));
    let mut missed = 0;
    for a in 0..=16 {
        for b in 0..=16 {
            let on = 0.3 + 0.4 * a as f64 / 16.0; // point on the diagonal
            let from = dvec3(
                on - 0.3 + 0.6 * b as f64 / 16.0,
                on + 0.1 * (a as f64 - 8.0) / 8.0,
                0.0,
            );
            let to = 2.0 * dvec3(on, on, 0.5) - from;
            if !o.occluded(from, to, (2, 3)) {
                missed += 1;
            }
        }
    }
    assert_eq!(missed, 0, "{missed} rays slipped through the diagonal");
}

#[test]
fn ray_ending_on_a_face_is_not_blocked_by_it() {
    let o = blocker(1.0);
    // From the floor to a point on the blocker itself (face 7 not ignored): the
    // end point lies on face 7 and the epsilon keeps that hit out.
    assert!(!o.occluded(dvec3(0.5, 0.5, 0.0), dvec3(0.5, 0.5, 0.5), (8, 9)));
}

#[test]
fn short_segments_near_geometry_are_not_culled() {
    // A tiny triangle right next to the ray origin (within obvhs' fixed node
    // epsilon) must still block.
    let mut t = vec![(
        1,
        [
            dvec3(-1e-6, -1e-6, 1e-5),
            dvec3(1e-6, -1e-6, 1e-5),
            dvec3(0.0, 1e-6, 1e-5),
        ],
    )];
    t.extend(quad(
        2,
        [
            dvec3(-1.0, -1.0, -1.0),
            dvec3(1.0, -1.0, -1.0),
            dvec3(1.0, 1.0, -1.0),
            dvec3(-1.0, 1.0, -1.0),
        ],
    ));
    let o = Occluders::new(t);
    assert!(o.occluded(dvec3(0.0, 0.0, 0.0), dvec3(0.0, 0.0, 0.5), (99, 99)));
}

#[test]
fn any_between_ignores_blockers_beside_a_slanted_pair() {
    // Floor patch at x, y ∈ [0, 0.1], ceiling patch at x, y ∈ [0.9, 1]: their hull is
    // a thin slanted prism along the diagonal. A small blocker in the corner
    // (0.8, 0.1, 0.5) is inside their bounding box but beside the prism; one at the
    // centre of the diagonal is inside it.
    let floor = [
        dvec3(0.0, 0.0, 0.0),
        dvec3(0.1, 0.0, 0.0),
        dvec3(0.1, 0.1, 0.0),
        dvec3(0.0, 0.1, 0.0),
    ];
    let ceiling = [
        dvec3(0.9, 0.9, 1.0),
        dvec3(0.9, 1.0, 1.0),
        dvec3(1.0, 1.0, 1.0),
        dvec3(1.0, 0.9, 1.0),
    ];
    let n_up = dvec3(0.0, 0.0, 1.0);
    let blocker_at = |c: DVec3| {
        let mut t = quad(
            7,
            [
                c + dvec3(-0.05, -0.05, 0.0),
                c + dvec3(0.05, -0.05, 0.0),
                c + dvec3(0.05, 0.05, 0.0),
                c + dvec3(-0.05, 0.05, 0.0),
            ],
        );
        t.extend(quad(8, floor));
        t.extend(quad(9, ceiling));
        Occluders::new(t)
    };
    let beside = blocker_at(dvec3(0.8, 0.1, 0.5));
    assert!(!beside.any_between(&Between::new(&floor, n_up, &ceiling, -n_up, (8, 9))));
    let inside = blocker_at(dvec3(0.5, 0.5, 0.5));
    assert!(inside.any_between(&Between::new(&floor, n_up, &ceiling, -n_up, (8, 9))));
    // And the ray test agrees: the centre blocker stops the centre ray.
    assert!(inside.occluded(dvec3(0.05, 0.05, 0.0), dvec3(0.95, 0.95, 1.0), (8, 9)));
}

#[test]
fn foreign_occluders_ignore_the_endpoint_planes_not_blockers() {
    // A coarse mesh whose floor lies 5e-7 above the fine floor z = 0 (within the
    // plane skin), a ceiling at z = 1 and a blocker at z = 0.5 over [0.25, 0.75]².
    let t = blocker_scene((1, 2, 3), 5e-7, 1.0);
    let occ = Occluders::new_foreign(t.clone());
    assert!(occ.is_foreign());
    let up = dvec3(0.0, 0.0, 1.0);
    let floor = (up, 0.0);
    // A shallow ray from the fine floor to a wall point: it crosses the coarse
    // floor ~1e-5 along, past the end-point epsilon. Planes tell it apart; the
    // patches' face ids (here 1, 2) mean nothing to a foreign mesh.
    let (a, b) = (dvec3(0.1, 0.1, 0.0), dvec3(1.0, 1.0, 0.05));
    let wall = (dvec3(-1.0, 0.0, 0.0), -1.0);
    assert!(occ.occluded(a, b, (1, 2)));
    assert!(!occ.occluded_between_planes(a, b, (1, 2), Some([floor, wall])));
    // Floor to ceiling through the blocker: still blocked.
    let ceiling = (-up, -1.0);
    let (a, c) = (dvec3(0.5, 0.5, 0.0), dvec3(0.5, 0.5, 1.0));
    assert!(occ.occluded_between_planes(a, c, (1, 3), Some([floor, ceiling])));
    assert!(!occ.occluded_between_planes(
        dvec3(0.1, 0.1, 0.0),
        dvec3(0.1, 0.9, 1.0),
        (1, 2),
        Some([floor, ceiling])
    ));
    // The same mesh as native occluders honours the face ids.
    let native = Occluders::new(t);
    assert!(!native.occluded(a, c, (1, 3)));
}

#[test]
fn any_between_sees_blocker_and_ignores_walls() {
    let o = blocker(1.0);
    let n_up = dvec3(0.0, 0.0, 1.0);
    let lower = [
        dvec3(0.0, 0.0, 0.0),
        dvec3(1.0, 0.0, 0.0),
        dvec3(1.0, 1.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
    ];
    let upper = [
        dvec3(0.0, 0.0, 1.0),
        dvec3(0.0, 1.0, 1.0),
        dvec3(1.0, 1.0, 1.0),
        dvec3(1.0, 0.0, 1.0),
    ];
    assert!(o.any_between(&Between::new(&lower, n_up, &upper, -n_up, (8, 9))));
    // Patches on the floor and ceiling away from the blocker's column, only the
    // walls (faces 8, 9 ignored) around: a corner patch pair at x, y ∈ [0, 0.2].
    let lo = [
        dvec3(0.0, 0.0, 0.0),
        dvec3(0.2, 0.0, 0.0),
        dvec3(0.2, 0.2, 0.0),
        dvec3(0.0, 0.2, 0.0),
    ];
    let hi = [
        dvec3(0.0, 0.0, 1.0),
        dvec3(0.0, 0.2, 1.0),
        dvec3(0.2, 0.2, 1.0),
        dvec3(0.2, 0.0, 1.0),
    ];
    assert!(!o.any_between(&Between::new(&lo, n_up, &hi, -n_up, (8, 9))));
    // Both below the blocker's plane: it is on one side of the whole hull.
    let mid = [
        dvec3(0.0, 0.0, 0.3),
        dvec3(0.0, 1.0, 0.3),
        dvec3(1.0, 1.0, 0.3),
        dvec3(1.0, 0.0, 0.3),
    ];
    assert!(!o.any_between(&Between::new(&lower, n_up, &mid, -n_up, (8, 9))));
    assert!(!Occluders::empty().any_between(&Between::new(&lower, n_up, &upper, -n_up, (8, 9))));
}

/// A cluttered scene for the f32-filter tests: random triangles of all shapes
/// (slivers, needles, large ones) and sizes, a few sharing edges or planes, in a
/// box of `scale`.
fn clutter(seed: u64, scale: f64) -> Vec<(u32, [DVec3; 3])> {
    let mut rng = crate::formfactor::sampling::SplitMix64::new(seed);
    let mut r = move || rng.next_f64();
    let mut tris = Vec::new();
    for f in 0..300u32 {
        let c = dvec3(r(), r(), r()) * scale;
        let size = scale * [0.3, 0.05, 0.005][f as usize % 3];
        let a = c + (dvec3(r(), r(), r()) - 0.5) * size;
        let b = c + (dvec3(r(), r(), r()) - 0.5) * size;
        let t = match f % 5 {
            // a sliver: the third vertex almost on the first edge
            0 => a + (b - a) * r() + dvec3(r(), r(), r()) * size * 1e-9,
            // axis-aligned, in the plane z = c.z (shared by the next ones)
            1 => dvec3(a.x, b.y, a.z),
            _ => c + (dvec3(r(), r(), r()) - 0.5) * size,
        };
        let t = if f % 5 == 1 {
            [
                dvec3(a.x, a.y, c.z),
                dvec3(b.x, b.y, c.z),
                dvec3(t.x, t.y, c.z),
            ]
        } else {
            [a, b, t]
        };
        tris.push((f, t));
        // every seventh triangle gets a neighbour across its first edge
        if f % 7 == 0 {
            tris.push((
                f + 1000,
                [t[1], t[0], c + (dvec3(r(), r(), r()) - 0.5) * size],
            ));
        }
    }
    tris
}

/// Segments of every kind through `occ`'s scene: random, along the axes, grazing
/// or ending on triangles, through shared edges, in triangle planes, and reaching
/// far outside the scene.
fn test_segments(
    tris: &[(u32, [DVec3; 3])],
    seed: u64,
    scale: f64,
    n: usize,
) -> Vec<(DVec3, DVec3)> {
    let mut rng = crate::formfactor::sampling::SplitMix64::new(seed);
    let mut r = move || rng.next_f64();
    (0..n)
        .map(|k| {
            let t = &tris[(r() * tris.len() as f64) as usize % tris.len()].1;
            let u = &tris[(r() * tris.len() as f64) as usize % tris.len()].1;
            let on = |t: &[DVec3; 3], a: f64, b: f64| {
                let (a, b) = if a + b > 1.0 {
                    (1.0 - a, 1.0 - b)
                } else {
                    (a, b)
                };
                t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b
            };
            let p = dvec3(r(), r(), r()) * scale;
            match k % 8 {
                0 => (p, dvec3(r(), r(), r()) * scale),
                // along an axis
                1 => (p, p + DVec3::AXES[k / 8 % 3] * scale * (r() - 0.5)),
                // from a point of one triangle to a point of another
                2 => (on(t, r(), r()), on(u, r(), r())),
                // through a vertex or an edge of a triangle
                3 => {
                    let x = if r() < 0.5 {
                        t[0]
                    } else {
                        t[0] + (t[1] - t[0]) * r()
                    };
                    let d = dvec3(r(), r(), r()) - 0.5;
                    (x - d * scale, x + d * scale)
                }
                // in the plane of a triangle, across it
                4 => (on(t, -0.5, r()), on(t, 1.5, r() * 0.5)),
                // far outside on both sides
                5 => (
                    p - dvec3(r(), r(), r()) * scale * 1e3,
                    p + dvec3(r(), r(), r()) * scale * 1e3,
                ),
                // short, near a triangle
                6 => {
                    let x = on(t, r(), r());
                    (
                        x + dvec3(r(), r(), r()) * scale * 1e-6,
                        x - dvec3(r(), r(), r()) * scale * 1e-6,
                    )
                }
                // grazing: almost parallel to a triangle, just above it
                _ => {
                    let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
                    let lift = n * scale * 1e-7 * (r() - 0.5);
                    (on(t, -0.2, 0.3) + lift, on(t, 1.2, 0.1) - lift)
                }
            }
        })
        .collect()
}

/// The f32 filter never contradicts the exact test: a triangle it misses for
/// sure is missed by the exact test, and one it crosses for sure is hit (every
/// triangle, every kind of segment, at three scales).
#[test]
fn f32_filter_agrees_with_the_exact_test() {
    let (mut sure, mut maybe, mut hits, mut short) = (0usize, 0usize, 0usize, 0usize);
    for (seed, scale) in [(1u64, 1.0), (2, 1e-3), (3, 1e4)] {
        let tris = clutter(seed, scale);
        let occ = Occluders::new(tris.clone());
        occ.validate();
        let bvh = occ.bvh.as_ref().unwrap();
        for (from, to) in test_segments(&tris, seed + 10, scale, 6000) {
            let (f, d) = occ.norm_segment(from, to);
            let Some(ray) = SegmentRay::new(f, d) else {
                continue;
            };
            let classes = bvh.classify_all(&ray, occ.tris.len());
            let Some(seg) = Segment::new(f, d) else {
                // Too short to count any hit: `occluded` relies on the filter
                // being sure of no crossing either.
                assert!(
                    classes.iter().all(|(s, _)| !s),
                    "sure hit on {from} -> {to}"
                );
                short += 1;
                continue;
            };
            for (id, (s, m)) in classes.into_iter().enumerate() {
                let exact = by_axes!(seg.sheared.axes, |KX, KY, KZ| {
                    occ.tris[id].hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                })
                .is_some();
                assert!(
                    !s || exact,
                    "sure hit that the exact test misses: tri {id}, {from} -> {to}"
                );
                assert!(s || m || !exact, "missed a hit: tri {id}, {from} -> {to}");
                sure += s as usize;
                maybe += m as usize;
                hits += exact as usize;
            }
        }
    }
    // The filter must decide most hits itself, or it saves nothing.
    assert!(
        hits > 3000 && sure > hits / 2 && short > 0,
        "{hits} hits, {sure} sure, {maybe} maybe, {short} too short"
    );
}

/// The walk answers as the exact test over every triangle does (random faces
/// ignored), native and foreign, on the cluttered scenes.
#[test]
fn walk_answers_like_a_scan_of_every_triangle() {
    let (mut blocked, mut free) = (0, 0);
    for (seed, scale) in [(4u64, 1.0), (5, 1e-3)] {
        let tris = clutter(seed, scale);
        for foreign in [false, true] {
            let occ = if foreign {
                Occluders::new_foreign(tris.clone())
            } else {
                Occluders::new(tris.clone())
            };
            // Leaves hold at most eight triangles; below the root, nodes add area.
            let st = occ.stats().expect("triangles");
            assert!(st.depth >= 2 && st.nodes >= 2, "{st:?}");
            assert!(st.leaves >= occ.len().div_ceil(8), "{st:?}");
            assert!(st.node_sah > 1.0 && st.block_sah > 0.0, "{st:?}");
            for (k, (from, to)) in test_segments(&tris, seed + 20, scale, 5000)
                .into_iter()
                .enumerate()
            {
                let ignore = (tris[k % tris.len()].0, tris[k * 7 % tris.len()].0);
                let planes = foreign.then(|| {
                    let n = (to - from).normalize_or_zero().any_orthonormal_vector();
                    [(n, n.dot(from)), (n, n.dot(to))]
                });
                let got = occ.occluded_between_planes(from, to, ignore, planes);
                let scan = occ.segment(from, to).is_some_and(|seg| {
                    let skip = occ.ignored_faces(ignore);
                    let planes = occ.normalized_planes(planes);
                    occ.tris.iter().any(|t| {
                        t.face != skip.0
                            && t.face != skip.1
                            && by_axes!(seg.sheared.axes, |KX, KY, KZ| {
                                t.hit::<KX, KY, KZ>(&seg.sheared, seg.t0, seg.t1)
                            })
                            .is_some()
                            && Segment::counts(t, &planes)
                    })
                });
                assert_eq!(
                    got, scan,
                    "{from} -> {to}, ignoring {ignore:?}, foreign {foreign}"
                );
                blocked += got as usize;
                free += !got as usize;
            }
        }
    }
    assert!(
        blocked > 1000 && free > 1000,
        "{blocked} blocked, {free} free"
    );
}

/// A packet of segments gets, lane by lane, the answers the segments get alone:
/// packets of 1–16 of the test segments (every kind, mixed directions, some lying
/// wholly outside the occluders' box: empty lanes) and
/// packets of rays between two random triangles, as a pair casts them; native and
/// foreign, the pair's faces ignored. The same packets against a random candidate
/// list answer as each segment does against that list alone.
#[test]
fn packets_answer_like_single_segments() {
    let (mut blocked, mut free, mut mixed, mut empty) = (0, 0, 0, 0);
    let (mut list_blocked, mut list_mixed) = (0, 0);
    for (seed, scale) in [(8u64, 1.0), (9, 1e3)] {
        let tris = clutter(seed, scale);
        let mut rng = crate::formfactor::sampling::SplitMix64::new(seed);
        // (the two triangles whose faces are ignored and whose planes bound a
        // foreign pair, the segments)
        let mut packets = Vec::new();
        for _ in 0..400 {
            let a = rng.below(tris.len());
            let b = rng.below(tris.len());
            let rays: Vec<_> = (0..PACKET)
                .map(|_| {
                    (
                        point_in(&tris[a].1, &mut rng),
                        point_in(&tris[b].1, &mut rng),
                    )
                })
                .collect();
            packets.push(((a, b), rays));
        }
        let singles = test_segments(&tris, seed + 30, scale, 3000);
        let mut at = 0;
        while at < singles.len() {
            let n = (1 + rng.below(PACKET)).min(singles.len() - at);
            let k = rng.below(tris.len());
            packets.push(((k, (k * 7) % tris.len()), singles[at..at + n].to_vec()));
            at += n;
        }
        let plane = |t: &[DVec3; 3]| {
            let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
            (n, n.dot(t[0]))
        };
        for foreign in [false, true] {
            let occ = if foreign {
                Occluders::new_foreign(tris.clone())
            } else {
                Occluders::new(tris.clone())
            };
            for ((a, b), segs) in &packets {
                let faces = (tris[*a].0, tris[*b].0);
                let planes = foreign.then(|| [plane(&tris[*a].1), plane(&tris[*b].1)]);
                let got = occ.occluded_packet(segs, faces, planes);
                let alone = segs.iter().enumerate().fold(0u32, |m, (l, &(x, y))| {
                    m | (occ.occluded_between_planes(x, y, faces, planes) as u32) << l
                });
                assert_eq!(
                    got, alone,
                    "packet {segs:?}, faces {faces:?}, foreign {foreign}"
                );
                // The same segments against a candidate list (a random quarter of
                // the triangles, internal ids), the last blocker anywhere in it or
                // past its end.
                let ids: Vec<u32> = (0..occ.len() as u32)
                    .filter(|_| rng.below(4) == 0)
                    .collect();
                let mut first = rng.below(ids.len() + 2);
                let got = occ.occluded_packet_by(segs, &ids, planes, &mut first);
                let mut first = 0;
                let alone_list = segs.iter().enumerate().fold(0u32, |m, (l, &(x, y))| {
                    m | (occ.occluded_by(x, y, &ids, planes, &mut first) as u32) << l
                });
                assert_eq!(
                    got, alone_list,
                    "packet {segs:?} against {ids:?}, foreign {foreign}"
                );
                list_blocked += alone_list.count_ones();
                list_mixed +=
                    (alone_list != 0 && alone_list.count_ones() < segs.len() as u32) as usize;
                let n = segs.len() as u32;
                blocked += alone.count_ones();
                free += n - alone.count_ones();
                mixed += (alone != 0 && alone.count_ones() < n) as usize;
                // Lanes left empty (nothing of the segment inside the box) next to
                // lanes that walk.
                let outside = segs
                    .iter()
                    .filter(|&&(x, y)| {
                        let (f, d) = occ.norm_segment(x, y);
                        SegmentRay::new(f, d).is_none()
                    })
                    .count();
                empty += (outside > 0 && outside < segs.len()) as usize;
            }
        }
    }
    assert!(
        blocked > 5000 && free > 10000 && mixed > 500 && empty > 200,
        "{blocked} blocked, {free} free, {mixed} packets partly blocked, \
         {empty} with empty lanes"
    );
    assert!(
        list_blocked > 2000 && list_mixed > 300,
        "candidate lists: {list_blocked} blocked, {list_mixed} packets partly blocked"
    );
}

/// More undecided (lane, triangle) pairs than the put-off list holds: with foreign
/// occluders every crossing waits for its exact test, and here ray 0's only blocker
/// (face 0, first in the list) is put off before twenty triangles that only ray 1
/// crosses. Both rays must come out blocked, as each does alone: the test fails
/// if a full list is emptied without running its tests.
#[test]
fn list_packets_settle_a_full_queue() {
    let square = |x: f64, z: f64| {
        [
            dvec3(x - 1.0, -1.0, z),
            dvec3(x + 1.0, -1.0, z),
            dvec3(x, 1.0, z),
        ]
    };
    let mut tris = vec![(0u32, square(0.0, 0.0))];
    for k in 1..=20 {
        tris.push((k, square(10.0, -0.9 + 0.08 * k as f64)));
    }
    let occ = Occluders::new_foreign(tris);
    let mut ids: Vec<u32> = (0..occ.len() as u32).collect();
    ids.sort_by_key(|&id| occ.tris[id as usize].face);
    let up = DVec3::Z;
    let planes = Some([(up, -1.0), (up, 1.0)]);
    let segs = [
        (dvec3(0.0, 0.0, -1.0), dvec3(0.0, 0.0, 1.0)),
        (dvec3(10.0, 0.0, -1.0), dvec3(10.0, 0.0, 1.0)),
    ];
    for (l, &(x, y)) in segs.iter().enumerate() {
        assert!(occ.occluded_by(x, y, &ids, planes, &mut 0), "ray {l} alone");
    }
    let mut first = 0;
    assert_eq!(
        occ.occluded_packet_by(&segs, &ids, planes, &mut first),
        0b11
    );
}

/// A uniform random point of triangle `t`.
fn point_in(t: &[DVec3; 3], rng: &mut crate::formfactor::sampling::SplitMix64) -> DVec3 {
    let (u, v) = (rng.next_f64(), rng.next_f64());
    let s = u.sqrt();
    t[0] * (1.0 - s) + t[1] * (s * (1.0 - v)) + t[2] * (s * v)
}

/// The box walk offers every triangle whose box meets the query box (a superset is
/// fine: the callers test each triangle again).
#[test]
fn box_walk_offers_every_overlapping_triangle() {
    let tris = clutter(6, 1.0);
    let occ = Occluders::new(tris.clone());
    let bvh = occ.bvh.as_ref().unwrap();
    let mut rng = crate::formfactor::sampling::SplitMix64::new(7);
    for _ in 0..500 {
        let c = dvec3(rng.next_f64(), rng.next_f64(), rng.next_f64()) - 0.5;
        let h = DVec3::splat(0.2 * rng.next_f64());
        let (lo, hi) = (c - h, c + h);
        let mut seen = vec![false; occ.tris.len()];
        bvh.for_each_in_box(
            lo,
            hi,
            |_, _| true,
            |id| {
                seen[id] = true;
                false
            },
        );
        for (id, t) in occ.tris.iter().enumerate() {
            let overlaps = !(t.max.cmplt(lo).any() || t.min.cmpgt(hi).any());
            assert!(
                !overlaps || seen[id],
                "triangle {id} overlapping the box not offered"
            );
        }
    }
}

#[test]
fn first_hit_meets_a_wall_right_beside_its_start() {
    // Floor (face 0, z = 0) and a wall standing on it (face 1, x = 0.5). A ray from
    // the floor a hair (1e-8 of the diagonal, below the ray tolerance) in front of
    // the wall, heading into it, must stop at the wall: the hemisphere row totals
    // count such a ray as seeing nothing if it passes into what stands behind.
    let mut tris = quad(
        0,
        [
            dvec3(0.0, 0.0, 0.0),
            dvec3(1.0, 0.0, 0.0),
            dvec3(1.0, 1.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
        ],
    );
    tris.extend(quad(
        1,
        [
            dvec3(0.5, 0.0, 0.0),
            dvec3(0.5, 1.0, 0.0),
            dvec3(0.5, 1.0, 1.0),
            dvec3(0.5, 0.0, 1.0),
        ],
    ));
    for occ in [Occluders::new(tris.clone()), Occluders::new_foreign(tris)] {
        let gap = 1e-8 * occ.diagonal();
        let from = dvec3(0.5 - gap, 0.5, 0.0);
        let floor = (DVec3::Z, 0.0);
        let hit = occ
            .first_hit(from, dvec3(1.0, 0.0, 1.0), 0, floor)
            .expect("the wall stops the ray");
        assert!((hit.x - 0.5).abs() < 1e-12, "{hit}");
        assert!(hit.z > 0.0 && hit.z < 2.0 * gap, "{hit}");
        // Away from the wall the ray meets nothing (no surface of the floor's own).
        assert_eq!(occ.first_hit(from, dvec3(-1.0, 0.0, 1.0), 0, floor), None);
    }
}
