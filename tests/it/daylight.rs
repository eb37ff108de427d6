//! Daylight from a real weather year (NREL's TMY3 for Greensboro, NC, shipped in
//! tests/data/weather): the Perez sky drawn on the dome against what the weather file
//! says a horizontal and a vertical plane receive.

use std::path::Path;

use ffstream::daylight::{
    dome::SkyDome,
    perez::{self, PerezSky},
    sun::{days_from_civil, SunPosition},
    weather,
};
use glam::DVec3;

/// The year the sun is computed for (TMY months come from different years; any
/// non-leap year serves).
const YEAR: i32 = 2005;

fn greensboro() -> weather::Weather {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/weather/723170TYA.CSV.zst");
    weather::read(&p).expect("the shipped TMY3 file reads")
}

/// One daylight hour: the sun, the sky, and the file's own values.
struct Lit {
    sun: DVec3,
    sky: PerezSky,
    dni: f64,
    dhi: f64,
    doy: u32,
}

fn lit_hours(w: &weather::Weather) -> Vec<Lit> {
    let jan1 = days_from_civil(YEAR, 1, 1);
    w.hours
        .iter()
        .filter_map(|h| {
            let sun = SunPosition::at(&w.site, h.mid(YEAR)).unwrap().enu();
            let doy = (days_from_civil(YEAR, h.month, h.day) - jan1 + 1) as u32;
            PerezSky::new(h.dni, h.dhi, sun, doy, h.dew_point).map(|sky| Lit {
                sun,
                sky,
                dni: h.dni,
                dhi: h.dhi,
                doy,
            })
        })
        .collect()
}

/// Perez's 1990 transposition of diffuse irradiance onto a tilted plane (Perez et al.,
/// Solar Energy 44(5) 271–289, 1990; coefficients "all sites composite 1990"), written
/// here independently of the all-weather luminance model the dome draws: circumsolar
/// and horizon-band terms on an isotropic background.
fn perez_1990_diffuse_on_plane(n: DVec3, sun: DVec3, dni: f64, dhi: f64, doy: u32) -> f64 {
    const F: [[f64; 6]; 8] = [
        [0.011, 0.570, -0.081, -0.095, 0.158, -0.018],
        [0.429, 0.363, -0.307, 0.050, 0.008, -0.065],
        [0.809, -0.054, -0.442, 0.181, -0.169, -0.092],
        [1.014, -0.252, -0.531, 0.275, -0.350, -0.096],
        [1.282, -0.420, -0.689, 0.380, -0.559, -0.114],
        [1.426, -0.653, -0.779, 0.425, -0.785, -0.097],
        [1.485, -1.214, -0.784, 0.411, -0.629, -0.082],
        [1.170, -0.300, -0.615, 0.518, -1.892, -0.055],
    ];
    let z = sun
        .z
        .clamp(-1.0, 1.0)
        .acos()
        .min(std::f64::consts::FRAC_PI_2);
    let k = 1.041 * z.powi(3);
    let eps = ((dhi + dni) / dhi + k) / (1.0 + k);
    let bin = [1.065, 1.230, 1.500, 1.950, 2.800, 4.500, 6.200]
        .iter()
        .position(|&b| eps < b)
        .unwrap_or(7);
    let delta = dhi * perez::air_mass(z) / (perez::SOLAR_CONSTANT * perez::eccentricity(doy));
    let f = F[bin];
    let f1 = (f[0] + f[1] * delta + f[2] * z).max(0.0);
    let f2 = f[3] + f[4] * delta + f[5] * z;
    let a = n.dot(sun).max(0.0);
    let b = z.cos().max(85f64.to_radians().cos());
    let tilt_cos = n.z;
    let tilt_sin = (1.0 - tilt_cos * tilt_cos).max(0.0).sqrt();
    dhi * ((1.0 - f1) * (1.0 + tilt_cos) / 2.0 + f1 * a / b + f2 * tilt_sin)
}

/// The dome the annual command uses by default: Reinhart MF:4 (2305 patches), 2 × 2 cells.
fn dome() -> SkyDome {
    SkyDome::reinhart(4, 2)
}

/// Issue 22's acceptance: a horizontal sensor under an unobstructed sky receives, hour by
/// hour, (DNI·cos z)·K_direct + DHI·K_diffuse within 0.5 %: the sky drawn on the dome's
/// patches loses nothing of the diffuse light the weather file gives.
///
/// Hours whose midpoint finds the sun below the horizon (twilight: diffuse light only)
/// are held to 1 %: the Perez model is drawn for them with the sun on the horizon, where
/// its circumsolar peak sits on the lowest band of patches and the patch mean differs
/// most from the cosine-weighted mean (0.64 % in the worst such hour of this file at
/// MF:4 on 4 × 4 cells; every hour with the sun up is within 0.26 %).
#[test]
fn horizontal_illuminance_is_the_weathers_irradiance_times_perez_efficacy() {
    let w = greensboro();
    let dome = dome();
    let up = dome.coefficients(DVec3::Z);
    let hours = lit_hours(&w);
    assert!(hours.len() > 4000, "{} lit hours", hours.len());
    let (mut worst_up, mut worst_twilight): (f64, f64) = (0.0, 0.0);
    for h in &hours {
        let v = dome.sky_vector(&h.sky, 0.2);
        assert_eq!(up[dome.len()], 0.0, "a horizontal sensor sees no ground");
        let sky: f64 = up.iter().zip(&v.luminance).map(|(c, l)| c * l).sum();
        let e = sky + h.sky.direct_normal * h.sun.z.max(0.0);
        let c = h.sky.condition;
        let direct = if h.sun.z > 0.0 {
            h.dni * c.direct_efficacy() * h.sun.z
        } else {
            0.0
        };
        let expected = h.dhi * c.diffuse_efficacy() + direct;
        let rel = (e - expected).abs() / expected;
        let (limit, worst) = if h.sun.z > 0.0 {
            (5e-3, &mut worst_up)
        } else {
            (1e-2, &mut worst_twilight)
        };
        *worst = worst.max(rel);
        assert!(
            rel <= limit,
            "E = {e} lx, expected {expected} lx (sky {sky}, sun z {}, {c:?})",
            h.sun.z
        );
    }
    eprintln!(
        "horizontal: worst relative difference {worst_up:.2e} with the sun up, \
         {worst_twilight:.2e} in twilight, over {} hours",
        hours.len()
    );
}

