//! Well-separated pairs for the `contour` method: a tensor Gauss rule on both patches.
//!
//! When two patches are far apart relative to their size and neither reaches behind
//! the other's plane, the kernel cosθ_i cosθ_j / (π r²) = (n_i·d)(−n_j·d) / (π |d|⁴)
//! is analytic over the whole pair: its only singularities are at complex points where
//! |d|² = 0, at an imaginary distance of at least the gap between the patches. A
//! q × q Gauss–Legendre rule on each patch (q⁴ kernel evaluations, no transcendental
//! functions) then converges like ρ^(−2q) with ρ = b + √(b² + 1), b = gap / radius
//! (the same Bernstein-ellipse bound as in [`super::contour`]), so for most pairs of
//! a large scene a handful of points reach the target `quad_tol` and cost a fraction
//! of the 16 edge pairs of the contour integral. Pairs that are close, touching or
//! need clipping go to the contour integral.
//!
//! Maps from [-1, 1]² onto a patch: bilinear for quads (Jacobian |∂x/∂u × ∂x/∂v|;
//! affine with a constant Jacobian for parallelograms),
//! the collapsed (Duffy) square for triangles, x = a + s (b − a) + s t (c − b) with
//! s, t ∈ [0, 1] and Jacobian 2A·s, whose factor s is the weight of Gauss–Jacobi
//! points in s (Gauss–Legendre in t). Both maps are polynomial, so the points stay
//! exact for polynomial integrands: to degree 2q − 1 on parallelograms and triangles,
//! one less on other quads (their Jacobian is linear in u and v).

use glam::DVec3;
use wide::f64x4;

use super::quadrature::GaussTable;
use super::sampling::PatchMap;

/// Largest order per dimension used for far pairs. q = 4 is q⁴ = 256 kernel
/// evaluations; with the inner loop over j's points in SIMD lanes
/// ([`area_form_factor_soa`]) that is ~4k instructions, half of the contour integral
/// of two quads (~8.6k with its logarithms and arc tangents; callgrind, 8.5k room).
pub(crate) const MAX_FAR_ORDER: usize = 4;

/// Lanes of the inner loop of [`area_form_factor_soa`] (point counts padded to it).
pub(crate) const LANES: usize = 4;

/// One patch's points of one order, structure-of-arrays (x, y, z, area weight),
/// padded to a multiple of [`LANES`] with zero weights, for [`area_form_factor_soa`].
/// Filled per pair into [`FarScratch`] (a per-patch table of all orders would cost
/// ~1 KiB per patch, 100 MB at 100k patches, for ~2 % of the time).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PatchLanes {
    x: [f64; MAX_FAR_ORDER * MAX_FAR_ORDER],
    y: [f64; MAX_FAR_ORDER * MAX_FAR_ORDER],
    z: [f64; MAX_FAR_ORDER * MAX_FAR_ORDER],
    w: [f64; MAX_FAR_ORDER * MAX_FAR_ORDER],
    len: usize,
}

impl PatchLanes {
    /// Replaces the lanes by the points of [`PatchPoints::on`] (j's side of a far pair,
    /// filled per pair into a buffer that lives in the thread's scratch: no zeroing
    /// of the 512-byte arrays per pair, which cost 5 % of a dense run).
    fn fill(&mut self, map: &PatchMap, q: usize, gauss: &GaussTable) {
        self.len = 0;
        for_each_point(map, q, gauss, |p, w| self.push(p, w));
        self.pad();
    }

    #[cfg(test)]
    pub(crate) fn new(p: &PatchPoints) -> Self {
        let mut out = Self::empty();
        for k in 0..p.n {
            out.push(p.p[k], p.w[k]);
        }
        out.pad();
        out
    }

    fn empty() -> Self {
        PatchLanes {
            x: [0.0; MAX_FAR_ORDER * MAX_FAR_ORDER],
            y: [0.0; MAX_FAR_ORDER * MAX_FAR_ORDER],
            z: [0.0; MAX_FAR_ORDER * MAX_FAR_ORDER],
            w: [0.0; MAX_FAR_ORDER * MAX_FAR_ORDER],
            len: 0,
        }
    }

