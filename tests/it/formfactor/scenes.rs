//! Test scenes built directly as patch sets (independent of the scene loader):
//! parallelogram faces subdivided into m × m quads (or 2m² triangles), with one scene
//! face per parallelogram and its two occluder triangles.

use std::sync::Arc;

use ffstream::formfactor::{FormFactorConfig, RowEngine, Scratch};
use ffstream::geometry::occluders::Occluders;
use ffstream::patch::{Patch, PatchSet};
use ffstream::rows::Row;
use glam::{dvec3, DVec3};

#[derive(Clone, Debug, Default)]
pub(crate) struct Built {
    pub patches: PatchSet,
    pub tris: Vec<(u32, [DVec3; 3])>,
    faces: u32,
}

impl Built {
    /// Adds the parallelogram origin + [0,1]·u + [0,1]·v (front normal u × v) as a new
    /// face in a new group, subdivided m × m; `split` cuts each cell into 2 triangles
    /// (alternating diagonals, so edges of every direction occur).
    pub(crate) fn face(
        &mut self,
        name: &str,
        origin: DVec3,
        u: DVec3,
        v: DVec3,
        m: usize,
        split: bool,
    ) -> &mut Self {
        self.cells(name, origin, u, v, (m, m), split)
    }

    /// [`Built::face`] subdivided mu × mv (mu along u).
    /// A bottomless box on the floor z = lo.z over [lo.x, hi.x] × [lo.y, hi.y], up to
    /// hi.z: a top and four outward walls ("box_top", "box_x0", "box_x1", "box_y0",
    /// "box_y1"), each m × m patches.
    pub(crate) fn bottomless_box(&mut self, lo: DVec3, hi: DVec3, m: usize) -> &mut Self {
        let d = hi - lo;
        let (w, depth, h) = (DVec3::X * d.x, DVec3::Y * d.y, DVec3::Z * d.z);
        self.face("box_top", lo + h, w, depth, m, false);
        self.face("box_x0", lo, h, depth, m, false);
        self.face("box_x1", lo + w, depth, h, m, false);
        self.face("box_y0", lo, w, h, m, false);
        self.face("box_y1", lo + depth, h, w, m, false)
    }