/// Issue 22's acceptance: a vertical sensor against an independent Perez transposition
/// (the 1990 tilted-surface model with its illuminance coefficients, a different model
/// from the 1993 luminance distribution the dome draws). The annual sky-diffuse
/// illuminance of vertical planes facing east, south and west agrees within 2 %. Hour by
/// hour the two models differ by up to a quarter (p5…p95 printed); facing north the
/// all-weather model gives about 5.6 % more over the year (docs/daylight.md), so north
/// is checked only for what both models must agree on: it receives the least.
#[test]
fn vertical_planes_receive_what_perez_transposition_gives() {
    let w = greensboro();
    let dome = dome();
    let hours = lit_hours(&w);
    let skies: Vec<_> = hours.iter().map(|h| dome.sky_vector(&h.sky, 0.2)).collect();
    let mut annual = Vec::new();
    for (name, n) in [
        ("north", DVec3::Y),
        ("east", DVec3::X),
        ("south", -DVec3::Y),
        ("west", -DVec3::X),
    ] {
        let c = dome.coefficients(n);
        let sky_only = &c[..dome.len()];
        let (mut ours, mut theirs) = (0.0, 0.0);
        let mut rels = Vec::new();
        for (h, v) in hours.iter().zip(&skies) {
            let e: f64 = sky_only.iter().zip(&v.luminance).map(|(c, l)| c * l).sum();
            let t = h.sky.condition.diffuse_efficacy()
                * perez_1990_diffuse_on_plane(n, h.sun, h.dni, h.dhi, h.doy);
            ours += e;
            theirs += t;
            if t > 1000.0 {
                rels.push(e / t - 1.0);
            }
        }
        rels.sort_by(f64::total_cmp);
        let q = |p: f64| 100.0 * rels[((rels.len() - 1) as f64 * p) as usize];
        let diff = ours / theirs - 1.0;
        eprintln!(
            "{name}: annual sky diffuse {ours:.4e} vs transposition {theirs:.4e} lx·h \
             ({:+.2} %); hourly p5 {:+.1} % median {:+.1} % p95 {:+.1} %",
            100.0 * diff,
            q(0.05),
            q(0.5),
            q(0.95)
        );
        if name != "north" {
            assert!(diff.abs() <= 0.02, "{name}: {:+.2} %", 100.0 * diff);
        }
        annual.push((ours, theirs));
    }
    for k in 1..4 {
        assert!(annual[0].0 < annual[k].0 && annual[0].1 < annual[k].1);
    }
}

/// An independent check of the efficacies: the TMY3 file carries NREL's own global
/// horizontal illuminance per hour (in units of 100 lx) with an uncertainty column (±%
/// of the value, 8–25 % in this file; the TMY3 manual's "uncertainty" fields). Ours, from the file's irradiance through Perez's
/// efficacy models, must fall within that interval (plus half the file's rounding) in
/// at least 95 % of the hours with the sun up. (The file's direct and diffuse
/// illuminance columns are split differently from Perez's 1990 models, −4.3 % and
/// +8.3 % over the year against ours, and are not used; docs/daylight.md.)
#[test]
fn global_illuminance_is_within_the_uncertainty_the_weather_file_states() {
    use std::io::Read;
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/weather/723170TYA.CSV.zst");
    let mut text = String::new();
    zstd::Decoder::new(std::fs::File::open(&p).unwrap())
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    let mut lines = text.lines().skip(1);
    let names: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| names.iter().position(|n| *n == name).unwrap();
    let (c_gh, c_unc) = (col("GH illum (lx)"), col("Global illum uncert (%)"));
    let w = greensboro();
    let jan1 = days_from_civil(YEAR, 1, 1);
    let (mut inside, mut up, mut ours_sum, mut file_sum) = (0usize, 0usize, 0.0, 0.0);
    for (line, h) in lines.zip(&w.hours) {
        let f: Vec<&str> = line.split(',').collect();
        let file = f[c_gh].parse::<f64>().unwrap() * 100.0;
        let unc = f[c_unc].parse::<f64>().unwrap() / 100.0;
        let sun = SunPosition::at(&w.site, h.mid(YEAR)).unwrap().enu();
        let doy = (days_from_civil(YEAR, h.month, h.day) - jan1 + 1) as u32;
        let Some(sky) = PerezSky::new(h.dni, h.dhi, sun, doy, h.dew_point) else {
            continue;
        };
        if sun.z <= 0.0 || file <= 0.0 {
            continue;
        }
        let ours = sky.global_horizontal();
        up += 1;
        ours_sum += ours;
        file_sum += file;
        if (ours - file).abs() <= unc * file + 50.0 {
            inside += 1;
        }
    }
    eprintln!(
        "global horizontal illuminance: {inside} of {up} sun-up hours within the file's \
         uncertainty; annual {:+.2} % against the file",
        100.0 * (ours_sum / file_sum - 1.0)
    );
    assert!(up > 4000);
    assert!(inside as f64 >= 0.95 * up as f64, "{inside} of {up}");
}
