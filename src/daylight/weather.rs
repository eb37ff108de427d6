//! Hourly weather for daylight: the EnergyPlus weather format (EPW) and NREL's TMY3
//! CSV, read into one [`Weather`]: the site (from the file's header) and, per hour,
//! global horizontal, direct normal and diffuse horizontal irradiance (W/m²), the
//! dew point (°C, for the Perez model's precipitable water) and the station pressure.
//!
//! Both formats give hour h as the hour *ending* at h (EPW hour 1 and TMY3 "01:00" cover
//! 00:00–01:00 local standard time); [`Hour::mid`] is the middle of that interval, where
//! the sun is to be placed (docs/daylight.md).
//!
//! Errors name the file, the line and the column (number and name). Missing values
//! (EPW's 9999 for irradiance, or a non-number) are errors, never zeros: an annual
//! series with holes would be silently darker.
//!
//! EPW: the EnergyPlus "Auxiliary Programs" manual, chapter "Weather Converter
//! Program", section "EnergyPlus Weather File (EPW) Data Dictionary" (eight header
//! lines, the first `LOCATION,city,state,country,source,WMO,lat,lon,tz,elevation`, then
//! one line of 35 fields per hour). TMY3: Wilcox and Marion, "Users Manual for TMY3
//! Data Sets", NREL/TP-581-43156 (2008): a line `USAF,name,state,tz,lat,lon,elev`, a
//! line of column names, then `MM/DD/YYYY,HH:MM,...` per hour; columns found by name.

use std::path::Path;

use super::input::InputError;
use super::sun::{LocalTime, Site};
use crate::table;

/// One hour of weather.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hour {
    pub month: u32,
    pub day: u32,
    /// 1–24: the hour ending at this clock hour, local standard time.
    pub hour: u32,
    /// Global horizontal irradiance, W/m².
    pub ghi: f64,
    /// Direct normal irradiance, W/m².
    pub dni: f64,
    /// Diffuse horizontal irradiance, W/m².
    pub dhi: f64,
    /// Dew point, °C.
    pub dew_point: f64,
    /// Station pressure, mbar.
    pub pressure: f64,
    /// The line of the file it was read from (0 when it was not read from a file).
    pub line: usize,
}

impl Hour {
    /// The middle of the hour this record stands for, in `year` (hour 24 of a day is
    /// 23:30 of that day).
    pub fn mid(&self, year: i32) -> LocalTime {
        LocalTime {
            year,
            month: self.month,
            day: self.day,
            hour: self.hour - 1,
            minute: 30,
            second: 0.0,
        }
    }
}

/// A weather file read.
#[derive(Clone, Debug)]
pub struct Weather {
    /// Where the file says it is, with standard air for refraction.
    pub site: Site,
    /// The place's name as the file gives it.
    pub name: String,
    /// The hours in file order.
    pub hours: Vec<Hour>,
}

impl Weather {
    /// Check the weather read from `path` against `year`, the year the sun is computed
    /// for: a February 29 in the file needs a leap year (the sun of a day that does not
    /// exist cannot be computed; before this check the run stopped after computing the
    /// form factors, on a debug dump of the time); and the file must hold a whole year,
    /// 8760 hours (8784 with February 29).
    ///
    /// # Errors
    /// [`InputError::At`] naming the line of the first February 29, with the nearest
    /// leap years as a hint; [`InputError::File`] naming the first missing hour.
    pub fn check_year(&self, path: &Path, year: i32) -> Result<(), InputError> {
        let feb29 = self.hours.iter().find(|h| (h.month, h.day) == (2, 29));
        match feb29 {
            _ if super::sun::days_in_month(year, 2) == 29 => {}
            None => {}
            Some(h) => {
                let before = (year - 3..year)
                    .rev()
                    .find(|&y| super::sun::days_in_month(y, 2) == 29);
                let after = (year + 1..=year + 4).find(|&y| super::sun::days_in_month(y, 2) == 29);
                let hint: Vec<String> = [before, after]
                    .iter()
                    .flatten()
                    .map(|y| y.to_string())
                    .collect();
                return Err(InputError::at(
                    path,
                    h.line,
                    format!(
                        "February 29, but the sun is computed for {year}, not a leap year: give a leap year with --year ({}), or remove the day from the file",
                        hint.join(" or ")
                    ),
                ));
            }
        }
        // A whole year: every hour once (duplicates and impossible dates are refused
        // when the file is read), with or without February 29. One hour passed as a
        // year, and the metrics (shares of the year's hours) meant nothing.
        let leap = feb29.is_some();
        let want = if leap { 8784 } else { 8760 };
        if self.hours.len() == want {
            return Ok(());
        }
        let have: std::collections::HashSet<(u32, u32, u32)> = self
            .hours
            .iter()
            .map(|h| (h.month, h.day, h.hour))
            .collect();
        let calendar = if leap { 2024 } else { 2025 };
        let missing = (1..=12)
            .flat_map(|m| (1..=super::sun::days_in_month(calendar, m)).map(move |d| (m, d)))
            .flat_map(|(m, d)| (1..=24).map(move |h| (m, d, h)))
            .find(|k| !have.contains(k));
        let first = missing.map_or(String::new(), |(m, d, h)| {
            format!(": the first missing is month {m}, day {d}, hour {h}")
        });
        Err(InputError::file(
            path,
            format!(
                "{} hours, not a whole year ({want}){first}; annual needs every hour of a year (its metrics are shares of them)",
                self.hours.len()
            ),
        ))
    }
}

