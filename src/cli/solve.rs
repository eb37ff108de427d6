//! `ffstream solve`: radiosity from an .ffz file, out of core.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::Args;

use ffstream::ffz::FfzReader;
use ffstream::patch::PatchSet;
use ffstream::scene::Scene;
use ffstream::solve::{self, Solution, SolveConfig, SolveMethod};

use super::choices::{DroppedArg, SolverArg};

#[derive(Args, Debug, Clone)]
pub(crate) struct SolveArgs {
    /// The .ffz file.
    pub file: PathBuf,
    /// Radiosity CSV to write (header patch,group,area,B_r,B_g,B_b,E_*,rho_*,H_*). With
    /// several emission cases: one file per case, named NAME_case{k}.csv.
    #[arg(short, long, value_name = "radiosity.csv")]
    pub output: PathBuf,
    /// Solver. (`--method` is the old spelling, kept for one release.)
    #[arg(
        long,
        alias = "method",
        value_enum,
        default_value_t = SolverArg::GaussSeidel,
        value_name = "SOLVER"
    )]
    pub solver: SolverArg,
    #[command(flatten)]
    pub opts: SolveOptions,
}

/// Settings of the solve (shared with `run`, where the solver is chosen with --solver).
#[derive(Args, Debug, Clone)]
pub(crate) struct SolveOptions {
    /// No progress lines (set from the global --quiet).
    #[arg(skip)]
    pub quiet: bool,
    /// Stop when the relative residual (shooting: unshot / emitted power) is below this.
    #[arg(long, default_value_t = 1e-6, value_name = "E", value_parser = super::choices::number::open_unit)]
    pub tolerance: f64,
    /// Most sweeps (shooting: shots / n), at least 1.
    #[arg(long, default_value_t = 10_000, value_name = "N", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub max_iterations: usize,
    /// Memory the solve may use to make its sweeps faster, in MiB (0 to 1048576): the
    /// rows as read, and for rows that link to clusters their links made ready to
    /// gather (docs/numerics.md §8), so that later sweeps neither decode the file nor
    /// work the links out again. The answer is the same with 0. Default: 2048, or half
    /// the memory available when that is less.
    #[arg(long, value_name = "MIB", value_parser = clap::value_parser!(u64).range(0..=1 << 20))]
    pub cache_mib: Option<u64>,
    /// Take reflectance and emission from this scene instead of the file's patch table
    /// (the scene must be the one the file was computed from).
    #[arg(long = "scene", value_name = "SCENE.obj")]
    pub materials_from: Option<String>,
    /// Solve several emission cases in one pass per sweep: CSV with header
    /// case,group,e_r,e_g,e_b (per-group exitance; unlisted groups emit nothing).
    #[arg(long, value_name = "CASES.csv")]
    pub emission: Option<PathBuf>,
    /// Also write the lit mesh as PLY with per-vertex colours (MeshLab, Blender).
    #[arg(long, value_name = "lit.ply")]
    pub ply: Option<PathBuf>,
    /// Also write the patches as a VTK unstructured grid (ParaView, meshio): one cell
    /// per patch with cell data radiosity, irradiance, emitted_exitance, reflectance
    /// (RGB each), area, patch and group (the values of the radiosity CSV), and the
    /// file's row_sum, sky_view and dropped_mass (as export --vtu). With several
    /// emission cases: one file per case, named NAME_case{k}.vtu.
    #[arg(long, value_name = "lit.vtu")]
    pub vtu: Option<PathBuf>,
    /// Top-k files: what to do with the light the rows left out (their dropped mass).
    /// `pool` shares it among the patches that dropped it and conserves power; `scale`
    /// multiplies each row's kept entries up to its true sum (solve's only way until
    /// this option);
    /// `absorb` loses it. Dense files drop nothing.
    #[arg(long, value_enum, default_value_t = DroppedArg::Pool, value_name = "HOW")]
    pub dropped_mass: DroppedArg,
    /// Old spelling of `--dropped-mass absorb`, kept for one release.
    #[arg(long, hide = true, conflicts_with = "dropped_mass")]
    pub no_renormalize: bool,
}

