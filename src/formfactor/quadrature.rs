//! The quadrature rules of the kernels: Gauss–Legendre on [-1, 1], used for the outer
//! line integral of the `contour` kernel (see [`super::contour`]), and the embedded pair
//! of triangle rules ([`RADON`] inside [`LAURIE`]) of the exact route's outer integral
//! ([`super::shadow`]). (The far-field rules, tied to its patch maps, are in
//! [`super::farfield`].)
//!
//! Nodes are the roots of the Legendre polynomial P_n, found by Newton's method from
//! the classical starting guess cos(π (k − ¼) / (n + ½)) (Abramowitz & Stegun 25.4.29,
//! with the standard asymptotic initial values); weights are 2 / ((1 − x²) P_n'(x)²).
//! An n-point rule integrates polynomials of degree ≤ 2n − 1 exactly, and converges
//! geometrically for functions analytic in a Bernstein ellipse around [-1, 1].

use std::sync::OnceLock;

/// Largest order held by [`GaussTable`].
pub(crate) const MAX_ORDER: usize = 24;

/// Nodes and weights for every order 1..=[`MAX_ORDER`].
#[derive(Clone, Debug)]
pub(crate) struct GaussTable {
    /// `rules[n]` holds the n-point rule as (node, weight) pairs; `rules[0]` is empty.
    rules: Vec<Vec<(f64, f64)>>,
}

impl GaussTable {
    /// Computes every rule up to [`MAX_ORDER`] points.
    pub(crate) fn new() -> Self {
        let rules = (0..=MAX_ORDER).map(gauss_legendre).collect();
        GaussTable { rules }
    }

    /// The n-point rule on [-1, 1] as (node, weight) pairs, n clamped to 1..=MAX_ORDER.
    #[inline]
    pub(crate) fn rule(&self, n: usize) -> &[(f64, f64)] {
        &self.rules[n.clamp(1, MAX_ORDER)]
    }
}

impl Default for GaussTable {
    fn default() -> Self {
        Self::new()
    }
}

/// The process-wide table (computed once; a few microseconds).
pub(crate) fn gauss_table() -> &'static GaussTable {
    static TABLE: OnceLock<GaussTable> = OnceLock::new();
    TABLE.get_or_init(GaussTable::new)
}