    fn push(&mut self, p: DVec3, w: f64) {
        let k = self.len;
        (self.x[k], self.y[k], self.z[k], self.w[k]) = (p.x, p.y, p.z, w);
        self.len += 1;
    }

    /// Rounds the length up to a multiple of [`LANES`]: the padding repeats the first
    /// point with weight 0 (no division by zero).
    fn pad(&mut self) {
        let n = self.len;
        self.len = n.div_ceil(LANES) * LANES;
        for k in n..self.len {
            (self.x[k], self.y[k], self.z[k], self.w[k]) = (self.x[0], self.y[0], self.z[0], 0.0);
        }
    }

    pub(crate) fn slice(&self) -> FarSlice<'_> {
        FarSlice {
            x: &self.x[..self.len],
            y: &self.y[..self.len],
            z: &self.z[..self.len],
            w: &self.w[..self.len],
        }
    }
}

impl Default for PatchLanes {
    fn default() -> Self {
        Self::empty()
    }
}

/// A thread's far-field working memory: the row patch's points by order (built once
/// per row) and the lanes of the current pair's other patch (refilled per pair).
#[derive(Debug, Default)]
pub(crate) struct FarScratch {
    /// (engine id, patch) whose points `points` holds.
    row: Option<(u64, u32)>,
    points: [Option<PatchPoints>; MAX_FAR_ORDER + 1],
    lanes: PatchLanes,
}

impl FarScratch {
    /// A_i F⁰_ij of a far pair by the order-q tensor rule (see
    /// [`area_form_factor_soa`]): i's points cached for the row (`engine`, `i`), j's
    /// written into the lanes.
    pub(crate) fn area_form_factor(
        &mut self,
        (engine, i): (u64, u32),
        (map_i, ni): (&PatchMap, DVec3),
        (map_j, nj): (&PatchMap, DVec3),
        q: usize,
        gauss: &GaussTable,
    ) -> f64 {
        if self.row != Some((engine, i)) {
            self.row = Some((engine, i));
            self.points = [None; MAX_FAR_ORDER + 1];
        }
        let pts_i = self.points[q].get_or_insert_with(|| PatchPoints::on(map_i, q, gauss));
        self.lanes.fill(map_j, q, gauss);
        area_form_factor_soa(pts_i, ni, self.lanes.slice(), nj)
    }
}

/// Points of one patch and order as slices (length a multiple of [`LANES`]).
#[derive(Clone, Copy)]
pub(crate) struct FarSlice<'a> {
    pub(crate) x: &'a [f64],
    pub(crate) y: &'a [f64],
    pub(crate) z: &'a [f64],
    pub(crate) w: &'a [f64],
}

/// Constant in front of the error bound ρ^(−2q) (see [`FarOrders`]). The kernel has
/// double poles, which put a factor growing with q in front of ρ^(−2q); measured on
/// cube pairs (test below) the actual error reaches ~250·ρ^(−6) at q = 3, so 1000
/// leaves a margin of 4.
const SAFETY: f64 = 1000.0;

/// Gauss points with area weights (Σ w = area) on one patch, for one order.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PatchPoints {
    pub(crate) p: [DVec3; MAX_FAR_ORDER * MAX_FAR_ORDER],
    pub(crate) w: [f64; MAX_FAR_ORDER * MAX_FAR_ORDER],
    pub(crate) n: usize,
}

impl PatchPoints {
    /// The q × q rule (q clamped to 1..=MAX_FAR_ORDER) on a triangle or quad.
    #[cfg(test)]
    pub(crate) fn new(corners: &[DVec3], area: f64, q: usize, gauss: &GaussTable) -> Self {
        Self::on(&PatchMap::new(corners, area), q, gauss)
    }

