//! From linear radiosity to 8-bit sRGB: exposure, sRGB transfer, quantisation.
//!
//! Automatic exposure: radiosity values have whatever units the scene's `Ke` had, so a
//! fixed scale is useless. [`auto_exposure`] takes the area-weighted 99th percentile
//! of the luminance of the patches that emit nothing and maps it to 0.8 (linear). The
//! lights are left out because they are usually far brighter than anything they light
//! and would push the rest into the dark; they saturate to white instead. The
//! percentile (rather than the maximum) keeps a few hot patches next to a light from
//! setting the scale; weighting by area makes it independent of how finely the scene
//! was subdivided. It is computed from all patches, visible or not, so it does not
//! change with the camera.

use super::image::Image;
use crate::patch::PatchSet;

/// Linear value the reference luminance is mapped to.
pub(crate) const AUTO_EXPOSURE_TARGET: f32 = 0.8;

/// Area fraction below the reference luminance.
pub(crate) const AUTO_EXPOSURE_PERCENTILE: f64 = 0.99;

/// Relative luminance of linear RGB with sRGB (ITU-R BT.709) primaries.
#[inline]
pub(crate) fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// Exposure that maps the area-weighted 99th percentile of the non-emitting patches'
/// luminance to [`AUTO_EXPOSURE_TARGET`]. Falls back to all patches when no
/// non-emitting patch is lit, and to 1 when nothing is lit at all. `radiosity` holds
/// one value per patch; negative and non-finite values count as 0.
pub fn auto_exposure(patches: &PatchSet, radiosity: &[[f32; 3]]) -> f32 {
    debug_assert_eq!(patches.len(), radiosity.len());
    let reference = |include_emitters: bool| -> f64 {
        let mut items: Vec<(f32, f64)> = patches
            .patches
            .iter()
            .zip(radiosity)
            .filter(|(p, _)| include_emitters || p.emission.iter().all(|&e| e == 0.0))
            .map(|(p, b)| {
                let y = luminance(b.map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 }));
                (y, p.area.max(0.0))
            })
            .collect();
        weighted_percentile(&mut items, AUTO_EXPOSURE_PERCENTILE)
    };
    let mut y = reference(false);
    if y <= 0.0 {
        y = reference(true);
    }
    if y > 0.0 && y.is_finite() {
        (f64::from(AUTO_EXPOSURE_TARGET) / y) as f32
    } else {
        1.0
    }
}

/// Smallest value `v` such that items with value ≤ `v` hold at least `q` of the total
/// weight (0 for an empty or weightless list).
fn weighted_percentile(items: &mut [(f32, f64)], q: f64) -> f64 {
    items.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = items.iter().map(|(_, w)| w).sum();
    if total <= 0.0 || !total.is_finite() {
        return 0.0;
    }
    let mut acc = 0.0;
    for &(v, w) in items.iter() {
        acc += w;
        if acc >= q * total {
            return f64::from(v);
        }
    }
    items.last().map_or(0.0, |&(v, _)| f64::from(v))
}

/// sRGB transfer function (IEC 61966-2-1): linear [0, 1] → encoded [0, 1]. Input is
/// clamped to [0, 1]; NaN gives 0.
#[inline]
pub fn srgb_encode(linear: f32) -> f32 {
    // In f64, so that 1 encodes to exactly 1 (in f32, 1.055 − 0.055 rounds below 1).
    let x = if linear.is_nan() {
        0.0
    } else {
        f64::from(linear.clamp(0.0, 1.0))
    };
    let e = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    e as f32
}

/// Encoded [0, 1] → 8-bit code, rounding to nearest.
#[inline]
pub(crate) fn quantise(encoded: f32) -> u8 {
    (encoded.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Linear pixels (already exposed, in [0, 1]) → 8-bit sRGB image.
pub(crate) fn to_image(linear: &[[f32; 3]], width: u32, height: u32) -> Image {
    debug_assert_eq!(linear.len(), width as usize * height as usize);
    let rgb = linear
        .iter()
        .flat_map(|c| c.map(|x| quantise(srgb_encode(x))))
        .collect();
    Image { width, height, rgb }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_known_values() {
        // Breakpoint: 12.92 · 0.0031308 = 0.04044994 (both branches meet there).
        assert!((srgb_encode(0.003_130_8) - 0.040_449_94).abs() < 1e-6);
        assert!((1.055 * 0.003_130_8f32.powf(1.0 / 2.4) - 0.055 - 0.040_449_94).abs() < 1e-5);
        // 1.055 · 0.5^(1/2.4) − 0.055 = 0.7353570.
        assert!((srgb_encode(0.5) - 0.735_357).abs() < 1e-6);
        assert_eq!(srgb_encode(1.0), 1.0);
        assert_eq!(srgb_encode(0.0), 0.0);
        assert_eq!(srgb_encode(2.0), 1.0);
        assert_eq!(srgb_encode(f32::NAN), 0.0);
        // 8-bit codes: 0.7353570 · 255 = 187.52 → 188; 0.0404499 · 255 = 10.31 → 10.
        assert_eq!(quantise(srgb_encode(0.5)), 188);
        assert_eq!(quantise(srgb_encode(0.003_130_8)), 10);
        assert_eq!(quantise(srgb_encode(1.0)), 255);
    }

    #[test]
    fn weighted_percentile_uses_area() {
        // 98 % of the area at 1, 2 % at 10: the 99th percentile is 10.
        let mut items = vec![(10.0, 2.0), (1.0, 98.0)];
        assert_eq!(weighted_percentile(&mut items, 0.99), 10.0);
        // 99.5 % at 1: the 99th percentile is 1, whatever the count of hot items.
        let mut items = vec![(1.0, 99.5), (10.0, 0.1), (10.0, 0.1), (10.0, 0.3)];
        assert_eq!(weighted_percentile(&mut items, 0.99), 1.0);
        assert_eq!(weighted_percentile(&mut [], 0.99), 0.0);
    }
}