/// The n-point Gauss–Legendre rule on [-1, 1], nodes ascending.
pub(crate) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    if n == 0 {
        return out;
    }
    let nf = n as f64;
    for k in 1..=n {
        // Initial guess for the k-th root counted from x = 1 downwards.
        let mut x = (std::f64::consts::PI * (k as f64 - 0.25) / (nf + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (p, d) = legendre_and_derivative(n, x);
            dp = d;
            let dx = p / d;
            x -= dx;
            if dx.abs() <= 1e-16 * x.abs().max(1.0) {
                break;
            }
        }
        let (_, d) = legendre_and_derivative(n, x);
        if d.is_finite() {
            dp = d;
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((x, w));
    }
    out.reverse();
    out
}

/// P_n(x) and P_n'(x) by the three-term recurrence (n + 1) P_{n+1} = (2n + 1) x P_n − n P_{n−1}.
fn legendre_and_derivative(n: usize, x: f64) -> (f64, f64) {
    let mut p0 = 1.0;
    let mut p1 = x;
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 1..n {
        let kf = k as f64;
        let p2 = ((2.0 * kf + 1.0) * x * p1 - kf * p0) / (kf + 1.0);
        p0 = p1;
        p1 = p2;
    }
    // P_n'(x) = n (x P_n − P_{n−1}) / (x² − 1)
    let nf = n as f64;
    let d = nf * (x * p1 - p0) / (x * x - 1.0);
    (p1, d)
}

/// The 7-point degree-5 rule on a triangle (Radon 1948; e.g. Stroud T2:5-1):
/// barycentric points and weights (summing to 1), centroid first, then the two orbits
/// of three.
pub(crate) const RADON: [([f64; 3], f64); 7] = {
    const S15: f64 = 3.872_983_346_207_417; // √15
    const A1: f64 = (6.0 - S15) / 21.0;
    const B1: f64 = (9.0 + 2.0 * S15) / 21.0;
    const A2: f64 = (6.0 + S15) / 21.0;
    const B2: f64 = (9.0 - 2.0 * S15) / 21.0;
    const W1: f64 = (155.0 - S15) / 1200.0;
    const W2: f64 = (155.0 + S15) / 1200.0;
    [
        ([1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0], 9.0 / 40.0),
        ([B1, A1, A1], W1),
        ([A1, B1, A1], W1),
        ([A1, A1, B1], W1),
        ([B2, A2, A2], W2),
        ([A2, B2, A2], W2),
        ([A2, A2, B2], W2),
    ]
};

/// The 19-point degree-8 rule on a triangle in which [`RADON`]'s seven points are
/// embedded (Laurie 1982, ACM TOMS 8(2), Algorithm 584 CUBTRI): the same seven points
/// first, in [`RADON`]'s order and with their own weights, then an orbit of three at
/// `A3`, one at `A4` and the six points (1 − A3 − A4, A3, A4). Weights sum to 1.
pub(crate) const LAURIE: [([f64; 3], f64); 19] = {
    let r = RADON;
    const A3: f64 = 0.232_102_326_775_050_4;
    const A4: f64 = 0.029_480_860_884_439_6;
    const B3: f64 = 1.0 - 2.0 * A3;
    const B4: f64 = 1.0 - 2.0 * A4;
    const C: f64 = 1.0 - A3 - A4;
    const W0: f64 = 0.037_861_091_200_314_7;
    const W1: f64 = 0.037_620_425_413_182_9;
    const W2: f64 = 0.078_357_352_244_117_4;
    const W3: f64 = 0.116_271_479_656_965_9;
    const W4: f64 = 0.013_444_267_375_165_5;
    const W6: f64 = 0.037_509_722_455_231_7;
    [
        (r[0].0, W0),
        (r[1].0, W1),
        (r[2].0, W1),
        (r[3].0, W1),
        (r[4].0, W2),
        (r[5].0, W2),
        (r[6].0, W2),
        ([B3, A3, A3], W3),
        ([A3, B3, A3], W3),
        ([A3, A3, B3], W3),
        ([B4, A4, A4], W4),
        ([A4, B4, A4], W4),
        ([A4, A4, B4], W4),
        ([C, A3, A4], W6),
        ([C, A4, A3], W6),
        ([A3, C, A4], W6),
        ([A4, C, A3], W6),
        ([A3, A4, C], W6),
        ([A4, A3, C], W6),
    ]
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_two_and_nodes_symmetric() {
        let t = GaussTable::new();
        for n in 1..=MAX_ORDER {
            let r = t.rule(n);
            assert_eq!(r.len(), n);
            let s: f64 = r.iter().map(|&(_, w)| w).sum();
            assert!((s - 2.0).abs() < 1e-14, "n={n} sum={s}");
            for k in 0..n {
                assert!((r[k].0 + r[n - 1 - k].0).abs() < 1e-14);
                assert!((r[k].1 - r[n - 1 - k].1).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn exact_for_degree_2n_minus_1() {
        let t = GaussTable::new();
        for n in 1..=MAX_ORDER {
            for deg in 0..(2 * n) {
                let q: f64 = t.rule(n).iter().map(|&(x, w)| w * x.powi(deg as i32)).sum();
                // ∫_{-1}^{1} x^d dx = 2/(d+1) for even d, 0 for odd d.
                let exact = if deg % 2 == 0 {
                    2.0 / (deg as f64 + 1.0)
                } else {
                    0.0
                };
                assert!((q - exact).abs() < 1e-13, "n={n} deg={deg} q={q}");
            }
        }
    }

    #[test]
    fn known_two_point_rule() {
        let r = gauss_legendre(2);
        let x = 1.0 / 3f64.sqrt();
        assert!((r[0].0 + x).abs() < 1e-15 && (r[1].0 - x).abs() < 1e-15);
        assert!((r[0].1 - 1.0).abs() < 1e-15);
    }

    #[test]
    fn the_rules_integrate_what_they_should() {
        // ∫ λ₁^a λ₂^b λ₃^c over a triangle / area = 2 a! b! c! / (a + b + c + 2)!.
        let f = |n: u32| (1..=n).product::<u32>() as f64;
        let moment = |rule: &[([f64; 3], f64)], (a, b, c): (u32, u32, u32)| -> (f64, f64) {
            let want = 2.0 * f(a) * f(b) * f(c) / f(a + b + c + 2);
            let got: f64 = rule
                .iter()
                .map(|(l, w)| w * l[0].powi(a as i32) * l[1].powi(b as i32) * l[2].powi(c as i32))
                .sum();
            (got, want)
        };
        let upto = |degree: u32| {
            (0..=degree).flat_map(move |a| {
                (0..=degree - a).flat_map(move |b| (0..=degree - a - b).map(move |c| (a, b, c)))
            })
        };
        for e in upto(5) {
            let (got, want) = moment(&RADON, e);
            assert!(
                (got - want).abs() < 1e-15,
                "degree 5: {e:?} {got} vs {want}"
            );
        }
        for e in upto(8) {
            let (got, want) = moment(&LAURIE, e);
            assert!(
                (got - want).abs() < 1e-15,
                "degree 8: {e:?} {got} vs {want}"
            );
        }
        // Neither is exact one degree up (else the error estimate would be blind there).
        let (got, want) = moment(&RADON, (6, 0, 0));
        assert!((got - want).abs() > 1e-6, "{got} vs {want}");
        let (got, want) = moment(&LAURIE, (9, 0, 0));
        assert!((got - want).abs() > 1e-8, "{got} vs {want}");
        // The degree-5 rule's points are the first seven of the degree-8 rule's.
        for (k, (l, _)) in RADON.iter().enumerate() {
            assert_eq!(*l, LAURIE[k].0);
        }
        for (l, w) in LAURIE {
            assert!(
                w > 0.0
                    && l.iter().all(|&x| x > 0.0)
                    && (l.iter().sum::<f64>() - 1.0).abs() < 1e-15
            );
        }
    }
}
