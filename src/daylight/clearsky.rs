//! A clear year when no weather file is given: every hour's direct-normal and
//! diffuse-horizontal irradiance from the clear-sky model of Ineichen and Perez, which
//! then drive the same Perez sky as measured weather does (docs/daylight.md, "Clear sky").
//!
//! P. Ineichen and R. Perez, "A new airmass independent formulation for the Linke
//! turbidity coefficient", Solar Energy 73(3) 151–157, 2002: global horizontal
//! irradiance from the Linke turbidity T_L, the site's elevation and the air mass, and a
//! beam (direct-normal) irradiance bounded so that the diffuse part never turns negative.
//! As pvlib does by default, the paper's extra factor exp(0.01·AM^1.8) (a fit to Perez's
//! own model at low sun) is left out: with it the global irradiance rises again near the
//! horizon. The air mass is Kasten and Young's at the sun's apparent (refracted) zenith,
//! scaled by the site's standard-atmosphere pressure.

use super::perez::{air_mass, eccentricity, SOLAR_CONSTANT};
use super::sun::{days_in_month, LocalTime, Site, SunError, SunPosition};
use super::weather::{Hour, Weather};

/// Linke turbidity used when none is given: a clean to average mid-latitude sky
/// (about 2 in mountain air, 3–4 over European and US lowlands, 5–7 in hazy cities).
pub const DEFAULT_LINKE: f64 = 3.0;

/// Dew point (°C) of a clear year, for the Perez efficacies' precipitable water
/// (10 °C: 1.9 cm of water; the efficacies change by about 1 % per 5 °C).
pub const DEFAULT_DEW_POINT: f64 = 10.0;

/// Irradiances of one clear hour, W/m².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClearHour {
    pub ghi: f64,
    pub dni: f64,
    pub dhi: f64,
}

/// Station pressure (mbar) at `elevation` metres in the ICAO standard atmosphere
/// (1013.25 mbar and 15 °C at sea level, 6.5 K/km lapse rate).
pub fn standard_pressure(elevation: f64) -> f64 {
    1013.25 * (1.0 - 2.25577e-5 * elevation).max(0.0).powf(5.25588)
}

/// The clear-sky irradiances for the sun at apparent zenith `zenith` (degrees) on day
/// `day_of_year`, at `elevation` metres where the pressure is `pressure` mbar (usually
/// [`standard_pressure`]), Linke turbidity `linke`. Zero with the sun at or below the
/// horizon.
pub fn ineichen(
    zenith: f64,
    elevation: f64,
    pressure: f64,
    linke: f64,
    day_of_year: u32,
) -> ClearHour {
    let cos_z = zenith.to_radians().cos();
    if !(zenith < 90.0 && cos_z > 0.0) {
        return ClearHour {
            ghi: 0.0,
            dni: 0.0,
            dhi: 0.0,
        };
    }
    let am = air_mass(zenith.to_radians()) * pressure / 1013.25;
    let i0 = SOLAR_CONSTANT * eccentricity(day_of_year);
    let h = elevation;
    let (fh1, fh2) = ((-h / 8000.0).exp(), (-h / 1250.0).exp());
    let (cg1, cg2) = (5.09e-5 * h + 0.868, 3.92e-5 * h + 0.0387);
    let ghi = cg1 * i0 * cos_z * (-cg2 * am * (fh1 + fh2 * (linke - 1.0))).exp();
    // Beam: the paper's b = 0.664 + 0.163 / fh1, bounded by the share of the global
    // irradiance that the paper's empirical correction allows as beam.
    let beam = (0.664 + 0.163 / fh1) * i0 * (-0.09 * am * (linke - 1.0)).exp();
    let share = (1.0 - (0.1 - 0.2 * (-linke).exp()) / (0.1 + 0.882 / fh1)) / cos_z;
    let dni = beam.max(0.0).min(ghi * share.max(0.0));
    ClearHour {
        ghi,
        dni,
        dhi: ghi - dni * cos_z,
    }
}

