//! `ffstream compute`: its arguments, their conversion into the library's job settings
//! ([`settings`]), and the run, embedded or under MPI (every MPI rank builds its job
//! itself, [`ffstream::job::build_job`]).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use ffstream::ffz::WriterOptions;
use ffstream::formfactor::{TopKTail, MAX_SAMPLES};
use ffstream::job::settings::defaults;
use ffstream::job::{build_job, FormSettings, JobSettings, PatchBudget, RowMode, MAX_THREADS};
use ffstream::scene::{self, Scene, SceneSpec};
use ffstream::service::{interrupt, ComputeJob, ComputeReport, Role};

use super::choices::{
    number, top_k_tail, MethodArg, PresetArg, RowsArg, ScheduleArg, SymmetricArg, TopKSearchArg,
    VisibilityArg,
};
use super::SceneInput;

#[derive(Args, Debug, Clone)]
pub(crate) struct ComputeArgs {
    #[command(flatten)]
    pub input: SceneInput,
    /// Output .ffz file.
    #[arg(short, long, value_name = "OUT.ffz")]
    pub output: PathBuf,
    #[command(flatten)]
    pub opts: ComputeOptions,
}

/// Settings of the form-factor computation and of the service (shared with `run`).
#[derive(Args, Debug, Clone)]
pub(crate) struct ComputeOptions {
    /// Settings preset. Options given explicitly override the preset's values.
    #[arg(long, value_enum, default_value_t = PresetArg::Accurate, value_name = "PRESET")]
    pub preset: PresetArg,
    /// Form-factor method (default: the preset's, contour).
    #[arg(long, value_enum, value_name = "METHOD")]
    pub method: Option<MethodArg>,
    /// How `contour` finds what the occluders take from a pair that may be occluded
    /// (default: the preset's).
    #[arg(long, value_enum, value_name = "MODE")]
    pub visibility: Option<VisibilityArg>,
    /// Exact visibility: target error of an entry's blocked part, relative to the
    /// entry's unoccluded value (default: the preset's, fast 1e-2, accurate 1e-3,
    /// reference 1e-6; docs/methods.md §3 gives cost against accuracy). The rule refines where its
    /// error estimate is largest until the estimates add up to the tolerance; pairs it
    /// cannot bring there (out of points or depth) are counted in the report. Below
    /// about 1e-7 the estimate itself can be fooled where a pair needs more than 256
    /// cells (bench/PERF.md §30).
    #[arg(long, value_name = "TOL", value_parser = number::tolerance)]
    pub shadow_tol: Option<f64>,
    /// contour: target relative error of each entry's unoccluded part (the quadrature
    /// of the contour integral and of the far-field rule). Default: the preset's, fast
    /// 1e-6, accurate 1e-8, reference 1e-13. Looser is cheaper and the errors stay far
    /// below it: 0.1 keeps the unit cube's row sums within 1.2e-5 for half the CPU
    /// (docs/methods.md §2).
    #[arg(long, value_name = "TOL", value_parser = number::tolerance)]
    pub quad_tol: Option<f64>,
    /// Visibility samples per pair (mc: point pairs; contour: rays per pair that may be
    /// occluded, all of them cast unless --first-batch is also given). 1 to 65536.
    #[arg(long, value_name = "S", value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_SAMPLES)))]
    pub samples: Option<u32>,
    /// Rays cast for a pair before the adaptive early stop (when they all agree the
    /// pair is done; the stop is biased, docs/methods.md §3). Equal to --samples: no early
    /// stop. Default: the preset's, or --samples when that is given. 1 to 65536.
    #[arg(long, value_name = "B", value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_SAMPLES)))]
    pub first_batch: Option<u32>,
    /// Keep only the K largest entries of each row (the dropped mass is stored per row).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..))]
    pub top_k: Option<u32>,
    /// Keep only the entries of at least EPS, 0 < EPS < 1 (threshold rows, as View3D and
    /// uDALES store them with 5e-7); the others go to the row's dropped mass. With
    /// --top-k, the K largest of those. Found through the same tree as --top-k.
    #[arg(long, value_name = "EPS", value_parser = number::open_unit)]
    pub min_ff: Option<f64>,
    /// With --top-k or --min-ff: how a row finds its K largest entries (default: the preset's;
    /// tree for fast and accurate, exhaustive for reference). Both keep the same
    /// entries bitwise; they differ in work and in how the dropped mass is obtained.
    #[arg(long, value_enum, value_name = "SEARCH")]
    pub top_k_search: Option<TopKSearchArg>,
    /// With --top-k or --min-ff: how the dropped mass of the entries left out is obtained:
    /// `exact` (every column evaluated, exhaustive search only) or a number N of
    /// points sampled in proportion to the entries' unoccluded values or, for parts of
    /// the tree never opened, an estimate of them (unbiased; error of order the dropped
    /// mass / √N; a tail of at most 2N patches is evaluated in full). With --links, a row's
    /// links share 4N points that place their masses: on the 16-box room at 10k patches,
    /// 512 cuts the per-patch noise by about a third, for about 1.25× the compute
    /// (docs/methods.md §5).
    /// Default: the preset's (fast 128, accurate 256, reference exact).
    #[arg(long, value_name = "exact|N", value_parser = top_k_tail)]
    pub top_k_tail: Option<TopKTail>,
    /// With --top-k or --min-ff and the tree search: the most links a row carries to
    /// clusters of patches for the mass it does not keep (spec §5.7), so that a solver
    /// puts that light where it goes; `off` stores it as one number per row, which the
    /// solver can only pool (docs/numerics.md §8). Default 256 (every preset). Links
    /// need the cluster order in the header, are left out with --symmetric on (half
    /// rows) and the exhaustive search, and are read by the gathering solvers
    /// (gauss-seidel, jacobi), not by shooting.
    #[arg(long, value_name = "N|off", value_parser = links_arg)]
    pub links: Option<LinksArg>,
    /// With links: a cluster is split while the spread of the kernel over it exceeds
    /// TOL times the row's total (0 < TOL < 1; default 1e-3): smaller gives more,
    /// finer links up to --links.
    #[arg(long, value_name = "TOL", value_parser = number::open_unit)]
    pub link_tol: Option<f64>,
    /// Compute threads per process (embedded) or per worker rank (MPI), 1 to 4096.
    /// Default: all cores.
    #[arg(long, value_name = "T", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=MAX_THREADS as u64))]
    pub threads: Option<usize>,
    /// Work distribution over the workers.
    #[arg(long, value_enum, default_value_t = ScheduleArg::Dynamic, value_name = "SCHEDULE")]
    pub schedule: ScheduleArg,
    /// Seed of the visibility sampling (rows depend on it and on (i, j) only, never on
    /// threads or ranks).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub seed: u64,
    /// Which rows to compute (a gathering solve never reads the rows of patches that
    /// neither reflect nor emit; the file marks them skipped). Default: all for
    /// `compute`, needed for `run`.
    #[arg(long, value_enum, value_name = "ROWS")]
    pub rows: Option<RowsArg>,
    /// Complete a partial file (after a crash, a kill, or a stop by SIGTERM/SIGINT,
    /// which closes the file cleanly and exits 143/130): compute only the missing rows.
    #[arg(long)]
    pub resume: bool,
    /// Overwrite the output file if it exists (without it, an existing file is an error
    /// so that a rerun cannot destroy a long computation by accident).
    #[arg(long, conflicts_with = "resume")]
    pub force: bool,
    /// Reciprocity half (the paper's trick): compute each unordered pair once and get
    /// F_ji = F_ij A_i / A_j. on: half the pair work; rows are merged by the I/O
    /// master through a spill file next to the output (OUT.ffz.spill, deleted at the
    /// end) in blocks, so a killed run keeps whole blocks only. off: every row on its
    /// own. auto: on for dense files with --method contour; off for --top-k (where the
    /// bound already skips most of the work, and the spill would hold half of all
    /// entries), for --gather, and for the point and mc baselines (they clamp each
    /// direction to 1, so a mirrored value is not the other direction; `on` refuses them).
    #[arg(long, value_enum, default_value_t = SymmetricArg::Auto, value_name = "MODE")]
    pub symmetric: SymmetricArg,
    /// The paper's design, as a baseline: every rank computes, rank 0 gathers the dense
    /// f64 matrix in memory and writes it at the end.
    #[arg(long)]
    pub gather: bool,
    /// zstd compression level of the row chunks, 1 (fastest) to 22.
    #[arg(long, default_value_t = defaults::ZSTD_LEVEL, value_name = "LEVEL", value_parser = clap::value_parser!(i32).range(1..=22))]
    pub zstd_level: i32,
    /// Target uncompressed size of a row chunk, in KiB (1 to 1048576, i.e. 1 GiB; a
    /// chunk holds at least one row).
    #[arg(long, default_value_t = defaults::CHUNK_KIB, value_name = "KIB", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1 << 20))]
    pub chunk_kib: usize,
    /// Seconds after which a compute thread sends its pending rows even if its chunk is
    /// not full (bounds the work a killed run loses). 0 to 1e9.
    #[arg(long, default_value_t = defaults::FLUSH_SECONDS, value_name = "SECONDS", value_parser = number::seconds)]
    pub flush_seconds: f64,
    /// MPI: rank 0 ends the job, keeping the rows written so far for --resume, when a
    /// worker rank has sent nothing for this many seconds (stopped by SIGSTOP, hung, its
    /// node lost). Quiet workers send a heartbeat every min(limit/4, 5 s), so a long row
    /// is not silence. A number > 0, at most 1e9.
    #[arg(long, default_value_t = defaults::STALL_SECONDS, value_name = "SECONDS", value_parser = number::positive_seconds)]
    pub stall_seconds: f64,
    /// Start even when the free disk is less than the file's size before compression
    /// (the plan printed first gives both; zstd may make the file fit, and a run that
    /// fills the disk stops with a clear error and its rows kept for --resume).
    #[arg(long)]
    pub no_space_check: bool,
    /// Do not fsync the file at the end (faster; a power loss may lose the index).
    #[arg(long)]
    pub no_fsync: bool,
    /// No progress display: the global -q/--quiet, set by `dispatch`.
    #[arg(skip)]
    pub quiet: bool,
    /// Visibility against this mesh (any scene format by extension, same geometry,
    /// usually coarser) instead of the
    /// scene's own faces. Self-occlusion is then told apart by the patches' planes.
    #[arg(long, value_name = "COARSE.obj")]
    pub occluders: Option<PathBuf>,
    /// Keep the occluder triangles as given. By default the triangles of each plane
    /// (a wall or a ground split into facets) are merged into as few as cover the same
    /// area, which blocks the same segments and makes `--visibility exact` far faster on
    /// pre-split meshes; needed to resume a file computed before the merge existed.
    #[arg(long)]
    pub no_merge_occluders: bool,
}