/// Most bytes a compressed weather file may decompress to: a year of hours is about
/// 1.6 MB as EPW, 1.8 MB as TMY3 CSV; a small `.zst` can hold gigabytes.
const MAX_WEATHER_BYTES: u64 = 64 << 20;

/// The weather in `path`: EPW when its first line starts with `LOCATION`, TMY3
/// otherwise; a name ending in `.zst` is decompressed first (zstd).
pub fn read(path: &Path) -> Result<Weather, InputError> {
    let io = |e| InputError::io(path, e);
    let mut bytes = crate::input::read(path).map_err(io)?;
    if path.extension().is_some_and(|e| e == "zst") {
        bytes = crate::input::zstd_capped(&bytes, MAX_WEATHER_BYTES).map_err(io)?;
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        InputError::file(path, format!("not UTF-8 text (byte {at})"))
    })?;
    if text.trim_start_matches('\u{feff}').starts_with("LOCATION") {
        parse_epw(path, &text)
    } else {
        parse_tmy3(path, &text)
    }
}

/// The records of `text` with errors naming `path`.
fn rows(path: &Path, text: &str) -> Result<Vec<table::Record>, InputError> {
    table::records(text)
        .map(|r| r.map_err(|(line, what)| InputError::at(path, line, what)))
        .collect()
}

/// Field `col` (0-based) of `rec` as a number in `range`, or an error naming line,
/// column number (1-based) and `name`.
fn number(
    path: &Path,
    rec: &table::Record,
    col: usize,
    name: &str,
    range: std::ops::RangeInclusive<f64>,
) -> Result<f64, InputError> {
    let at = |what: String| InputError::field(path, rec, col, name, what);
    let field = rec.fields.get(col).ok_or_else(|| {
        at(format!(
            "missing (the line has {} fields)",
            rec.fields.len()
        ))
    })?;
    let v: f64 = field
        .parse()
        .map_err(|_| at(format!("{field:?} is not a number")))?;
    if !v.is_finite() || !range.contains(&v) {
        return Err(at(format!(
            "{v} is outside {}…{} (missing values are not accepted)",
            range.start(),
            range.end()
        )));
    }
    Ok(v)
}

/// Irradiance, W/m²: 0 to 1500 (EPW marks a missing value 9999).
const IRRADIANCE: std::ops::RangeInclusive<f64> = 0.0..=1500.0;

/// Field `col` as a whole number in `range` (see [`number`]).
fn whole(
    path: &Path,
    rec: &table::Record,
    col: usize,
    name: &str,
    range: std::ops::RangeInclusive<f64>,
) -> Result<u32, InputError> {
    let v = number(path, rec, col, name, range)?;
    match v.fract() == 0.0 {
        true => Ok(v as u32),
        false => Err(InputError::field(
            path,
            rec,
            col,
            name,
            format!("{v} is not a whole number"),
        )),
    }
}

fn check_date(path: &Path, line: usize, month: u32, day: u32, hour: u32) -> Result<(), InputError> {
    let ok = (1..=12).contains(&month)
        && day >= 1
        && day <= super::sun::days_in_month(2024, month) // leap years allowed
        && (1..=24).contains(&hour);
    match ok {
        true => Ok(()),
        false => Err(InputError::at(
            path,
            line,
            format!("month {month}, day {day}, hour {hour} is not a date and hour 1-24"),
        )),
    }
}

