//! The sun's position by NREL's Solar Position Algorithm (Reda & Andreas 2003, Solar
//! Energy 76(5) 577–589; uncertainty ±0.0003° for the years −2000 to 6000), computed by
//! the `solar-positioning` crate (an implementation of the paper, validated there
//! against NREL's reference tables). What this module adds: the place and the clock as
//! lighting people give them (latitude, longitude, a time zone in hours from UTC, local
//! *standard* time as weather files use it, no daylight saving), the conversion to UTC
//! across day, month and year boundaries, and the direction of the sun as a unit vector
//! in east–north–up coordinates.
//!
//! Conventions: latitude north positive, longitude east positive (degrees); azimuth from
//! north, clockwise (east 90°, south 180°); zenith angle from the vertical, topocentric,
//! corrected for refraction when [`Site::refraction`] holds the air's pressure and
//! temperature.

use glam::DVec3;
use solar_positioning::{spa, time::JulianDate, RefractionCorrection};

/// Why a sun position could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SunError {
    /// A coordinate, time zone or elevation out of range or not finite.
    #[error("site: {0}")]
    Site(String),
    /// A date or time that does not exist.
    #[error("time {0}: not a valid date and time")]
    Time(String),
    /// The algorithm refused the input (outside −2000…6000, say).
    #[error("solar position: {0}")]
    Algorithm(String),
}

/// A place on the Earth.
#[derive(Clone, Debug, PartialEq)]
pub struct Site {
    /// Degrees, north positive, in [−90, 90].
    pub latitude: f64,
    /// Degrees, east positive, in [−180, 180].
    pub longitude: f64,
    /// Hours from UTC of the local standard time (−7 for US Mountain time), in [−14, 14].
    pub time_zone: f64,
    /// Metres above sea level.
    pub elevation: f64,
    /// Annual mean air pressure (millibar) and temperature (°C) for the refraction
    /// correction; `None` gives the geometric (unrefracted) position.
    pub refraction: Option<(f64, f64)>,
    /// ΔT = TT − UT1 in seconds (about 69 s in the 2020s).
    pub delta_t: f64,
}

impl Site {
    /// A site with standard air (1013.25 mbar, 12 °C, as NREL's and pvlib's defaults
    /// are) and ΔT = 69 s.
    pub fn new(latitude: f64, longitude: f64, time_zone: f64, elevation: f64) -> Self {
        Site {
            latitude,
            longitude,
            time_zone,
            elevation,
            refraction: Some((1013.25, 12.0)),
            delta_t: 69.0,
        }
    }

    /// Check the site's numbers (ranges, finiteness), naming the bad field.
    ///
    /// # Errors
    /// [`SunError::Site`].
    pub fn check(&self) -> Result<(), SunError> {
        let bad = |what: &str, v: f64| SunError::Site(format!("{what} {v} is out of range"));
        let finite = [
            self.latitude,
            self.longitude,
            self.time_zone,
            self.elevation,
            self.delta_t,
        ];
        if finite.iter().any(|v| !v.is_finite()) {
            return Err(SunError::Site(format!("not a finite number in {finite:?}")));
        }
        if !(-90.0..=90.0).contains(&self.latitude) {
            return Err(bad("latitude", self.latitude));
        }
        if !(-180.0..=180.0).contains(&self.longitude) {
            return Err(bad("longitude", self.longitude));
        }
        if !(-14.0..=14.0).contains(&self.time_zone) {
            return Err(bad("time zone", self.time_zone));
        }
        Ok(())
    }
}

/// A local standard time (no daylight saving), as weather files give it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalTime {
    pub year: i32,
    pub month: u32,
    pub day: u32,
    pub hour: u32,
    pub minute: u32,
    pub second: f64,
}