    /// As `PatchPoints::new` (tests) on the patch whose map is `map` (built once per patch,
    /// not once per pair).
    pub(crate) fn on(map: &PatchMap, q: usize, gauss: &GaussTable) -> Self {
        let mut out = PatchPoints {
            p: [DVec3::ZERO; MAX_FAR_ORDER * MAX_FAR_ORDER],
            w: [0.0; MAX_FAR_ORDER * MAX_FAR_ORDER],
            n: 0,
        };
        for_each_point(map, q, gauss, |p, w| {
            out.p[out.n] = p;
            out.w[out.n] = w;
            out.n += 1;
        });
        out
    }
}

/// Calls `f(point, area weight)` for each point of the q × q rule (q clamped to
/// 1..=MAX_FAR_ORDER) on the patch whose map is `map`: triangles through the collapsed
/// square, quads through the bilinear map of sampling (affine with a constant
/// Jacobian for parallelograms).
fn for_each_point(map: &PatchMap, q: usize, gauss: &GaussTable, mut f: impl FnMut(DVec3, f64)) {
    let q = q.clamp(1, MAX_FAR_ORDER);
    if let (MAX_FAR_ORDER, PatchMap::Parallelogram { o, e1, e2, area }) = (q, *map) {
        // Under an affine map a polynomial keeps its total degree, so the 12-point
        // rule of total degree 7 does what the 4 × 4 product rule (16 points, also
        // degree 7 in each variable) does for these integrands: the same ρ^(−8)
        // convergence, checked against the same bound by `calibrate`.
        for &(x, y, w) in degree7_square_rule() {
            f(
                o + e1 * (0.5 * (x + 1.0)) + e2 * (0.5 * (y + 1.0)),
                0.25 * w * area,
            );
        }
        return;
    }
    let rule = gauss.rule(q);
    if let PatchMap::Triangle { a, b, c, area } = *map {
        // The collapsed square's Jacobian 2A·s goes into the s-rule (Gauss–Jacobi for
        // the weight s): with Gauss–Legendre in s instead, a polynomial of degree m
        // on the triangle became s·(degree m in s), and the rule lost an order (its
        // error fell like ρ^(1−2q), not ρ^(−2q); at q = 1 its point was not the
        // centroid).
        for &(s, ws) in &jacobi_s_rules()[q - 1][..q] {
            for &(xv, wv) in rule {
                let t = 0.5 * (xv + 1.0);
                f(a + (b - a) * s + (c - b) * (s * t), area * ws * wv);
            }
        }
        return;
    }
    for &(xu, wu) in rule {
        for &(xv, wv) in rule {
            let (s, t) = (0.5 * (xu + 1.0), 0.5 * (xv + 1.0));
            let (p, j) = map.eval(s, t);
            f(p, 0.25 * wu * wv * j);
        }
    }
}

/// Gauss–Jacobi rules on [0, 1] for the weight s, by order: `jacobi_s_rules()[q − 1]`
/// holds q pairs (s_k, w_k) (the rest unused) with Σ w_k f(s_k) = ∫₀¹ s f(s) ds for
/// every polynomial f of degree ≤ 2q − 1. The nodes are the roots of the Jacobi
/// polynomial P_q^(0,1)(2s − 1) (three-term recurrence, DLMF 18.9.2), bracketed on a
/// grid and bisected to rounding; the weights solve the first q moment equations.
/// Built once.
fn jacobi_s_rules() -> &'static [[(f64, f64); MAX_FAR_ORDER]; MAX_FAR_ORDER] {
    static RULES: std::sync::OnceLock<[[(f64, f64); MAX_FAR_ORDER]; MAX_FAR_ORDER]> =
        std::sync::OnceLock::new();
    RULES.get_or_init(|| {
        let mut out = [[(0.0, 0.0); MAX_FAR_ORDER]; MAX_FAR_ORDER];
        for (k, rule) in out.iter_mut().enumerate() {
            let q = k + 1;
            let nodes = jacobi01_roots(q);
            let weights = moment_weights(&nodes);
            for (slot, (s, w)) in rule.iter_mut().zip(nodes.iter().zip(&weights)) {
                *slot = (*s, *w);
            }
        }
        out
    })
}

