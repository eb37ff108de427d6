//! Deterministic sampling: a small counter-based random generator seeded by the pair
//! (i, j) and the run seed (never by thread or rank, docs/numerics.md §6), Latin-hypercube
//! stratification, and the maps from the unit square onto a patch.
//!
//! Stratification: S point pairs are drawn as a 4-dimensional Latin hypercube
//! (McKay, Beckman & Conover 1979) over (u_i, v_i, u_j, v_j): every one of the four
//! coordinates has exactly one sample in each of the S strata [k/S, (k+1)/S). So the
//! points on patch i are stratified in both directions, likewise on patch j, and the
//! pairing between them is a random permutation. This works for any S (a jittered
//! √S×√S grid would need square S).

use glam::DVec3;

pub(crate) use crate::random::mix64;
pub use crate::random::SplitMix64;

/// The uses of a pair's random numbers, each its own stream (see [`pair_seed`]). The
/// values are part of the numbers a file holds: changing one changes rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stream {
    /// `contour` visibility: the first batch of rays.
    FirstBatch = 0,
    /// `contour` visibility: the rest of the rays.
    SecondBatch = 1,
    /// `mc`: the point pairs.
    Mc = 2,
    /// Top-k with a sampled tail: the systematic sample of a row's tail (j = u32::MAX).
    TopKTail = 3,
    /// The emitters drawn for a patch's first-bounce radiosity (`engine/first_bounce.rs`;
    /// j = u32::MAX).
    FirstBounce = 4,
    /// The points drawn for a patch's second-bounce radiosity (j = u32::MAX).
    SecondBounce = 5,
}

/// A draw below `n` from 32 random bits r: ⌊r · n / 2³²⌋ (multiply-shift, bias
/// < n / 2³²); the permutations use it.
#[inline]
fn below_from(r: u64, n: u32) -> u32 {
    ((r * n as u64) >> 32) as u32
}

/// Two independent uniform numbers in [0, 1) with 32 random bits each, from one step
/// (jitter inside a stratum of width 1/S needs far fewer than 53 bits).
#[inline]
fn two_unit(rng: &mut SplitMix64) -> (f64, f64) {
    let r = rng.next_u64();
    const SCALE: f64 = 1.0 / (1u64 << 32) as f64;
    ((r >> 32) as f64 * SCALE, (r & 0xFFFF_FFFF) as f64 * SCALE)
}

/// Seed of the random stream for the ordered pair (i, j), the run seed and a stream
/// tag (so that different uses of the same pair draw independent numbers).
#[inline]
pub(crate) fn pair_seed(seed: u64, i: u32, j: u32, stream: Stream) -> u64 {
    let ij = ((i as u64) << 32) | j as u64;
    mix64(
        mix64(mix64(seed ^ 0x5851_F42D_4C95_7F2D) ^ ij)
            ^ (stream as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
    )
}

/// Fills `out` with a random permutation of 0..out.len() (Fisher–Yates), two swaps
/// per step of the generator (32 bits each).
pub(crate) fn permutation(rng: &mut SplitMix64, out: &mut [u32]) {
    for (k, x) in out.iter_mut().enumerate() {
        *x = k as u32;
    }
    let mut k = out.len().saturating_sub(1);
    while k >= 1 {
        let r = rng.next_u64();
        out.swap(k, below_from(r >> 32, k as u32 + 1) as usize);
        if k >= 2 {
            out.swap(k - 1, below_from(r & 0xFFFF_FFFF, k as u32) as usize);
        }
        k = k.saturating_sub(2);
    }
}

/// S stratified point pairs in the unit square × unit square (a Latin hypercube).
/// `perms` is scratch space (3·S entries); the result goes to `out` as
/// `[u_i, v_i, u_j, v_j]`.
pub(crate) fn latin_pairs(
    rng: &mut SplitMix64,
    s: usize,
    perms: &mut Vec<u32>,
    out: &mut Vec<[f64; 4]>,
) {
    perms.clear();
    perms.resize(3 * s, 0);
    out.clear();
    if s == 0 {
        return;
    }
    let (p1, rest) = perms.split_at_mut(s);
    let (p2, p3) = rest.split_at_mut(s);
    permutation(rng, p1);
    permutation(rng, p2);
    permutation(rng, p3);
    let inv = 1.0 / s as f64;
    for k in 0..s {
        let (a, b) = two_unit(rng);
        let (c, d) = two_unit(rng);
        out.push([
            (k as f64 + a) * inv,
            (p1[k] as f64 + b) * inv,
            (p2[k] as f64 + c) * inv,
            (p3[k] as f64 + d) * inv,
        ]);
    }
}

/// A map from the unit square onto a patch, with its area Jacobian, so that
/// ∫_patch f dA = ∫∫ f(x(u, v)) J(u, v) du dv.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum PatchMap {
    /// Area-preserving square-to-triangle map x = (1 − √u) a + √u (1 − v) b + √u v c
    /// (Shirley & Chiu 1997 style); J = area everywhere.
    Triangle {
        a: DVec3,
        b: DVec3,
        c: DVec3,
        area: f64,
    },
    /// Bilinear map of a planar convex quad that is not a parallelogram; J varies.
    Quad { p: [DVec3; 4] },
    /// A parallelogram (the quads of a grid on a rectangle or parallelogram face):
    /// x = o + u e1 + v e2, J = area everywhere.
    Parallelogram {
        o: DVec3,
        e1: DVec3,
        e2: DVec3,
        area: f64,
    },
}

