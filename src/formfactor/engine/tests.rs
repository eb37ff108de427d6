//! Tests of the row engine: clusters, packets and candidate lists change no value,
//! half rows and full rows agree, rows do not depend on the order they are computed in.

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
        &facing_pair(),
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

/// Rooms of 16 and 64 boxes (188 and 780 occluder triangles: candidate lists for
/// rays, and hierarchy rays), and the Cornell box: every row is bitwise the same
/// whether pairs take their occluders from cluster lists or query the hierarchy,
/// in full rows and in the half rows of a partial run, whatever rows came before
/// through the same scratch.
#[test]
fn cluster_lists_change_no_value() {
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    let cases = [
        ("room", None, 1200, 7),
        ("room", Some(64.0), 3000, 29),
        ("cornell", None, 700, 7),
    ];
    for (name, param, target, step) in cases {
        let scene = builtin(name, param).unwrap();
        let patches = Arc::new(subdivide(&scene, default_max_edge(&scene, target)));
        let occ = Arc::new(Occluders::new(scene.triangles().collect()));
        let cfg = FormFactorConfig::accurate();
        let with = RowEngine::new(&patches, occ.clone(), cfg.clone());
        assert!(with.clusters.is_some(), "{name}: no clusters");
        let without = RowEngine::new(&patches, occ, cfg).without_clusters();
        let n = with.n();
        // A partial run (rows already in the file or skipped), so half rows also
        // evaluate pairs (j, i) with j < i; the rows in a shuffled order through one
        // scratch, so its cluster cache holds whatever earlier rows left.
        let in_run: Vec<bool> = (0..n).map(|k| k % 3 != 1).collect();
        let mut order: Vec<u32> = (0..n as u32).step_by(step).collect();
        let mut rng = crate::formfactor::sampling::SplitMix64::new(n as u64);
        for k in (1..order.len()).rev() {
            order.swap(k, rng.below(k + 1));
        }
        let (mut s1, mut s2) = (Scratch::new(), Scratch::new());
        let (mut own1, mut own2, mut m1, mut m2) = (vec![], vec![], vec![], vec![]);
        for &i in &order {
            assert_eq!(
                with.compute_row(i, &mut s1),
                without.compute_row(i, &mut s2),
                "{name}: row {i}"
            );
            if in_run[i as usize] {
                with.half_row(i, &in_run, &mut s1, &mut own1, &mut m1);
                without.half_row(i, &in_run, &mut s2, &mut own2, &mut m2);
                assert!(own1 == own2 && m1 == m2, "{name}: half row {i}");
            }
        }
        let (c1, c2) = (s1.counters(), s2.counters());
        // The pair's own query gives up on crowded pairs (rays then decide);
        // cluster lists are complete, so they may spare rays, never add any.
        assert!(c1.rays_cast <= c2.rays_cast && c1.pairs_unoccludable >= c2.pairs_unoccludable);
        assert!(
            c1.pairs_unoccludable > 0 && c1.rays_cast > 0,
            "{name}: both kinds of pairs: {c1:?}"
        );
    }
}

/// Rows of a room of 64 boxes (780 occluder triangles: pairs walk the hierarchy)
/// and of the 16-box room (188 triangles: pairs test their candidate lists), each
/// with its own occluders and with the same room as foreign (`--occluders`)
/// occluders, full rows and top-k rows: bitwise the same whether a pair's rays go
/// as packets or one at a time.
#[test]
fn packets_change_no_value() {
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    for (boxes, lists) in [(64.0, false), (16.0, true)] {
        let scene = builtin("room", Some(boxes)).unwrap();
        let patches = Arc::new(subdivide(&scene, default_max_edge(&scene, 1500)));
        for foreign in [false, true] {
            let occ = if foreign {
                Occluders::new_foreign(scene.triangles().collect())
            } else {
                Occluders::new(scene.triangles().collect())
            };
            let occ = Arc::new(occ);
            for cfg in [
                FormFactorConfig::accurate(),
                FormFactorConfig::fast().with_top_k(Some(32)),
            ] {
                let packets = RowEngine::new(&patches, occ.clone(), cfg.clone());
                assert_eq!(packets.list_max > 0, lists, "{boxes} boxes");
                let single = RowEngine::new(&patches, occ.clone(), cfg).one_ray_at_a_time();
                let (mut s1, mut s2) = (Scratch::new(), Scratch::new());
                for i in (0..packets.n() as u32).step_by(11) {
                    assert_eq!(
                        packets.compute_row(i, &mut s1),
                        single.compute_row(i, &mut s2),
                        "row {i}, {boxes} boxes, foreign {foreign}"
                    );
                }
                let (c1, c2) = (s1.counters(), s2.counters());
                assert_eq!(c1.rays_cast, c2.rays_cast);
                assert!(c1.rays_cast > 10_000, "{c1:?}");
            }
        }
    }
}

#[test]
fn shared_types_are_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<RowEngine>();
    check::<Occluders>();
    check::<Scratch>();
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
        &ps,
        Arc::new(Occluders::empty()),
        FormFactorConfig::accurate(),
    );
    let mut s = Scratch::new();
    assert_eq!(e.pair_value(0, 1, &mut s), 0.0);
    assert_eq!(s.counters().pairs_facing_away, 1);
    assert_eq!(s.counters().pairs_evaluated, 0);
}
