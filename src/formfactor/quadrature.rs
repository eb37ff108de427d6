//! Gauss–Legendre quadrature on [-1, 1], used for the outer line integral of the
//! `contour` kernel (see [`super::contour`]).
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
}