/// P_n^(0,1)(x) (α = 0, β = 1): P_0 = 1, P_1 = (3x − 1)/2, and for n ≥ 2
/// 2n(n+1)(2n−1) P_n = 2n((2n+1)(2n−1)x − 1) P_{n−1} − 2(n−1)n(2n+1) P_{n−2}.
fn jacobi01(n: usize, x: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, 0.5 * (3.0 * x - 1.0));
    if n == 0 {
        return p0;
    }
    for m in 2..=n {
        let m = m as f64;
        let p2 = (2.0 * m * ((2.0 * m + 1.0) * (2.0 * m - 1.0) * x - 1.0) * p1
            - 2.0 * (m - 1.0) * m * (2.0 * m + 1.0) * p0)
            / (2.0 * m * (m + 1.0) * (2.0 * m - 1.0));
        (p0, p1) = (p1, p2);
    }
    p1
}

/// The n roots of P_n^(0,1)(2s − 1) in (0, 1), ascending.
fn jacobi01_roots(n: usize) -> Vec<f64> {
    const GRID: usize = 4096;
    let g = |s: f64| jacobi01(n, 2.0 * s - 1.0);
    let mut roots = Vec::with_capacity(n);
    for k in 0..GRID {
        let (mut lo, mut hi) = (k as f64 / GRID as f64, (k + 1) as f64 / GRID as f64);
        if g(lo).signum() == g(hi).signum() {
            continue;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if g(mid).signum() == g(lo).signum() {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        roots.push(0.5 * (lo + hi));
    }
    assert_eq!(roots.len(), n, "P_{n}^(0,1) has {n} simple roots in (0, 1)");
    roots
}

/// Weights w with Σ w_k s_k^m = ∫₀¹ s · s^m ds = 1/(m + 2) for m < nodes.len()
/// (Gaussian elimination with partial pivoting on the small Vandermonde system).
fn moment_weights(nodes: &[f64]) -> Vec<f64> {
    let n = nodes.len();
    let mut a: Vec<Vec<f64>> = (0..n)
        .map(|m| {
            let mut row: Vec<f64> = nodes.iter().map(|s| s.powi(m as i32)).collect();
            row.push(1.0 / (m as f64 + 2.0));
            row
        })
        .collect();
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))
            .unwrap_or(col);
        a.swap(col, pivot);
        for r in col + 1..n {
            let f = a[r][col] / a[col][col];
            let (upper, lower) = a.split_at_mut(r);
            for (x, p) in lower[0][col..].iter_mut().zip(&upper[col][col..]) {
                *x -= f * p;
            }
        }
    }
    let mut w = vec![0.0; n];
    for r in (0..n).rev() {
        let tail: f64 = (r + 1..n).map(|c| a[r][c] * w[c]).sum();
        w[r] = (a[r][n] - tail) / a[r][r];
    }
    w
}

/// A 12-point rule on [−1, 1]² exact for every polynomial of total degree ≤ 7 (Stroud,
/// "Approximate Calculation of Multiple Integrals", 1971, C2: 7-3): (x, y, weight),
/// weights summing to 4, every point inside the square.
fn degree7_square_rule() -> &'static [(f64, f64, f64); 12] {
    // Built once: its square roots were taken for every far pair before.
    static RULE: std::sync::OnceLock<[(f64, f64, f64); 12]> = std::sync::OnceLock::new();
    RULE.get_or_init(degree7_square_rule_uncached)
}

fn degree7_square_rule_uncached() -> [(f64, f64, f64); 12] {
    let s583 = 583f64.sqrt();
    let r = (6.0f64 / 7.0).sqrt();
    let s = ((114.0 - 3.0 * s583) / 287.0).sqrt();
    let t = ((114.0 + 3.0 * s583) / 287.0).sqrt();
    let b1 = 4.0 * 49.0 / 810.0;
    let b2 = 4.0 * (178_981.0 + 2_769.0 * s583) / 1_888_920.0;
    let b3 = 4.0 * (178_981.0 - 2_769.0 * s583) / 1_888_920.0;
    [
        (r, 0.0, b1),
        (-r, 0.0, b1),
        (0.0, r, b1),
        (0.0, -r, b1),
        (s, s, b2),
        (s, -s, b2),
        (-s, s, b2),
        (-s, -s, b2),
        (t, t, b3),
        (t, -t, b3),
        (-t, t, b3),
        (-t, -t, b3),
    ]
}

