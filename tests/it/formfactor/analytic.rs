//! Analytic form factors from docs/known-answers.md §2, §3, §4 (Howell's catalog), written out here and
//! checked against the tabulated values before anything else uses them.

use std::f64::consts::PI;

/// Howell C-11: parallel, directly opposed, equal rectangles a × b at distance c,
/// X = a/c, Y = b/c.
pub(crate) fn parallel_rectangles(x: f64, y: f64) -> f64 {
    let (x2, y2) = (x * x, y * y);
    let ln_term = (((1.0 + x2) * (1.0 + y2)) / (1.0 + x2 + y2)).sqrt().ln();
    2.0 / (PI * x * y)
        * (ln_term
            + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
            + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
            - x * x.atan()
            - y * y.atan())
}

/// Howell C-14: perpendicular rectangles sharing an edge of length l; emitter width
/// w, receiver height h, W = w/l, H = h/l. Returns F from the emitter to the receiver.
pub(crate) fn perpendicular_rectangles(w: f64, h: f64) -> f64 {
    let (w2, h2) = (w * w, h * h);
    let s = w2 + h2;
    let a = (1.0 + w2) * (1.0 + h2) / (1.0 + s);
    let b = (w2 * (1.0 + s) / ((1.0 + w2) * s)).powf(w2);
    let c = (h2 * (1.0 + s) / ((1.0 + h2) * s)).powf(h2);
    1.0 / (PI * w)
        * (w * (1.0 / w).atan() + h * (1.0 / h).atan() - s.sqrt() * (1.0 / s.sqrt()).atan()
            + 0.25 * (a * b * c).ln())
}

/// Howell C-41: coaxial parallel disks, emitter radius r1, receiver radius r2,
/// distance l.
pub(crate) fn coaxial_disks(r1: f64, r2: f64, l: f64) -> f64 {
    let (big_r1, big_r2) = (r1 / l, r2 / l);
    let s = 1.0 + (1.0 + big_r2 * big_r2) / (big_r1 * big_r1);
    0.5 * (s - (s * s - 4.0 * (r2 / r1).powi(2)).sqrt())
}

/// Unit cube, inward faces (docs/known-answers.md §5).
pub(crate) const CUBE_OPPOSITE: f64 = 0.19982489570;
pub(crate) const CUBE_ADJACENT: f64 = 0.20004377608;

#[test]
fn formulas_reproduce_the_tables() {
    // Tabulated to 7 decimals: check to half a unit in the last place.
    let tol = 5e-8;
    for (x, f) in [
        (0.5, 0.0685896),
        (1.0, 0.1998249),
        (2.0, 0.4152533),
        (10.0, 0.8269945),
    ] {
        assert!(
            (parallel_rectangles(x, x) - f).abs() < tol,
            "C-11 X=Y={x}: {}",
            parallel_rectangles(x, x)
        );
    }
    assert!((parallel_rectangles(1.0, 2.0) - 0.2858754).abs() < tol);
    assert!((parallel_rectangles(1.0, 1.0) - CUBE_OPPOSITE).abs() < 1e-11);
    for (w, h, f) in [
        (1.0, 1.0, 0.2000438),
        (0.5, 0.5, 0.2406360),
        (2.0, 2.0, 0.1492998),
        (1.0, 2.0, 0.2328526),
        (2.0, 1.0, 0.1164263),
    ] {
        let v = perpendicular_rectangles(w, h);
        assert!((v - f).abs() < tol, "C-14 W={w} H={h}: {v}");
    }
    assert!((perpendicular_rectangles(1.0, 1.0) - CUBE_ADJACENT).abs() < 1e-11);
    // Unit cube row sum: one opposite and four adjacent faces.
    assert!((CUBE_OPPOSITE + 4.0 * CUBE_ADJACENT - 1.0).abs() < 1e-10);
    for (r, f) in [(1.0, 0.3819660), (0.5, 0.1715729), (2.0, 0.6096118)] {
        let v = coaxial_disks(r, r, 1.0);
        assert!((v - f).abs() < tol, "C-41 r/L={r}: {v}");
    }
}