    pub(crate) fn cells(
        &mut self,
        name: &str,
        origin: DVec3,
        u: DVec3,
        v: DVec3,
        (mu, mv): (usize, usize),
        split: bool,
    ) -> &mut Self {
        let (face, group) = self.new_face(name);
        let n = u.cross(v).normalize();
        let at =
            |a: usize, b: usize| origin + u * (a as f64 / mu as f64) + v * (b as f64 / mv as f64);
        for b in 0..mv {
            for a in 0..mu {
                let c = [at(a, b), at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)];
                if split {
                    let (t1, t2) = if (a + b) % 2 == 0 {
                        ([c[0], c[1], c[2]], [c[0], c[2], c[3]])
                    } else {
                        ([c[0], c[1], c[3]], [c[1], c[2], c[3]])
                    };
                    for t in [t1, t2] {
                        self.patches.patches.push(patch(&t, n, group, face));
                    }
                } else {
                    self.patches.patches.push(patch(&c, n, group, face));
                }
            }
        }
        self.tris.push((face, [origin, origin + u, origin + u + v]));
        self.tris.push((face, [origin, origin + u + v, origin + v]));
        self
    }

    /// Adds the triangle v (front = counter-clockwise) as a new face in a new group,
    /// subdivided into k² similar triangles.
    pub(crate) fn triangle(&mut self, name: &str, v: [DVec3; 3], k: usize) -> &mut Self {
        let (face, group) = self.new_face(name);
        let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
        let at = |a: usize, b: usize| {
            v[0] + (v[1] - v[0]) * (a as f64 / k as f64) + (v[2] - v[0]) * (b as f64 / k as f64)
        };
        for b in 0..k {
            for a in 0..k - b {
                self.patches.patches.push(patch(
                    &[at(a, b), at(a + 1, b), at(a, b + 1)],
                    n,
                    group,
                    face,
                ));
                if a + b + 1 < k {
                    self.patches.patches.push(patch(
                        &[at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)],
                        n,
                        group,
                        face,
                    ));
                }
            }
        }
        self.tris.push((face, v));
        self
    }

    /// A regular `sides`-gon of circumradius `r` about `centre` in the plane z =
    /// centre.z, facing +z (`up`) or −z, as one face in a new group: a fan of `sides`
    /// triangle patches (centre and two consecutive corners), each also an occluder
    /// triangle of that face.
    pub(crate) fn polygon_disk(
        &mut self,
        name: &str,
        centre: DVec3,
        r: f64,
        sides: usize,
        up: bool,
    ) -> &mut Self {
        let (face, group) = self.new_face(name);
        let n = if up { DVec3::Z } else { -DVec3::Z };
        let corner = |k: usize| {
            let a = std::f64::consts::TAU * k as f64 / sides as f64;
            centre + dvec3(r * a.cos(), r * a.sin(), 0.0)
        };
        for k in 0..sides {
            // Counter-clockwise about the front normal.
            let t = if up {
                [centre, corner(k), corner(k + 1)]
            } else {
                [centre, corner(k + 1), corner(k)]
            };
            self.patches.patches.push(patch(&t, n, group, face));
            self.tris.push((face, t));
        }
        self
    }

    /// A new scene face in a new group called `name`: (face, group).
    fn new_face(&mut self, name: &str) -> (u32, u32) {
        let face = self.faces;
        self.faces += 1;
        let group = self.patches.groups.len() as u32;
        self.patches.groups.push(name.to_string());
        (face, group)
    }

    /// An occluder only (no patches): a parallelogram as two triangles.
    pub(crate) fn blocker(&mut self, origin: DVec3, u: DVec3, v: DVec3) -> &mut Self {
        let face = self.faces;
        self.faces += 1;
        self.tris.push((face, [origin, origin + u, origin + u + v]));
        self.tris.push((face, [origin, origin + u + v, origin + v]));
        self
    }

    /// Occluders only: the six faces of the cube [lo, lo + s]³ (a closed box).
    pub(crate) fn blocker_box(&mut self, lo: DVec3, s: f64) -> &mut Self {
        self.blocker_cuboid(lo, DVec3::splat(s))
    }

    /// Occluders only: the six faces of the box [lo, lo + size] (closed).
    pub(crate) fn blocker_cuboid(&mut self, lo: DVec3, size: DVec3) -> &mut Self {
        let (x, y, z) = (DVec3::X * size.x, DVec3::Y * size.y, DVec3::Z * size.z);
        for (o, u, v) in [
            (lo, y, x),
            (lo + z, x, y),
            (lo, z, y),
            (lo + x, y, z),
            (lo, x, z),
            (lo + y, z, x),
        ] {
            self.blocker(o, u, v);
        }
        self
    }

    pub(crate) fn scaled(&self, s: f64) -> Built {
        let mut b = self.clone();
        for p in &mut b.patches.patches {
            for c in &mut p.corners {
                *c *= s;
            }
            p.area *= s * s;
        }
        for (_, t) in &mut b.tris {
            for c in t {
                *c *= s;
            }
        }
        b
    }

    pub(crate) fn engine(&self, cfg: FormFactorConfig) -> RowEngine {
        RowEngine::new(
            &self.patches,
            Arc::new(Occluders::new(self.tris.clone())),
            cfg,
        )
    }

    pub(crate) fn n(&self) -> usize {
        self.patches.len()
    }
}

fn patch(c: &[DVec3], n: DVec3, group: u32, face: u32) -> Patch {
    let mut corners = [DVec3::ZERO; 4];
    corners[..c.len()].copy_from_slice(c);
    let area = if c.len() == 3 {
        0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length()
    } else {
        0.5 * ((c[1] - c[0]).cross(c[2] - c[0]).length()
            + (c[2] - c[0]).cross(c[3] - c[0]).length())
    };
    Patch {
        corners,
        n_corners: c.len() as u8,
        normal: n,
        area,
        group,
        face,
        rho: [0.5; 3],
        emission: [0.0; 3],
    }
}

/// Two squares of side 1 at distance 1/x, directly opposed, facing each other
/// (Howell C-11 with X = Y = x). Groups 0 (lower) and 1 (upper).
pub(crate) fn parallel_squares(x: f64, m: usize, split: bool) -> Built {
    let c = 1.0 / x;
    let mut b = Built::default();
    b.face(
        "lower",
        DVec3::ZERO,
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
        m,
        split,
    );
    b.face(
        "upper",
        dvec3(0.0, 0.0, c),
        dvec3(0.0, 1.0, 0.0),
        dvec3(1.0, 0.0, 0.0),
        m,
        split,
    );
    b
}

