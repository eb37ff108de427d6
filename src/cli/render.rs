//! `ffstream render`: the lit scene as a PNG (software rasterizer).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;

use ffstream::ffz::FfzReader;
use ffstream::patch::PatchSet;
use ffstream::render::{self, Camera, RenderOptions};

#[derive(Args, Debug, Clone)]
pub(crate) struct RenderArgs {
    /// The .ffz file (for the patch table: geometry and groups).
    pub file: PathBuf,
    /// Radiosity CSV written by `ffstream solve`.
    #[arg(long, value_name = "radiosity.csv")]
    pub radiosity: PathBuf,
    /// Output PNG.
    #[arg(short, long, value_name = "image.png")]
    pub output: PathBuf,
    #[command(flatten)]
    pub view: ViewOptions,
}

/// How to draw (shared with `run`).
#[derive(Args, Debug, Clone)]
pub(crate) struct ViewOptions {
    /// Camera as ex,ey,ez,tx,ty,tz,ux,uy,uz,fov (eye, target, up, vertical field of view
    /// in degrees). Default: the published Cornell box camera for the Cornell box,
    /// otherwise a view that frames the whole scene.
    #[arg(long, value_name = "CAMERA", allow_hyphen_values = true, value_parser = parse_camera)]
    pub camera: Option<Camera>,
    /// Per-patch colours instead of radiosity interpolated across patches (Gouraud).
    #[arg(long)]
    pub flat: bool,
    /// Overlay the patch edges.
    #[arg(long)]
    pub wireframe: bool,
    /// Exposure: linear radiosity multiplied by this before sRGB encoding. Default:
    /// automatic (the 99th percentile of non-emitting patches maps to 0.8).
    #[arg(long, value_name = "X", value_parser = render_exposure)]
    pub exposure: Option<f32>,
    /// Image width in pixels (1 to 16384).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub width: u32,
    /// Image height in pixels (1 to 16384).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub height: u32,
    /// Samples per pixel for anti-aliasing (a perfect square: 1, 4, 9, 16).
    #[arg(long, default_value_t = 9, value_name = "N", value_parser = render_spp)]
    pub spp: u32,
}

/// `--spp`: a perfect square from 1 to 256.
fn render_spp(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(n) if (1..=16u32).any(|k| k * k == n) => Ok(n),
        _ => Err(format!(
            "{s} is not a perfect square from 1 to 256 (1, 4, 9, ..., 256)"
        )),
    }
}

/// `--exposure`: a number > 0 that is finite and not 0 as a 32-bit float (1e300 became
/// infinity and was refused only when the picture was drawn, exit 1).
fn render_exposure(s: &str) -> Result<f32, String> {
    let x = super::choices::number::positive(s)? as f32;
    match x.is_finite() && x > 0.0 {
        true => Ok(x),
        false => Err(format!(
            "{s} is not a finite number > 0 as a 32-bit float ({:e} to {:e})",
            f32::MIN_POSITIVE,
            f32::MAX
        )),
    }
}

/// `--camera`, checked when the command line is read (a usage error).
fn parse_camera(s: &str) -> Result<Camera, String> {
    s.parse::<Camera>().map_err(|e| e.to_string())
}

/// The group names of the Cornell box (built-in and the published file).
const CORNELL_GROUPS: [&str; 8] = [
    "floor",
    "ceiling",
    "back_wall",
    "right_wall",
    "left_wall",
    "short_block",
    "tall_block",
    "light",
];

fn default_camera(patches: &PatchSet) -> Camera {
    let is_cornell = patches.groups.len() == CORNELL_GROUPS.len()
        && CORNELL_GROUPS
            .iter()
            .all(|g| patches.groups.iter().any(|h| h == g));
    if is_cornell {
        Camera::cornell()
    } else {
        Camera::frame_for(patches, 1.0)
    }
}

/// Render `radiosity` on `patches` to `output`.
pub(super) fn render_to(
    patches: &PatchSet,
    radiosity: &[[f32; 3]],
    output: &Path,
    v: &ViewOptions,
    wireframe: bool,
) -> anyhow::Result<()> {
    let camera = match v.camera {
        Some(c) => c,
        None => {
            let mut c = default_camera(patches);
            if v.width != v.height
                && !CORNELL_GROUPS
                    .iter()
                    .all(|g| patches.groups.iter().any(|h| h == g))
            {
                c = Camera::frame_for(patches, v.width as f64 / v.height as f64);
            }
            c
        }
    };
    let opts = RenderOptions {
        width: v.width,
        height: v.height,
        flat: v.flat,
        wireframe,
        exposure: v.exposure,
        samples_per_pixel: v.spp,
        ..RenderOptions::default()
    };
    let image = render::render(patches, radiosity, &camera, &opts)?;
    image.write_png(output)?;
    eprintln!("ffstream: wrote {}", output.display());
    Ok(())
}

pub(super) fn run(a: RenderArgs) -> anyhow::Result<ExitCode> {
    super::outputs::check(
        &[("FILE", &a.file), ("--radiosity", &a.radiosity)],
        &[("-o", &a.output)],
    )?;
    super::regular_input("FILE", &a.file)?;
    super::regular_input("--radiosity", &a.radiosity)?;
    let reader = FfzReader::open(&a.file)?;
    let patches = reader.meta().patches.clone();
    let radiosity = ffstream::solve::read_radiosity_csv(&a.radiosity, patches.len())?;
    render_to(&patches, &radiosity, &a.output, &a.view, a.view.wireframe)?;
    Ok(ExitCode::SUCCESS)
}
