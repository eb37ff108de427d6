//! The figure the paper asked for: one sensor's illuminance over a year as a heat map,
//! day of the year across, hour of the day up, a colour bar in lux and a title naming
//! the sensor and the place. Written as PNG through the renderer's image type; letters
//! from the public-domain 8 × 8 bitmap font of the `font8x8` crate.

use std::path::Path;

use crate::render::{Image, RenderError};

/// Pixels per day (across) and per hour (up).
const DAY_W: u32 = 2;
const HOUR_H: u32 = 12;
const LEFT: u32 = 56;
const RIGHT: u32 = 128;
const TOP: u32 = 36;
const BOTTOM: u32 = 40;

/// Viridis anchor colours at 0, ¼, ½, ¾, 1 (matplotlib's perceptually uniform map,
/// CC0), interpolated linearly between them.
const RAMP: [[f64; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];

/// The colour of `x` in [0, 1] (clamped).
pub fn colour(x: f64) -> [u8; 3] {
    let x = if x.is_finite() {
        x.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = x * 4.0;
    let k = (s.floor() as usize).min(3);
    let f = s - k as f64;
    std::array::from_fn(|c| (RAMP[k][c] + f * (RAMP[k + 1][c] - RAMP[k][c])).round() as u8)
}

/// The top of the colour scale: the 99th percentile of the non-zero values rounded up
/// to 1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten (so a few hours of sun on the
/// sensor do not wash out the rest), at least 1 lux.
pub fn scale_top(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|&x| x > 0.0).collect();
    if v.is_empty() {
        return 1.0;
    }
    v.sort_by(f64::total_cmp);
    let p99 = v[((v.len() - 1) as f64 * 0.99) as usize].max(1.0);
    let e = 10f64.powf(p99.log10().floor());
    [1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0]
        .into_iter()
        .map(|m| m * e)
        .find(|&t| t >= p99)
        .unwrap_or(10.0 * e)
}

struct Canvas {
    img: Image,
}

impl Canvas {
    fn new(width: u32, height: u32) -> Self {
        Canvas {
            img: Image {
                width,
                height,
                rgb: vec![255; width as usize * height as usize * 3],
            },
        }
    }

    fn put(&mut self, x: u32, y: u32, c: [u8; 3]) {
        if x < self.img.width && y < self.img.height {
            let i = (y as usize * self.img.width as usize + x as usize) * 3;
            self.img.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    fn rect(&mut self, x: u32, y: u32, w: u32, h: u32, c: [u8; 3]) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.put(xx, yy, c);
            }
        }
    }

    /// ASCII text with its top-left corner at (x, y); other characters as '?'.
    fn text(&mut self, x: u32, y: u32, s: &str) {
        for (k, ch) in s.chars().enumerate() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                '?' as usize
            };
            let glyph = font8x8::legacy::BASIC_LEGACY[code];
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 1 {
                        self.put(x + 8 * k as u32 + col, y + row as u32, [0, 0, 0]);
                    }
                }
            }
        }
    }

    /// A vertical colour bar at x = `bx` from `TOP`, `height` pixels, ticks at 0, ¼, …, 1 of
    /// `top` (the last labelled `>=` when `open_top`), `unit` above it.
    fn colour_bar(&mut self, bx: u32, height: u32, top: f64, open_top: bool, unit: &str) {
        for y in 0..height {
            let f = 1.0 - f64::from(y) / f64::from(height - 1);
            self.rect(bx, TOP + y, 14, 1, colour(f));
        }
        for k in 0..=4u32 {
            let y = TOP + height - 1 - k * (height - 1) / 4;
            self.rect(bx + 14, y, 4, 1, [0, 0, 0]);
            let v = top * f64::from(k) / 4.0;
            let label = if k == 4 && open_top {
                format!(">={v:.0}")
            } else {
                format!("{v:.0}")
            };
            self.text(bx + 21, y.saturating_sub(4), &label);
        }
        self.text(bx, TOP - 14, unit);
    }

    /// Text right-aligned to end at x.
    fn text_right(&mut self, x: u32, y: u32, s: &str) {
        self.text(x.saturating_sub(8 * s.len() as u32), y, s);
    }
}

const MONTHS: [&str; 12] = [
    "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
];

/// Where the cell of hour `t` (file order, 24 per day) with hour-of-day `hour` (1–24,
/// the hour ending) is drawn: its top-left pixel.
pub fn cell(t: usize, hour: u32) -> (u32, u32) {
    let day = (t / 24) as u32;
    (LEFT + day * DAY_W, TOP + (24 - hour) * HOUR_H)
}

