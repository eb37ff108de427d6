//! The tree's structure: every valid patch once, small leaves, the same tree for the
//! same patches. Its bounds are tested against computed F⁰ in `engine/tests.rs`.

use super::*;
use crate::geometry::subdivide::{default_max_edge, subdivide};
use crate::scene::builtin;

fn geometry(name: &str, target: usize) -> (Vec<PatchGeom>, Vec<bool>) {
    let scene = builtin(name, None).unwrap();
    let patches = subdivide(&scene, default_max_edge(&scene, target));
    let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
    let valid = geom.iter().map(PatchGeom::is_valid).collect();
    (geom, valid)
}

#[test]
fn every_valid_patch_is_in_one_leaf_and_the_tree_is_reproducible() {
    let (geom, mut valid) = geometry("room", 900);
    // Some patches left out, as zero-area ones would be.
    for j in (0..valid.len()).step_by(37) {
        valid[j] = false;
    }
    let tree = PatchTree::new(&geom, &valid, 1e-10, 1e-12);
    let mut seen = vec![0u32; geom.len()];
    for id in 0..tree.len() as u32 {
        let node = tree.node(id);
        let under = tree.patches_under(id);
        assert_eq!(under.len() as u32, node.count);
        let area: f64 = under.iter().map(|&j| geom[j as usize].area).sum();
        assert!((area - node.area_sum).abs() <= 1e-12 * area, "{id}");
        for &j in under {
            let g = &geom[j as usize];
            for c in g.poly.verts() {
                assert!(c.cmpge(node.lo).all() && c.cmple(node.hi).all(), "{id} {j}");
            }
            assert!(
                angle_between(node.axis, g.normal) <= node.spread,
                "{id} {j}"
            );
        }
        match node.kids {
            Kids::Leaf => {
                let patches = tree.patches_under(id);
                assert!(patches.len() <= LEAF_PATCHES && !patches.is_empty());
                assert!(patches.windows(2).all(|w| w[0] < w[1]));
                for &j in patches {
                    seen[j as usize] += 1;
                }
            }
            Kids::Inner(l, r) => {
                let (a, b) = (tree.node(l).count, tree.node(r).count);
                assert_eq!(a + b, node.count);
                assert!(a > 0 && b > 0);
                if node.spread <= SPLIT_ON_NORMALS_ABOVE {
                    assert!(a.abs_diff(b) <= 1, "median split {a} / {b}");
                }
            }
        }
    }
    for (j, &n) in seen.iter().enumerate() {
        assert_eq!(n, u32::from(valid[j]), "patch {j}");
    }
    let again = PatchTree::new(&geom, &valid, 1e-10, 1e-12);
    assert_eq!(again.order, tree.order);
    assert_eq!(again.nodes.len(), tree.nodes.len());
}

#[test]
fn the_walls_of_a_room_part_before_anything_else() {
    let (geom, valid) = geometry("cube", 600);
    let tree = PatchTree::new(&geom, &valid, 1e-10, 1e-12);
    // The root holds six directions; nodes of a sixth of the patches or fewer face
    // one way (a node straddling two walls would have a 45° cone).
    let sixth = tree.node(0).count / 6;
    let (mut narrow, mut wide) = (0, 0);
    for id in 0..tree.len() as u32 {
        let node = tree.node(id);
        if node.count <= sixth {
            if node.spread < 1e-3 {
                narrow += 1;
            } else {
                wide += 1;
            }
        }
    }
    assert!(tree.node(0).spread > 2.0, "{:?}", tree.node(0));
    assert!(narrow > 100 && wide == 0, "narrow {narrow}, wide {wide}");
}