fn parse_epw(path: &Path, text: &str) -> Result<Weather, InputError> {
    let recs = rows(path, text)?;
    let loc = recs
        .first()
        .ok_or_else(|| InputError::file(path, "empty"))?;
    let site = site(path, loc, [6, 7, 8, 9])?;
    // The header is eight lines, the last `DATA PERIODS`; every line after it is an hour.
    let periods = recs.iter().find(|r| r.line == 8);
    let periods = periods.and_then(|r| r.fields.first());
    if periods.map(String::as_str) != Some("DATA PERIODS") {
        let what = "not `DATA PERIODS,...`: an EPW file has eight header lines";
        return Err(InputError::at(path, 8, what.into()));
    }
    let data = recs.iter().filter(|r| r.line > 8);
    let mut hours = Vec::new();
    for rec in data {
        let month = whole(path, rec, 1, "month", 1.0..=12.0)?;
        let day = whole(path, rec, 2, "day", 1.0..=31.0)?;
        let hour = whole(path, rec, 3, "hour", 1.0..=24.0)?;
        check_date(path, rec.line, month, day, hour)?;
        hours.push(Hour {
            month,
            day,
            hour,
            dew_point: number(path, rec, 7, "dew point temperature", -90.0..=70.0)?,
            pressure: number(
                path,
                rec,
                9,
                "atmospheric station pressure",
                31_000.0..=120_000.0,
            )? / 100.0,
            ghi: number(path, rec, 13, "global horizontal radiation", IRRADIANCE)?,
            dni: number(path, rec, 14, "direct normal radiation", IRRADIANCE)?,
            dhi: number(path, rec, 15, "diffuse horizontal radiation", IRRADIANCE)?,
            line: rec.line,
        });
    }
    finish(path, site, name_of(loc), hours)
}

fn parse_tmy3(path: &Path, text: &str) -> Result<Weather, InputError> {
    let recs = rows(path, text)?;
    let (head, names) = match recs.as_slice() {
        [h, n, ..] => (h, n),
        _ => {
            return Err(InputError::file(
                path,
                "not an EPW file (no LOCATION line) and too short for TMY3 (a site line and a line of column names)",
            ))
        }
    };
    let site = site(path, head, [4, 5, 3, 6])?;
    let col = |want: &str| {
        names
            .fields
            .iter()
            .position(|f| f.eq_ignore_ascii_case(want))
            .ok_or_else(|| InputError::at(path, names.line, format!("no column named {want:?}")))
    };
    let (c_date, c_time) = (col("Date (MM/DD/YYYY)")?, col("Time (HH:MM)")?);
    let (c_ghi, c_dni, c_dhi) = (
        col("GHI (W/m^2)")?,
        col("DNI (W/m^2)")?,
        col("DHI (W/m^2)")?,
    );
    let (c_dew, c_p) = (col("Dew-point (C)")?, col("Pressure (mbar)")?);
    let mut hours = Vec::new();
    for rec in &recs[2..] {
        let date = rec.fields.get(c_date).map(String::as_str).unwrap_or("");
        let time = rec.fields.get(c_time).map(String::as_str).unwrap_or("");
        let md: Vec<u32> = date.split('/').filter_map(|x| x.parse().ok()).collect();
        let hm: Vec<u32> = time.split(':').filter_map(|x| x.parse().ok()).collect();
        let (month, day, hour) = match (md.as_slice(), hm.as_slice()) {
            ([m, d, _], [h, 0]) => (*m, *d, *h),
            _ => {
                return Err(InputError::at(
                    path,
                    rec.line,
                    format!(
                        "column {} ({date:?}) and {} ({time:?}): not MM/DD/YYYY and HH:00",
                        c_date + 1,
                        c_time + 1
                    ),
                ))
            }
        };
        check_date(path, rec.line, month, day, hour)?;
        hours.push(Hour {
            month,
            day,
            hour,
            ghi: number(path, rec, c_ghi, "GHI (W/m^2)", IRRADIANCE)?,
            dni: number(path, rec, c_dni, "DNI (W/m^2)", IRRADIANCE)?,
            dhi: number(path, rec, c_dhi, "DHI (W/m^2)", IRRADIANCE)?,
            dew_point: number(path, rec, c_dew, "Dew-point (C)", -90.0..=70.0)?,
            pressure: number(path, rec, c_p, "Pressure (mbar)", 310.0..=1200.0)?,
            line: rec.line,
        });
    }
    finish(path, site, name_of(head), hours)
}

