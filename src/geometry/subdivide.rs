//! Subdivision of scene faces into patches (docs/numerics.md §4: no patch edge longer than
//! `--max-edge`).
//!
//! - A triangle ABC becomes k² congruent triangles, k = ⌈longest edge / max_edge⌉:
//!   the grid points A + (i/k)(B−A) + (j/k)(C−A), i + j ≤ k, cut into k(k+1)/2
//!   "upright" and k(k−1)/2 "inverted" triangles. Every sub-edge is parallel to an
//!   edge of ABC and 1/k of its length.
//! - A planar convex quad P0P1P2P3 becomes an a × b grid of sub-quads at the points of
//!   the bilinear map P(u, v) = (1−v)[(1−u)P0 + uP1] + v[(1−u)P3 + uP2]. Lines of
//!   constant u or v are straight, so the sub-quads tile the quad exactly; each is
//!   planar, and convex because the map's Jacobian at its corners (the cross products
//!   of its edges) is positive wherever the quad's corners are. An edge of constant v
//!   has length (Δu)·|(1−v)(P1−P0) + v(P2−P3)| ≤ Δu·max(|P0P1|, |P3P2|), hence
//!   a = ⌈max(|P0P1|, |P3P2|) / max_edge⌉ and b likewise with the other pair of edges.
//!
//! Grid points are computed once and shared by neighbouring patches, so shared corners
//! are bit-identical. Patches keep the face's orientation and unit normal; areas come
//! from the patch's own corners and sum to the face area up to rounding.

use glam::DVec3;

use crate::patch::{Patch, PatchSet};
use crate::scene::{polygon_area, polygon_normal, Face, Scene};

/// Patch count [`default_max_edge`] aims at when the user gives no `--max-edge`.
pub const DEFAULT_TARGET_PATCHES: usize = 2000;

/// Grid size of a face: `(k, k)` for a triangle (k² patches), `(a, b)` for a quad
/// (a·b patches).
fn grid(face: &Face, max_edge: f64) -> (usize, usize) {
    let c = &face.corners;
    let cuts = |len: f64| ((len / max_edge).ceil() as usize).max(1);
    if c.len() == 3 {
        let longest = c[0]
            .distance(c[1])
            .max(c[1].distance(c[2]))
            .max(c[2].distance(c[0]));
        let k = cuts(longest);
        (k, k)
    } else {
        (
            cuts(c[0].distance(c[1]).max(c[3].distance(c[2]))),
            cuts(c[1].distance(c[2]).max(c[0].distance(c[3]))),
        )
    }
}

/// Number of patches [`subdivide`] would make, without making them.
pub fn patch_count(scene: &Scene, max_edge: f64) -> usize {
    scene
        .faces
        .iter()
        .map(|f| {
            let (a, b) = grid(f, max_edge);
            // Saturating: a tiny max_edge (user input) must give a huge count for the
            // caller to refuse, not an overflow.
            a.saturating_mul(b)
        })
        .fold(0usize, usize::saturating_add)
}

