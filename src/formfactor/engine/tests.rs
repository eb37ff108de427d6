//! Tests of the row engine: clusters, packets and candidate lists change no value,
//! half rows and full rows agree, rows do not depend on the order they are computed in.

use super::*;
use crate::patch::Patch;
use glam::dvec3;

/// The 16-box room at about `target` patches and an engine for linked top-16 rows
/// (64 links), as the links' tests use them.
pub(super) fn linked_room(target: usize) -> (PatchSet, RowEngine) {
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    let scene = crate::scene::builtin("room", None).unwrap();
    let patches = subdivide(&scene, default_max_edge(&scene, target));
    let occ = Arc::new(Occluders::new(scene.triangles().collect()));
    let mut cfg = FormFactorConfig::accurate();
    cfg.top_k = Some(16);
    cfg.links = Some(64);
    let engine = RowEngine::new(&patches, occ, cfg);
    (patches, engine)
}

fn square(origin: DVec3, u: DVec3, v: DVec3, face: u32) -> Patch {
    quad([origin, origin + u, origin + u + v, origin + v], face)
}

/// A planar parallelogram patch with these corners (counter-clockwise about its front).
fn quad(corners: [DVec3; 4], face: u32) -> Patch {
    let n = (corners[1] - corners[0]).cross(corners[3] - corners[0]);
    Patch {
        corners,
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
/// through the same scratch; so are the kept entries of linked top-k rows.
#[test]
fn cluster_lists_change_no_value() {
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    // Last: the room as a mesh delivered split into facets (every patch its own face)
    // with its occluders merged, so foreign: clusters by plane.
    let cases = [
        ("room", None, 1200, 7, false),
        ("room", Some(64.0), 3000, 29, false),
        ("cornell", None, 700, 7, false),
        ("room", None, 1200, 7, true),
    ];
    for (name, param, target, step, presplit) in cases {
        let scene = builtin(name, param).unwrap();
        let mut patches = subdivide(&scene, default_max_edge(&scene, target));
        let occ = if presplit {
            for (k, p) in patches.patches.iter_mut().enumerate() {
                p.face = k as u32;
            }
            let merged = crate::geometry::merge::merge_coplanar(scene.triangles().map(|t| t.1));
            Arc::new(Occluders::new_foreign(
                (0u32..).zip(merged.triangles).collect(),
            ))
        } else {
            Arc::new(Occluders::new(scene.triangles().collect()))
        };
        let patches = Arc::new(patches);
        // Dense rows, and the kept entries of linked rows.
        let mut linked = FormFactorConfig::fast().with_top_k(Some(16));
        linked.links = Some(64);
        for (cfg, linked) in [(FormFactorConfig::accurate(), false), (linked, true)] {
            let with = RowEngine::new(&patches, occ.clone(), cfg.clone());
            assert!(with.clusters.is_some(), "{name}: no clusters");
            let without = RowEngine::new(&patches, occ.clone(), cfg).without_clusters();
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
                let (r1, r2) = (
                    with.compute_row(i, &mut s1),
                    without.compute_row(i, &mut s2),
                );
                match linked {
                    // Kept entries only: a tail column the lists find nothing in front
                    // of is exact in a link, one whose own query gave up is sampled,
                    // so the links' estimates may differ (both unbiased; with the
                    // clusters always built, a row is the same on every thread).
                    true => assert_eq!(r1.values, r2.values, "{name}: row {i}"),
                    false => assert_eq!(r1, r2, "{name}: row {i}"),
                }
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
}

/// Rows of a room of 64 boxes (780 occluder triangles: pairs walk the hierarchy)
/// and of the 16-box room (188 triangles: pairs test their candidate lists), each
/// with its own occluders and with the same room as foreign (`--occluders`)
/// occluders, full rows, top-k rows and linked rows (whose points' rays go as packets
/// too, `points.rs`): bitwise the same whether rays go as packets or one at a time.
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
            let mut linked = FormFactorConfig::fast().with_top_k(Some(32));
            linked.links = Some(64);
            for cfg in [
                FormFactorConfig::accurate(),
                FormFactorConfig::fast().with_top_k(Some(32)),
                linked,
            ] {
                let packets = RowEngine::new(&patches, occ.clone(), cfg.clone());
                assert_eq!(packets.list_max > 0, lists, "{boxes} boxes");
                let single = RowEngine::new(&patches, occ.clone(), cfg).one_ray_at_a_time();
                let (mut s1, mut s2) = (Scratch::new(), Scratch::new());
                for i in (0..packets.n() as u32).step_by(5) {
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

/// Patches in general position and in contact: tilted squares and triangles of sizes
/// from 0.02 to 1.5 anywhere in a 4 m box, and grids of small squares (neighbours
/// touching along edges, coplanar), some grids folded at right angles (touching at
/// 90°), so the tree has nodes of every kind: far, near, touching, behind.
fn patch_soup(seed: u64) -> PatchSet {
    use crate::formfactor::sampling::SplitMix64;
    let mut rng = SplitMix64::new(seed);
    let mut r = |lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
    let mut patches = Vec::new();
    let mut face = 0u32;
    for _ in 0..120 {
        let origin = dvec3(r(0.0, 4.0), r(0.0, 4.0), r(0.0, 4.0));
        let size = (r(-4.0, 0.4)).exp();
        let u = dvec3(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)).normalize() * size;
        let w = dvec3(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0));
        let v = (w - u * (w.dot(u) / u.length_squared())).normalize() * size * r(0.3, 1.0);
        let mut p = square(origin, u, v, face);
        if r(0.0, 1.0) < 0.4 {
            // The triangle of the first three corners.
            p.n_corners = 3;
            p.area *= 0.5;
        }
        patches.push(p);
        face += 1;
    }
    for _ in 0..6 {
        let origin = dvec3(r(0.0, 3.0), r(0.0, 3.0), r(0.0, 3.0));
        let u = dvec3(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)).normalize();
        let w = dvec3(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0));
        let v = (w - u * w.dot(u)).normalize();
        let cell = r(0.05, 0.2);
        let (du, dv) = (u * cell, v * cell);
        for a in 0..6 {
            for b in 0..6 {
                patches.push(square(origin + du * a as f64 + dv * b as f64, du, dv, face));
            }
        }
        // The fold: a second grid at 90° along the first one's v = 0 edge, facing the
        // first grid.
        let down = u.cross(v) * cell;
        for a in 0..6 {
            for b in 1..4 {
                patches.push(square(
                    origin + du * a as f64 + down * b as f64,
                    -down,
                    du,
                    face + 1,
                ));
            }
        }
        face += 2;
    }
    PatchSet {
        patches,
        groups: vec!["g".into()],
    }
}

/// The tree's bounds are never below the truth: over every row and every node, the
/// largest and the summed F⁰_ij of the node's patches (the engine's own unoccluded
/// values, which the search compares with the bounds) stay at or below the node's
/// bounds. Random soups of patches (touching, coplanar, folded, behind one another),
/// the Cornell box and a room.
#[test]
fn tree_bounds_are_never_below_the_unoccluded_form_factors() {
    use crate::formfactor::geom::PatchBound;
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    let mut sets = vec![
        ("soup 1".to_string(), patch_soup(1)),
        ("soup 2".to_string(), patch_soup(2)),
        ("soup 3".to_string(), patch_soup(3)),
    ];
    for (name, target) in [("cornell", 300), ("room", 400)] {
        let scene = builtin(name, None).unwrap();
        sets.push((
            name.to_string(),
            subdivide(&scene, default_max_edge(&scene, target)),
        ));
    }
    let cfg = FormFactorConfig::accurate().with_top_k(Some(8));
    let (mut nodes_checked, mut leaves_seen, mut tight) = (0u64, 0u64, 0u64);
    for (name, patches) in &sets {
        let e = RowEngine::new(patches, Arc::new(Occluders::empty()), cfg.clone());
        let tree = e.tree.as_ref().expect("a tree for top-k rows");
        let mut s = Scratch::new();
        let mut values = Vec::new();
        for i in 0..e.n() as u32 {
            if !e.valid[i as usize] {
                continue;
            }
            e.row_values(i, &mut s, &mut values);
            let row = PatchBound::of(&e.geom[i as usize]);
            for id in 0..tree.len() as u32 {
                let b = tree.bound(id, &row);
                let under = tree.patches_under(id);
                let max = under
                    .iter()
                    .map(|&j| values[j as usize])
                    .fold(0.0, f64::max);
                let sum: f64 = under.iter().map(|&j| values[j as usize]).sum();
                assert!(
                    max <= b.max && sum <= b.sum,
                    "{name}: row {i}, node {id} ({} patches): max {max:e} > {:e} or sum {sum:e} > {:e}",
                    under.len(),
                    b.max,
                    b.sum
                );
                // The one-patch bound the tail's walk uses.
                for &j in under {
                    let pb = tree.patch_bound(&e.geom[j as usize], &row);
                    assert!(values[j as usize] <= pb.max, "{name}: row {i}, patch {j}");
                }
                nodes_checked += 1;
                if let crate::formfactor::tree::Kids::Leaf = tree.node(id).kids {
                    if sum > 0.0 && b.sum.is_finite() && tree.node(id).is_far_from(&row, 3.0) {
                        leaves_seen += 1;
                        if b.sum < 4.0 * sum {
                            tight += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(nodes_checked > 200_000, "{nodes_checked}");
    // Bounds that are safe but useless would pass the above: most leaves that see
    // something and are 3 radii away from the row patch must be bounded within 4x.
    assert!(
        2 * tight > leaves_seen,
        "{tight} of {leaves_seen} leaves within 4x"
    );
}

/// The tree search keeps bitwise the entries of the exhaustive one (rooms with boxes,
/// rays through candidate lists and through the hierarchy, the Cornell box; several k,
/// including k above the number of non-zero entries), evaluates far fewer columns, and
/// its dropped mass is an unbiased estimate: stored + dropped against the dense row's
/// sum, over many rows, has a mean error within three standard errors of 0 and a
/// spread that the tail's size explains.
#[test]
fn tree_search_keeps_the_exhaustive_entries() {
    use crate::formfactor::TopKSearch;
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    let cases = [
        ("room", Some(16.0), 1500, 16),
        ("room", Some(64.0), 1500, 64),
        ("cornell", None, 800, 4000),
    ];
    // Without links (the search and the pooled dropped mass) and with them (the same
    // search; the dropped mass is the links' sum, which must be as unbiased).
    for ((name, param, target, k), links) in cases
        .into_iter()
        .flat_map(|c| [(c, None), (c, Some(crate::formfactor::DEFAULT_LINKS))])
    {
        let scene = builtin(name, param).unwrap();
        let patches = subdivide(&scene, default_max_edge(&scene, target));
        let occ = Arc::new(Occluders::new(scene.triangles().collect()));
        let mut tree_cfg = FormFactorConfig::accurate().with_top_k(Some(k));
        tree_cfg.links = links;
        assert_eq!(tree_cfg.top_k_search, TopKSearch::Tree);
        let mut flat_cfg = tree_cfg.clone();
        flat_cfg.top_k_search = TopKSearch::Exhaustive;
        let dense = RowEngine::new(&patches, occ.clone(), FormFactorConfig::accurate());
        let tree = RowEngine::new(&patches, occ.clone(), tree_cfg);
        let flat = RowEngine::new(&patches, occ, flat_cfg);
        assert!(tree.tree.is_some() && flat.tree.is_none());
        let (mut st, mut sf, mut sd) = (Scratch::new(), Scratch::new(), Scratch::new());
        let mut values = Vec::new();
        let (mut errors, mut tails) = (Vec::new(), Vec::new());
        // Every row: the tail estimate's errors are heavy-tailed (rows partly hidden
        // under a box), so the bias test needs them all.
        for i in 0..tree.n() as u32 {
            let (a, b) = (tree.compute_row(i, &mut st), flat.compute_row(i, &mut sf));
            assert_eq!(a.values, b.values, "{name}: row {i}");
            dense.row_values(i, &mut sd, &mut values);
            let total: f64 = values.iter().sum();
            let stored: f64 = match &a.values {
                crate::rows::RowValues::Sparse { vals, .. } => {
                    vals.iter().map(|&v| f64::from(v)).sum()
                }
                _ => unreachable!(),
            };
            errors.push(stored + f64::from(a.dropped) - total);
            tails.push(total - stored);
        }
        let (ct, cf) = (st.counters(), sf.counters());
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let var = errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let tail = tails.iter().sum::<f64>() / n;
        eprintln!(
            "{name} k={k}: F0 evaluations {} vs {}, mean error {mean:.2e} ± {:.2e}, rms {:.2e}, mean tail {tail:.3}",
            ct.pairs_evaluated,
            cf.pairs_evaluated,
            (var / n).sqrt(),
            var.sqrt()
        );
        assert!(
            mean.abs() <= 3.0 * (var / n).sqrt() + 1e-6,
            "{name}: biased {mean:e}"
        );
        // t = 256 points (the preset): the error of a row is of order tail / √t, well under tail / 4.
        assert!(
            var.sqrt() <= 0.25 * tail + 1e-6,
            "{name}: spread {:e}",
            var.sqrt()
        );
        if k < 1000 && links.is_none() {
            // Columns the search evaluated (each walk of the tail evaluates one more;
            // links evaluate their small clusters in full, a cost bench/LINKS.md states).
            let searched = ct.pairs_evaluated - ct.tree_tail_samples.min(ct.pairs_evaluated);
            assert!(
                2 * searched < cf.pairs_evaluated,
                "{name}: the tree evaluated {searched} columns, the exhaustive search {}",
                cf.pairs_evaluated
            );
        }
    }
}

/// Threshold rows (`--min-ff`) keep exactly the entries of the dense row at or above
/// the threshold (with a top-k, the k largest of those), bitwise, whichever search
/// finds them; the rest is dropped mass.
#[test]
fn threshold_rows_keep_exactly_the_dense_entries_at_or_above_it() {
    use crate::formfactor::TopKSearch;
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::rows::RowValues;
    use crate::scene::builtin;
    let scene = builtin("room", Some(16.0)).unwrap();
    let patches = subdivide(&scene, default_max_edge(&scene, 1500));
    let occ = Arc::new(Occluders::new(scene.triangles().collect()));
    let dense = RowEngine::new(&patches, occ.clone(), FormFactorConfig::accurate());
    let eps = 2e-4;
    let mut sd = Scratch::new();
    let mut values = Vec::new();
    for top_k in [None, Some(24)] {
        let tree_cfg = FormFactorConfig::accurate()
            .with_top_k(top_k)
            .with_min_ff(Some(eps));
        let mut exact_cfg = tree_cfg.clone();
        exact_cfg.top_k_search = TopKSearch::Exhaustive;
        exact_cfg.top_k_tail = TopKTail::Exact;
        let tree = RowEngine::new(&patches, occ.clone(), tree_cfg);
        let exact = RowEngine::new(&patches, occ.clone(), exact_cfg);
        let (mut st, mut sx) = (Scratch::new(), Scratch::new());
        let mut kept_some = 0;
        for i in (0..dense.n() as u32).step_by(13) {
            dense.row_values(i, &mut sd, &mut values);
            let mut want: Vec<u32> = (0..values.len() as u32)
                .filter(|&j| values[j as usize] >= eps)
                .collect();
            if let Some(k) = top_k {
                want.sort_by(|&a, &b| {
                    values[b as usize]
                        .total_cmp(&values[a as usize])
                        .then(a.cmp(&b))
                });
                want.truncate(k as usize);
                want.sort_unstable();
            }
            let (a, b) = (tree.compute_row(i, &mut st), exact.compute_row(i, &mut sx));
            assert_eq!(a.values, b.values, "row {i}, top-k {top_k:?}");
            let RowValues::Sparse { cols, vals } = &b.values else {
                panic!("sparse rows")
            };
            assert_eq!(cols, &want, "row {i}");
            for (&j, &v) in cols.iter().zip(vals) {
                assert_eq!(v, values[j as usize] as f32, "row {i} column {j}");
            }
            let total: f64 = values.iter().sum();
            assert!(
                (b.true_sum() - total).abs() <= 1e-5 * total.max(1.0),
                "row {i}"
            );
            kept_some += usize::from(!cols.is_empty() && cols.len() < values.len() / 2);
        }
        assert!(kept_some > 50, "{kept_some} rows with a real threshold");
    }
}

/// Rows that find many hidden columns (floor cells under the room's boxes, standing or
/// floating) skip the nodes an occluder polygon or an enclosing cell hides (topk_tree
/// step 4): the kept entries are bit for bit those without the shortcut and those of
/// the exhaustive search; the dropped mass of a row that skips a node is unbiased (the
/// skipped nodes, all zeros, are not sampled); the shortcut is taken and saves
/// evaluations.
#[test]
fn hidden_rows_skip_hidden_nodes_and_keep_their_rows() {
    use crate::formfactor::TopKSearch;
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    let scene = builtin("room", Some(16.0)).unwrap();
    let patches = subdivide(&scene, default_max_edge(&scene, 6000));
    let occ = Arc::new(Occluders::new(scene.triangles().collect()));
    let k = 64;
    let cfg = FormFactorConfig::fast().with_top_k(Some(k));
    assert_eq!(cfg.top_k_search, TopKSearch::Tree);
    let mut flat_cfg = cfg.clone();
    flat_cfg.top_k_search = TopKSearch::Exhaustive;
    let dense_cfg = FormFactorConfig::fast();
    let culling = RowEngine::new(&patches, occ.clone(), cfg.clone());
    let plain = RowEngine::new(&patches, occ.clone(), cfg).without_hidden_culling();
    let flat = RowEngine::new(&patches, occ.clone(), flat_cfg);
    let dense = RowEngine::new(&patches, occ, dense_cfg);
    let mut s = [
        Scratch::new(),
        Scratch::new(),
        Scratch::new(),
        Scratch::new(),
    ];
    let (mut hidden_rows, mut same_dropped, mut errors) = (0, 0, Vec::new());
    let mut evaluated = [0u64; 2];
    let mut values = Vec::new();
    for i in 0..culling.n() as u32 {
        // The floor (y = 0, facing up) right under a box (the room is 3 high), and a
        // sample of the rest.
        let g = &culling.geom[i as usize];
        let up = g.centroid + DVec3::Y * 2.5;
        let under = g.normal.y > 0.9
            && g.centroid.y.abs() < 1e-9
            && culling.occluders.occluded(g.centroid, up, (g.face, g.face));
        if !under && i % 29 != 0 {
            continue;
        }
        let (before, e0, e1) = (
            s[0].counters().tree_nodes_hidden,
            s[0].counters().pairs_evaluated,
            s[1].counters().pairs_evaluated,
        );
        let a = culling.compute_row(i, &mut s[0]);
        let b = plain.compute_row(i, &mut s[1]);
        if s[0].counters().tree_nodes_hidden > before {
            hidden_rows += 1;
            evaluated[0] += s[0].counters().pairs_evaluated - e0;
            evaluated[1] += s[1].counters().pairs_evaluated - e1;
        }
        assert_eq!(a.values, b.values, "row {i}");
        assert_eq!(a.values, flat.compute_row(i, &mut s[2]).values, "row {i}");
        same_dropped += usize::from(a.dropped.to_bits() == b.dropped.to_bits());
        let stored: f64 = match &a.values {
            crate::rows::RowValues::Sparse { vals, .. } => vals.iter().map(|&v| f64::from(v)).sum(),
            _ => unreachable!(),
        };
        dense.row_values(i, &mut s[3], &mut values);
        errors.push(stored + f64::from(a.dropped) - values.iter().sum::<f64>());
    }
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let var = errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0);
    eprintln!(
        "{} rows, {hidden_rows} with hidden nodes, {same_dropped} with the same dropped mass; \
         their evaluations {} vs {}, nodes skipped {}; row total error {mean:.2e} ± {:.2e}",
        errors.len(),
        evaluated[0],
        evaluated[1],
        s[0].counters().tree_nodes_hidden,
        (var / n).sqrt()
    );
    assert!(hidden_rows >= 20, "{hidden_rows} rows took the shortcut");
    // Measured: 0.54 at these patches (the saving grows with them: bench/PERF.md §23).
    assert!(3 * evaluated[0] < 2 * evaluated[1], "{evaluated:?}");
    assert!(
        mean.abs() <= 3.0 * (var / n).sqrt() + 1e-6,
        "biased {mean:e}"
    );
}

/// The hidden rows' shortcut on two more scenes with hidden patches, every row: the
/// Cornell box (floor under the blocks) and the city (ground under the buildings, open
/// to the sky): kept entries bit for bit those of the search without it, and the
/// dropped mass too for a row that skips no node; the shortcut taken.
#[test]
fn hidden_rows_shortcut_changes_no_entry_in_the_cornell_box_and_the_city() {
    use crate::geometry::subdivide::{default_max_edge, subdivide};
    use crate::scene::builtin;
    for (name, target) in [("cornell", 3000), ("city", 3000)] {
        let scene = builtin(name, None).unwrap();
        let patches = subdivide(&scene, default_max_edge(&scene, target));
        let occ = Arc::new(Occluders::new(scene.triangles().collect()));
        let cfg = FormFactorConfig::fast().with_top_k(Some(64));
        let culling = RowEngine::new(&patches, occ.clone(), cfg.clone());
        let plain = RowEngine::new(&patches, occ, cfg).without_hidden_culling();
        let (mut sc, mut sp) = (Scratch::new(), Scratch::new());
        let (mut hidden_rows, mut evaluated) = (0, [0u64; 2]);
        for i in 0..culling.n() as u32 {
            let (before, e0, e1) = (
                sc.counters().tree_nodes_hidden,
                sc.counters().pairs_evaluated,
                sp.counters().pairs_evaluated,
            );
            let (a, b) = (
                culling.compute_row(i, &mut sc),
                plain.compute_row(i, &mut sp),
            );
            assert_eq!(a.values, b.values, "{name}: row {i}");
            let took = sc.counters().tree_nodes_hidden > before;
            if took {
                hidden_rows += 1;
                evaluated[0] += sc.counters().pairs_evaluated - e0;
                evaluated[1] += sp.counters().pairs_evaluated - e1;
            } else {
                assert_eq!(a.dropped.to_bits(), b.dropped.to_bits(), "{name}: row {i}");
            }
        }
        eprintln!("{name}: {hidden_rows} rows took the shortcut; their evaluations {evaluated:?}");
        assert!(
            hidden_rows >= 20,
            "{name}: {hidden_rows} rows took the shortcut"
        );
        assert!(evaluated[0] < evaluated[1], "{name}: {evaluated:?}");
    }
}

/// A floor cell and the bottom patch of a rotated box's wall whose foot passes 1e-4 m
/// from the cell's corner (rows 103,666 and 952,880 of the 16-box room at 1M patches):
/// clipping puts an edge of the cell along the wall's foot, collinear within rounding,
/// and the contour kernel split that edge pair toward 10⁹ panels (a hang of `compute`).
/// Now the pair returns, each direction in [0, 1] and at most the area of the part of
/// the patch in front of the other's plane (a sliver of the cell; the whole wall).
/// (The two directions are not reciprocal here, 4.1e-9 against 2.8e-9 m² of exchange:
/// each clips a different sliver; a known limit of grazing pairs, bench/PERF.md §23.)
#[test]
fn a_wall_foot_along_a_clipped_edge_does_not_hang_the_kernel() {
    let cell = quad(
        [
            dvec3(4.230769230769231, 0.0, 8.502024291497976),
            dvec3(4.230769230769231, 0.0, 8.522267206477732),
            dvec3(4.251012145748988, 0.0, 8.522267206477732),
            dvec3(4.251012145748988, 0.0, 8.502024291497976),
        ],
        0,
    );
    let wall = quad(
        [
            dvec3(4.240166380756312, 0.0, 8.528552135018098),
            dvec3(4.240166380756312, 0.019614379177935373, 8.528552135018098),
            dvec3(4.223602773163755, 0.01961437917793538, 8.51728797942914),
            dvec3(4.223602773163755, 0.0, 8.51728797942914),
        ],
        1,
    );
    assert!(cell.normal.y > 0.99 && wall.normal.z > 0.8);
    // The area of each patch in front of the other's plane.
    let front = |p: &Patch, q: &Patch| {
        let poly = Polygon::new(p.corners()).clip_front(q.normal, q.normal.dot(q.corners[0]), 0.0);
        let v = poly.verts();
        (1..v.len().saturating_sub(1))
            .map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length())
            .sum::<f64>()
    };
    let (ai, aj) = (front(&cell, &wall), front(&wall, &cell));
    let (area_i, area_j) = (cell.area, wall.area);
    assert!(ai > 0.0 && ai < 1e-3 * area_i && (aj - area_j).abs() < 1e-12);
    let patches = PatchSet {
        patches: vec![cell, wall],
        groups: vec!["g".into()],
    };
    for cfg in [FormFactorConfig::fast(), FormFactorConfig::accurate()] {
        let e = RowEngine::new(&patches, Arc::new(Occluders::empty()), cfg);
        let mut s = Scratch::new();
        let (fij, fji) = (e.pair_value(0, 1, &mut s), e.pair_value(1, 0, &mut s));
        assert!(
            (0.0..=1.0).contains(&fij) && (0.0..=1.0).contains(&fji),
            "{fij} {fji}"
        );
        assert!(area_i * fij <= ai && area_j * fji <= ai, "{fij} {fji} {ai}");
    }
}