/// Perpendicular rectangles sharing the edge x ∈ [0, 1] (Howell C-14): the emitter
/// (group 0) spans y ∈ [0, w] in z = 0 facing +z, the receiver (group 1) spans
/// z ∈ [0, h] in y = 0 facing +y.
pub(crate) fn perpendicular(w: f64, h: f64, m: usize, split: bool) -> Built {
    let mut b = Built::default();
    b.face(
        "emitter",
        DVec3::ZERO,
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, w, 0.0),
        m,
        split,
    );
    b.face(
        "receiver",
        DVec3::ZERO,
        dvec3(0.0, 0.0, h),
        dvec3(1.0, 0.0, 0.0),
        m,
        split,
    );
    b
}

/// Unit cube with inward faces, each subdivided m × m. Groups: 0 z=0, 1 z=1, 2 x=0,
/// 3 x=1, 4 y=0, 5 y=1 (so 0–1, 2–3, 4–5 are opposite).
pub(crate) fn cube(m: usize, split: bool) -> Built {
    let (x, y, z) = (
        dvec3(1.0, 0.0, 0.0),
        dvec3(0.0, 1.0, 0.0),
        dvec3(0.0, 0.0, 1.0),
    );
    let mut b = Built::default();
    b.face("z0", DVec3::ZERO, x, y, m, split);
    b.face("z1", z, y, x, m, split);
    b.face("x0", DVec3::ZERO, y, z, m, split);
    b.face("x1", x, z, y, m, split);
    b.face("y0", DVec3::ZERO, z, x, m, split);
    b.face("y1", y, x, z, m, split);
    b
}

/// Regular icosahedron (circumradius √(1 + φ²)) with inward faces, each cut into k²
/// triangles: a closed convex enclosure whose edges run in many directions.
pub(crate) fn icosahedron(k: usize) -> Built {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v = Vec::new();
    for (a, b) in [(1.0, phi), (-1.0, phi), (1.0, -phi), (-1.0, -phi)] {
        v.push(dvec3(0.0, a, b));
        v.push(dvec3(a, b, 0.0));
        v.push(dvec3(b, 0.0, a));
    }
    // Faces: the triples of mutually adjacent vertices (edge length 2).
    let mut b = Built::default();
    let adjacent = |p: DVec3, q: DVec3| ((p - q).length() - 2.0).abs() < 1e-9;
    for i in 0..12 {
        for j in i + 1..12 {
            for l in j + 1..12 {
                if adjacent(v[i], v[j]) && adjacent(v[j], v[l]) && adjacent(v[i], v[l]) {
                    let mut t = [v[i], v[j], v[l]];
                    let n = (t[1] - t[0]).cross(t[2] - t[0]);
                    if n.dot(t[0] + t[1] + t[2]) > 0.0 {
                        t.swap(1, 2); // make it face inward
                    }
                    b.triangle("face", t, k);
                }
            }
        }
    }
    assert_eq!(b.patches.groups.len(), 20);
    b
}

/// Every row of the engine (dense f32 as stored), in order.
pub(crate) fn all_rows(e: &RowEngine) -> Vec<Row> {
    let mut s = Scratch::new();
    (0..e.n() as u32)
        .map(|i| e.compute_row(i, &mut s))
        .collect()
}

/// Group-to-group form factor F_IJ = Σ_{i∈I} (A_i / A_I) Σ_{j∈J} F_ij (docs/known-answers.md §1).
pub(crate) fn group_ff(ps: &PatchSet, rows: &[Row], gi: u32, gj: u32) -> f64 {
    let mut num = 0.0;
    let mut area = 0.0;
    for (i, p) in ps.patches.iter().enumerate() {
        if p.group != gi {
            continue;
        }
        area += p.area;
        let mut s = 0.0;
        rows[i].for_each_nonzero(|j, f| {
            if ps.patches[j as usize].group == gj {
                s += f as f64;
            }
        });
        num += p.area * s;
    }
    num / area
}

/// max |A_i F_ij − A_j F_ji| / max A_i F_ij over all pairs.
pub(crate) fn reciprocity_error(ps: &PatchSet, rows: &[Row]) -> f64 {
    let n = ps.len();
    let dense: Vec<Vec<f32>> = rows.iter().map(|r| r.to_dense(n)).collect();
    let (mut worst, mut scale) = (0.0f64, 0.0f64);
    for (i, row) in dense.iter().enumerate() {
        for (j, &fij) in row.iter().enumerate() {
            let a = ps.patches[i].area * fij as f64;
            let b = ps.patches[j].area * dense[j][i] as f64;
            worst = worst.max((a - b).abs());
            scale = scale.max(a);
        }
    }
    worst / scale
}