/// Cut every face of `scene` so that no patch edge is longer than `max_edge`.
/// Patches are in face order; within a face, row by row.
///
/// `max_edge` must be positive and finite (the caller validates user input); the
/// result has [`patch_count`] patches, which the caller may check first against a
/// memory budget.
pub fn subdivide(scene: &Scene, max_edge: f64) -> PatchSet {
    debug_assert!(max_edge > 0.0, "max_edge must be positive, got {max_edge}");
    let mut patches = Vec::with_capacity(patch_count(scene, max_edge));
    for (fi, face) in scene.faces.iter().enumerate() {
        let m = &scene.materials[face.material as usize];
        let normal = polygon_normal(&face.corners);
        let mut push = |corners: &[DVec3]| {
            let mut c = [DVec3::ZERO; 4];
            c[..corners.len()].copy_from_slice(corners);
            patches.push(Patch {
                corners: c,
                n_corners: corners.len() as u8,
                normal,
                area: polygon_area(corners),
                group: face.group,
                face: fi as u32,
                rho: m.rho,
                emission: m.emission,
            });
        };
        let (a, b) = grid(face, max_edge);
        let c = &face.corners;
        if c.len() == 3 {
            let k = a;
            let (e1, e2) = ((c[1] - c[0]) / k as f64, (c[2] - c[0]) / k as f64);
            // Row j holds the k + 1 − j points with that j.
            let rows: Vec<Vec<DVec3>> = (0..=k)
                .map(|j| {
                    (0..=k - j)
                        .map(|i| {
                            if i == k {
                                c[1]
                            } else if j == k {
                                c[2]
                            } else {
                                c[0] + e1 * i as f64 + e2 * j as f64
                            }
                        })
                        .collect()
                })
                .collect();
            for j in 0..k {
                for i in 0..k - j {
                    push(&[rows[j][i], rows[j][i + 1], rows[j + 1][i]]);
                    if i + 1 < k - j {
                        push(&[rows[j][i + 1], rows[j + 1][i + 1], rows[j + 1][i]]);
                    }
                }
            }
        } else {
            let point = |i: usize, j: usize| {
                // Exact corners at the ends, so the grid reproduces the face outline.
                match (i == 0, i == a, j == 0, j == b) {
                    (true, _, true, _) => c[0],
                    (_, true, true, _) => c[1],
                    (_, true, _, true) => c[2],
                    (true, _, _, true) => c[3],
                    _ => {
                        let (u, v) = (i as f64 / a as f64, j as f64 / b as f64);
                        (c[0] * (1.0 - u) + c[1] * u) * (1.0 - v)
                            + (c[3] * (1.0 - u) + c[2] * u) * v
                    }
                }
            };
            let pts: Vec<DVec3> = (0..=b)
                .flat_map(|j| (0..=a).map(move |i| (i, j)))
                .map(|(i, j)| point(i, j))
                .collect();
            let at = |i: usize, j: usize| pts[j * (a + 1) + i];
            for j in 0..b {
                for i in 0..a {
                    push(&[at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
    }
    PatchSet {
        patches,
        groups: scene.groups.clone(),
    }
}

/// A `max_edge` that gives `scene` about `target_patches` patches (never fewer than
/// one per face). The count is a non-increasing step function of `max_edge`, cheap to
/// evaluate, so this bisects on it (in log scale) and returns the value whose count is
/// closest to the target. The caller should print what was chosen.
pub fn default_max_edge(scene: &Scene, target_patches: usize) -> f64 {
    let longest = scene
        .faces
        .iter()
        .map(Face::longest_edge)
        .fold(0.0, f64::max);
    // (Not finite: the halving below could never reach the target.)
    if scene.faces.is_empty() || !longest.is_finite() || longest <= 0.0 {
        return 1.0;
    }
    // One patch per face at `longest`; the count only grows as max_edge shrinks.
    let mut hi = longest * (1.0 + 1e-9);
    if target_patches <= scene.faces.len() {
        return hi;
    }
    // Shrink until the count reaches the target.
    let mut lo = hi;
    while patch_count(scene, lo) < target_patches {
        hi = lo;
        lo *= 0.5;
        if lo < longest * 1e-9 {
            return lo; // unreachable target (more than ~1e18 patches)
        }
    }
    // Invariant: count(lo) >= target > count(hi).
    for _ in 0..60 {
        let mid = (lo * hi).sqrt();
        if mid <= lo || mid >= hi {
            break;
        }
        if patch_count(scene, mid) >= target_patches {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let (nl, nh) = (patch_count(scene, lo), patch_count(scene, hi));
    // lo and hi sit within an ulp or so of a jump of the count (some edge length is an
    // integer multiple of them), where rounding decides the count: the same scene in
    // other units (scaled) would then get another patch count. Step 1e-6 (relative) into
    // the chosen step when it is that wide, far beyond any rounding.
    let inside = |x: f64, n: usize, toward: f64| {
        let y = x * toward;
        if patch_count(scene, y) == n {
            y
        } else {
            x
        }
    };
    if nl - target_patches <= target_patches - nh {
        inside(lo, nl, 1.0 - 1e-6)
    } else {
        inside(hi, nh, 1.0 + 1e-6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin;

    fn check(scene: &Scene, max_edge: f64) -> PatchSet {
        let ps = subdivide(scene, max_edge);
        assert_eq!(ps.len(), patch_count(scene, max_edge));
        let mut area = vec![0.0; scene.faces.len()];
        for p in &ps.patches {
            let c = p.corners();
            for i in 0..c.len() {
                let e = c[i].distance(c[(i + 1) % c.len()]);
                assert!(e <= max_edge * (1.0 + 1e-12), "edge {e} > {max_edge}");
            }
            let face = &scene.faces[p.face as usize];
            assert_eq!(p.normal, face.normal());
            // Own orientation agrees with the face's.
            assert!(polygon_normal(c).dot(p.normal) > 1.0 - 1e-9);
            assert!(p.area > 0.0);
            area[p.face as usize] += p.area;
        }
        for (f, a) in scene.faces.iter().zip(&area) {
            assert!(
                (a - f.area()).abs() <= 1e-12 * f.area(),
                "{a} vs {}",
                f.area()
            );
        }
        ps
    }

    #[test]
    fn triangle_k_squared() {
        let s = builtin("cornell", None).unwrap();
        let ps = check(&s, 100.0);
        // Left wall triangle 1: edges 559.2.., longest ≈ 780 → k = 8 → 64 patches.
        let n0 = ps.patches.iter().filter(|p| p.face == 7).count();
        let k = (s.faces[7].longest_edge() / 100.0).ceil() as usize;
        assert_eq!(n0, k * k);
        check(&s, 13.7);
    }

    #[test]
    fn quad_grid_counts() {
        let s = builtin("plates", None).unwrap();
        let ps = check(&s, 0.25);
        assert_eq!(ps.len(), 2 * 16);
        let ps = check(&s, 0.3);
        assert_eq!(ps.len(), 2 * 16);
        let ps = check(&s, 1.0);
        assert_eq!(ps.len(), 2);
    }

    #[test]
    fn default_max_edge_hits_target() {
        let s = builtin("cornell", None).unwrap();
        for target in [100, 2000, 20000] {
            let e = default_max_edge(&s, target);
            let n = patch_count(&s, e);
            assert!(
                (n as f64 - target as f64).abs() < 0.1 * target as f64,
                "target {target}: got {n} at {e}"
            );
        }
        let e = default_max_edge(&s, 1);
        assert_eq!(patch_count(&s, e), s.faces.len());
    }
}

#[cfg(test)]
mod proptests {
    use super::*;
    use crate::scene::{Material, Scene};
    use proptest::prelude::*;

    fn point() -> impl Strategy<Value = DVec3> {
        (-10.0..10.0f64, -10.0..10.0f64, -10.0..10.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    fn scene_of(corners: Vec<DVec3>) -> Scene {
        Scene {
            faces: vec![Face {
                corners,
                group: 0,
                material: 0,
                line: 0,
            }],
            groups: vec!["g".into()],
            materials: vec![Material {
                name: "m".into(),
                rho: [0.5; 3],
                emission: [0.0; 3],
            }],
            ..Scene::default()
        }
    }

    proptest! {
        /// Random triangles and random planar convex quads (a parallelogram sheared at
        /// one corner, kept convex), at random max_edge: edges bounded, area conserved,
        /// every patch with the face's orientation.
        #[test]
        fn random_faces(a in point(), b in point(), c in point(),
                        t in 0.05..0.95f64, s in 0.05..0.95f64, frac in 0.02..1.5f64,
                        quad in any::<bool>()) {
            let corners = if quad {
                // o, o+u, o+u+v, o+v with the third corner pulled towards the centre:
                // stays planar and convex.
                let (u, v) = (b - a, c - a);
                vec![a, a + u, a + (u + v) * (0.5 + 0.5 * t) + (u - v) * (0.25 * (s - 0.5)), a + v]
            } else {
                vec![a, b, c]
            };
            let scene = scene_of(corners);
            prop_assume!(scene.validate().is_ok());
            let face = &scene.faces[0];
            let max_edge = face.longest_edge() * frac;
            let ps = subdivide(&scene, max_edge);
            prop_assert_eq!(ps.len(), patch_count(&scene, max_edge));
            let n = face.normal();
            let mut area = 0.0;
            for p in &ps.patches {
                let c = p.corners();
                for i in 0..c.len() {
                    prop_assert!(c[i].distance(c[(i + 1) % c.len()]) <= max_edge * (1.0 + 1e-12));
                }
                prop_assert!(polygon_normal(c).dot(n) > 1.0 - 1e-9);
                area += p.area;
            }
            prop_assert!((area - face.area()).abs() <= 1e-11 * face.area());
        }
    }
}
