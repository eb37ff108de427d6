//! The sky of one hour from its weather: R. Perez's models.
//!
//! - **Sky condition**: clearness ε and brightness Δ from direct-normal and
//!   diffuse-horizontal irradiance, the sun's zenith angle and the day (Perez, Ineichen,
//!   Seals, Michalsky, Stewart, "Modeling daylight availability and irradiance
//!   components from direct and global irradiance", Solar Energy 44(5) 271–289, 1990,
//!   eqs. 1–2), sorted into the eight clearness categories of that paper.
//! - **Luminous efficacy** (lm/W) of the diffuse and the direct light, from the category,
//!   the precipitable water, the zenith angle and Δ (same paper, Table 4 and its eqs. for
//!   diffuse and direct illuminance).
//! - **Luminance distribution** over the sky (Perez, Seals, Michalsky, "All-weather model
//!   for sky luminance distribution — preliminary configuration and validation", Solar
//!   Energy 50(3) 235–245, 1993, eqs. 1, 6–8 and Table 1): relative luminance
//!   `(1 + a·exp(b / cos ζ)) · (1 + c·exp(d·γ) + e·cos²γ)` at zenith angle ζ and angle γ
//!   from the sun, with a…e from the category, the sun's zenith angle and Δ.
//!
//! The coefficient tables are the papers' published numbers; they were checked against
//! the two copies in Radiance (`src/gen/gendaylit.c` and `gendaymtx.c`, which agree to
//! the last digit). Where ffstream departs from the papers, as Radiance does:
//! - Δ is floored at 0.01 (the diffuse efficacy has ln Δ; Δ → 0 only when the diffuse
//!   irradiance does, and then there is no sky to draw);
//! - for 1.065 < ε < 2.8 the luminance coefficients use Δ ≥ 0.2 (below it the table gives
//!   negative luminance near the horizon; both Radiance generators do this);
//! - the sun's zenith angle in the formulas is at most 90°: in the hour after sunrise and
//!   before sunset the hour's midpoint may find the sun just below the horizon while the
//!   file has diffuse light; the sky is then drawn with the sun on the horizon at its
//!   azimuth (as `gendaymtx` does).
//!
//! The absolute scale of the luminance is set by whoever integrates the distribution over
//! the sky ([`super::dome::SkyDome::sky_vector`]): the integral of luminance × cos ζ over
//! the hemisphere must equal the diffuse horizontal illuminance.

use glam::DVec3;

/// Upper clearness bounds of Perez's eight categories (the last is open).
const CLEARNESS_BOUNDS: [f64; 7] = [1.065, 1.230, 1.500, 1.950, 2.800, 4.500, 6.200];

/// Solar constant, W/m² (the value Perez 1990 and Radiance use).
pub const SOLAR_CONSTANT: f64 = 1367.0;

/// Diffuse efficacy coefficients (a, b, c, d) per category: lm/W =
/// a + b·W + c·cos Z + d·ln Δ (Perez 1990, Table 4).
const DIFFUSE_EFFICACY: [[f64; 4]; 8] = [
    [97.24, -0.46, 12.00, -8.91],
    [107.22, 1.15, 0.59, -3.95],
    [104.97, 2.96, -5.53, -8.77],
    [102.39, 5.59, -13.95, -13.90],
    [100.71, 5.94, -22.75, -23.74],
    [106.42, 3.83, -36.15, -28.83],
    [141.88, 1.90, -53.24, -14.03],
    [152.23, 0.35, -45.27, -7.98],
];

/// Direct efficacy coefficients (a, b, c, d) per category: lm/W =
/// max(0, a + b·W + c·exp(5.73·Z − 5) + d·Δ) (Perez 1990, Table 4).
const DIRECT_EFFICACY: [[f64; 4]; 8] = [
    [57.20, -4.55, -2.98, 117.12],
    [98.99, -3.46, -1.21, 12.38],
    [109.83, -4.90, -1.71, -8.81],
    [110.34, -5.84, -1.99, -4.56],
    [106.36, -3.97, -1.75, -6.16],
    [107.19, -1.25, -1.51, -26.73],
    [105.75, 0.77, -1.26, -34.44],
    [101.18, 1.58, -1.10, -8.29],
];

