//! The sky divided into patches, and what a point with a normal receives from them.
//!
//! Subdivision: Tregenza's 145 patches (P. R. Tregenza, "Subdivision of the sky
//! hemisphere for luminance measurements", Lighting Research and Technology 19(1)
//! 13–14, 1987: seven 12° bands of 30, 30, 24, 24, 18, 12, 6 patches and a 6° polar cap)
//! and Reinhart's refinement by a factor `mf` (each band cut into `mf` bands of `mf`
//! times as many patches, the cap kept whole; C. Reinhart's MF:n, as in Radiance's
//! `reinhart.cal`): 145, 577, 1297, 2305 patches for mf = 1, 2, 3, 4. Band height is
//! 90°/(7·mf + 0.5); the cap has half a band's radius.
//!
//! Conventions (ffstream's own; Radiance numbers its patches differently): patches are
//! numbered from the horizon band upwards, the cap last; within a band patch 0 is
//! centred on north and numbers grow clockwise (towards east). Directions are unit
//! vectors in east–north–up coordinates. After the sky patches comes one ground patch:
//! the lower hemisphere with uniform luminance ρ·E_h/π (E_h the global horizontal
//! illuminance, ρ the ground's reflectance), as Radiance's `gendaymtx` models the ground.
//!
//! Integrals over a patch use an s × s grid of equal-solid-angle cells (uniform in
//! sin(altitude) and azimuth; the cap s × 4s). A sky vector holds each patch's mean
//! luminance over its cells, scaled so that the whole sky's horizontal illuminance,
//! integrated on the same cells, equals the diffuse horizontal illuminance of the hour.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::DVec3;

use super::perez::PerezSky;

/// Patches per band in Tregenza's subdivision, horizon first.
const TREGENZA: [u32; 7] = [30, 30, 24, 24, 18, 12, 6];

/// One patch's extent: altitudes and azimuths (radians; azimuth from north,
/// clockwise, `az1` > `az0`, possibly beyond 2π).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch {
    pub alt0: f64,
    pub alt1: f64,
    pub az0: f64,
    pub az1: f64,
}

impl Patch {
    /// Solid angle, steradians.
    pub fn solid_angle(&self) -> f64 {
        (self.az1 - self.az0) * (self.alt1.sin() - self.alt0.sin())
    }

    /// Direction of the patch's centre (mid altitude, mid azimuth; the zenith for the
    /// cap).
    pub fn centre(&self) -> DVec3 {
        if self.alt1 >= FRAC_PI_2 && self.az1 - self.az0 >= TAU - 1e-12 {
            return DVec3::Z;
        }
        direction(0.5 * (self.alt0 + self.alt1), 0.5 * (self.az0 + self.az1))
    }

    /// The patch's cells: `(direction, solid angle)`, `s` × `s` (the cap `s` × 4`s`)
    /// cells of equal solid angle.
    pub fn cells(&self, s: usize) -> impl Iterator<Item = (DVec3, f64)> + '_ {
        let na = if self.az1 - self.az0 >= TAU - 1e-12 {
            4 * s
        } else {
            s
        };
        let (u0, u1) = (self.alt0.sin(), self.alt1.sin());
        let w = self.solid_angle() / (s * na) as f64;
        (0..s).flat_map(move |k| {
            let alt = (u0 + (k as f64 + 0.5) / s as f64 * (u1 - u0)).asin();
            (0..na).map(move |l| {
                let az = self.az0 + (l as f64 + 0.5) / na as f64 * (self.az1 - self.az0);
                (direction(alt, az), w)
            })
        })
    }
}

/// Unit vector (east, north, up) at altitude `alt` and azimuth `az` (radians).
pub fn direction(alt: f64, az: f64) -> DVec3 {
    DVec3::new(alt.cos() * az.sin(), alt.cos() * az.cos(), alt.sin())
}

/// A subdivided sky.
#[derive(Clone, Debug)]
pub struct SkyDome {
    mf: u32,
    patches: Vec<Patch>,
    /// Per band, horizon first: its first patch and its patch count (the cap last, 1).
    bands: Vec<(usize, u32)>,
    /// Height of a band, radians.
    band_height: f64,
    /// Cells per patch side for integrals.
    cells: usize,
}

/// Luminance of every sky patch (cd/m², the patch's mean) and of the ground (last).
#[derive(Clone, Debug, PartialEq)]
pub struct SkyVector {
    pub luminance: Vec<f64>,
}

impl SkyDome {
    /// Reinhart's subdivision MF:`mf` (1 = Tregenza's 145 patches), integrals on
    /// `cells` × `cells` cells per patch.
    pub fn reinhart(mf: u32, cells: usize) -> Self {
        assert!(mf >= 1 && cells >= 1, "mf and cells must be at least 1");
        let bands = 7 * mf;
        let h = FRAC_PI_2 / (f64::from(bands) + 0.5);
        let mut patches = Vec::new();
        let mut rows = Vec::new();
        for r in 0..bands {
            let n = TREGENZA[(r / mf) as usize] * mf;
            rows.push((patches.len(), n));
            let width = TAU / f64::from(n);
            for j in 0..n {
                patches.push(Patch {
                    alt0: f64::from(r) * h,
                    alt1: f64::from(r + 1) * h,
                    az0: (f64::from(j) - 0.5) * width,
                    az1: (f64::from(j) + 0.5) * width,
                });
            }
        }
        rows.push((patches.len(), 1));
        patches.push(Patch {
            alt0: f64::from(bands) * h,
            alt1: FRAC_PI_2,
            az0: 0.0,
            az1: TAU,
        });
        SkyDome {
            mf,
            patches,
            bands: rows,
            band_height: h,
            cells,
        }
    }