/// Every hour of `year` at `site` under a clear sky of Linke turbidity `linke`, as a
/// weather year: hours 1–24 of every day (the sun at each hour's middle, as for weather
/// files), the dew point [`DEFAULT_DEW_POINT`] and the site's standard pressure.
///
/// # Errors
/// A sun position that cannot be computed (a bad site).
pub fn clear_year(site: &Site, year: i32, linke: f64) -> Result<Weather, SunError> {
    site.check()?;
    if !(linke.is_finite() && linke >= 1.0) {
        return Err(SunError::Site(format!(
            "Linke turbidity {linke}: expected a number ≥ 1 (1 is a dry, clean atmosphere)"
        )));
    }
    let pressure = standard_pressure(site.elevation);
    let mut hours = Vec::with_capacity(8784);
    for month in 1..=12 {
        for day in 1..=days_in_month(year, month) {
            for hour in 1..=24 {
                let mid = LocalTime {
                    year,
                    month,
                    day,
                    hour: hour - 1,
                    minute: 30,
                    second: 0.0,
                };
                let sun = SunPosition::at(site, mid)?;
                let doy = super::annual::day_of_year(year, month, day);
                let c = ineichen(sun.zenith, site.elevation, pressure, linke, doy);
                hours.push(Hour {
                    month,
                    day,
                    hour,
                    ghi: c.ghi,
                    dni: c.dni,
                    dhi: c.dhi,
                    dew_point: DEFAULT_DEW_POINT,
                    pressure,
                    line: 0,
                });
            }
        }
    }
    Ok(Weather {
        site: site.clone(),
        name: format!("clear sky (Linke turbidity {})", crate::brief_number(linke)),
        hours,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// pvlib 0.16.1 (an independent implementation), printed by
    /// tests/reference/clearsky_pvlib.py: apparent zenith (°), elevation (m), pressure
    /// (mbar, pvlib's standard atmosphere), Linke turbidity, day of the year → GHI, DNI,
    /// DHI (W/m²), with the solar constant 1367 and Spencer's eccentricity as here.
    #[allow(clippy::type_complexity)]
    const PVLIB: [(f64, f64, f64, f64, u32, [f64; 3]); 6] = [
        (
            0.0,
            0.0,
            1.013249987e+03,
            3.0,
            172,
            [1.022130774e+03, 9.135847136e+02, 1.085460608e+02],
        ),
        (
            30.0,
            0.0,
            1.013249987e+03,
            3.0,
            1,
            [9.302380064e+02, 9.506580111e+02, 1.069440185e+02],
        ),
        (
            60.0,
            1500.0,
            8.455626234e+02,
            2.0,
            80,
            [5.415538651e+02, 1.015237150e+03, 3.393529025e+01],
        ),
        (
            75.0,
            300.0,
            9.777263408e+02,
            4.5,
            200,
            [1.516644363e+02, 3.458407488e+02, 6.215426391e+01],
        ),
        (
            85.0,
            0.0,
            1.013249987e+03,
            3.0,
            355,
            [3.232361780e+01, 1.828981977e+02, 1.638298953e+01],
        ),
        (
            89.5,
            3000.0,
            7.010898819e+02,
            6.0,
            300,
            [2.577643973e-01, 7.193985296e-02, 2.571366116e-01],
        ),
    ];

    #[test]
    fn ineichen_agrees_with_pvlib() {
        for (z, h, p, tl, doy, want) in PVLIB {
            let c = ineichen(z, h, p, tl, doy);
            for (got, want) in [c.ghi, c.dni, c.dhi].into_iter().zip(want) {
                // The same formulas; the references are printed to 10 digits.
                assert!(
                    (got - want).abs() <= 1e-8 * want,
                    "z {z} h {h} TL {tl}: {got} vs {want}"
                );
            }
            // The standard atmosphere, written with rounded constants here and in pvlib.
            assert!(
                (standard_pressure(h) - p).abs() <= 1e-5 * p,
                "{h} m: {p} mbar"
            );
        }
    }

    #[test]
    fn a_clear_year_closes_and_stays_below_the_extraterrestrial_light() {
        let site = Site::new(36.1, -79.9, -5.0, 270.0);
        let w = clear_year(&site, 2005, DEFAULT_LINKE).unwrap();
        assert_eq!(w.hours.len(), 8760);
        assert_eq!(clear_year(&site, 2004, 3.0).unwrap().hours.len(), 8784);
        let mut lit = 0;
        for (k, h) in w.hours.iter().enumerate() {
            let sun = SunPosition::at(&site, h.mid(2005)).unwrap();
            let cos_z = sun.zenith.to_radians().cos();
            if sun.zenith >= 90.0 {
                assert_eq!([h.ghi, h.dni, h.dhi], [0.0; 3], "hour {k}");
                continue;
            }
            lit += 1;
            assert!(h.dhi >= 0.0 && h.dni >= 0.0, "hour {k}: {h:?}");
            assert!((h.dni * cos_z + h.dhi - h.ghi).abs() <= 1e-9 * h.ghi.max(1.0));
            assert!(h.dni < SOLAR_CONSTANT * 1.035 && h.ghi <= SOLAR_CONSTANT * 1.035 * cos_z);
        }
        // About half the hours of a year have the sun up.
        assert!((4300..4500).contains(&lit), "{lit}");
        // Turbidity dims the beam and brightens the diffuse light.
        let (a, b) = (
            ineichen(40.0, 0.0, 1013.25, 2.0, 100),
            ineichen(40.0, 0.0, 1013.25, 5.0, 100),
        );
        assert!(b.dni < a.dni && b.dhi > a.dhi);
        assert!(clear_year(&site, 2005, 0.5).is_err());
    }
}