/// Luminance-distribution coefficients per category: for each of a, b, c, d, e the four
/// numbers (x1, x2, x3, x4) of `x1 + x2·Z + Δ·(x3 + x4·Z)` (Perez 1993, Table 1; the
/// first category's c and d use other formulas, see [`distribution`]).
const DISTRIBUTION: [[[f64; 4]; 5]; 8] = [
    [
        [1.3525, -0.2576, -0.2690, -1.4366],
        [-0.7670, 0.0007, 1.2734, -0.1233],
        [2.8000, 0.6004, 1.2375, 1.0000],
        [1.8734, 0.6297, 0.9738, 0.2809],
        [0.0356, -0.1246, -0.5718, 0.9938],
    ],
    [
        [-1.2219, -0.7730, 1.4148, 1.1016],
        [-0.2054, 0.0367, -3.9128, 0.9156],
        [6.9750, 0.1774, 6.4477, -0.1239],
        [-1.5798, -0.5081, -1.7812, 0.1080],
        [0.2624, 0.0672, -0.2190, -0.4285],
    ],
    [
        [-1.1000, -0.2515, 0.8952, 0.0156],
        [0.2782, -0.1812, -4.5000, 1.1766],
        [24.7219, -13.0812, -37.7000, 34.8438],
        [-5.0000, 1.5218, 3.9229, -2.6204],
        [-0.0156, 0.1597, 0.4199, -0.5562],
    ],
    [
        [-0.5484, -0.6654, -0.2672, 0.7117],
        [0.7234, -0.6219, -5.6812, 2.6297],
        [33.3389, -18.3000, -62.2500, 52.0781],
        [-3.5000, 0.0016, 1.1477, 0.1062],
        [0.4659, -0.3296, -0.0876, -0.0329],
    ],
    [
        [-0.6000, -0.3566, -2.5000, 2.3250],
        [0.2937, 0.0496, -5.6812, 1.8415],
        [21.0000, -4.7656, -21.5906, 7.2492],
        [-3.5000, -0.1554, 1.4062, 0.3988],
        [0.0032, 0.0766, -0.0656, -0.1294],
    ],
    [
        [-1.0156, -0.3670, 1.0078, 1.4051],
        [0.2875, -0.5328, -3.8500, 3.3750],
        [14.0000, -0.9999, -7.1406, 7.5469],
        [-3.4000, -0.1078, -1.0750, 1.5702],
        [-0.0672, 0.4016, 0.3017, -0.4844],
    ],
    [
        [-1.0000, 0.0211, 0.5025, -0.5119],
        [-0.3000, 0.1922, 0.7023, -1.6317],
        [19.0000, -5.0000, 1.2438, -1.9094],
        [-4.0000, 0.0250, 0.3844, 0.2656],
        [1.0468, -0.3788, -2.4517, 1.4656],
    ],
    [
        [-1.0500, 0.0289, 0.4260, 0.3590],
        [-0.3250, 0.1156, 0.7781, 0.0025],
        [31.0625, -14.5000, -46.1148, 55.3750],
        [-7.2312, 0.4050, 13.3500, 0.6234],
        [1.5000, -0.6426, 1.8564, 0.5636],
    ],
];

/// Earth–sun distance correction (R₀/R)² on day `n` of the year (1-based): Spencer's
/// Fourier series (J. W. Spencer, "Fourier series representation of the position of the
/// sun", Search 2(5) 172, 1971).
pub fn eccentricity(day_of_year: u32) -> f64 {
    let g = 2.0 * std::f64::consts::PI * (f64::from(day_of_year) - 1.0) / 365.0;
    1.00011
        + 0.034221 * g.cos()
        + 0.00128 * g.sin()
        + 0.000719 * (2.0 * g).cos()
        + 0.000077 * (2.0 * g).sin()
}

/// Relative optical air mass at zenith angle `z` (radians, ≤ 90°): F. Kasten and A. T.
/// Young, "Revised optical air mass tables and approximation formula", Applied Optics
/// 28(22) 4735–4738, 1989.
pub fn air_mass(z: f64) -> f64 {
    let deg = z.to_degrees().min(90.0);
    1.0 / (deg.to_radians().cos() + 0.50572 * (96.07995 - deg).powf(-1.6364))
}

/// Precipitable water (cm) from the dew point (°C): Perez 1990 after Wright, Perez and
/// Michalsky (1989): W = exp(0.07·T_d − 0.075).
pub fn precipitable_water(dew_point: f64) -> f64 {
    (0.07 * dew_point - 0.075).exp()
}

/// The sky condition of one hour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Condition {
    /// Clearness ε (1 for overcast, about 6 and more for clear skies).
    pub clearness: f64,
    /// Brightness Δ (already floored at 0.01).
    pub brightness: f64,
    /// Category 0…7 of the clearness.
    pub category: usize,
    /// Zenith angle used in the formulas, radians, in [0, π/2].
    pub zenith: f64,
    /// Precipitable water, cm.
    pub water: f64,
}