/// The library's settings of a job from the arguments: the only place the command
/// line's values become the job's (the rules are the library's).
pub(super) fn settings(
    input: &SceneInput,
    output: PathBuf,
    o: &ComputeOptions,
) -> anyhow::Result<JobSettings> {
    Ok(JobSettings {
        scene: SceneSpec::parse(&input.scene)?,
        budget: match input.max_edge {
            Some(e) => PatchBudget::MaxEdge(e),
            None => PatchBudget::Target(input.patches),
        },
        strict: input.strict,
        daylight: input.daylight,
        output,
        form: FormSettings {
            preset: o.preset.into(),
            method: o.method.map(Into::into),
            visibility: o.visibility.map(Into::into),
            shadow_tol: o.shadow_tol,
            quad_tol: o.quad_tol,
            samples: o.samples,
            first_batch: o.first_batch,
            seed: o.seed,
            rows: RowMode::of(o.top_k, o.min_ff),
            top_k_search: o.top_k_search.map(Into::into),
            top_k_tail: o.top_k_tail,
            links: o.links.map(|LinksArg(l)| l),
            link_tol: o.link_tol,
        },
        half_rows: o.symmetric.into(),
        gather: o.gather,
        occluders: o.occluders.clone(),
        merge_occluders: !o.no_merge_occluders,
        threads: o.threads,
        schedule: o.schedule.into(),
        rows: o.rows.unwrap_or(RowsArg::All).into(),
        resume: o.resume,
        overwrite: o.force,
        writer: WriterOptions {
            zstd_level: o.zstd_level,
            chunk_bytes: o.chunk_kib * 1024,
            fsync: !o.no_fsync,
        },
        flush_seconds: o.flush_seconds,
        stall_seconds: o.stall_seconds,
        progress: !o.quiet,
        space_check: !o.no_space_check,
    })
}