impl PatchMap {
    pub(crate) fn new(corners: &[DVec3], area: f64) -> Self {
        if corners.len() == 3 {
            PatchMap::Triangle {
                a: corners[0],
                b: corners[1],
                c: corners[2],
                area,
            }
        } else {
            let p = [corners[0], corners[1], corners[2], corners[3]];
            let (e1, e2) = (p[1] - p[0], p[3] - p[0]);
            // A parallelogram up to rounding: the bilinear map is affine.
            let skew = (p[2] - p[1] - e2).length();
            if skew <= 1e-12 * (e1.length() + e2.length()) {
                PatchMap::Parallelogram {
                    o: p[0],
                    e1,
                    e2,
                    area: e1.cross(e2).length(),
                }
            } else {
                PatchMap::Quad { p }
            }
        }
    }

    /// Point and Jacobian at (u, v) ∈ [0, 1]².
    #[inline]
    pub(crate) fn eval(&self, u: f64, v: f64) -> (DVec3, f64) {
        match *self {
            PatchMap::Triangle { a, b, c, area } => {
                let s = u.sqrt();
                (a * (1.0 - s) + b * (s * (1.0 - v)) + c * (s * v), area)
            }
            PatchMap::Quad { p } => {
                let x = p[0] * ((1.0 - u) * (1.0 - v))
                    + p[1] * (u * (1.0 - v))
                    + p[2] * (u * v)
                    + p[3] * ((1.0 - u) * v);
                let du = (p[1] - p[0]) * (1.0 - v) + (p[2] - p[3]) * v;
                let dv = (p[3] - p[0]) * (1.0 - u) + (p[2] - p[1]) * u;
                (x, du.cross(dv).length())
            }
            PatchMap::Parallelogram { o, e1, e2, area } => (o + e1 * u + e2 * v, area),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::dvec3;

    #[test]
    fn streams_are_deterministic_and_distinct() {
        let a: Vec<u64> = {
            let mut r = SplitMix64::new(pair_seed(7, 3, 4, Stream::FirstBatch));
            (0..4).map(|_| r.next_u64()).collect()
        };
        let b: Vec<u64> = {
            let mut r = SplitMix64::new(pair_seed(7, 3, 4, Stream::FirstBatch));
            (0..4).map(|_| r.next_u64()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(
            pair_seed(7, 3, 4, Stream::FirstBatch),
            pair_seed(7, 4, 3, Stream::FirstBatch)
        );
        assert_ne!(
            pair_seed(7, 3, 4, Stream::FirstBatch),
            pair_seed(8, 3, 4, Stream::FirstBatch)
        );
        assert_ne!(
            pair_seed(7, 3, 4, Stream::FirstBatch),
            pair_seed(7, 3, 4, Stream::SecondBatch)
        );
    }

    #[test]
    fn latin_pairs_are_stratified() {
        let mut rng = SplitMix64::new(1);
        let (mut perms, mut out) = (Vec::new(), Vec::new());
        for s in [1usize, 2, 5, 16, 17] {
            latin_pairs(&mut rng, s, &mut perms, &mut out);
            assert_eq!(out.len(), s);
            for d in 0..4 {
                let mut seen = vec![false; s];
                for q in &out {
                    let k = (q[d] * s as f64) as usize;
                    assert!(q[d] >= 0.0 && q[d] < 1.0);
                    assert!(!seen[k], "stratum {k} of dim {d} used twice (s={s})");
                    seen[k] = true;
                }
            }
        }
    }

    #[test]
    fn maps_integrate_area() {
        // Midpoint rule on a fine grid: ∫∫ J du dv = area.
        let tri = PatchMap::new(
            &[
                dvec3(0.0, 0.0, 0.0),
                dvec3(2.0, 0.0, 0.0),
                dvec3(0.0, 1.0, 1.0),
            ],
            2f64.sqrt(),
        );
        let quad = PatchMap::new(
            &[
                dvec3(0.0, 0.0, 0.0),
                dvec3(2.0, 0.0, 0.0),
                dvec3(1.5, 1.0, 0.0),
                dvec3(0.0, 2.0, 0.0),
            ],
            0.0,
        );
        // A slanted parallelogram in 3-D: |e1 × e2| = |(2, 0, 0) × (0.5, 1, 1)| = 2√2.
        let para = PatchMap::new(
            &[
                dvec3(0.0, 0.0, 0.0),
                dvec3(2.0, 0.0, 0.0),
                dvec3(2.5, 1.0, 1.0),
                dvec3(0.5, 1.0, 1.0),
            ],
            0.0,
        );
        assert!(matches!(quad, PatchMap::Quad { .. }));
        assert!(matches!(para, PatchMap::Parallelogram { .. }));
        // Quad area by the shoelace formula: ½|Σ x_k y_{k+1} − x_{k+1} y_k| = 2.5.
        for (m, area) in [(tri, 2f64.sqrt()), (quad, 2.5), (para, 8f64.sqrt())] {
            let g = 200;
            let mut s = 0.0;
            for a in 0..g {
                for b in 0..g {
                    let (_, j) = m.eval((a as f64 + 0.5) / g as f64, (b as f64 + 0.5) / g as f64);
                    s += j;
                }
            }
            s /= (g * g) as f64;
            assert!((s - area).abs() < 1e-9, "{s} vs {area}");
        }
    }

    /// The parallelogram shortcut is the bilinear map of the same corners.
    #[test]
    fn parallelogram_map_is_the_bilinear_map() {
        let c = [
            dvec3(0.3, -1.0, 2.0),
            dvec3(1.3, -0.5, 2.0),
            dvec3(1.0, 0.5, 3.0),
            dvec3(0.0, 0.0, 3.0),
        ];
        let para = PatchMap::new(&c, 0.0);
        let mut rng = SplitMix64::new(9);
        for _ in 0..100 {
            let (u, v) = (rng.next_f64(), rng.next_f64());
            let bilinear = c[0] * ((1.0 - u) * (1.0 - v))
                + c[1] * (u * (1.0 - v))
                + c[2] * (u * v)
                + c[3] * ((1.0 - u) * v);
            let (x, j) = para.eval(u, v);
            assert!((x - bilinear).length() < 1e-14, "{x} vs {bilinear}");
            let area = (c[1] - c[0]).cross(c[3] - c[0]).length();
            assert!((j - area).abs() < 1e-14);
        }
    }

    /// Every permutation of 4 elements comes out equally often (240 000 draws, 10 000
    /// expected each, σ ≈ 98: ±5σ), and of 16, every value equally often at every
    /// position.
    #[test]
    fn permutations_are_uniform() {
        let mut rng = SplitMix64::new(4);
        let mut counts = std::collections::HashMap::new();
        let mut p = [0u32; 4];
        for _ in 0..240_000 {
            permutation(&mut rng, &mut p);
            *counts.entry(p).or_insert(0u32) += 1;
        }
        assert_eq!(counts.len(), 24);
        for (p, c) in &counts {
            assert!((9_500..=10_500).contains(c), "{p:?} drawn {c} times");
        }
        let mut at = [[0u32; 16]; 16];
        let mut p = [0u32; 16];
        for _ in 0..160_000 {
            permutation(&mut rng, &mut p);
            for (pos, &x) in p.iter().enumerate() {
                at[pos][x as usize] += 1;
            }
        }
        // 10 000 expected per (position, value), σ ≈ 97.
        for (pos, row) in at.iter().enumerate() {
            for (x, &c) in row.iter().enumerate() {
                assert!((9_500..=10_500).contains(&c), "value {x} at {pos}: {c}");
            }
        }
    }

    #[test]
    fn triangle_map_stays_inside() {
        let m = PatchMap::new(
            &[
                dvec3(0.0, 0.0, 0.0),
                dvec3(1.0, 0.0, 0.0),
                dvec3(0.0, 1.0, 0.0),
            ],
            0.5,
        );
        let mut rng = SplitMix64::new(3);
        for _ in 0..1000 {
            let (p, _) = m.eval(rng.next_f64(), rng.next_f64());
            assert!(p.x >= 0.0 && p.y >= 0.0 && p.x + p.y <= 1.0 + 1e-15);
        }
    }
}
