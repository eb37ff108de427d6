//! Tests of the links of sparse rows: the slope's algebra and the points' estimates.

use super::*;
use crate::formfactor::geom::PatchGeom;
use crate::formfactor::sampling::SplitMix64;
use crate::formfactor::tree::second_matrix;
use crate::geometry::subdivide::{default_max_edge, subdivide};
use crate::scene::builtin;

fn room_tree() -> (PatchTree, Vec<PatchGeom>) {
    let scene = builtin("room", None).unwrap();
    let patches = subdivide(&scene, default_max_edge(&scene, 600));
    let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
    let valid: Vec<bool> = geom.iter().map(PatchGeom::is_valid).collect();
    (PatchTree::new(&geom, &valid, 1e-10, 1e-12), geom)
}

/// The points of an unopened node (step 2) estimate the node's Σ_j F_ij without
/// bias: in the 16-box room (boxes between many pairs), for rows on the floor,
/// the ceiling and a wall and every node of a few dozen patches clear of the row
/// patch (finite bound), the mean of 4,000 points is within four standard errors
/// of the sum of the pair rule's values over the node, plus 1 % of that sum for
/// the pair rule's own ray estimate (16 rays a pair, a ratio estimator).
#[test]
fn node_points_estimate_the_nodes_form_factor_sum_without_bias() {
    let (patches, e) = crate::formfactor::engine::tests::linked_room(600);
    let tree = e.tree.as_ref().expect("a tree search");
    let group = |name: &str| {
        let g = patches.groups.iter().position(|x| x == name).unwrap() as u32;
        patches.patches.iter().position(|p| p.group == g).unwrap() as u32
    };
    let mut s = Scratch::new();
    let (mut tried, mut occluded) = (0, 0);
    for i in [group("floor"), group("ceiling"), group("wall_x0")] {
        let row = e.bounds[i as usize];
        for id in 0..tree.len() as u32 {
            let node = tree.node(id);
            let under = tree.patches_under(id);
            if !(24..=64).contains(&node.count())
                || under.contains(&i)
                || !tree.bound(id, &row).sum.is_finite()
            {
                continue;
            }
            let exact: f64 = under.iter().map(|&j| e.pair_value(i, j, &mut s)).sum();
            let unoccluded: f64 = under
                .iter()
                .filter_map(|&j| {
                    let (gi, gj) = (&e.geom[i as usize], &e.geom[j as usize]);
                    let extent = e.facing(i as usize, j as usize, &mut s)?;
                    e.contour_unoccluded((i, j), gi, gj, extent, &mut s)
                        .map(|u| u.f)
                })
                .sum();
            let mut rng = SplitMix64::new(u64::from(id) << 32 | u64::from(i));
            let (mut sum, mut squares, mut count) = (0.0, 0.0, 0.0);
            let (mut plan, mut points) = (Vec::new(), Vec::new());
            e.plan_node_points(tree, id, i, 4000, &mut rng, &mut plan);
            e.eval_points(tree, i, &plan, &mut s, &mut points);
            for (y, _) in points {
                sum += y;
                squares += y * y;
                count += 1.0;
            }
            let mean = sum / count;
            let se = ((squares / count - mean * mean).max(0.0) / count).sqrt();
            assert!(
                (mean - exact).abs() <= 4.0 * se + 0.01 * exact + 1e-12,
                "row {i}, node {id}: points {mean} ± {se}, pairs {exact}"
            );
            tried += 1;
            occluded += (exact < 0.9 * unoccluded) as usize;
        }
    }
    assert!(
        tried >= 40 && occluded >= 10,
        "{tried} nodes, {occluded} occluded"
    );
}

#[test]
fn pseudo_solve_inverts_a_full_matrix_and_leaves_out_a_flat_direction() {
    let m = [4.0, 3.0, 2.0, 1.0, 0.5, -0.25];
    let v = DVec3::new(1.0, -2.0, 0.5);
    let x = pseudo_solve(m, v);
    assert!((second_matrix(m) * x - v).length() < 1e-12, "{x}");
    // A cluster flat across z (rotated): no second moment along the normal n.
    let n = DVec3::new(1.0, 2.0, 2.0) / 3.0;
    let (u, w) = n.any_orthonormal_pair();
    let flat = 2.0
        * glam::DMat3::from_cols(u, DVec3::ZERO, DVec3::ZERO)
        * glam::DMat3::from_cols(u, DVec3::ZERO, DVec3::ZERO).transpose()
        + 5.0
            * glam::DMat3::from_cols(w, DVec3::ZERO, DVec3::ZERO)
            * glam::DMat3::from_cols(w, DVec3::ZERO, DVec3::ZERO).transpose();
    let c = flat.to_cols_array();
    let m = [c[0], c[4], c[8], c[1], c[2], c[5]];
    let x = pseudo_solve(m, v);
    let in_plane = v - n * n.dot(v);
    assert!(x.dot(n).abs() < 1e-12, "{x}");
    assert!((flat * x - in_plane).length() < 1e-12, "{x}");
}