/// Load a scene: an OBJ path, or builtin:NAME[:PARAM] (or a bare built-in name when no
/// file of that name exists).
pub(super) fn load_scene(spec: &str) -> anyhow::Result<Scene> {
    Ok(scene::open_scene(spec)?)
}

/// The scene's load warnings (those that matter for how it is lit: `input.daylight`):
/// an error under `--strict`, else printed when `print`.
pub(super) fn scene_warnings(input: &SceneInput, scene: &Scene, print: bool) -> anyhow::Result<()> {
    for w in ffstream::job::scene_warnings(scene, input.strict, input.daylight)? {
        if print {
            super::say(&format!("ffstream: warning: {w}"));
        }
    }
    Ok(())
}

/// `--links`: the most links a row carries, or none (`off`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct LinksArg(Option<u32>);

/// `--links`: a count of at least 1, or `off`.
fn links_arg(s: &str) -> Result<LinksArg, String> {
    match s {
        "off" => Ok(LinksArg(None)),
        _ => match s.parse::<u32>() {
            Ok(0) | Err(_) => Err(format!("{s} is not `off` or a count of at least 1")),
            Ok(m) => Ok(LinksArg(Some(m))),
        },
    }
}

/// A job built for `role`, its choices said on stderr.
fn job_for(settings: &JobSettings, role: Role) -> anyhow::Result<ComputeJob> {
    Ok(build_job(settings, role, &super::say)?)
}

