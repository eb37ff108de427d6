//! Shared by the numerical stress tests: patch sets built directly (independent of the
//! scene loader), Howell's formulas (docs/known-answers.md §2, §3) written out once more and checked
//! against the tables, and small matrix helpers.

use std::f64::consts::PI;

use ffstream::formfactor::{RowEngine, Scratch};
use glam::{DQuat, DVec3};

/// Patches plus the occluder triangles of their faces: the builder of the form-factor
/// tests, with what the stress tests add to it.
pub(crate) use crate::formfactor::scenes::Built as Geo;

impl Geo {
    /// The parallelogram origin + [0,1]·u + [0,1]·v (front normal u × v), one scene face
    /// in a new group, cut into mu × mv quads.
    pub(crate) fn para(
        &mut self,
        origin: DVec3,
        u: DVec3,
        v: DVec3,
        mu: usize,
        mv: usize,
    ) -> &mut Self {
        let name = format!("g{}", self.patches.groups.len());
        self.cells(&name, origin, u, v, (mu, mv), false)
    }

    /// Closed box [0,a]×[0,b]×[0,c] with inward faces, each cut m × m.
    pub(crate) fn closed_box(a: f64, b: f64, c: f64, m: usize) -> Geo {
        let (x, y, z) = (DVec3::X * a, DVec3::Y * b, DVec3::Z * c);
        let mut g = Geo::default();
        g.para(DVec3::ZERO, x, y, m, m)
            .para(z, y, x, m, m)
            .para(DVec3::ZERO, z, x, m, m)
            .para(y, x, z, m, m)
            .para(DVec3::ZERO, y, z, m, m)
            .para(x, z, y, m, m);
        g
    }

    /// The same geometry moved by p ↦ s·R·p + t (areas scale by s²).
    pub(crate) fn transformed(&self, s: f64, r: DQuat, t: DVec3) -> Geo {
        let f = |p: DVec3| r * (p * s) + t;
        let mut g = self.clone();
        for p in &mut g.patches.patches {
            for c in &mut p.corners {
                *c = f(*c);
            }
            p.normal = (r * p.normal).normalize();
            p.area *= s * s;
        }
        for (_, t) in &mut g.tris {
            for c in t {
                *c = f(*c);
            }
        }
        g
    }

    pub(crate) fn area(&self, i: usize) -> f64 {
        self.patches.patches[i].area
    }
}

/// The full matrix in f64, row-major.
pub(crate) fn matrix(e: &RowEngine) -> Vec<f64> {
    let (mut s, mut row, mut out) = (Scratch::new(), Vec::new(), Vec::new());
    for i in 0..e.n() as u32 {
        e.row_values(i, &mut s, &mut row);
        out.extend_from_slice(&row);
    }
    out
}

/// Group-to-group factor F_IJ = Σ_{i∈I} (A_i/A_I) Σ_{j∈J} F_ij.
pub(crate) fn group_ff(g: &Geo, f: &[f64], gi: u32, gj: u32) -> f64 {
    let n = g.n();
    let p = &g.patches.patches;
    let (mut num, mut den) = (0.0, 0.0);
    for i in (0..n).filter(|&i| p[i].group == gi) {
        den += p[i].area;
        for j in (0..n).filter(|&j| p[j].group == gj) {
            num += p[i].area * f[i * n + j];
        }
    }
    num / den
}

/// Howell C-11 (the formula the formfactor tests check against the tables of docs/known-answers.md §2).
pub(crate) use crate::formfactor::analytic::parallel_rectangles as howell_c11;
/// Howell C-14 (likewise).
pub(crate) use crate::formfactor::analytic::perpendicular_rectangles as howell_c14;

/// Differential area to a parallel rectangle a × b whose corner is straight above
/// (below) it at distance c (Howell B-3 form): X = a/c, Y = b/c.
pub(crate) fn howell_point_to_corner_rectangle(x: f64, y: f64) -> f64 {
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * PI)
}

#[test]
fn formulas_reproduce_the_tables() {
    for (x, f) in [
        (0.5, 0.0685896),
        (1.0, 0.1998249),
        (2.0, 0.4152533),
        (10.0, 0.8269945),
    ] {
        assert!((howell_c11(x, x) - f).abs() < 5e-8, "C-11 {x}");
    }
    assert!((howell_c11(1.0, 2.0) - 0.2858754).abs() < 5e-8);
    for (w, h, f) in [
        (1.0, 1.0, 0.2000438),
        (0.5, 0.5, 0.2406360),
        (2.0, 2.0, 0.1492998),
        (1.0, 2.0, 0.2328526),
        (2.0, 1.0, 0.1164263),
    ] {
        assert!((howell_c14(w, h) - f).abs() < 5e-8, "C-14 {w} {h}");
    }
    // Point below the corner of a 1 × 2 rectangle at distance 1, against the
    // midpoint rule on cos θ_i cos θ_j / (π r²) = c² / (π r⁴) (independent of the formula).
    let m = 2000;
    let mut sum = 0.0;
    for a in 0..m {
        for b in 0..2 * m {
            let (x, y) = ((a as f64 + 0.5) / m as f64, (b as f64 + 0.5) / m as f64);
            let r2 = x * x + y * y + 1.0;
            sum += 1.0 / (PI * r2 * r2);
        }
    }
    let numeric = sum / (m * m) as f64;
    let v = howell_point_to_corner_rectangle(1.0, 2.0);
    assert!((v - numeric).abs() < 1e-7, "{v} vs {numeric}");
    // An infinite plane takes everything.
    assert!((4.0 * howell_point_to_corner_rectangle(1e9, 1e9) - 1.0).abs() < 1e-8);
}
