//! Z-buffered rasterization on a supersampled grid, box-filtered down to pixels.
//!
//! The image is cut into horizontal bands of pixel rows, handed round-robin to
//! `std::thread::scope` threads. Every band walks all triangles in patch order with its
//! own sample depth and colour buffers, so a sample's value depends only on the
//! triangles and its position: the image is identical for any thread count or band
//! size. Ties in depth go to the first triangle drawn (strict `>`), which also makes
//! the result deterministic.
//!
//! Coverage: a sample at the centre `(i + 0.5, j + 0.5)` of grid cell `(i, j)` is
//! inside a triangle when all three edge functions are ≥ 0. The edge functions are
//! computed so that the two triangles sharing an edge get exactly opposite values
//! ([`super::setup::edge_function`]); a sample on a shared edge is therefore inside at
//! least one of them and meshes have no cracks.
//!
//! Filtering: each sample is clamped to [0, 1] (after exposure) before the box filter,
//! so a saturated light does not bleed into its neighbours' pixels.

use super::setup::{edge_function, ScreenScene, Triangle, WIRE_COLOUR};

/// Sample budget of one band (depth f64 + colour 3 × f32: 20 bytes per sample).
const MAX_BAND_SAMPLES: usize = 1 << 20;

/// Linear RGB per pixel, row-major, top row first, black background.
pub(crate) fn rasterize(
    scene: &ScreenScene,
    width: u32,
    height: u32,
    ss: u32,
    threads: usize,
) -> Vec<[f32; 3]> {
    let (w, h) = (width as usize, height as usize);
    let mut pixels = vec![[0.0f32; 3]; w * h];
    let threads = if threads == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        threads
    };
    // About four bands per thread, for balance when the scene is uneven, and no more
    // than MAX_BAND_SAMPLES samples per band, to bound memory for huge images.
    let samples_per_row = (w * (ss as usize).pow(2)).max(1);
    let band_rows = h
        .div_ceil(threads * 4)
        .min(MAX_BAND_SAMPLES / samples_per_row)
        .max(1);
    let bands: Vec<BandSlice> = pixels
        .chunks_mut(band_rows * w)
        .enumerate()
        .map(|(b, chunk)| (b * band_rows, chunk))
        .collect();
    let threads = threads.min(bands.len()).max(1);
    let mut per_thread: Vec<Vec<BandSlice>> = (0..threads).map(|_| Vec::new()).collect();
    for (k, band) in bands.into_iter().enumerate() {
        per_thread[k % threads].push(band);
    }
    let ctx = Band {
        scene,
        width: w,
        ss: ss as usize,
    };
    if threads == 1 {
        for (row0, out) in per_thread.into_iter().flatten() {
            ctx.draw(row0, out);
        }
    } else {
        std::thread::scope(|s| {
            for mine in per_thread {
                let ctx = &ctx;
                s.spawn(move || {
                    for (row0, out) in mine {
                        ctx.draw(row0, out);
                    }
                });
            }
        });
    }
    pixels
}

/// First pixel row of a band and its pixels.
type BandSlice<'a> = (usize, &'a mut [[f32; 3]]);

struct Band<'a> {
    scene: &'a ScreenScene,
    width: usize,
    ss: usize,
}