/// Where this process stands after a compute: rank 0 / embedded get the report.
pub(super) enum Outcome {
    Master(ComputeReport),
    /// An MPI worker rank: it has nothing to report (rank 0 does).
    #[cfg_attr(not(feature = "mpi"), allow(dead_code))]
    Worker,
}

/// Run a compute job, under MPI when launched by mpirun, else embedded.
pub(super) fn execute(
    input: &SceneInput,
    output: PathBuf,
    o: &ComputeOptions,
) -> anyhow::Result<Outcome> {
    let settings = settings(input, output, o)?;
    settings.check_gather()?;
    #[cfg(feature = "mpi")]
    if ffstream::service::mpi::launched_by_mpi() {
        return execute_mpi(input, settings);
    }
    let job = job_for(&settings, Role::Alone)?;
    let report = if settings.gather {
        ffstream::service::gather::run_gather_embedded(&job)?
    } else {
        embedded(&job)?
    };
    Ok(Outcome::Master(report))
}

/// An embedded run, stopped cleanly by SIGINT or SIGTERM while it computes
/// ([`ffstream::service::interrupt`]).
fn embedded(job: &ComputeJob) -> anyhow::Result<ComputeReport> {
    let report = interrupt::while_computing(|| ffstream::service::embedded::run_embedded(job))
        .context(HANDLER)?;
    Ok(report?)
}

/// Why a run could not start: installing the signal handler failed.
const HANDLER: &str = "cannot install the SIGINT/SIGTERM handler";

