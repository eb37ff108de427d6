//! Micro-benchmarks of the form-factor kernels and the visibility queries.
//!
//! Run: `cargo bench --no-default-features --bench kernels` (add a filter such as
//! `-- row` to run one group). Throughput is set on every benchmark, so criterion
//! reports pairs/s, rays/s or rows/s directly.
//!
//! Scenes are built here from parallelograms (no scene loader needed): a closed unit
//! cube subdivided m × m per face, and a "room" with a grid of boxes inside it for
//! the ray benchmarks.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use ffstream::formfactor::sampling::SplitMix64;
use ffstream::formfactor::{FormFactorConfig, Method, RowEngine, Scratch, TopKTail};
use ffstream::geometry::occluders::{Between, Occluders};
use ffstream::patch::{Patch, PatchSet};
use glam::{dvec3, DVec3};

#[derive(Default)]
struct Builder {
    patches: Vec<Patch>,
    tris: Vec<(u32, [DVec3; 3])>,
    faces: u32,
}

impl Builder {
    /// Parallelogram origin + [0,1]u + [0,1]v, front normal u × v, m × m quads.
    fn face(&mut self, origin: DVec3, u: DVec3, v: DVec3, m: usize) {
        let face = self.faces;
        self.faces += 1;
        let n = u.cross(v);
        let at =
            |a: usize, b: usize| origin + u * (a as f64 / m as f64) + v * (b as f64 / m as f64);
        for b in 0..m {
            for a in 0..m {
                self.patches.push(Patch {
                    corners: [at(a, b), at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)],
                    n_corners: 4,
                    normal: n.normalize(),
                    area: n.length() / (m * m) as f64,
                    group: 0,
                    face,
                    rho: [0.5; 3],
                    emission: [0.0; 3],
                });
            }
        }
        self.tris.push((face, [origin, origin + u, origin + u + v]));
        self.tris.push((face, [origin, origin + u + v, origin + v]));
    }

    /// Axis-aligned box [lo, lo + size] with outward faces, occluder only.
    fn box_occluder(&mut self, lo: DVec3, size: DVec3) {
        let (x, y, z) = (
            dvec3(size.x, 0.0, 0.0),
            dvec3(0.0, size.y, 0.0),
            dvec3(0.0, 0.0, size.z),
        );
        for (o, u, v) in [
            (lo, y, x),
            (lo + z, x, y),
            (lo, z, y),
            (lo + x, y, z),
            (lo, x, z),
            (lo + y, z, x),
        ] {
            let face = self.faces;
            self.faces += 1;
            self.tris.push((face, [o, o + u, o + u + v]));
            self.tris.push((face, [o, o + u + v, o + v]));
        }
    }

    fn cube(m: usize) -> Self {
        let (x, y, z) = (
            dvec3(1.0, 0.0, 0.0),
            dvec3(0.0, 1.0, 0.0),
            dvec3(0.0, 0.0, 1.0),
        );
        let mut b = Builder::default();
        for (o, u, v) in [
            (DVec3::ZERO, x, y),
            (z, y, x),
            (DVec3::ZERO, y, z),
            (x, z, y),
            (DVec3::ZERO, z, x),
            (y, x, z),
        ] {
            b.face(o, u, v, m);
        }
        b
    }

    fn engine(&self, cfg: FormFactorConfig) -> RowEngine {
        let ps = PatchSet {
            patches: self.patches.clone(),
            groups: vec!["all".into()],
        };
        RowEngine::new(&ps, Arc::new(Occluders::new(self.tris.clone())), cfg)
    }
}

/// The cube with a g × g × g grid of small boxes inside: 12 g³ + 12 triangles.
fn cluttered_cube(m: usize, g: usize) -> Builder {
    let mut b = Builder::cube(m);
    let cell = 1.0 / g as f64;
    for i in 0..g {
        for j in 0..g {
            for k in 0..g {
                let lo = dvec3(i as f64, j as f64, k as f64) * cell + DVec3::splat(0.3 * cell);
                b.box_occluder(lo, DVec3::splat(0.4 * cell));
            }
        }
    }
    b
}