/// Draw the heat map of `values` (one per hour, file order; `when[t]` = (month, hour))
/// with `title` and write it to `path`. Returns the scale's top (lux).
///
/// # Errors
/// The PNG cannot be written.
pub fn write(
    path: &Path,
    title: &str,
    values: &[f64],
    when: &[(u32, u32)],
) -> Result<f64, RenderError> {
    let days = values.len().div_ceil(24) as u32;
    let (pw, ph) = (days * DAY_W, 24 * HOUR_H);
    let mut c = Canvas::new(LEFT + pw + RIGHT, TOP + ph + BOTTOM);
    let top = scale_top(values);
    for (t, (&v, &(_, hour))) in values.iter().zip(when).enumerate() {
        let (x, y) = cell(t, hour);
        c.rect(x, y, DAY_W, HOUR_H, colour(v / top));
    }
    // Frame and axes.
    let black = [0, 0, 0];
    c.rect(LEFT - 1, TOP - 1, pw + 2, 1, black);
    c.rect(LEFT - 1, TOP + ph, pw + 2, 1, black);
    c.rect(LEFT - 1, TOP - 1, 1, ph + 2, black);
    c.rect(LEFT + pw, TOP - 1, 1, ph + 2, black);
    for h in [0u32, 6, 12, 18, 24] {
        let y = TOP + (24 - h) * HOUR_H;
        c.rect(LEFT - 5, y, 4, 1, black);
        c.text_right(LEFT - 8, y.saturating_sub(4), &format!("{h:02}h"));
    }
    let mut last = 0;
    for (t, &(month, _)) in when.iter().enumerate().step_by(24) {
        if month != last {
            last = month;
            let x = LEFT + (t / 24) as u32 * DAY_W;
            c.rect(x, TOP + ph + 1, 1, 5, black);
            if let Some(name) = MONTHS.get(month as usize - 1) {
                c.text(x + 2, TOP + ph + 8, name);
            }
        }
    }
    c.text(LEFT, TOP + ph + 24, "day of the year (local standard time)");
    c.text(LEFT, 8, title);
    c.colour_bar(LEFT + pw + 16, ph, top, true, "lux");
    c.img.write_png(path)?;
    Ok(top)
}

/// How a grid map is laid out: the lattice's corner positions, its size in cells and the
/// cell's size in pixels.
struct GridLayout {
    lo: (f64, f64),
    hi: (f64, f64),
    cols: u32,
    rows: u32,
    cell: u32,
    spacing: f64,
}

impl GridLayout {
    fn new(points: &[(f64, f64)], spacing: f64) -> Self {
        let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
        for &(a, b) in points {
            lo = (lo.0.min(a), lo.1.min(b));
            hi = (hi.0.max(a), hi.1.max(b));
        }
        let cols = ((hi.0 - lo.0) / spacing).round() as u32 + 1;
        let rows = ((hi.1 - lo.1) / spacing).round() as u32 + 1;
        GridLayout {
            lo,
            hi,
            cols,
            rows,
            cell: (480 / cols.max(rows)).clamp(2, 48),
            spacing,
        }
    }

    /// Top-left pixel of the cell of the sensor at `(a, b)`.
    fn corner(&self, (a, b): (f64, f64)) -> (u32, u32) {
        let i = ((a - self.lo.0) / self.spacing).round() as u32;
        let j = ((self.hi.1 - b) / self.spacing).round() as u32;
        (LEFT + i * self.cell, TOP + j * self.cell)
    }
}

/// A map of one value per grid sensor (daylight autonomy, percent): each sensor a square
/// cell at its position `(a, b)` in the grid's plane (scene units, `spacing` apart),
/// coloured on a 0…`top` scale, with a colour bar, `unit` over it and `title`. Columns
/// run along a, rows along −b (b up).
///
/// # Errors
/// The PNG cannot be written.
pub fn write_grid_map(
    path: &Path,
    title: &str,
    points: &[(f64, f64)],
    values: &[f64],
    spacing: f64,
    top: f64,
    unit: &str,
) -> Result<(), RenderError> {
    let g = GridLayout::new(points, spacing);
    let (pw, ph) = (g.cols * g.cell, (g.rows * g.cell).max(160));
    let width = (LEFT + pw + RIGHT).max(LEFT + 8 * title.len() as u32 + 16);
    let mut c = Canvas::new(width, TOP + ph + BOTTOM);
    for (&p, &v) in points.iter().zip(values) {
        let (x, y) = g.corner(p);
        c.rect(x, y, g.cell, g.cell, colour(v / top));
    }
    c.text(LEFT, 8, title);
    c.text(
        LEFT,
        TOP + g.rows * g.cell + 8,
        &format!("{} x {} sensors, {spacing} apart", g.cols, g.rows),
    );
    c.colour_bar(LEFT + pw + 16, ph, top, false, unit);
    c.img.write_png(path)
}

/// The centre pixel of the cell of the sensor at `at` on the map [`write_grid_map`]
/// draws of `points` (for tests).
pub fn grid_map_pixel(points: &[(f64, f64)], spacing: f64, at: (f64, f64)) -> (u32, u32) {
    let g = GridLayout::new(points, spacing);
    let (x, y) = g.corner(at);
    (x + g.cell / 2, y + g.cell / 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_ends_and_scale() {
        assert_eq!(colour(0.0), [68, 1, 84]);
        assert_eq!(colour(1.0), [253, 231, 37]);
        assert_eq!(colour(7.0), colour(1.0));
        assert_eq!(scale_top(&[0.0, 120.0, 80.0]), 80.0);
        assert_eq!(scale_top(&[2200.0; 10]), 2500.0);
        assert_eq!(scale_top(&[0.0; 4]), 1.0);
        let many: Vec<f64> = (1..=1000).map(f64::from).collect();
        assert_eq!(scale_top(&many), 1000.0);
    }
}