impl Condition {
    /// The condition from direct-normal `dni` and diffuse-horizontal `dhi` irradiance
    /// (W/m²), the sun's zenith angle (degrees; clamped at 90), the day of the year and
    /// the dew point (°C). `None` when there is no diffuse light (`dhi` ≤ 0): no sky.
    pub fn new(
        dni: f64,
        dhi: f64,
        zenith_deg: f64,
        day_of_year: u32,
        dew_point: f64,
    ) -> Option<Self> {
        if dhi.is_nan() || dhi <= 0.0 {
            return None;
        }
        let z = zenith_deg.clamp(0.0, 90.0).to_radians();
        let k = 1.041 * z.powi(3);
        let clearness = ((dhi + dni.max(0.0)) / dhi + k) / (1.0 + k);
        let e0 = SOLAR_CONSTANT * eccentricity(day_of_year);
        let brightness = (dhi * air_mass(z) / e0).max(0.01);
        let category = CLEARNESS_BOUNDS
            .iter()
            .position(|&b| clearness < b)
            .unwrap_or(CLEARNESS_BOUNDS.len());
        Some(Condition {
            clearness,
            brightness,
            category,
            zenith: z,
            water: precipitable_water(dew_point),
        })
    }

    /// Luminous efficacy of the diffuse light, lm/W.
    pub fn diffuse_efficacy(&self) -> f64 {
        let [a, b, c, d] = DIFFUSE_EFFICACY[self.category];
        a + b * self.water + c * self.zenith.cos() + d * self.brightness.ln()
    }

    /// Luminous efficacy of the direct light, lm/W (never negative).
    pub fn direct_efficacy(&self) -> f64 {
        let [a, b, c, d] = DIRECT_EFFICACY[self.category];
        (a + b * self.water + c * (5.73 * self.zenith - 5.0).exp() + d * self.brightness).max(0.0)
    }

    /// The luminance distribution's coefficients a…e (Perez 1993, eqs. 6–8).
    pub fn distribution(&self) -> [f64; 5] {
        distribution(self.category, self.zenith, self.clearness, self.brightness)
    }
}

/// Coefficients a…e of the all-weather model for a category, the sun's zenith angle `z`
/// (radians), clearness and brightness.
pub fn distribution(category: usize, z: f64, clearness: f64, brightness: f64) -> [f64; 5] {
    let delta = if clearness > 1.065 && clearness < 2.8 {
        brightness.max(0.2)
    } else {
        brightness
    };
    let x = &DISTRIBUTION[category];
    let lin = |k: usize| x[k][0] + x[k][1] * z + delta * (x[k][2] + x[k][3] * z);
    if category == 0 {
        let c = (delta * (x[2][0] + x[2][1] * z)).powf(x[2][2]).exp() - x[2][3];
        let d = -(delta * (x[3][0] + x[3][1] * z)).exp() + x[3][2] + delta * x[3][3];
        [lin(0), lin(1), c, d, lin(4)]
    } else {
        [lin(0), lin(1), lin(2), lin(3), lin(4)]
    }
}

/// The sky of one hour: its shape (relative luminance) and the illuminances the weather
/// gives it.
#[derive(Clone, Debug)]
pub struct PerezSky {
    /// The condition the shape was drawn from.
    pub condition: Condition,
    coefficients: [f64; 5],
    /// Unit vector to the sun used for the shape (east, north, up), on the horizon when
    /// the sun is below it.
    sun: DVec3,
    /// Diffuse horizontal illuminance, lux.
    pub diffuse_horizontal: f64,
    /// Direct normal illuminance, lux (0 with the sun below the horizon).
    pub direct_normal: f64,
}

impl PerezSky {
    /// The sky for irradiances `dni`, `dhi` (W/m²), the sun at `sun` (unit vector, east,
    /// north, up), day of the year and dew point (°C). `None` when the hour has no light
    /// at all (no diffuse irradiance and no direct light from a sun above the horizon).
    /// An hour with direct light but no diffuse gets a dark sky and keeps its sun, with
    /// the clearest category's efficacy.
    pub fn new(dni: f64, dhi: f64, sun: DVec3, day_of_year: u32, dew_point: f64) -> Option<Self> {
        let up = sun.z > 0.0;
        let zenith_deg = sun.z.clamp(-1.0, 1.0).acos().to_degrees();
        let shape_sun = if up {
            sun
        } else {
            let h = DVec3::new(sun.x, sun.y, 0.0);
            if h.length_squared() > 0.0 {
                h.normalize()
            } else {
                DVec3::X
            }
        };
        let condition = match Condition::new(dni, dhi, zenith_deg, day_of_year, dew_point) {
            Some(c) => c,
            // Direct light without diffuse (measured data can say so): the sky is dark,
            // the sun keeps its light with the clearest category's efficacy.
            None if up && dni > 0.0 => Condition {
                clearness: f64::INFINITY,
                brightness: 0.01,
                category: CLEARNESS_BOUNDS.len(),
                zenith: zenith_deg.to_radians(),
                water: precipitable_water(dew_point),
            },
            None => return None,
        };
        let diffuse = if dhi > 0.0 { dhi } else { 0.0 };
        Some(PerezSky {
            coefficients: condition.distribution(),
            sun: shape_sun,
            diffuse_horizontal: diffuse * condition.diffuse_efficacy(),
            direct_normal: if up {
                dni.max(0.0) * condition.direct_efficacy()
            } else {
                0.0
            },
            condition,
        })
    }