/// The slope puts the centroid of the link's weights A_j (1 + q · (x_j − x̄)) at
/// the centre it was given, for every node of the room's tree with some extent,
/// while the limiter keeps every weight ≥ [`WEIGHT_FLOOR`] A_j; a centre far outside
/// shrinks it, and the spread it reports bounds (1 + Σ |w_j| / Σ w_j) / 2.
#[test]
fn a_slope_moves_the_weights_centroid_to_the_links_centre_and_no_weight_below_the_floor() {
    let (tree, geom) = room_tree();
    let mut exact = 0;
    for id in 0..tree.len() as u32 {
        let node = tree.node(id);
        let (area, mean, m) = node.moments();
        if node.count() < 2 {
            continue;
        }
        let pat = tree.patches_under(id);
        // A centre a little toward the node's first patch, and one far away.
        let near = mean + 0.05 * (geom[pat[0] as usize].centroid - mean);
        let far = mean + 1e3 * (geom[pat[0] as usize].centroid - mean);
        for centre in [near, far] {
            let inverse = PseudoInverse::of(tree.node(id).moments().2);
            let slope = link_slope(&tree, &geom, None, (id, &inverse), centre.extend(0.0), &[]);
            let q = DVec3::from_array(slope.q.map(f64::from));
            let w: Vec<f64> = pat
                .iter()
                .map(|&j| geom[j as usize].area * (1.0 + q.dot(geom[j as usize].centroid - mean)))
                .collect();
            assert!(
                pat.iter()
                    .zip(&w)
                    .all(|(&j, &x)| x >= WEIGHT_FLOOR * geom[j as usize].area - 1e-12 * area),
                "node {id}: {w:?}"
            );
            let sum: f64 = w.iter().sum();
            let abs: f64 = w.iter().map(|x| x.abs()).sum();
            assert!(
                slope.spread >= (1.0 + abs / sum) / 2.0 - 1e-12,
                "node {id}: spread {} for weights {w:?}",
                slope.spread
            );
            assert!(
                (sum - area).abs() < 1e-9 * area,
                "node {id}: weights sum {sum} vs {area}"
            );
            let got = pat
                .iter()
                .zip(&w)
                .map(|(&j, &x)| x * geom[j as usize].centroid)
                .sum::<DVec3>()
                / sum;
            // The reachable part of the shift: its projection on the node's extent.
            let want = mean + second_matrix(m) * pseudo_solve(m, centre - mean);
            let size = (node.centroid_bounds().1 - node.centroid_bounds().0).length();
            if centre == near && (got - want).length() < 0.07 * (want - mean).length() + 1e-9 * size
            {
                exact += 1;
            }
            if centre == far {
                // Limited: it leans the right way, less far.
                assert!(
                    (got - mean).dot(want - mean) >= 0.0,
                    "node {id}: got {got} want {want} mean {mean} q {q} m {m:?} count {}",
                    node.count()
                );
                assert!((got - mean).length() <= (want - mean).length() + 1e-9 * size);
            }
        }
    }
    // Near centres are reached (to the slopes' 5 bits) unless the box limits them.
    assert!(exact > tree.len() / 2, "{exact} of {} nodes", tree.len());
}

/// With a first-bounce estimate B¹, the slope is moved (least in the weights' own
/// metric) until the weights gather the target B¹ the link's samples found: for
/// every node of the room's tree over which B¹ varies, a target a little above the
/// node's area mean of B¹ is gathered to within the slope's rounding (4 bits).
#[test]
fn a_first_bounce_target_is_gathered_by_the_weights() {
    let (tree, geom) = room_tree();
    let b: Vec<f32> = geom
        .iter()
        .map(|g| (g.centroid.x * g.centroid.x + 0.5 * g.centroid.y + 3.0) as f32)
        .collect();
    let contrast = Contrast::new(&tree, b.clone(), &vec![0.0; b.len()], &geom);
    let mut tried = 0;
    for id in 0..tree.len() as u32 {
        let node = tree.node(id);
        let (area, mean, _) = node.moments();
        let (sum, g) = contrast.moments[id as usize];
        if node.count() < 2 || g.length() < 1e-3 * sum.abs() {
            continue;
        }
        let pat = tree.patches_under(id);
        let top = pat
            .iter()
            .map(|&j| b[j as usize] as f64)
            .fold(f64::MIN, f64::max);
        let target = sum / area + 0.02 * (top - sum / area);
        let q = DVec3::from_array(
            link_slope(
                &tree,
                &geom,
                Some(&contrast),
                (id, &PseudoInverse::of(tree.node(id).moments().2)),
                mean.extend(target),
                &[],
            )
            .q
            .map(f64::from),
        );
        let w = |j: u32| geom[j as usize].area * (1.0 + q.dot(geom[j as usize].centroid - mean));
        let total: f64 = pat.iter().map(|&j| w(j)).sum();
        let got = pat
            .iter()
            .map(|&j| w(j) * b[j as usize] as f64)
            .sum::<f64>()
            / total;
        let asked = target - sum / area;
        assert!(
            (got - target).abs() <= 0.07 * asked.abs() + 1e-9,
            "node {id}: gathered {got}, target {target} (mean {})",
            sum / area
        );
        tried += 1;
    }
    assert!(tried > 10, "{tried} nodes tried");
}