impl Band<'_> {
    /// Draws the pixel rows `row0 ..` that `out` holds (a whole number of rows).
    fn draw(&self, row0: usize, out: &mut [[f32; 3]]) {
        let ss = self.ss;
        let ws = self.width * ss;
        let rows = out.len() / self.width;
        let (sy0, sy1) = (row0 * ss, (row0 + rows) * ss);
        let mut depth = vec![0.0f64; ws * (sy1 - sy0)];
        let mut colour = vec![[0.0f32; 3]; ws * (sy1 - sy0)];
        for t in &self.scene.triangles {
            self.draw_triangle(t, sy0, sy1, &mut depth, &mut colour);
        }
        // Box filter of clamped samples.
        let norm = 1.0 / (ss * ss) as f32;
        for (r, out_row) in out.chunks_mut(self.width).enumerate() {
            for (x, px) in out_row.iter_mut().enumerate() {
                let mut acc = [0.0f32; 3];
                for j in 0..ss {
                    let base = (r * ss + j) * ws + x * ss;
                    for c in &colour[base..base + ss] {
                        for (a, v) in acc.iter_mut().zip(c) {
                            *a += v.clamp(0.0, 1.0);
                        }
                    }
                }
                *px = acc.map(|a| a * norm);
            }
        }
    }

    fn draw_triangle(
        &self,
        t: &Triangle,
        sy0: usize,
        sy1: usize,
        depth: &mut [f64],
        colour: &mut [[f32; 3]],
    ) {
        let ws = self.width * self.ss;
        // Sample centres i + 0.5 inside [min, max]: i from ceil(min − 0.5) to
        // floor(max − 0.5), clamped to the band (in f64 first: coordinates can be huge).
        let Some((i0, i1)) = span(t.bbox[0], t.bbox[2], 0, ws) else {
            return;
        };
        let Some((j0, j1)) = span(t.bbox[1], t.bbox[3], sy0, sy1) else {
            return;
        };
        let wire = t.wire.map(|k| &self.scene.wires[k as usize]);
        let half_width = self.scene.wire_half_width;
        let [v0, v1, v2] = t.v;
        for j in j0..j1 {
            let py = j as f64 + 0.5;
            let row = (j - sy0) * ws;
            for i in i0..i1 {
                let p = [i as f64 + 0.5, py];
                let e0 = edge_function(v1, v2, p) * t.sign;
                if e0 < 0.0 {
                    continue;
                }
                let e1 = edge_function(v2, v0, p) * t.sign;
                if e1 < 0.0 {
                    continue;
                }
                let e2 = edge_function(v0, v1, p) * t.sign;
                if e2 < 0.0 {
                    continue;
                }
                let l = [e0 * t.inv_area, e1 * t.inv_area, e2 * t.inv_area];
                let w = l[0] * t.w[0] + l[1] * t.w[1] + l[2] * t.w[2];
                let idx = row + i;
                if w <= depth[idx] {
                    continue;
                }
                depth[idx] = w;
                let on_wire = wire.is_some_and(|poly| poly.distance(p[0], p[1]) < half_width);
                let c = if on_wire {
                    WIRE_COLOUR
                } else {
                    let mut c = [0.0f64; 3];
                    for (k, ck) in c.iter_mut().enumerate() {
                        *ck = (l[0] * t.cw[0][k] + l[1] * t.cw[1][k] + l[2] * t.cw[2][k]) / w;
                    }
                    c
                };
                colour[idx] = c.map(|x| x as f32);
            }
        }
    }
}

/// Grid indices `lo..hi` (half-open) of sample centres within `[min, max]`, clamped to
/// `[start, end)`; `None` when empty.
fn span(min: f64, max: f64, start: usize, end: usize) -> Option<(usize, usize)> {
    let lo = (min - 0.5).ceil().max(start as f64);
    let hi = ((max - 0.5).floor() + 1.0).min(end as f64);
    (lo < hi).then_some((lo as usize, hi as usize))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn span_selects_sample_centres() {
        // Centres 2.5, 3.5 lie in [2.2, 3.9].
        assert_eq!(span(2.2, 3.9, 0, 10), Some((2, 4)));
        // A centre exactly on the bound counts.
        assert_eq!(span(2.5, 2.5, 0, 10), Some((2, 3)));
        assert_eq!(span(2.6, 3.4, 0, 10), None);
        assert_eq!(span(-1e300, 1e300, 3, 7), Some((3, 7)));
        assert_eq!(span(20.0, 30.0, 0, 10), None);
    }
}