type Rgb = [f32; 3];

/// Reflectance and emission of the file's patches taken from `scene` instead: each patch
/// keeps the index of the face it was cut from, which must exist in `scene`, carry the
/// same group name and contain the patch.
pub(super) fn materials_from_scene(
    patches: &PatchSet,
    scene: &Scene,
    spec: &str,
) -> anyhow::Result<(Vec<Rgb>, Vec<Rgb>)> {
    let (lo, hi) = scene.bounds();
    let tol = 1e-6 * (hi - lo).length().max(f64::MIN_POSITIVE);
    let mut rho = Vec::with_capacity(patches.len());
    let mut emission = Vec::with_capacity(patches.len());
    for (i, p) in patches.patches.iter().enumerate() {
        let mismatch = |why: String| {
            anyhow::anyhow!("{spec} is not the scene this file was computed from: patch {i}: {why}")
        };
        let face = scene
            .faces
            .get(p.face as usize)
            .ok_or_else(|| mismatch(format!("face {} does not exist", p.face)))?;
        let group = &scene.groups[face.group as usize];
        if group != patches.group_name(i) {
            return Err(mismatch(format!(
                "face {} is in group '{group}', the file says '{}'",
                p.face,
                patches.group_name(i)
            )));
        }
        let n = face.normal();
        let c = p.centroid();
        if (c - face.corners[0]).dot(n).abs() > tol || n.dot(p.normal) < 1.0 - 1e-9 {
            return Err(mismatch(format!(
                "it does not lie on face {} (line {})",
                p.face, face.line
            )));
        }
        let m = &scene.materials[face.material as usize];
        rho.push(m.rho);
        emission.push(m.emission);
    }
    Ok((rho, emission))
}

/// The files a solve reads: the .ffz file, `--scene`'s file, `--emission`.
pub(super) fn solve_inputs<'a>(
    file: &'a Path,
    o: &'a SolveOptions,
) -> Vec<super::outputs::Named<'a>> {
    let mut inputs = vec![("FILE", file)];
    if let Some(p) = o
        .materials_from
        .as_deref()
        .and_then(super::outputs::scene_file)
    {
        inputs.push(("--scene", p));
    }
    if let Some(p) = &o.emission {
        inputs.push(("--emission", p));
    }
    inputs
}