fn pair_kernels(c: &mut Criterion) {
    let b = Builder::cube(8);
    let m = 8;
    // Patch indices: face 0 (z = 0) cell (a, b) is a + m·b; face 2 (x = 0) starts at 2m².
    let adjacent = (0u32, (2 * m * m) as u32); // perpendicular, sharing an edge
    let neighbour = (0u32, (m * m + 1) as u32); // across the cube, near
    let far = (0u32, (m * m + m * m - 1) as u32); // across the cube, far corner
    let mut g = c.benchmark_group("pair");
    g.throughput(Throughput::Elements(1));
    for (name, cfg) in [
        ("contour_fast", FormFactorConfig::fast()),
        ("contour_accurate", FormFactorConfig::accurate()),
        ("contour_reference", FormFactorConfig::reference()),
        (
            "mc16",
            FormFactorConfig::accurate()
                .with_method(Method::Mc)
                .with_samples(16),
        ),
        (
            "point",
            FormFactorConfig::accurate().with_method(Method::Point),
        ),
    ] {
        let e = b.engine(cfg);
        let mut s = Scratch::new();
        for (label, (i, j)) in [
            ("adjacent", adjacent),
            ("opposite_near", neighbour),
            ("opposite_far", far),
        ] {
            g.bench_function(BenchmarkId::new(name, label), |bn| {
                bn.iter(|| e.pair_value(black_box(i), black_box(j), &mut s))
            });
        }
    }
    g.finish();
}

fn random_points(n: usize, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut rng = SplitMix64::new(seed);
    let mut p = || dvec3(rng.next_f64(), rng.next_f64(), rng.next_f64());
    (0..n).map(|_| (p(), p())).collect()
}

fn shadow_rays(c: &mut Criterion) {
    let mut g = c.benchmark_group("shadow_rays");
    for grid in [4usize, 10] {
        let b = cluttered_cube(1, grid);
        let occ = Occluders::new(b.tris.clone());
        let rays = random_points(4096, 1);
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.bench_function(
            BenchmarkId::new("occluded", format!("{}tris", occ.len())),
            |bn| {
                bn.iter(|| {
                    rays.iter()
                        .filter(|(a, z)| occ.occluded(*a, *z, (u32::MAX, u32::MAX)))
                        .count()
                })
            },
        );
        // Pairs that face each other (as the engine asks: facing-away pairs never get
        // here): a facing +z below b facing -z.
        let quads: Vec<([DVec3; 4], [DVec3; 4])> = random_points(1024, 2)
            .into_iter()
            .map(|(a, z)| {
                let (a, z) = if a.z <= z.z { (a, z) } else { (z, a) };
                let d = 0.05;
                let qa = [
                    a,
                    a + dvec3(d, 0.0, 0.0),
                    a + dvec3(d, d, 0.0),
                    a + dvec3(0.0, d, 0.0),
                ];
                let qz = [
                    z,
                    z + dvec3(0.0, d, 0.0),
                    z + dvec3(d, d, 0.0),
                    z + dvec3(d, 0.0, 0.0),
                ];
                (qa, qz)
            })
            .collect();
        g.throughput(Throughput::Elements(quads.len() as u64));
        g.bench_function(
            BenchmarkId::new("any_between", format!("{}tris", occ.len())),
            |bn| {
                bn.iter(|| {
                    quads
                        .iter()
                        .filter(|(a, z)| {
                            occ.any_between(&Between::new(
                                a,
                                DVec3::Z,
                                z,
                                -DVec3::Z,
                                (u32::MAX, u32::MAX),
                            ))
                        })
                        .count()
                })
            },
        );
    }
    g.finish();
}

fn rows(c: &mut Criterion) {
    let mut g = c.benchmark_group("row");
    g.sample_size(10);
    // Closed cube, 18 × 18 per face = 1944 patches (the ~2k default of the CLI).
    let b = Builder::cube(18);
    // The same cube with 64 boxes inside, so rows need rays.
    let cluttered = cluttered_cube(18, 4);
    for (scene, builder) in [("cube1944", &b), ("cube1944_boxes", &cluttered)] {
        for (name, cfg) in [
            ("contour_fast", FormFactorConfig::fast()),
            ("contour_accurate", FormFactorConfig::accurate()),
            (
                "contour_accurate_top200_tail32",
                FormFactorConfig {
                    top_k: Some(200),
                    top_k_tail: TopKTail::Sampled(32),
                    ..FormFactorConfig::accurate()
                },
            ),
            (
                "mc16",
                FormFactorConfig::accurate()
                    .with_method(Method::Mc)
                    .with_samples(16),
            ),
            (
                "point",
                FormFactorConfig::accurate().with_method(Method::Point),
            ),
        ] {
            let e = builder.engine(cfg);
            let mut s = Scratch::new();
            let n = e.n() as u32;
            g.throughput(Throughput::Elements(1));
            let mut i = 0u32;
            g.bench_function(BenchmarkId::new(name, scene), |bn| {
                bn.iter(|| {
                    i = (i + 97) % n;
                    e.compute_row(i, &mut s)
                })
            });
        }
    }
    g.finish();
}

fn config() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(2))
}

criterion_group! { name = benches; config = config(); targets = pair_kernels, shadow_rays, rows }
criterion_main!(benches);