    /// The refinement factor.
    pub fn mf(&self) -> u32 {
        self.mf
    }

    /// Cells per patch side in integrals.
    pub fn cells(&self) -> usize {
        self.cells
    }

    /// Number of sky patches (the ground not counted).
    pub fn len(&self) -> usize {
        self.patches.len()
    }

    /// Whether there are no sky patches (never, for a built dome).
    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }

    /// The sky patches.
    pub fn patches(&self) -> &[Patch] {
        &self.patches
    }

    /// The sky patch containing direction `dir` (unit, upper hemisphere), or `None`
    /// below the horizon.
    pub fn find(&self, dir: DVec3) -> Option<usize> {
        if dir.z < 0.0 {
            return None;
        }
        let alt = dir.z.clamp(-1.0, 1.0).asin();
        let r = ((alt / self.band_height) as usize).min(self.bands.len() - 1);
        let (first, n) = self.bands[r];
        let az = dir.x.atan2(dir.y).rem_euclid(TAU);
        let j = ((az / (TAU / f64::from(n)) + 0.5).floor() as u32) % n;
        Some(first + j as usize)
    }

    /// The hour's sky vector: each patch's mean luminance, normalised so that the sky's
    /// horizontal illuminance is the hour's diffuse horizontal illuminance; then the
    /// ground's luminance for reflectance `ground_reflectance`.
    pub fn sky_vector(&self, sky: &PerezSky, ground_reflectance: f64) -> SkyVector {
        let s = self.cells;
        let mut luminance = Vec::with_capacity(self.patches.len() + 1);
        let mut horizontal = 0.0;
        for p in &self.patches {
            let (mut sum, mut omega) = (0.0, 0.0);
            for (d, w) in p.cells(s) {
                let l = sky.relative(d);
                sum += l * w;
                horizontal += l * d.z * w;
                omega += w;
            }
            luminance.push(sum / omega);
        }
        let scale = if horizontal > 0.0 {
            sky.diffuse_horizontal / horizontal
        } else {
            0.0
        };
        for l in &mut luminance {
            *l *= scale;
        }
        luminance.push(ground_reflectance * sky.global_horizontal() / PI);
        SkyVector { luminance }
    }

    /// What an unobstructed point with unit normal `n` receives from each patch per unit
    /// luminance: the integral of max(0, n·d) over the patch (sr), the ground's last
    /// (exactly π(1 − n_z)/2). Illuminance = Σ coefficient × luminance.
    pub fn coefficients(&self, n: DVec3) -> Vec<f64> {
        let s = self.cells;
        let mut c: Vec<f64> = self
            .patches
            .iter()
            .map(|p| p.cells(s).map(|(d, w)| n.dot(d).max(0.0) * w).sum())
            .collect();
        c.push(PI * (1.0 - n.z) / 2.0);
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reinhart_counts_and_solid_angles() {
        for (mf, n) in [(1, 145), (2, 577), (3, 1297), (4, 2305)] {
            let d = SkyDome::reinhart(mf, 2);
            assert_eq!(d.len(), n, "MF:{mf}");
            let total: f64 = d.patches().iter().map(Patch::solid_angle).sum();
            assert!((total - TAU).abs() < 1e-12, "MF:{mf}: {total}");
        }
        let t = SkyDome::reinhart(1, 1);
        assert!((t.patches()[0].alt1.to_degrees() - 12.0).abs() < 1e-12);
        assert!((t.patches()[144].alt0.to_degrees() - 84.0).abs() < 1e-12);
    }

    #[test]
    fn every_direction_finds_the_patch_that_contains_it() {
        let d = SkyDome::reinhart(2, 3);
        for (i, p) in d.patches().iter().enumerate() {
            for (dir, _) in p.cells(3) {
                assert_eq!(d.find(dir), Some(i), "cell {dir} of patch {i}");
            }
            assert_eq!(d.find(p.centre()), Some(i));
        }
        assert_eq!(d.find(DVec3::new(0.0, 1.0, -0.01).normalize()), None);
    }

    #[test]
    fn coefficients_integrate_the_cosine_over_the_sphere() {
        // Σ over the sky of max(0, n·d) dω is π(1 + n_z)/2 for a plane, the ground's
        // share π(1 − n_z)/2: together π, the cosine's integral over a hemisphere.
        let d = SkyDome::reinhart(2, 8);
        for n in [
            DVec3::Z,
            DVec3::X,
            DVec3::new(0.0, -1.0, 1.0).normalize(),
            DVec3::new(0.3, 0.2, -0.9).normalize(),
        ] {
            let c = d.coefficients(n);
            let sky: f64 = c[..d.len()].iter().sum();
            let exact = PI * (1.0 + n.z) / 2.0;
            assert!((sky - exact).abs() < 2e-3 * PI, "n = {n}: {sky} vs {exact}");
            assert!((sky + c[d.len()] - PI).abs() < 2e-3 * PI);
        }
        // Horizontal: each patch exactly Δφ (sin²a1 − sin²a0)/2 up to the cell rule.
        let c = d.coefficients(DVec3::Z);
        for (p, ci) in d.patches().iter().zip(&c) {
            let exact = (p.az1 - p.az0) * (p.alt1.sin().powi(2) - p.alt0.sin().powi(2)) / 2.0;
            assert!(
                (ci - exact).abs() < 1e-6 * exact.max(1e-3),
                "{ci} vs {exact}"
            );
        }
    }
}