/// Solve `file` and write the outputs; returns the solution and the patches.
pub(super) fn solve_file(
    file: &Path,
    output: &Path,
    method: SolveMethod,
    o: &SolveOptions,
) -> anyhow::Result<(Solution, PatchSet)> {
    for (option, path) in solve_inputs(file, o) {
        super::regular_input(option, path)?;
    }
    let reader = FfzReader::open(file)?;
    for w in reader.warnings() {
        eprintln!("ffstream: warning: {w}");
    }
    let patches = reader.meta().patches.clone();
    let (rho, own_emission) = match &o.materials_from {
        Some(spec) => materials_from_scene(&patches, &super::compute::load_scene(spec)?, spec)?,
        None => (
            solve::scene_reflectance(&patches),
            solve::scene_emission(&patches),
        ),
    };
    let cases = match &o.emission {
        Some(path) => solve::read_emission_cases(path, &patches)?,
        None => vec![own_emission],
    };
    // Every output is known once the cases are: none may be an input or another.
    let csvs: Vec<PathBuf> = (0..cases.len())
        .map(|k| solve::case_path(output, k, cases.len()))
        .collect();
    let mut outputs: Vec<super::outputs::Named<'_>> =
        csvs.iter().map(|p| ("-o", p.as_path())).collect();
    if let Some(ply) = &o.ply {
        outputs.push(("--ply", ply));
    }
    let vtus: Vec<PathBuf> = match &o.vtu {
        Some(vtu) => (0..cases.len())
            .map(|k| solve::case_path(vtu, k, cases.len()))
            .collect(),
        None => Vec::new(),
    };
    outputs.extend(vtus.iter().map(|p| ("--vtu", p.as_path())));
    super::outputs::check(&solve_inputs(file, o), &outputs)?;
    let emits = |c: &Vec<[f32; 3]>| c.iter().any(|e| e.iter().any(|&x| x > 0.0));
    if !cases.iter().any(emits) {
        bail!(
            "{}: nothing emits light (every Ke is 0){}: the radiosity would be zero everywhere",
            file.display(),
            if o.emission.is_some() {
                " in the emission cases"
            } else {
                ""
            }
        );
    }
    let cfg = SolveConfig {
        method,
        tolerance: o.tolerance,
        max_iterations: o.max_iterations,
        cache_bytes: cache_bytes(o.cache_mib),
        dropped: if o.no_renormalize {
            solve::DroppedMass::Absorb
        } else {
            o.dropped_mass.into()
        },
        progress: (!o.quiet).then_some(print_sweep as fn(&solve::SweepProgress)),
    };
    let solution = solve::solve(&reader, &cases, &rho, &cfg)
        .with_context(|| format!("solving {}", file.display()))?;
    eprint!("{}", solution.summary());
    let k = solution.cases();
    // The matrix side of the grids (row sums, sky view, dropped mass): one more pass.
    let sums = match vtus.is_empty() {
        true => None,
        false => Some(ffstream::report::tools::row_sum_arrays(&reader)?),
    };
    for case in 0..k {
        let path = solve::case_path(output, case, k);
        solve::write_csv(&path, &patches, &solution, case)?;
        let table = solve::group_table(&patches, &solution, case)?;
        println!(
            "{}per-group area-averaged radiosity{}:",
            if k > 1 { "\n" } else { "" },
            if k > 1 {
                format!(" (case {case})")
            } else {
                String::new()
            }
        );
        print!("{}", solve::format_group_table(&table));
        eprintln!("ffstream: wrote {}", path.display());
        if let Some(vtu) = vtus.get(case) {
            solve::write_vtu(
                vtu,
                &patches,
                &solution,
                case,
                sums.as_ref().map_or(&[], |a| &a[..]),
            )?;
            eprintln!("ffstream: wrote {}", vtu.display());
        }
    }
    if let Some(ply) = &o.ply {
        ffstream::render::write_ply(ply, &patches, &solution.radiosity_f32(0))?;
        eprintln!("ffstream: wrote {}", ply.display());
    }
    Ok((solution, patches))
}

pub(super) fn run(a: SolveArgs) -> anyhow::Result<ExitCode> {
    solve_file(&a.file, &a.output, a.solver.into(), &a.opts)?;
    Ok(ExitCode::SUCCESS)
}

/// One progress line a sweep (shooting: every n shots) on stderr.
fn print_sweep(p: &solve::SweepProgress) {
    let (what, residual) = match p.method {
        SolveMethod::Shooting => ("shots", "unshot power"),
        SolveMethod::GaussSeidel => ("sweep", "residual bound"),
        SolveMethod::Jacobi => ("sweep", "residual"),
    };
    eprintln!(
        "progress: {} {what} {}, {residual} {:.2e}, {:.1} s",
        p.method,
        p.sweep,
        p.residual,
        p.elapsed.as_secs_f64()
    );
}

/// `--cache-mib` in bytes, or by default [`solve::DEFAULT_CACHE_BYTES`] or half the
/// memory available, whichever is less.
fn cache_bytes(mib: Option<u64>) -> usize {
    match mib {
        Some(m) => (m as usize) << 20,
        None => ffstream::job::plan::mem_available().map_or(solve::DEFAULT_CACHE_BYTES, |a| {
            solve::DEFAULT_CACHE_BYTES.min((a / 2) as usize)
        }),
    }
}