impl LocalTime {
    /// The same instant in UTC, `zone` hours behind this clock: (year, month, day,
    /// hour, minute, second). Crosses day, month and year boundaries (the time zone may
    /// be fractional, e.g. +5.5).
    fn to_utc(self, zone: f64) -> Result<(i32, u32, u32, u32, u32, f64), SunError> {
        let valid = (1..=12).contains(&self.month)
            && self.day >= 1
            && self.day <= days_in_month(self.year, self.month)
            && self.hour < 24
            && self.minute < 60
            && (0.0..60.0).contains(&self.second);
        if !valid {
            return Err(SunError::Time(format!("{self:?}")));
        }
        let secs = days_from_civil(self.year, self.month, self.day) as f64 * 86_400.0
            + f64::from(self.hour * 3600 + self.minute * 60)
            + self.second
            - zone * 3600.0;
        let days = (secs / 86_400.0).floor();
        let rest = secs - days * 86_400.0;
        let (y, m, d) = civil_from_days(days as i64);
        let whole = rest.floor();
        let (h, min) = ((whole as u32) / 3600, (whole as u32 % 3600) / 60);
        Ok((y, m, d, h, min, rest - f64::from(h * 3600 + min * 60)))
    }
}

/// Where the sun is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunPosition {
    /// Topocentric zenith angle, degrees (refracted when the site asks for it).
    pub zenith: f64,
    /// Azimuth from north, clockwise, degrees in [0, 360).
    pub azimuth: f64,
}

impl SunPosition {
    /// The position at `site` and local standard time `t`.
    pub fn at(site: &Site, t: LocalTime) -> Result<Self, SunError> {
        site.check()?;
        let (y, mo, d, h, mi, s) = t.to_utc(site.time_zone)?;
        let algo = |e: solar_positioning::Error| SunError::Algorithm(e.to_string());
        let jd = JulianDate::from_utc(y, mo, d, h, mi, s, site.delta_t).map_err(algo)?;
        let refraction = match site.refraction {
            Some((p, temp)) => Some(RefractionCorrection::new(p, temp).map_err(algo)?),
            None => None,
        };
        let p = spa::solar_position_from_julian(
            jd,
            site.latitude,
            site.longitude,
            site.elevation,
            refraction,
        )
        .map_err(algo)?;
        Ok(SunPosition {
            zenith: p.zenith_angle(),
            azimuth: p.azimuth(),
        })
    }

    /// Unit vector towards the sun in (east, north, up) coordinates.
    pub fn enu(&self) -> DVec3 {
        let (z, a) = (self.zenith.to_radians(), self.azimuth.to_radians());
        DVec3::new(z.sin() * a.sin(), z.sin() * a.cos(), z.cos())
    }

    /// Whether the sun's centre is above the horizon.
    pub fn is_up(&self) -> bool {
        self.zenith < 90.0
    }
}

fn is_leap(y: i32) -> bool {
    (y % 4 == 0 && y % 100 != 0) || y % 400 == 0
}

