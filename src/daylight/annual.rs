//! Illuminance at sensors for every hour of a weather year: direct light from the sky
//! and the sun plus the light inter-reflected by the scene, by daylight coefficients.
//!
//! For sensor s and hour t (docs/daylight.md, "Sensors across the year"):
//!
//! ```text
//! E_s(t) = Σ_p D_sp L_p(t)                    direct sky and ground, fine dome (MF:4)
//!        + E_bn(t) V_s(t) max(0, n_s · σ(t))   direct sun, exact direction σ(t)
//!        + Σ_q C_sq L'_q(t)                    sky inter-reflected, coarse dome (MF:1)
//!        + E_bn(t) S_s(b(t))                   sun inter-reflected, sun bin b(t)
//! ```
//!
//! with C_sq = Σ_i U_si K_iq and S_s(b) = Σ_i U_si Z_i(b): K_iq the coarse sky
//! coefficients of patch i, Z_i(b) its sunlit cosine for the bin's direction, and U_si
//! the photopic sum over RGB of the adjoint response u = ρ ∘ y of
//! [`crate::solve::solve_adjoint`] (its g the sensor's form factors to the patches). The
//! inter-reflected part is therefore exactly what a forward radiosity solve per hour
//! with first-arrival irradiance E⁰_i(t) = Σ_q K_iq L'_q(t) + E_bn(t) Z_i(b(t)) gives
//! ([`first_arrival`]), at the cost of one solve per sensor instead of one per hour.
//!
//! Suns are binned for the inter-reflected part only: the hours whose sun falls in one
//! patch of the fine dome share the bin's mean direction. The direct sun on a sensor
//! uses each hour's own direction.

use glam::DVec3;

use super::dome::{SkyDome, SkyVector};
use super::perez::PerezSky;
use super::scene::{SceneLight, Sensor};
use super::sun::{days_from_civil, SunPosition};
use super::weather::Weather;
use crate::solve::{solve_adjoint, RowSource, SolveConfig, SolveError};

/// Photopic weights of the RGB channels (ITU-R BT.709 luminance): illuminance from a
/// per-channel result. Daylight is taken as white: the direct terms are the same in
/// every channel and the weights sum to 1.
pub const PHOTOPIC: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The sky of one hour as the annual calculation uses it.
#[derive(Clone, Debug)]
pub struct HourSky {
    /// Month, day, hour (1–24, the hour ending) as in the weather file.
    pub month: u32,
    pub day: u32,
    pub hour: u32,
    /// Unit vector to the sun (east, north, up) at the hour's middle.
    pub sun: DVec3,
    /// The hour's sky (`None`: no light at all). Drawn on the domes only when needed
    /// ([`HourSky::vectors`]), so memory does not grow with the hours beyond the output.
    pub sky: Option<PerezSky>,
}

impl HourSky {
    /// Whether the hour has any light.
    pub fn is_lit(&self) -> bool {
        self.sky.is_some()
    }

    /// Direct normal illuminance, lux (0 with the sun down or no light).
    pub fn direct_normal(&self) -> f64 {
        self.sky.as_ref().map_or(0.0, |s| s.direct_normal)
    }

    /// The sky on the fine and on the coarse dome, with the ground for reflectance
    /// `ground` (`None`: no sky this hour).
    pub fn vectors(&self, domes: &Domes, ground: f64) -> Option<(SkyVector, SkyVector)> {
        self.sky.as_ref().map(|s| {
            (
                domes.fine.sky_vector(s, ground),
                domes.coarse.sky_vector(s, ground),
            )
        })
    }
}

/// The domes of an annual calculation.
pub struct Domes {
    /// For the sensors' direct view of the sky and for sun bins.
    pub fine: SkyDome,
    /// For the patches' first-arrival light (inter-reflection).
    pub coarse: SkyDome,
}

impl Default for Domes {
    fn default() -> Self {
        Domes {
            fine: SkyDome::reinhart(4, 2),
            coarse: SkyDome::reinhart(1, 4),
        }
    }
}

/// Day of the year (1-based) of a month and day in `year`.
pub fn day_of_year(year: i32, month: u32, day: u32) -> u32 {
    (days_from_civil(year, month, day) - days_from_civil(year, 1, 1) + 1) as u32
}

/// Every hour's sun and sky from the weather, the sun computed for `year` (weather files
/// mix years; any non-leap year gives the typical year's geometry).
///
/// # Errors
/// A sun position that cannot be computed (a bad site in the file).
pub fn hour_skies(w: &Weather, year: i32) -> Result<Vec<HourSky>, super::SunError> {
    w.hours
        .iter()
        .map(|h| {
            let sun = SunPosition::at(&w.site, h.mid(year))?.enu();
            let doy = day_of_year(year, h.month, h.day);
            Ok(HourSky {
                month: h.month,
                day: h.day,
                hour: h.hour,
                sun,
                sky: PerezSky::new(h.dni, h.dhi, sun, doy, h.dew_point),
            })
        })
        .collect()
}

