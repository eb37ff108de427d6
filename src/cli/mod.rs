//! Command-line layer: clap structures holding raw values, turned into validated
//! library settings by each subcommand's module. The library never sees clap.

mod annual;
mod choices;
mod compute;
mod files;
mod outputs;
mod render;
mod run;
mod scene;
mod solve;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

/// Print `line` and a newline to stderr in one write. Under mpirun several ranks print
/// while the job sets up, and Open MPI forwards whatever each write gives it: a line
/// that `eprintln!` writes piece by piece came out with another rank's line inside it.
pub(crate) fn say(line: &str) {
    use std::io::Write;
    let mut out = String::with_capacity(line.len() + 1);
    out.push_str(line);
    out.push('\n');
    let _ = std::io::stderr().lock().write_all(out.as_bytes());
}

/// A mistake on the command line found after clap's parse (an output that is an input,
/// an option missing in this combination): `main` prints it as the one error line and
/// exits 2, as clap does for its own usage errors.
#[derive(Debug)]
pub(crate) struct Usage(pub String);

impl std::fmt::Display for Usage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

#[derive(Parser, Debug)]
#[command(
    name = "ffstream",
    version,
    about = "Radiosity form factors for large triangle meshes, streamed into compressed .ffz files, solved out of core and rendered",
    long_about = "Radiosity form factors for large triangle meshes, computed in parallel \
(threads, or MPI ranks under mpirun with rank 0 as a pure I/O master), streamed into a \
chunked zstd-compressed .ffz file, solved out of core and rendered.\n\n\
Run without mpirun for one process (embedded mode); under `mpirun -n P` rank 0 writes the \
file and ranks 1..P-1 compute. Scenes are OBJ+MTL (Kd = reflectance, Ke = emitted \
exitance), STL, PLY or glTF/GLB files (the format from the extension, or FORMAT:PATH; \
STL and PLY take their materials from NAME.mtl beside them), or built-in scenes written \
as builtin:NAME (see `ffstream scene --help`)."
)]
pub(crate) struct Cli {
    /// More log output (-v: info, -vv: debug). RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// No progress display (the rows, rows/s and ETA lines of compute and run, the
    /// sweep lines of solve and run); results, warnings and errors are still printed.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

// Parsed once per run: the size of its largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
pub(crate) enum Command {
    /// Write a built-in scene as OBJ + MTL (cornell, cube, plates, perpendicular, obstructed, room,
    /// city, office).
    Scene(scene::SceneArgs),
    /// Compute the form-factor matrix of a scene into an .ffz file.
    Compute(compute::ComputeArgs),
    /// Show a file's header, sizes, compression ratio and which rows are present.
    Info(files::InfoArgs),
    /// Check every checksum, row sums and reciprocity; optionally compare with another file.
    Verify(files::VerifyArgs),
    /// Export the matrix (Matrix Market) and the patch table (CSV).
    Export(files::ExportArgs),
    /// Solve the radiosity from an .ffz file, out of core.
    Solve(solve::SolveArgs),
    /// Render the lit scene to a PNG with a software rasterizer.
    Render(render::RenderArgs),
    /// The main job: compute + solve + render, with good defaults.
    Run(run::RunArgs),
    /// Daylight across a year: illuminance at sensor points for every hour of a weather
    /// file, or of a year of clear skies (sun, Perez sky, glazing, inter-reflection), with
    /// daylight metrics and heat maps.
    Annual(annual::AnnualArgs),
}

/// How the scene is given and cut into patches (shared by compute and run).
#[derive(Args, Debug, Clone)]
pub(crate) struct SceneInput {
    /// Mesh file: OBJ (with its MTL), STL or PLY (materials from NAME.mtl beside it),
    /// glTF (.gltf or .glb), by extension (or FORMAT:PATH, or --format); or
    /// builtin:NAME[:PARAM] for a built-in scene (NAME one of cornell, cube, plates,
    /// perpendicular, obstructed, room, city, office; see `ffstream scene --help`).
    #[arg(value_parser = scene_spec)]
    pub scene: String,
    /// Read the scene file in this format whatever its extension (recorded in the file
    /// header as FORMAT:PATH, so solve and --resume read it the same way).
    #[arg(long, value_enum, value_name = "FORMAT")]
    pub format: Option<choices::FormatArg>,
    /// Longest patch edge, in scene units. Default: chosen so the scene gets about
    /// --patches patches (the value chosen is printed). A finite length > 0.
    #[arg(long, value_name = "L", value_parser = choices::number::positive)]
    pub max_edge: Option<f64>,
    /// Target patch count used to choose --max-edge when it is not given (1 to 2^26).
    #[arg(long, value_name = "N", default_value_t = ffstream::geometry::subdivide::DEFAULT_TARGET_PATCHES,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=ffstream::job::MAX_PATCHES as u64))]
    pub patches: usize,
    /// Refuse a scene that loads with warnings (faces that repeat another, text read as
    /// Latin-1, degenerate faces dropped, non-planar quads split, no emitter, ...):
    /// each is then an error, exit 1, instead of a warning.
    #[arg(long)]
    pub strict: bool,
    /// Set by `annual`: the scene is lit by daylight, so a scene without an emitting
    /// material is no fault (not an option).
    #[arg(skip)]
    pub daylight: bool,
}

impl SceneInput {
    /// Fold `--format` into the scene spec as its `FORMAT:` prefix, the form the
    /// header records.
    fn apply_format(&mut self) {
        if let Some(f) = self.format.take() {
            self.scene = format!("{}:{}", f.prefix(), self.scene);
        }
    }
}

/// Checks a `builtin:NAME[:PARAM]` scene at parse time (a usage error naming the
/// possible scenes); a file path is checked when it is opened.
fn scene_spec(spec: &str) -> Result<String, String> {
    if let Some(body) = spec.strip_prefix("builtin:") {
        let (name, param) = body
            .split_once(':')
            .map_or((body, None), |(n, p)| (n, Some(p)));
        let names = ffstream::scene::builtin_names();
        if !names.contains(&name) {
            return Err(format!(
                "unknown built-in scene `{name}` [possible values: {}]",
                names.join(", ")
            ));
        }
        if let Some(p) = param {
            p.parse::<f64>()
                .map_err(|_| format!("the parameter `{p}` of builtin:{name} is not a number"))?;
        }
    }
    Ok(spec.to_string())
}

pub(crate) fn init_tracing(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        // Colour codes only on a terminal: a log file or a batch system's stderr
        // capture gets plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .try_init();
}

pub(crate) fn dispatch(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Scene(a) => scene::run(a),
        Command::Compute(mut a) => {
            a.opts.quiet = cli.quiet;
            a.input.apply_format();
            compute::run(a)
        }
        Command::Info(a) => files::info(a),
        Command::Verify(a) => files::verify(a),
        Command::Export(a) => files::export(a),
        Command::Solve(mut a) => {
            a.opts.quiet = cli.quiet;
            solve::run(a)
        }
        Command::Render(a) => render::run(a),
        Command::Run(mut a) => {
            a.compute.quiet = cli.quiet;
            a.solve.quiet = cli.quiet;
            a.input.apply_format();
            run::run(a)
        }
        Command::Annual(mut a) => {
            a.compute.quiet = cli.quiet;
            a.input.apply_format();
            annual::run(a)
        }
    }
}

/// Refuses an input file named on the command line that is a device, FIFO or socket
/// (`src/input.rs`): `/dev/zero` as `--emission` or `--radiosity` was read until memory
/// ran out, a FIFO blocked (issue 48, item 16). An error (exit 1) naming the option.
pub(crate) fn regular_input(option: &str, path: &std::path::Path) -> anyhow::Result<()> {
    use anyhow::Context;
    ffstream::refuse_special_file(path).with_context(|| format!("{option} {}", path.display()))
}

/// Default output directory of `run`.
pub(crate) fn default_run_dir(scene: &str) -> PathBuf {
    let stem = scene
        .strip_prefix("builtin:")
        .map(|s| s.split(':').next().unwrap_or(s).to_string())
        .unwrap_or_else(|| {
            std::path::Path::new(scene)
                .file_stem()
                .map_or("scene".into(), |s| s.to_string_lossy().into_owned())
        });
    PathBuf::from(format!("out/{stem}"))
}
