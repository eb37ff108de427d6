//! Set-up cost of merging coplanar occluders (`ffstream::geometry::merge`), which every
//! computing process pays once before it builds its occluder tree.
//!
//!     cargo bench --bench occluder_merge                    # about 10⁵ and 10⁶ triangles
//!     cargo bench --bench occluder_merge -- --cells 300     # one size: a 300 × 300 ground
//!
//! The mesh is a city as a mesher delivers it: a square ground of 1 m cells, two
//! triangles each, with every fifth block of 3 × 3 cells taken by a box building whose
//! walls and roof are split into 1 m cells too (so the ground has a hole under each
//! building, and no facet is shared between faces). Printed: triangles in and out, the
//! planes merged, and the median wall time of 3 runs.

use std::time::Instant;

use ffstream::geometry::merge::merge_coplanar;
use glam::{dvec3, DVec3};

/// The pre-split city on a `cells` × `cells` ground.
fn city(cells: usize) -> Vec<[DVec3; 3]> {
    let mut t = Vec::new();
    let mut quad = |p: [DVec3; 4]| {
        t.push([p[0], p[1], p[2]]);
        t.push([p[0], p[2], p[3]]);
    };
    let block = |i: usize, j: usize| {
        (i / 3 + 7 * (j / 3)).is_multiple_of(5) && i / 3 < cells / 3 && j / 3 < cells / 3
    };
    for i in 0..cells {
        for j in 0..cells {
            let (x, y) = (i as f64, j as f64);
            if !block(i, j) {
                quad([
                    dvec3(x, y, 0.0),
                    dvec3(x + 1.0, y, 0.0),
                    dvec3(x + 1.0, y + 1.0, 0.0),
                    dvec3(x, y + 1.0, 0.0),
                ]);
            }
        }
    }
    for bi in 0..cells / 3 {
        for bj in 0..cells / 3 {
            if !block(3 * bi, 3 * bj) {
                continue;
            }
            let (x0, y0) = (3.0 * bi as f64, 3.0 * bj as f64);
            let h = 3 + (bi * 7 + bj * 13) % 6;
            for k in 0..3 {
                for z in 0..h {
                    let (a, z0, z1) = (k as f64, z as f64, z as f64 + 1.0);
                    for (p, q) in [
                        (dvec3(x0 + a, y0, 0.0), dvec3(x0 + a + 1.0, y0, 0.0)),
                        (
                            dvec3(x0 + 3.0, y0 + a, 0.0),
                            dvec3(x0 + 3.0, y0 + a + 1.0, 0.0),
                        ),
                        (
                            dvec3(x0 + 3.0 - a, y0 + 3.0, 0.0),
                            dvec3(x0 + 2.0 - a, y0 + 3.0, 0.0),
                        ),
                        (dvec3(x0, y0 + 3.0 - a, 0.0), dvec3(x0, y0 + 2.0 - a, 0.0)),
                    ] {
                        let up = |v: DVec3, z: f64| dvec3(v.x, v.y, z);
                        quad([up(p, z0), up(q, z0), up(q, z1), up(p, z1)]);
                    }
                }
                for m in 0..3 {
                    let (x, y, z) = (x0 + k as f64, y0 + m as f64, h as f64);
                    quad([
                        dvec3(x, y, z),
                        dvec3(x + 1.0, y, z),
                        dvec3(x + 1.0, y + 1.0, z),
                        dvec3(x, y + 1.0, z),
                    ]);
                }
            }
        }
    }
    t
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let sizes: Vec<usize> = match args.iter().position(|a| a == "--cells") {
        Some(k) => vec![args[k + 1].parse().expect("--cells N")],
        None => vec![200, 650],
    };
    for cells in sizes {
        let mesh = city(cells);
        let mut times = Vec::new();
        let mut last = None;
        for _ in 0..3 {
            let t0 = Instant::now();
            let m = merge_coplanar(mesh.iter().copied());
            times.push(t0.elapsed().as_secs_f64());
            last = Some(m);
        }
        times.sort_by(f64::total_cmp);
        let m = last.expect("three runs");
        println!(
            "ground {cells} x {cells}: {} triangles -> {} ({} planes merged), median {:.3} s",
            m.input,
            m.triangles.len(),
            m.groups,
            times[1]
        );
    }
}