/// The far-field order for one tolerance `tol`: for two patches with a gap of at least
/// `gap` and radii (centroid to farthest corner) at most `radius`, the smallest order
/// q per dimension with SAFETY · ρ^(−2q) ≤ tol (four dimensions, each contributing its
/// own ρ^(−2q) error), ρ = b + √(b² + 1), b = gap / radius; `None` when more than
/// [`MAX_FAR_ORDER`] would be needed (or they touch).
///
/// Without logarithms: q ≤ Q exactly when ln ρ ≥ ln(SAFETY/tol) / 2Q, i.e.
/// (ρ = e^asinh(b)) when b ≥ sinh(ln(SAFETY/tol) / 2Q). The thresholds are computed
/// once; a pair then costs a division and up to [`MAX_FAR_ORDER`] comparisons (it runs
/// for every pair that faces the other).
#[derive(Clone, Copy, Debug)]
pub(crate) struct FarOrders {
    /// `min_b[q - 1]`: the smallest gap / radius for which order q is enough.
    min_b: [f64; MAX_FAR_ORDER],
}

impl FarOrders {
    pub(crate) fn new(tol: f64) -> Self {
        let l = (SAFETY / tol).ln();
        let mut min_b = [0.0; MAX_FAR_ORDER];
        for (k, b) in min_b.iter_mut().enumerate() {
            *b = (l / (2.0 * (k + 1) as f64)).sinh();
        }
        FarOrders { min_b }
    }

    /// The order for these two patches (see [`FarOrders`]).
    #[inline]
    pub(crate) fn order(&self, gap: f64, radius: f64) -> Option<usize> {
        if gap.is_nan() || gap <= 0.0 || radius <= 0.0 {
            return None;
        }
        let b = gap / radius;
        self.min_b.iter().position(|&m| b >= m).map(|k| k + 1)
    }
}

/// A_i F_ij (unoccluded) by the tensor rule: Σ_a Σ_b w_a w_b (n_i·d)(−n_j·d) / (π |d|⁴).
/// Valid only when both cosines are non-negative over the whole pair (the caller
/// checks that neither patch reaches behind the other's plane).
#[cfg(test)]
pub(crate) fn area_form_factor(pi: &PatchPoints, ni: DVec3, pj: &PatchPoints, nj: DVec3) -> f64 {
    let mut sum = 0.0;
    for a in 0..pi.n {
        let x = pi.p[a];
        let mut inner = 0.0;
        for b in 0..pj.n {
            let d = pj.p[b] - x;
            let r2 = d.length_squared();
            inner += pj.w[b] * ni.dot(d) * -nj.dot(d) / (r2 * r2);
        }
        sum += pi.w[a] * inner;
    }
    sum / std::f64::consts::PI
}

/// As `area_form_factor` (the test oracle) with the j side from a [`FarSlice`] (a slice of the
/// far-field table): the inner loop runs over j's points in [`LANES`] independent
/// partial sums (a fixed order, so the result is the same on every machine), written
/// with `wide::f64x4` (the compiler alone vectorised only half of the lane loop, 2 of
/// 4 lanes per instruction).
///
/// On x86-64 with AVX2 the same code is compiled a second time for 4-wide vectors and
/// chosen at run time. Only AVX2, not FMA: every operation is the same IEEE
/// multiply, add or divide in the same order, so both versions give bitwise equal
/// results (rows stay identical across machines and ranks).
pub(crate) fn area_form_factor_soa(
    pi: &PatchPoints,
    ni: DVec3,
    pj: FarSlice<'_>,
    nj: DVec3,
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { soa_avx2(pi, ni, pj, nj) };
        }
    }
    soa_body(pi, ni, pj, nj)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn soa_avx2(pi: &PatchPoints, ni: DVec3, pj: FarSlice<'_>, nj: DVec3) -> f64 {
    soa_body(pi, ni, pj, nj)
}