/// The site of a header line whose fields `cols` hold latitude, longitude, time zone
/// and elevation (EPW and TMY3 order them differently), with standard air.
fn site(path: &Path, rec: &table::Record, cols: [usize; 4]) -> Result<Site, InputError> {
    let [lat, lon, tz, elev] = cols;
    Ok(Site::new(
        number(path, rec, lat, "latitude", -90.0..=90.0)?,
        number(path, rec, lon, "longitude", -180.0..=180.0)?,
        number(path, rec, tz, "time zone", -14.0..=14.0)?,
        number(path, rec, elev, "elevation", -500.0..=9000.0)?,
    ))
}

/// The place's name: the second field of the header line in both formats.
fn name_of(rec: &table::Record) -> String {
    rec.fields.get(1).cloned().unwrap_or_default()
}

/// A year of hours at most, each (month, day, hour) once.
fn finish(path: &Path, site: Site, name: String, hours: Vec<Hour>) -> Result<Weather, InputError> {
    if hours.is_empty() {
        return Err(InputError::file(path, "no hourly data"));
    }
    let mut seen = std::collections::HashSet::new();
    for h in &hours {
        if !seen.insert((h.month, h.day, h.hour)) {
            let (m, d, hr) = (h.month, h.day, h.hour);
            return Err(InputError::file(
                path,
                format!("month {m}, day {d}, hour {hr} appears twice"),
            ));
        }
    }
    Ok(Weather { site, name, hours })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// An EPW text: the eight header lines, then `data` lines.
    fn epw(data: &[String]) -> String {
        let mut s = String::from(
            "LOCATION,GOLDEN,CO,USA,TEST,724666,39.74,-105.18,-7.0,1829.0\n\
             DESIGN CONDITIONS,0\nTYPICAL/EXTREME PERIODS,0\nGROUND TEMPERATURES,0\n\
             HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0\nCOMMENTS 1,made by the test\nCOMMENTS 2,\n\
             DATA PERIODS,1,1,Data,Sunday, 1/ 1,12/31\n",
        );
        for d in data {
            s += d;
            s.push('\n');
        }
        s
    }

    /// One EPW data line: 35 fields with the given irradiance.
    fn epw_line(month: u32, day: u32, hour: u32, ghi: &str, dni: &str, dhi: &str) -> String {
        let mut f: Vec<String> = vec![
            "2003".into(),
            month.to_string(),
            day.to_string(),
            hour.to_string(),
            "60".into(),
            "?9?9?9?9E0".into(),
            "11.0".into(),
            "-2.5".into(),
            "40".into(),
            "82000".into(),
            "0".into(),
            "1415".into(),
            "300".into(),
            ghi.into(),
            dni.into(),
            dhi.into(),
        ];
        f.resize(35, "0".into());
        f.join(",")
    }

    fn write(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn epw_site_and_hours() {
        let (_d, p) = write(
            "a.epw",
            &epw(&[
                epw_line(10, 17, 13, "550", "820", "90"),
                epw_line(10, 17, 14, "480", "760", "85"),
            ]),
        );
        let w = read(&p).unwrap();
        assert_eq!(w.name, "GOLDEN");
        assert_eq!(
            (w.site.latitude, w.site.longitude, w.site.time_zone),
            (39.74, -105.18, -7.0)
        );
        assert_eq!(w.hours.len(), 2);
        let h = w.hours[0];
        assert_eq!(
            (h.month, h.day, h.hour, h.ghi, h.dni, h.dhi),
            (10, 17, 13, 550.0, 820.0, 90.0)
        );
        assert_eq!((h.dew_point, h.pressure), (-2.5, 820.0));
        let mid = h.mid(2003);
        assert_eq!((mid.hour, mid.minute), (12, 30));
    }

    #[test]
    fn epw_missing_values_and_bad_dates_name_line_and_column() {
        let cases = [
            (
                epw_line(1, 1, 1, "0", "9999", "0"),
                "line 9: column 15 (direct normal radiation)",
            ),
            (
                epw_line(1, 1, 1, "0", "0", "x"),
                "line 9: column 16 (diffuse horizontal radiation): \"x\" is not a number",
            ),
            (
                epw_line(2, 30, 1, "0", "0", "0"),
                "line 9: month 2, day 30, hour 1",
            ),
            (epw_line(1, 1, 25, "0", "0", "0"), "line 9: column 4 (hour)"),
            (
                epw_line(1, 1, 1, "0", "0", "0").replacen(",1,1,1,", ",1.5,1,1,", 1),
                "line 9: column 2 (month): 1.5 is not a whole number",
            ),
            (
                "2003,1,1,1".to_string(),
                "line 9: column 8 (dew point temperature): missing",
            ),
        ];
        for (line, want) in cases {
            let (_d, p) = write("b.epw", &epw(&[line]));
            let e = read(&p).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("b.epw"), "{e} lacks {want}");
        }
        let (_d, p) = write(
            "c.epw",
            &epw(&[
                epw_line(1, 1, 1, "0", "0", "0"),
                epw_line(1, 1, 1, "0", "0", "0"),
            ]),
        );
        assert!(read(&p).unwrap_err().to_string().contains("appears twice"));
        let (_d, p) = write("d.epw", &epw(&[]));
        assert!(read(&p).unwrap_err().to_string().contains("no hourly data"));
        // A header line short: the first hour would be taken for the header.
        let short = epw(&[epw_line(1, 1, 1, "0", "0", "0")]).replace("COMMENTS 2,\n", "");
        let (_d, p) = write("e.epw", &short);
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("e.epw: line 8: not `DATA PERIODS"), "{e}");
    }

    #[test]
    fn tmy3_columns_by_name() {
        let text = "724666,\"DENVER/CENTENNIAL [GOLDEN - NREL]\",CO,-7.0,39.742,-105.179,1829\n\
            Date (MM/DD/YYYY),Time (HH:MM),ETR (W/m^2),GHI (W/m^2),GHI source,DNI (W/m^2),DNI source,DHI (W/m^2),Dew-point (C),Pressure (mbar)\n\
            10/17/1988,13:00,900,550,1,820,1,90,-2.5,820\n\
            10/17/1988,24:00,0,0,1,0,1,0,-3.0,821\n";
        let (_d, p) = write("t.csv", text);
        let w = read(&p).unwrap();
        assert_eq!(w.name, "DENVER/CENTENNIAL [GOLDEN - NREL]");
        assert_eq!(
            (w.site.latitude, w.site.time_zone, w.site.elevation),
            (39.742, -7.0, 1829.0)
        );
        let h = w.hours[0];
        assert_eq!(
            (h.month, h.day, h.hour, h.ghi, h.dni, h.dhi, h.pressure),
            (10, 17, 13, 550.0, 820.0, 90.0, 820.0)
        );
        assert_eq!(w.hours[1].mid(1988).hour, 23);
        let broken = text.replace("DNI (W/m^2)", "DNI");
        let (_d, p) = write("u.csv", &broken);
        let e = read(&p).unwrap_err().to_string();
        assert!(
            e.contains("u.csv: line 2: no column named \"DNI (W/m^2)\""),
            "{e}"
        );
        let (_d, p) = write("v.csv", &text.replace("13:00", "13:30"));
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("line 3: column 1") && e.contains("HH:00"), "{e}");
    }

    /// A real TMY3 file (NREL, public domain; see tests/data/weather/README.md): a
    /// whole year read, the site from its first line, and the annual global horizontal
    /// irradiation equal to the sum of its GHI column taken by Python's csv module
    /// (1566.203 kWh/m²).
    #[test]
    fn real_tmy3_file_reads_whole() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/weather/723170TYA.CSV.zst");
        let w = read(&p).unwrap();
        assert_eq!(w.name, "GREENSBORO PIEDMONT TRIAD INT");
        assert_eq!(
            (
                w.site.latitude,
                w.site.longitude,
                w.site.time_zone,
                w.site.elevation
            ),
            (36.1, -79.95, -5.0, 273.0)
        );
        assert_eq!(w.hours.len(), 8760);
        let ghi: f64 = w.hours.iter().map(|h| h.ghi).sum();
        assert!((ghi / 1000.0 - 1566.203).abs() < 1e-9, "{ghi}");
        let (first, last) = (w.hours[0], w.hours[8759]);
        assert_eq!((first.month, first.day, first.hour), (1, 1, 1));
        assert_eq!((last.month, last.day, last.hour), (12, 31, 24));
        // Closure: GHI = DNI cos z + DHI holds roughly in measured-and-modelled data;
        // here only that diffuse never exceeds global by more than rounding.
        assert!(w.hours.iter().all(|h| h.dhi <= h.ghi + 1.0));
    }
}