#[cfg(feature = "mpi")]
fn execute_mpi(input: &SceneInput, mut settings: JobSettings) -> anyhow::Result<Outcome> {
    use ffstream::service::mpi::{agree_on_job, run, run_gather, MpiContext};
    use ffstream::service::role::{after_failure, AfterFailure, AWAIT_ABORT, BEFORE_ABORT};
    use ffstream::service::ServiceError;
    let ctx = MpiContext::init()?;
    if ctx.size() == 1 {
        // `mpirun -n 1`: nobody to compute for a pure master; run embedded.
        let job = job_for(&settings, Role::Alone)?;
        drop(ctx);
        return Ok(Outcome::Master(embedded(&job)?));
    }
    let rank = ctx.rank();
    let role = Role::of_rank(rank, settings.gather);
    let built = SceneSpec::parse(&scene_for_rank(input, rank).scene)
        .map_err(anyhow::Error::from)
        .and_then(|scene| {
            settings.scene = scene;
            job_for(&settings, role)
        })
        .map_err(|e| format!("{e:#}"));
    let result = agree_on_job(&ctx, built).and_then(|job| {
        if settings.gather {
            run_gather(&ctx, &job)
        } else {
            interrupt::while_computing(|| run(&ctx, &job))
                .map_err(|e| ServiceError::Transport(format!("{HANDLER}: {e}")))?
        }
    });
    let e = match result {
        Ok(Some(report)) => return Ok(Outcome::Master(report)),
        Ok(None) => return Ok(Outcome::Worker),
        Err(e) => e,
    };
    match after_failure(rank, &e) {
        AfterFailure::PassOn => Err(e.into()),
        AfterFailure::Abort { message } => {
            // One write, then a moment for mpirun to forward it (`BEFORE_ABORT`).
            super::say(&message);
            std::thread::sleep(BEFORE_ABORT);
            ctx.abort(1)
        }
        AfterFailure::AwaitAbort { message } => {
            if let Some(m) = message {
                super::say(&m);
            }
            ctx.await_abort(AWAIT_ABORT)
        }
    }
}

/// Test hook (`test-hooks` feature only, tests/README.md): `FFSTREAM_TEST_SCENE_RANK=R:SCENE`
/// makes rank R load SCENE instead, to exercise the start-up check that names a rank
/// whose scene differs or is missing. Without the feature, the scene given.
#[cfg(feature = "mpi")]
fn scene_for_rank(input: &SceneInput, rank: i32) -> SceneInput {
    #[cfg_attr(not(feature = "test-hooks"), allow(unused_mut))]
    let mut input = input.clone();
    #[cfg(not(feature = "test-hooks"))]
    let _ = rank;
    #[cfg(feature = "test-hooks")]
    if let Ok(v) = std::env::var("FFSTREAM_TEST_SCENE_RANK") {
        if let Some((r, scene)) = v.split_once(':') {
            if r.parse::<i32>() == Ok(rank) {
                input.scene = scene.to_string();
            }
        }
    }
    input
}

/// A run stopped cleanly by a signal ([`ServiceError::Interrupted`]) is said in one
/// line and ends with the shell's convention, 128 + the signal; any other error is
/// passed on.
///
/// [`ServiceError::Interrupted`]: ffstream::service::ServiceError::Interrupted
pub(super) fn stopped_by_signal(e: anyhow::Error) -> anyhow::Result<ExitCode> {
    match e.downcast_ref::<ffstream::service::ServiceError>() {
        Some(&ffstream::service::ServiceError::Interrupted { signal }) => Ok(stopped(signal)),
        _ => Err(e),
    }
}

/// Says that `signal` stopped the run and gives its exit code, 128 + the signal.
pub(super) fn stopped(signal: i32) -> ExitCode {
    let e = ffstream::service::ServiceError::Interrupted { signal };
    super::say(&format!("ffstream: {e}"));
    ExitCode::from(128u8.saturating_add(signal as u8))
}

/// The files a computation reads: the scene file and `--occluders`.
pub(super) fn compute_inputs<'a>(
    input: &'a SceneInput,
    o: &'a ComputeOptions,
) -> Vec<super::outputs::Named<'a>> {
    let mut inputs = Vec::new();
    if let Some(p) = super::outputs::scene_file(&input.scene) {
        inputs.push(("SCENE", p));
    }
    if let Some(p) = &o.occluders {
        inputs.push(("--occluders", p.as_path()));
    }
    inputs
}

pub(super) fn run(a: ComputeArgs) -> anyhow::Result<ExitCode> {
    super::outputs::check(&compute_inputs(&a.input, &a.opts), &[("-o", &a.output)])?;
    let outcome = match execute(&a.input, a.output.clone(), &a.opts) {
        Err(e) => return stopped_by_signal(e),
        Ok(o) => o,
    };
    match outcome {
        Outcome::Master(report) => {
            eprintln!("{}", report.summary());
            eprintln!("ffstream: wrote {}", a.output.display());
        }
        Outcome::Worker => {}
    }
    Ok(ExitCode::SUCCESS)
}