pub(crate) fn days_in_month(y: i32, m: u32) -> u32 {
    match m {
        2 if is_leap(y) => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (the era-based method of
/// H. Hinnant's "chrono-Compatible Low-Level Date Algorithms").
pub fn days_from_civil(y: i32, m: u32, d: u32) -> i64 {
    let y = i64::from(y) - i64::from(m <= 2);
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (i64::from(m) + 9) % 12;
    let doy = (153 * mp + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The inverse of [`days_from_civil`]: (year, month, day) of a day count since
/// 1970-01-01 (also the date in `compute`'s file header).
pub fn civil_from_days(z: i64) -> (i32, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    ((yoe + era * 400 + i64::from(m <= 2)) as i32, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(year: i32, month: u32, day: u32, hour: u32, minute: u32, second: f64) -> LocalTime {
        LocalTime {
            year,
            month,
            day,
            hour,
            minute,
            second,
        }
    }

    /// The worked example of NREL's SPA report (Reda & Andreas, NREL/TP-560-34302,
    /// table A4.1): Golden, Colorado, 17 October 2003 12:30:30 local standard time
    /// (UTC−7), 39.742476° N, 105.1786° W, 1830.14 m, 820 mbar, 11 °C, ΔT 67 s:
    /// topocentric zenith 50.11162°, azimuth 194.34024°.
    #[test]
    fn nrel_spa_worked_example_within_a_thousandth_of_a_degree() {
        let site = Site {
            latitude: 39.742476,
            longitude: -105.1786,
            time_zone: -7.0,
            elevation: 1830.14,
            refraction: Some((820.0, 11.0)),
            delta_t: 67.0,
        };
        let p = SunPosition::at(&site, t(2003, 10, 17, 12, 30, 30.0)).unwrap();
        assert!((p.zenith - 50.11162).abs() < 1e-3, "zenith {}", p.zenith);
        assert!(
            (p.azimuth - 194.34024).abs() < 1e-3,
            "azimuth {}",
            p.azimuth
        );
        // The direction: south-south-west, 39.9° above the horizon.
        let v = p.enu();
        assert!((v.length() - 1.0).abs() < 1e-12);
        assert!(
            v.x < 0.0 && v.y < 0.0 && (v.z - (90.0 - 50.11162f64).to_radians().sin()).abs() < 1e-4
        );
    }

    #[test]
    fn local_time_crosses_day_month_and_year_boundaries() {
        // 1 Jan 2004 03:15 at UTC+5.5 is 31 Dec 2003 21:45 UTC.
        let (y, m, d, h, mi, s) = t(2004, 1, 1, 3, 15, 0.0).to_utc(5.5).unwrap();
        assert_eq!((y, m, d, h, mi), (2003, 12, 31, 21, 45));
        assert!(s.abs() < 1e-9);
        // 28 Feb 2004 (leap year) 20:00 at UTC−7 is 29 Feb 03:00 UTC.
        let (y, m, d, h, ..) = t(2004, 2, 28, 20, 0, 0.0).to_utc(-7.0).unwrap();
        assert_eq!((y, m, d, h), (2004, 2, 29, 3));
        // Every day of four years round-trips through the day count.
        for days in days_from_civil(1999, 1, 1)..days_from_civil(2003, 1, 1) {
            let (y, m, d) = civil_from_days(days);
            assert!(d >= 1 && d <= days_in_month(y, m));
            assert_eq!(days_from_civil(y, m, d), days);
        }
    }

    #[test]
    fn invalid_times_and_sites_are_errors_naming_them() {
        let site = Site::new(48.2, 16.4, 1.0, 190.0);
        assert!(matches!(
            SunPosition::at(&site, t(2023, 2, 29, 12, 0, 0.0)),
            Err(SunError::Time(_))
        ));
        assert!(matches!(
            SunPosition::at(&site, t(2023, 6, 1, 24, 0, 0.0)),
            Err(SunError::Time(_))
        ));
        let far = Site {
            latitude: 95.0,
            ..site.clone()
        };
        let e = SunPosition::at(&far, t(2023, 6, 1, 12, 0, 0.0)).unwrap_err();
        assert!(e.to_string().contains("latitude 95"), "{e}");
        let nan = Site {
            longitude: f64::NAN,
            ..site
        };
        assert!(matches!(
            SunPosition::at(&nan, t(2023, 6, 1, 12, 0, 0.0)),
            Err(SunError::Site(_))
        ));
    }

    /// Known geometry without the algorithm's fine terms: at an equinox the sun culminates
    /// at a zenith angle close to the latitude, due south in the north, and it is down at
    /// local midnight.
    #[test]
    fn equinox_noon_zenith_is_the_latitude_and_midnight_is_dark() {
        let mut site = Site::new(45.0, 0.0, 0.0, 0.0);
        site.refraction = None;
        // 20 March 2024 12:07 UTC is close to solar noon on the Greenwich meridian
        // (equation of time ≈ −7.5 min); the declination is within 0.1° of 0.
        let noon = SunPosition::at(&site, t(2024, 3, 20, 12, 7, 30.0)).unwrap();
        assert!((noon.zenith - 45.0).abs() < 0.2, "zenith {}", noon.zenith);
        assert!(
            (noon.azimuth - 180.0).abs() < 1.0,
            "azimuth {}",
            noon.azimuth
        );
        let night = SunPosition::at(&site, t(2024, 3, 20, 0, 7, 30.0)).unwrap();
        assert!(!night.is_up() && noon.is_up());
    }
}