/// Sun bins of the lit hours: per hour the bin (or `None` with no direct light), and per
/// bin its mean direction.
pub fn sun_bins(hours: &[HourSky], fine: &SkyDome) -> (Vec<Option<usize>>, Vec<DVec3>) {
    let mut sum: Vec<DVec3> = Vec::new();
    let mut slot = vec![usize::MAX; fine.len()];
    let of_hour = hours
        .iter()
        .map(|h| {
            if h.direct_normal() <= 0.0 {
                return None;
            }
            let p = fine.find(h.sun)?;
            if slot[p] == usize::MAX {
                slot[p] = sum.len();
                sum.push(DVec3::ZERO);
            }
            sum[slot[p]] += h.sun;
            Some(slot[p])
        })
        .collect();
    (of_hour, sum.into_iter().map(DVec3::normalize).collect())
}

/// What the patches receive first, before any reflection, for every bin and the sky:
/// computed once per scene.
pub struct PatchLight {
    /// Coarse sky coefficients, `n × (coarse.len() + 1)`.
    pub sky: Vec<f32>,
    pub width: usize,
    /// Per sun bin, per patch: sunlit cosine.
    pub sun: Vec<Vec<f32>>,
    /// Per hour: its sun bin.
    pub bin_of_hour: Vec<Option<usize>>,
}

impl PatchLight {
    pub fn new(light: &SceneLight<'_>, domes: &Domes, hours: &[HourSky]) -> Self {
        let (bin_of_hour, dirs) = sun_bins(hours, &domes.fine);
        PatchLight {
            sky: light.patch_sky(&domes.coarse),
            width: domes.coarse.len() + 1,
            sun: dirs.iter().map(|&d| light.patch_sun(d)).collect(),
            bin_of_hour,
        }
    }
}

/// First-arrival illuminance E⁰_i (lux) of every patch in hour `t`: the right-hand side of
/// a forward solve for that hour (used to check the adjoint route, and for pictures).
pub fn first_arrival(
    pl: &PatchLight,
    hours: &[HourSky],
    t: usize,
    domes: &Domes,
    ground: f64,
) -> Vec<f64> {
    let n = pl.sky.len() / pl.width;
    let h = &hours[t];
    let coarse = h.sky.as_ref().map(|s| domes.coarse.sky_vector(s, ground));
    (0..n)
        .map(|i| {
            let mut e = 0.0;
            if let Some(v) = &coarse {
                let row = &pl.sky[i * pl.width..(i + 1) * pl.width];
                e += row
                    .iter()
                    .zip(&v.luminance)
                    .map(|(&c, l)| f64::from(c) * l)
                    .sum::<f64>();
            }
            if let Some(b) = pl.bin_of_hour[t] {
                e += h.direct_normal() * f64::from(pl.sun[b][i]);
            }
            e
        })
        .collect()
}

/// Everything a sensor needs per hour, after the scene's work is done.
pub struct SensorModel {
    /// Direct sky coefficients on the fine dome (ground last), with visibility.
    pub direct_sky: Vec<f64>,
    /// Inter-reflected sky coefficients on the coarse dome (ground last).
    pub reflected_sky: Vec<f64>,
    /// Inter-reflected sun per bin, per lux of direct normal illuminance.
    pub reflected_sun: Vec<f64>,
    /// The sensor itself (for its direct sun).
    pub sensor: Sensor,
}

/// Build the sensors' models: their direct views and the adjoint solve over the
/// form-factor rows in `src` (the same patches as `light`).
///
/// # Errors
/// The adjoint solve's errors (missing rows, bad reflectance...).
pub fn sensor_models(
    light: &SceneLight<'_>,
    domes: &Domes,
    pl: &PatchLight,
    sensors: &[Sensor],
    src: &dyn RowSource,
    cfg: &SolveConfig,
) -> Result<Vec<SensorModel>, SolveError> {
    let g: Vec<Vec<f32>> = sensors
        .iter()
        .map(|s| light.sensor_form_factors(s))
        .collect();
    let rho: Vec<[f32; 3]> = light.patches.patches.iter().map(|p| p.rho).collect();
    let adj = solve_adjoint(src, &g, &rho, cfg)?;
    if !adj.converged {
        return Err(SolveError::InvalidInput(format!(
            "the sensors' adjoint solve stopped after {} sweeps at relative change {:.2e}, \
             above the tolerance {:e}",
            adj.iterations, adj.residual, cfg.tolerance
        )));
    }
    // Each sensor's view of the sky is one ray per cell: spread the sensors over the
    // threads (the form factors above are spread over the patches).
    let direct = super::scene::par_map(sensors.len(), light.threads, |k| {
        light.sensor_sky(&sensors[k], &domes.fine)
    });
    Ok(sensors
        .iter()
        .zip(&adj.u)
        .zip(direct)
        .map(|((s, u), direct_sky)| {
            let big_u: Vec<f64> = u
                .iter()
                .map(|c| c.iter().zip(PHOTOPIC).map(|(x, w)| x * w).sum())
                .collect();
            let mut reflected_sky = vec![0.0; pl.width];
            for (i, &ui) in big_u.iter().enumerate() {
                if ui == 0.0 {
                    continue;
                }
                let row = &pl.sky[i * pl.width..(i + 1) * pl.width];
                for (r, &c) in reflected_sky.iter_mut().zip(row) {
                    *r += ui * f64::from(c);
                }
            }
            let reflected_sun = pl
                .sun
                .iter()
                .map(|z| z.iter().zip(&big_u).map(|(&z, u)| f64::from(z) * u).sum())
                .collect();
            SensorModel {
                direct_sky,
                reflected_sky,
                reflected_sun,
                sensor: s.clone(),
            }
        })
        .collect())
}