#[test]
fn a_node_behind_the_row_patch_or_facing_away_is_bounded_by_zero() {
    let (geom, valid) = geometry("cornell", 200);
    let tree = PatchTree::new(&geom, &valid, 1e-10, 1e-12);
    // A patch of the floor: nothing below the floor's plane can be seen.
    let floor = (0..geom.len())
        .find(|&j| valid[j] && geom[j].normal.y > 0.999 && geom[j].centroid.y < 1e-6)
        .expect("a floor patch");
    let row = PatchBound::of(&geom[floor]);
    for id in 0..tree.len() as u32 {
        let under = tree.patches_under(id);
        let coplanar = under.iter().all(|&j| {
            let g = &geom[j as usize];
            g.poly.verts().iter().all(|c| c.y.abs() < 1e-9)
        });
        if coplanar {
            assert_eq!(tree.bound(id, &row), Bound::ZERO, "node {id}");
        }
    }
}

/// With kinds (emitters apart from the rest), a node that holds both kinds has one
/// kind in each child: no node below the split mixes the room's lamp with its ceiling,
/// and the cluster order still holds every patch once.
#[test]
fn kinds_are_parted_before_anything_else() {
    let scene = builtin("room", None).unwrap();
    let patches = subdivide(&scene, default_max_edge(&scene, 900));
    let geom: Vec<PatchGeom> = patches.patches.iter().map(PatchGeom::new).collect();
    let valid: Vec<bool> = geom.iter().map(PatchGeom::is_valid).collect();
    let kinds: Vec<u8> = patches
        .patches
        .iter()
        .map(|p| u8::from(p.emission.iter().any(|&e| e > 0.0)))
        .collect();
    assert!(kinds.contains(&1) && kinds.contains(&0));
    let tree = PatchTree::with_kinds(&geom, &valid, &kinds, 1e-10, 1e-12);
    let mixed = |id: u32| {
        let under = tree.patches_under(id);
        under
            .iter()
            .any(|&j| kinds[j as usize] != kinds[under[0] as usize])
    };
    for id in 0..tree.len() as u32 {
        if let Kids::Inner(a, b) = tree.node(id).kids {
            if mixed(id) {
                assert!(!mixed(a) || !mixed(b), "node {id}: both children mix kinds");
            }
        } else {
            assert!(!mixed(id), "leaf {id} mixes kinds");
        }
    }
    let mut order = tree.cluster_order(geom.len());
    order.sort_unstable();
    assert!(order.iter().enumerate().all(|(k, &j)| k as u32 == j));
}

/// `position_at_area` lays a node's patches along its area in tree order: a point in the
/// middle of a patch's stretch draws that patch, the ends of the stretch draw the
/// first and last, and so a uniform point draws each patch in proportion to its area.
#[test]
fn a_point_along_a_nodes_area_draws_the_patch_whose_stretch_holds_it() {
    let (geom, mut valid) = geometry("room", 900);
    for j in (0..valid.len()).step_by(41) {
        valid[j] = false;
    }
    let tree = PatchTree::new(&geom, &valid, 1e-10, 1e-12);
    let order = tree.cluster_order(geom.len());
    let at = |id: u32, u: f64| order[tree.position_at_area(id, u) as usize];
    for id in 0..tree.len() as u32 {
        let under = tree.patches_under(id);
        let mut before = 0.0;
        for &j in under {
            let a = geom[j as usize].area;
            assert_eq!(at(id, before + 0.5 * a), j, "node {id}");
            before += a;
        }
        assert_eq!(at(id, 0.0), under[0], "node {id}");
        let last = *under.last().unwrap();
        assert_eq!(at(id, before), last, "node {id}");
        assert_eq!(at(id, 2.0 * before), last, "node {id}");
    }
    // Several searches in step give the positions of one at a time, for points
    // anywhere along every node (and past its end).
    let mut rng = crate::formfactor::sampling::SplitMix64::new(5);
    let ids: Vec<u32> = (0..tree.len() as u32).collect();
    for group in ids.chunks(7) {
        let queries: Vec<(u32, f64)> = group
            .iter()
            .map(|&id| (id, 1.05 * rng.next_f64() * tree.node(id).moments().0))
            .collect();
        let mut out = [u32::MAX; 8];
        tree.positions_at_area(&queries, &mut out);
        for (t, &(id, u)) in queries.iter().enumerate() {
            assert_eq!(out[t], tree.position_at_area(id, u), "node {id} at {u}");
        }
        assert_eq!(out[queries.len()], u32::MAX);
    }
}