    /// Relative luminance towards `dir` (unit vector, upper hemisphere); 0 below the
    /// horizon. Never negative (clamped; see the module's notes).
    pub fn relative(&self, dir: DVec3) -> f64 {
        if dir.z <= 0.0 {
            return 0.0;
        }
        let [a, b, c, d, e] = self.coefficients;
        let cos_g = dir.dot(self.sun).clamp(-1.0, 1.0);
        let gamma = cos_g.acos();
        let gradation = 1.0 + a * (b / dir.z).exp();
        let indicatrix = 1.0 + c * (d * gamma).exp() + e * cos_g * cos_g;
        (gradation * indicatrix).max(0.0)
    }

    /// Global horizontal illuminance, lux: the diffuse plus the direct on the
    /// horizontal.
    pub fn global_horizontal(&self) -> f64 {
        self.diffuse_horizontal + self.direct_normal * self.sun.z.max(0.0)
    }

    /// The direction of the sun the shape was drawn with.
    pub fn sun(&self) -> DVec3 {
        self.sun
    }

    /// The coefficients a…e in use.
    pub fn coefficients(&self) -> [f64; 5] {
        self.coefficients
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clearness_and_brightness_follow_their_definitions() {
        // Sun at 60° zenith on day 172, DNI 600, DHI 100.
        let c = Condition::new(600.0, 100.0, 60.0, 172, 10.0).unwrap();
        let z = 60f64.to_radians();
        let k = 1.041 * z.powi(3);
        assert!((c.clearness - (7.0 + k) / (1.0 + k)).abs() < 1e-12);
        assert_eq!(c.category, 5, "ε = {} lies in [2.8, 4.5)", c.clearness);
        let m = air_mass(z);
        assert!((m - 1.995).abs() < 5e-3, "air mass at 60° is about 2: {m}");
        let e0 = SOLAR_CONSTANT * eccentricity(172);
        assert!((c.brightness - 100.0 * m / e0).abs() < 1e-12);
        // Near aphelion the sun is ~3.3 % weaker than at perihelion.
        assert!((eccentricity(1) / eccentricity(183) - 1.068).abs() < 0.003);
        assert!(Condition::new(500.0, 0.0, 30.0, 100, 5.0).is_none());
    }

    #[test]
    fn a_clear_sky_is_brightest_near_the_sun_and_an_overcast_one_at_the_zenith() {
        // The sun 60° high in the south.
        let sun = DVec3::new(0.0, -(60f64.to_radians().cos()), 60f64.to_radians().sin());
        let clear = PerezSky::new(850.0, 80.0, sun, 172, 10.0).unwrap();
        assert_eq!(clear.condition.category, 7);
        let near = clear.relative((sun + DVec3::new(0.05, 0.0, 0.0)).normalize());
        let away = clear.relative(DVec3::new(0.0, 0.7, 0.7).normalize());
        assert!(near > 5.0 * away, "circumsolar {near} vs opposite {away}");
        // Direct light without diffuse keeps its sun; no light at all is no sky.
        let bare = PerezSky::new(800.0, 0.0, sun, 172, 10.0).unwrap();
        assert_eq!(bare.diffuse_horizontal, 0.0);
        assert!(bare.direct_normal > 800.0 * 90.0, "{}", bare.direct_normal);
        assert!(PerezSky::new(0.0, 0.0, sun, 172, 10.0).is_none());
        assert!(PerezSky::new(800.0, 0.0, -sun, 172, 10.0).is_none());
        let overcast = PerezSky::new(0.0, 150.0, sun, 172, 10.0).unwrap();
        assert_eq!(overcast.condition.category, 0);
        let zen = overcast.relative(DVec3::Z);
        let low = overcast.relative(DVec3::new(0.0, 0.97, 0.25).normalize());
        assert!(zen > 1.5 * low, "overcast zenith {zen} vs low {low}");
        assert_eq!(overcast.relative(DVec3::new(0.0, 1.0, -0.1)), 0.0);
    }
}
