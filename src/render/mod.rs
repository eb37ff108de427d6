//! Software renderer for the lit scene: a CPU z-buffer rasterizer that turns a
//! [`PatchSet`] and its per-patch radiosity into an sRGB PNG. No GPU and no window: the
//! paper (Nasman and Zolla) rendered with OpenGL on a separate machine because the
//! cluster had none; this module plays that part inside ffstream.
//!
//! Pipeline, one file per step:
//!
//! | step | file | what happens |
//! |---|---|---|
//! | camera | [`camera`] | [`Camera`] (eye, target, up, vertical field of view), automatic framing, the published Cornell box camera, `"ex,ey,ez,tx,ty,tz,ux,uy,uz,fov"` parsing |
//! | shading | [`shading`] | per-vertex radiosity for Gouraud shading (area-weighted, welded per group, split at creases) or per-patch colour (`flat`) |
//! | setup | [`setup`] | world → camera space, near-plane clipping, projection to the sample grid, triangle fans, wireframe edge lines |
//! | raster | [`raster`] | z-buffered, perspective-correct rasterization of horizontal bands on several threads, box filter |
//! | tone map | [`tonemap`] | exposure (automatic or given), clamp, sRGB transfer, 8-bit quantisation |
//! | image | [`image`] | [`Image`] and its PNG reader and writer |
//! | mesh | [`lit_ply`] | the lit mesh as PLY with the picture's vertices, colours and tone map |
//!
//! Conventions (all documented where they are implemented):
//! - Image coordinates: x to the right, y down, pixel `(i, j)` covers `[i, i+1) × [j, j+1)`,
//!   so its centre is at `(i + 0.5, j + 0.5)`. The camera's right vector is
//!   `forward × up`: with the Cornell camera (looking along +z, up +y) world +x points to
//!   the image's left, which puts the red wall (x ≈ 550) on the left as in the classic
//!   picture.
//! - Both sides of every patch are drawn and occlude. The radiosity of a patch is the
//!   exitance of its front side; a back side shows the same colour scaled by
//!   [`RenderOptions::back_face_scale`] (default 0.3) so a viewer can tell that it is
//!   looking at the back of a one-sided wall.
//! - Background is black.

pub(crate) mod camera;
pub(crate) mod image;
pub(crate) mod lit_ply;
pub(crate) mod raster;
pub(crate) mod setup;
pub(crate) mod shading;
pub(crate) mod tonemap;

use std::path::PathBuf;

use crate::patch::PatchSet;

pub use camera::Camera;
pub use image::Image;
pub use lit_ply::{write_ply, write_ply_with, PlyEncoding, PlyOptions};
pub use tonemap::{auto_exposure, srgb_encode};

/// Errors of the render layer.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A camera string did not parse (`"ex,ey,ez,tx,ty,tz,ux,uy,uz,fov"`).
    #[error("camera {input:?}: {reason} (expected \"ex,ey,ez,tx,ty,tz,ux,uy,uz,fov_y_deg\")")]
    CameraParse { input: String, reason: String },
    /// A camera that cannot define a view (eye on the target, up along the view
    /// direction, field of view out of range, non-finite values).
    #[error("invalid camera {camera}: {reason}")]
    InvalidCamera { camera: String, reason: String },
    /// The radiosity slice does not match the patch set.
    #[error("radiosity has {got} values but the scene has {expected} patches")]
    RadiosityLength { expected: usize, got: usize },
    /// A radiosity value is NaN or infinite.
    #[error("radiosity of patch {patch} is not finite: {value:?}")]
    NonFiniteRadiosity { patch: usize, value: [f32; 3] },
    /// Options out of range (zero size, samples per pixel not a square, ...).
    #[error("invalid render options: {0}")]
    InvalidOptions(String),
    /// An image whose pixel buffer does not match its size.
    #[error("invalid image: {0}")]
    InvalidImage(String),
    /// Reading or writing an image file failed.
    #[error("{}: {cause}", .path.display())]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// The PNG encoder rejected the image.
    #[error("{}: PNG encoding failed: {cause}", .path.display())]
    PngEncode {
        path: PathBuf,
        cause: png::EncodingError,
    },
    /// The PNG decoder rejected the file.
    #[error("{}: PNG decoding failed: {cause}", .path.display())]
    PngDecode {
        path: PathBuf,
        cause: png::DecodingError,
    },
    /// A PNG this reader does not convert to 8-bit RGB.
    #[error("{}: unsupported PNG: {reason}", .path.display())]
    UnsupportedPng { path: PathBuf, reason: String },
}

