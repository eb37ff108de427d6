//! What `annual` writes: the hourly illuminance table, the daylight metrics per sensor
//! and their table (CSV dialect of [`crate::table`]).
//!
//! Metrics over the occupied hours (docs/daylight.md): daylight autonomy DA_T, the share
//! of occupied hours with illuminance ≥ T (C. Reinhart and O. Walkenhorst, "Validation of
//! dynamic RADIANCE-based daylight simulations for a test office with external blinds",
//! Energy and Buildings 33(7) 683–697, 2001; T = 300 lx by default), and useful daylight
//! illuminance, the shares below 100 lx, within 100–2000 lx and above 2000 lx (A. Nabil
//! and J. Mardaljevic, "Useful daylight illuminances: a replacement for daylight
//! factors", Energy and Buildings 38(7) 905–913, 2006).

use std::path::Path;

use super::annual::{HourSky, Series};
use crate::table::TableWriter;

/// Occupied hours [start, end) of the day, local standard time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Occupied {
    pub start: u32,
    pub end: u32,
}

impl Occupied {
    /// Whether the weather-file hour ending at `hour` (1–24) lies within.
    pub fn contains(self, hour: u32) -> bool {
        hour > self.start && hour <= self.end
    }
}

impl Default for Occupied {
    /// 8:00 to 18:00.
    fn default() -> Self {
        Occupied { start: 8, end: 18 }
    }
}

/// Metrics of one sensor over the occupied hours.
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    /// Occupied hours counted.
    pub hours: usize,
    /// Daylight autonomy: share of occupied hours at or above the threshold, percent.
    pub da: f64,
    /// Useful daylight illuminance: shares below 100, within 100–2000, above 2000 lux.
    pub udi: [f64; 3],
    /// Mean over the occupied hours, lux.
    pub mean: f64,
    /// Largest value over all hours, lux.
    pub max: f64,
}

/// The metrics of the hourly `total` (lux, one per hour of `hours`).
pub fn metrics(total: &[f64], hours: &[HourSky], occ: Occupied, threshold: f64) -> Metrics {
    let (mut n, mut da, mut udi, mut sum) = (0usize, 0usize, [0usize; 3], 0.0);
    for (&e, h) in total.iter().zip(hours) {
        if !occ.contains(h.hour) {
            continue;
        }
        n += 1;
        sum += e;
        da += usize::from(e >= threshold);
        let bin = if e < 100.0 {
            0
        } else if e <= 2000.0 {
            1
        } else {
            2
        };
        udi[bin] += 1;
    }
    let pct = |k: usize| 100.0 * k as f64 / n.max(1) as f64;
    Metrics {
        hours: n,
        da: pct(da),
        udi: udi.map(pct),
        mean: sum / n.max(1) as f64,
        max: total.iter().copied().fold(0.0, f64::max),
    }
}

/// `month,day,hour,<sensor>...`: lux with one decimal, one line per hour.
///
/// # Errors
/// The file cannot be created or written.
pub fn write_illuminance(
    path: &Path,
    hours: &[HourSky],
    names: &[&str],
    series: &[Series],
) -> std::io::Result<()> {
    let mut w = TableWriter::create(path)?;
    let head = ["month", "day", "hour"]
        .into_iter()
        .chain(names.iter().copied());
    w.record(head)?;
    for (t, h) in hours.iter().enumerate() {
        let mut f = vec![h.month.to_string(), h.day.to_string(), h.hour.to_string()];
        f.extend(series.iter().map(|s| format!("{:.1}", s.total[t])));
        w.record(f)?;
    }
    w.finish()
}

/// The header of the metrics table for threshold `threshold` (lux).
pub fn metrics_header(threshold: f64) -> [String; 8] {
    [
        "sensor".into(),
        "occupied_hours".into(),
        format!("da{}_percent", crate::brief_number(threshold)),
        "udi_below_100_percent".into(),
        "udi_100_2000_percent".into(),
        "udi_above_2000_percent".into(),
        "mean_occupied_lux".into(),
        "max_lux".into(),
    ]
}

/// One line per sensor: [`metrics_header`].
///
/// # Errors
/// The file cannot be created or written.
pub fn write_metrics(
    path: &Path,
    names: &[&str],
    m: &[Metrics],
    threshold: f64,
) -> std::io::Result<()> {
    let mut w = TableWriter::create(path)?;
    w.record(metrics_header(threshold))?;
    for (n, m) in names.iter().zip(m) {
        w.record([
            n.to_string(),
            m.hours.to_string(),
            format!("{:.2}", m.da),
            format!("{:.2}", m.udi[0]),
            format!("{:.2}", m.udi[1]),
            format!("{:.2}", m.udi[2]),
            format!("{:.1}", m.mean),
            format!("{:.1}", m.max),
        ])?;
    }
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_count_the_occupied_hours_only() {
        // One day: hour h (ending) has 100·h lux. Occupied 8–18: hours 9…18, i.e.
        // 900…1800 lux; all ≥ 300, all within 100–2000.
        let hours: Vec<HourSky> = (1..=24)
            .map(|h| HourSky {
                month: 1,
                day: 1,
                hour: h,
                sun: glam::DVec3::Z,
                sky: None,
            })
            .collect();
        let total: Vec<f64> = (1..=24).map(|h| 100.0 * f64::from(h)).collect();
        let m = metrics(&total, &hours, Occupied::default(), 300.0);
        assert_eq!(m.hours, 10);
        assert_eq!((m.da, m.udi), (100.0, [0.0, 100.0, 0.0]));
        assert!((m.mean - 1350.0).abs() < 1e-9 && m.max == 2400.0);
        // Threshold 1500: hours 15…18 of 10.
        let m = metrics(&total, &hours, Occupied { start: 8, end: 18 }, 1500.0);
        assert!((m.da - 40.0).abs() < 1e-9);
        // Occupied 18-24: hours 19…24, 1900…2400 lux: 1900 and 2000 useful (the bin
        // includes 2000), 4 above.
        let m = metrics(&total, &hours, Occupied { start: 18, end: 24 }, 300.0);
        assert_eq!(m.hours, 6);
        assert!((m.udi[1] - 200.0 / 6.0).abs() < 1e-9 && (m.udi[2] - 400.0 / 6.0).abs() < 1e-9);
    }
}
