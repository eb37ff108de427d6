//! `ffstream scene NAME -o FILE.obj`: write a built-in scene.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

#[derive(Args, Debug)]
pub(crate) struct SceneArgs {
    /// Scene name.
    #[arg(value_parser = clap::builder::PossibleValuesParser::new(ffstream::scene::builtin_names()))]
    pub name: String,
    /// Output OBJ file (the MTL is written beside it).
    #[arg(short, long, value_name = "FILE.obj")]
    pub output: PathBuf,
    /// Scene parameter: plates = distance (default 1), cube = side (1), perpendicular =
    /// height (1), room = clutter (number of boxes, 16), city = blocks per side (4).
    #[arg(long, value_name = "P", value_parser = super::choices::number::finite)]
    pub param: Option<f64>,
}

pub(super) fn run(a: SceneArgs) -> anyhow::Result<ExitCode> {
    let scene = ffstream::scene::builtin(&a.name, a.param)?;
    ffstream::scene::write_obj(&scene, &a.output)?;
    eprintln!(
        "ffstream: wrote {} ({} faces, {} groups)",
        a.output.display(),
        scene.faces.len(),
        scene.groups.len()
    );
    Ok(ExitCode::SUCCESS)
}