/// How to render. Build with `RenderOptions { wireframe: true, ..Default::default() }`.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels (default 512).
    pub width: u32,
    /// Image height in pixels (default 512).
    pub height: u32,
    /// One colour per patch (its own radiosity) instead of Gouraud shading.
    pub flat: bool,
    /// Overlay patch edges as thin dark lines (the paper's figure 8).
    pub wireframe: bool,
    /// Linear scale applied to radiosity before the sRGB transfer; `None` picks it
    /// automatically with [`auto_exposure`].
    pub exposure: Option<f32>,
    /// Supersampling: samples per pixel on a regular `s × s` grid, box-filtered. Must be
    /// a perfect square (1, 4, 9, 16, ...); default 9 (3 × 3).
    pub samples_per_pixel: u32,
    /// Factor applied to the colour of back sides (0 = black, 1 = same as the front);
    /// default 0.3.
    pub back_face_scale: f32,
    /// Total width of wireframe lines in pixels (default 1).
    pub wire_width_px: f32,
    /// Threads used to rasterize; 0 = all available. The image does not depend on it.
    pub threads: usize,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            flat: false,
            wireframe: false,
            exposure: None,
            samples_per_pixel: 9,
            back_face_scale: 0.3,
            wire_width_px: 1.0,
            threads: 0,
        }
    }
}

/// Largest image side accepted (keeps sample buffers and `u32` arithmetic sane).
pub(crate) const MAX_IMAGE_SIDE: u32 = 1 << 15;

impl RenderOptions {
    /// Supersampling factor per axis, `√samples_per_pixel`.
    ///
    /// # Errors
    /// [`RenderError::InvalidOptions`] when `samples_per_pixel` is not a perfect square
    /// between 1 and 256.
    pub(crate) fn supersampling(&self) -> Result<u32, RenderError> {
        let spp = self.samples_per_pixel;
        let s = (1..=16u32).find(|s| s * s == spp);
        s.ok_or_else(|| {
            RenderError::InvalidOptions(format!(
                "samples_per_pixel = {spp} is not a perfect square between 1 and 256"
            ))
        })
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`RenderError::InvalidOptions`] naming the field that is out of range.
    pub(crate) fn validate(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::InvalidOptions(m));
        if self.width == 0 || self.height == 0 {
            return bad(format!(
                "image size {}x{} is empty",
                self.width, self.height
            ));
        }
        if self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return bad(format!(
                "image size {}x{} exceeds {MAX_IMAGE_SIDE} pixels per side",
                self.width, self.height
            ));
        }
        self.supersampling()?;
        if let Some(e) = self.exposure {
            if !(e.is_finite() && e > 0.0) {
                return bad(format!("exposure {e} must be finite and positive"));
            }
        }
        if !(self.back_face_scale.is_finite() && self.back_face_scale >= 0.0) {
            return bad(format!(
                "back_face_scale {} must be finite and non-negative",
                self.back_face_scale
            ));
        }
        if !(self.wire_width_px.is_finite() && self.wire_width_px >= 0.0) {
            return bad(format!(
                "wire_width_px {} must be finite and non-negative",
                self.wire_width_px
            ));
        }
        Ok(())
    }
}

/// Renders `patches` lit by `radiosity` (linear RGB exitance per patch, the solver's
/// B) as seen by `cam`.
///
/// Steps: per-vertex (or per-patch, `flat`) colours from [`shading`], exposure from
/// `opts.exposure` or [`auto_exposure`], triangle setup with near-plane clipping
/// ([`setup`]), z-buffered supersampled rasterization and box filter ([`raster`]), then
/// sRGB transfer and 8-bit quantisation ([`tonemap`]). Negative radiosity (solver
/// round-off) is drawn as zero.
///
/// # Errors
/// [`RenderError::RadiosityLength`] when `radiosity.len() != patches.len()`,
/// [`RenderError::NonFiniteRadiosity`] for a NaN or infinite value,
/// [`RenderError::InvalidCamera`] and [`RenderError::InvalidOptions`] for unusable
/// settings.
pub fn render(
    patches: &PatchSet,
    radiosity: &[[f32; 3]],
    cam: &Camera,
    opts: &RenderOptions,
) -> Result<Image, RenderError> {
    opts.validate()?;
    cam.validate()?;
    if radiosity.len() != patches.len() {
        return Err(RenderError::RadiosityLength {
            expected: patches.len(),
            got: radiosity.len(),
        });
    }
    if let Some((patch, value)) = radiosity
        .iter()
        .enumerate()
        .find(|(_, b)| b.iter().any(|x| !x.is_finite()))
    {
        return Err(RenderError::NonFiniteRadiosity {
            patch,
            value: *value,
        });
    }
    let _span = tracing::debug_span!("render", patches = patches.len()).entered();

    let ss = opts.supersampling()?;
    let exposure = opts
        .exposure
        .unwrap_or_else(|| auto_exposure(patches, radiosity));
    let colours = if opts.flat {
        shading::flat_colours(radiosity)
    } else {
        shading::vertex_colours(patches, radiosity)
    };
    let view = camera::View::new(cam, opts.width * ss, opts.height * ss)?;
    let params = setup::SetupParams {
        exposure: f64::from(exposure),
        back_face_scale: f64::from(opts.back_face_scale),
        wireframe: opts.wireframe,
        wire_half_width: f64::from(opts.wire_width_px) * f64::from(ss) * 0.5,
    };
    let scene = setup::setup(patches, &colours, &view, &params);
    let linear = raster::rasterize(&scene, opts.width, opts.height, ss, opts.threads);
    Ok(tonemap::to_image(&linear, opts.width, opts.height))
}