/// r⁴ and (n_i·d)(n_j·d) for d = y − x (the kernel is −their ratio), in four lanes of
/// j's points at once.
#[inline(always)]
fn kernel_terms(
    x: DVec3,
    (yx, yy, yz): (f64x4, f64x4, f64x4),
    ni: DVec3,
    nj: DVec3,
) -> (f64x4, f64x4) {
    let (dx, dy, dz) = (
        yx - f64x4::splat(x.x),
        yy - f64x4::splat(x.y),
        yz - f64x4::splat(x.z),
    );
    let r2 = dx * dx + dy * dy + dz * dz;
    let ci = f64x4::splat(ni.x) * dx + f64x4::splat(ni.y) * dy + f64x4::splat(ni.z) * dz;
    let cj = f64x4::splat(nj.x) * dx + f64x4::splat(nj.y) * dy + f64x4::splat(nj.z) * dz;
    (r2 * r2, ci * cj)
}

/// The sum of an accumulator's lanes, pairwise ((0 + 1) + (2 + 3)).
#[inline(always)]
fn lane_sum(v: f64x4) -> f64 {
    let a = v.to_array();
    (a[0] + a[1]) + (a[2] + a[3])
}

#[inline(always)]
fn soa_body(pi: &PatchPoints, ni: DVec3, pj: FarSlice<'_>, nj: DVec3) -> f64 {
    let mut sum = 0.0;
    debug_assert!(pj.w.len().is_multiple_of(LANES));
    // j's points four at a time as vectors (`wide`: one AVX instruction per operation
    // where the build has AVX, else the same IEEE operations lane by lane, so every
    // build gives the same bits).
    let load = |s: &[f64]| f64x4::from(<[f64; LANES]>::try_from(s).unwrap_or([0.0; LANES]));
    let chunks = || {
        pj.x.chunks_exact(LANES)
            .zip(pj.y.chunks_exact(LANES))
            .zip(pj.z.chunks_exact(LANES))
            .zip(pj.w.chunks_exact(LANES))
            .map(|(((x, y), z), w)| ((load(x), load(y), load(z)), load(w)))
    };
    // Points of i two at a time: the two kernels of a lane share one division
    // (1/r⁴_a = r⁴_b / (r⁴_a r⁴_b)), the most expensive operation of the loop. r⁴_a r⁴_b
    // must stay a normal f64: checked on one pair of points (the distances of a far
    // pair differ by a small factor); outside 1e-35..1e35 scene units, one division
    // per kernel as before. The choice depends on the pair only.
    let r2 = {
        let (x, y) = (pi.p[0], DVec3::new(pj.x[0], pj.y[0], pj.z[0]));
        (y - x).length_squared()
    };
    let shared = r2 > 1e-70 && r2 < 1e70;
    // One point of i, one division per kernel.
    let single = |a: usize| {
        let x = pi.p[a];
        let mut acc = f64x4::ZERO;
        for (c, cw) in chunks() {
            let (d, k) = kernel_terms(x, c, ni, nj);
            acc -= cw * k / d;
        }
        pi.w[a] * lane_sum(acc)
    };
    if !shared {
        for a in 0..pi.n {
            sum += single(a);
        }
        return sum / std::f64::consts::PI;
    }
    let mut a = 0;
    while a + 1 < pi.n {
        let (xa, xb) = (pi.p[a], pi.p[a + 1]);
        let (mut acc_a, mut acc_b) = (f64x4::ZERO, f64x4::ZERO);
        for (c, cw) in chunks() {
            let (da, ka) = kernel_terms(xa, c, ni, nj);
            let (db, kb) = kernel_terms(xb, c, ni, nj);
            let inv = f64x4::ONE / (da * db);
            acc_a -= cw * ka * (db * inv);
            acc_b -= cw * kb * (da * inv);
        }
        sum += pi.w[a] * lane_sum(acc_a);
        sum += pi.w[a + 1] * lane_sum(acc_b);
        a += 2;
    }
    if a < pi.n {
        sum += single(a);
    }
    sum / std::f64::consts::PI
}

#[cfg(test)]
mod tests;