/// A sensor's illuminance (lux) in every hour, split into its four parts (direct sky,
/// direct sun, inter-reflected sky, inter-reflected sun) and summed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Series {
    pub total: Vec<f64>,
    pub direct_sky: Vec<f64>,
    pub direct_sun: Vec<f64>,
    pub reflected: Vec<f64>,
}

/// Every sensor's hourly illuminance. Hours are spread over `threads` threads; each
/// hour's sky is drawn once for all sensors and dropped.
pub fn series(
    models: &[SensorModel],
    light: &SceneLight<'_>,
    hours: &[HourSky],
    bin_of_hour: &[Option<usize>],
    domes: &Domes,
    ground: f64,
) -> Vec<Series> {
    let dot = |c: &[f64], v: &SkyVector| c.iter().zip(&v.luminance).map(|(c, l)| c * l).sum();
    let per_hour: Vec<Vec<[f64; 3]>> = super::scene::par_map(hours.len(), light.threads, |t| {
        let h = &hours[t];
        let Some((fine, coarse)) = h.vectors(domes, ground) else {
            return vec![[0.0; 3]; models.len()];
        };
        let e_bn = h.direct_normal();
        models
            .iter()
            .map(|m| {
                let sky: f64 = dot(&m.direct_sky, &fine);
                let sun = if e_bn > 0.0 {
                    e_bn * light.sensor_sun(&m.sensor, h.sun)
                } else {
                    0.0
                };
                let mut refl: f64 = dot(&m.reflected_sky, &coarse);
                if let Some(b) = bin_of_hour[t] {
                    refl += e_bn * m.reflected_sun[b];
                }
                [sky, sun, refl]
            })
            .collect()
    });
    (0..models.len())
        .map(|k| {
            let mut s = Series::default();
            for h in &per_hour {
                let [sky, sun, refl] = h[k];
                s.direct_sky.push(sky);
                s.direct_sun.push(sun);
                s.reflected.push(refl);
                s.total.push(sky + sun + refl);
            }
            s
        })
        .collect()
}

/// Why an annual calculation stopped.
#[derive(Debug, thiserror::Error)]
pub enum AnnualError {
    #[error(transparent)]
    Sun(#[from] super::SunError),
    #[error(transparent)]
    Solve(#[from] SolveError),
}

/// The hours and every sensor's series.
pub struct AnnualResult {
    pub hours: Vec<HourSky>,
    pub series: Vec<Series>,
    /// Sun bins used for the inter-reflected sun.
    pub sun_positions: usize,
}

/// The whole calculation for `sensors` in the scene `light` over the weather year `w`
/// (sun for `year`, ground reflectance `ground`), the form factors from `src`; `progress`
/// hears a line after each stage.
///
/// # Errors
/// A sun position that cannot be computed; the adjoint solve's errors.
#[allow(clippy::too_many_arguments)]
pub fn sensors_over_year(
    light: &SceneLight<'_>,
    w: &Weather,
    year: i32,
    ground: f64,
    sensors: &[Sensor],
    src: &dyn RowSource,
    cfg: &SolveConfig,
    progress: &mut dyn FnMut(String),
) -> Result<AnnualResult, AnnualError> {
    let domes = Domes::default();
    let hours = hour_skies(w, year)?;
    let lit = hours.iter().filter(|h| h.is_lit()).count();
    progress(format!(
        "{} hours, {lit} with daylight: suns and sky conditions",
        hours.len()
    ));
    let pl = PatchLight::new(light, &domes, &hours);
    progress(format!(
        "{} patches' views of {} sky patches, the ground and {} sun positions",
        light.patches.len(),
        domes.coarse.len(),
        pl.sun.len()
    ));
    let models = sensor_models(light, &domes, &pl, sensors, src, cfg)?;
    progress(format!(
        "{} sensors' views and inter-reflection (adjoint solve)",
        sensors.len()
    ));
    let series = series(&models, light, &hours, &pl.bin_of_hour, &domes, ground);
    progress(format!("{} hours at every sensor", hours.len()));
    Ok(AnnualResult {
        hours,
        series,
        sun_positions: pl.sun.len(),
    })
}
