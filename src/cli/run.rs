//! `ffstream run`: the main job. Compute (embedded, or under mpirun) + solve + render
//! with good defaults, everything in one directory.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use super::choices::{RowsArg, SolverArg};
use super::compute::{execute, stopped, stopped_by_signal, ComputeOptions, Outcome};
use super::render::{render_to, ViewOptions};
use super::solve::{solve_file, SolveOptions};
use super::SceneInput;

#[derive(Args, Debug)]
pub(crate) struct RunArgs {
    #[command(flatten)]
    pub input: SceneInput,
    /// Output directory (default: out/SCENE_NAME). It receives form_factors.ffz,
    /// radiosity.csv, lit.ply, lit.vtu (ParaView), image.png and wireframe.png. (`-o`/`--output` are the
    /// old spellings, kept for one release: elsewhere -o names a file.)
    #[arg(long, short_alias = 'o', alias = "output", value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    #[command(flatten)]
    pub compute: ComputeOptions,
    /// Solver (see `ffstream solve --help`).
    #[arg(long, value_enum, default_value_t = SolverArg::GaussSeidel, value_name = "SOLVER")]
    pub solver: SolverArg,
    #[command(flatten)]
    pub solve: SolveOptions,
    #[command(flatten)]
    pub view: ViewOptions,
}

pub(super) fn run(mut a: RunArgs) -> anyhow::Result<ExitCode> {
    let dir = a
        .out_dir
        .clone()
        .unwrap_or_else(|| super::default_run_dir(&a.input.scene));
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    let ffz = dir.join("form_factors.ffz");
    let (csv, image, wireframe) = (
        dir.join("radiosity.csv"),
        dir.join("image.png"),
        dir.join("wireframe.png"),
    );
    if a.solve.ply.is_none() {
        a.solve.ply = Some(dir.join("lit.ply"));
    }
    if a.solve.vtu.is_none() {
        a.solve.vtu = Some(dir.join("lit.vtu"));
    }
    // No output of the run may be one of its inputs (a scene kept in its own
    // directory under an output's name) or another output (--ply image.png).
    let mut inputs = super::compute::compute_inputs(&a.input, &a.compute);
    inputs.extend(
        super::solve::solve_inputs(&ffz, &a.solve)
            .into_iter()
            .skip(1),
    );
    let mut outputs = vec![
        ("form_factors.ffz", ffz.as_path()),
        ("radiosity.csv", csv.as_path()),
        ("image.png", image.as_path()),
    ];
    if !a.view.wireframe {
        outputs.push(("wireframe.png", wireframe.as_path()));
    }
    if let Some(ply) = &a.solve.ply {
        outputs.push(("--ply", ply));
    }
    if let Some(vtu) = &a.solve.vtu {
        outputs.push(("--vtu", vtu));
    }
    super::outputs::check(&inputs, &outputs)?;
    // `run` owns its directory: a rerun recomputes unless --resume is given.
    a.compute.force |= !a.compute.resume;
    // A gathering solve never reads rows of patches that neither reflect nor emit.
    a.compute.rows.get_or_insert(RowsArg::Needed);
    let report = match execute(&a.input, ffz.clone(), &a.compute) {
        Ok(Outcome::Master(r)) => r,
        Ok(Outcome::Worker) => return Ok(ExitCode::SUCCESS),
        Err(e) => return stopped_by_signal(e),
    };
    // A signal that came as the last rows were written: the file is complete, but
    // the user asked to stop before the solve.
    if let Some(signal) = ffstream::service::interrupt::interrupted() {
        return Ok(stopped(signal));
    }
    eprintln!("{}", report.summary());
    eprintln!("ffstream: wrote {}", ffz.display());
    let (solution, patches) = solve_file(&ffz, &csv, a.solver.into(), &a.solve)?;
    let radiosity = solution.radiosity_f32(0);
    render_to(&patches, &radiosity, &image, &a.view, a.view.wireframe)?;
    if !a.view.wireframe {
        render_to(&patches, &radiosity, &wireframe, &a.view, true)?;
    }
    println!("picture: {}", image.display());
    Ok(ExitCode::SUCCESS)
}
