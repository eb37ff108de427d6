//! `ffstream compute`: build the job from the arguments (every MPI rank does this itself)
//! and run it embedded or under MPI.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{bail, Context};
use clap::Args;

use ffstream::ffz::{FileMeta, Layout, WriterOptions};
use ffstream::formfactor::{
    FormFactorConfig, Method, RowEngine, TopKSearch, TopKTail, Visibility, MAX_SAMPLES,
};
use ffstream::geometry::merge::OccluderMesh;
use ffstream::geometry::subdivide::{default_max_edge, patch_count, subdivide};
use ffstream::patch::PatchSet;
use ffstream::scene::{self, Scene};
#[cfg(feature = "mpi")]
use ffstream::service::ServiceError;
use ffstream::service::{interrupt, ComputeJob, ComputeReport};

use super::choices::{
    number, top_k_tail, MethodArg, PresetArg, RowsArg, ScheduleArg, SymmetricArg, TopKSearchArg,
    VisibilityArg,
};
use super::SceneInput;

/// Most patches a job may have: 2^26 (row ids are u32; the patch table alone is then
/// about 10 GB, and a dense f32 row 256 MiB per compute thread).
pub(super) const MAX_PATCHES: usize = 1 << 26;

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
    /// mass / √N; a tail of at most 2N patches is evaluated in full). Default: the preset's (fast 128,
    /// accurate 256, reference exact).
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
    #[arg(long, default_value_t = 1, value_name = "LEVEL", value_parser = clap::value_parser!(i32).range(1..=22))]
    pub zstd_level: i32,
    /// Target uncompressed size of a row chunk, in KiB (1 to 1048576, i.e. 1 GiB; a
    /// chunk holds at least one row).
    #[arg(long, default_value_t = 1024, value_name = "KIB", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1 << 20))]
    pub chunk_kib: usize,
    /// Seconds after which a compute thread sends its pending rows even if its chunk is
    /// not full (bounds the work a killed run loses). 0 to 1e9.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS", value_parser = number::seconds)]
    pub flush_seconds: f64,
    /// MPI: rank 0 ends the job, keeping the rows written so far for --resume, when a
    /// worker rank has sent nothing for this many seconds (stopped by SIGSTOP, hung, its
    /// node lost). Quiet workers send a heartbeat every min(limit/4, 5 s), so a long row
    /// is not silence. A number > 0, at most 1e9.
    #[arg(long, default_value_t = 600.0, value_name = "SECONDS", value_parser = number::positive_seconds)]
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

impl ComputeOptions {
    /// `--threads`, or one per core.
    pub(super) fn threads_or_all(&self) -> usize {
        self.threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
    }
}

/// Load a scene: an OBJ path, or builtin:NAME[:PARAM] (or a bare built-in name when no
/// file of that name exists).
pub(super) fn load_scene(spec: &str) -> anyhow::Result<Scene> {
    Ok(scene::open_scene(spec)?)
}

/// The scene's load warnings (those that matter for how it is lit: `input.daylight`):
/// an error under `--strict`, else printed when `print`.
pub(super) fn scene_warnings(input: &SceneInput, scene: &Scene, print: bool) -> anyhow::Result<()> {
    let warnings: Vec<&String> = scene.warnings_for(input.daylight).collect();
    if input.strict {
        if let Some(first) = warnings.first() {
            let more = match warnings.len() - 1 {
                0 => String::new(),
                m => format!(" (and {m} more warning(s))"),
            };
            bail!("--strict refuses this scene: {first}{more}");
        }
    }
    if print {
        for w in warnings {
            super::say(&format!("ffstream: warning: {w}"));
        }
    }
    Ok(())
}

/// What a process does in a run, which decides what [`build_job`] builds and prints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Role {
    /// Computes rows and writes the file: an embedded run, or rank 0 of `--gather`.
    Alone,
    /// Rank 0 of a streaming MPI run: writes the file and computes nothing, so it
    /// builds no occluder hierarchy and no row engine (only what the file header
    /// needs, e.g. the number of occluder triangles).
    Master,
    /// An MPI worker (its rank): computes rows and prints nothing of the set-up but
    /// what only an engine knows (the first worker says which convex solids it found).
    Worker(i32),
}

/// Everything built from the scene: patches and, unless `role` is the I/O master, the
/// engine. The master and a process running alone print what was chosen.
pub(super) fn build_job(
    input: &SceneInput,
    output: PathBuf,
    o: &ComputeOptions,
    role: Role,
) -> anyhow::Result<ComputeJob> {
    // The settings first: a refused option costs no scene loading.
    let cfg = form_factor_config(o)?;
    let setup_start = std::time::Instant::now();
    let scene = tracing::info_span!("load_scene").in_scope(|| load_scene(&input.scene))?;
    let announce = !matches!(role, Role::Worker(_));
    scene_warnings(input, &scene, announce)?;
    let symmetric = symmetric_mode(o, &cfg)?;
    let threads = o.threads_or_all();
    let (count, max_edge) = patch_budget(input, &scene)?;
    if announce {
        // Printed and checked before subdividing: a file the disk cannot hold costs no
        // subdivision.
        super::plan::Plan {
            scene: &input.scene,
            output: &output,
            n: count as u64,
            faces: scene.faces.len() as u64,
            target: input.max_edge.is_none().then_some(input.patches as u64),
            layout: layout_of(&cfg, count),
            threshold: cfg.min_ff,
            symmetric,
            threads: threads as u64,
            chunk_bytes: (o.chunk_kib * 1024) as u64,
            occluder_triangles: scene.triangles().count() as u64,
            resume: o.resume,
            no_space_check: o.no_space_check,
        }
        .check()?;
    }
    let patches = subdivided(input, &scene, max_edge, announce)?;
    let (engine, description) = engine_for(role, o, &scene, &patches, &cfg, announce)?;
    let took = setup_start.elapsed().as_secs_f64();
    match role {
        // Every process that computes does this set-up itself; this is its cost
        // (docs/cluster.md §2: why ranks load the scene rather than receive it).
        Role::Alone => super::say(&format!(
            "ffstream: set-up (load, subdivide, Bvh, engine) took {took:.3} s"
        )),
        Role::Master => super::say(&format!(
            "ffstream: set-up of rank 0 (load, subdivide) took {took:.3} s; it builds no \
             Bvh or engine, every worker builds its own"
        )),
        Role::Worker(_) => {}
    }
    let meta = FileMeta {
        layout: layout_of(&cfg, patches.len()),
        method: cfg.method.to_string(),
        params: format!(
            "{} max_edge={max_edge} scene_path={}{}{}",
            description,
            param_value(&input.scene),
            // Half rows give (slightly) different numbers from full rows, so a resume
            // must use the same mode: the header says which one.
            if symmetric { " pairs=half" } else { "" },
            match &o.occluders {
                Some(p) => format!(" occluders_path={}", param_value(&p.to_string_lossy())),
                None => String::new(),
            }
        ),
        scene_hash: patches.content_hash(),
        created: creation_info(),
        patches: (*patches).clone(),
        clusters: match symmetric {
            true => None,
            false => RowEngine::cluster_order_of(&patches, &cfg),
        },
    };
    Ok(ComputeJob {
        output,
        meta,
        patches,
        engine,
        resume: o.resume,
        overwrite: o.force,
        schedule: o.schedule.into(),
        symmetric,
        rows: o.rows.unwrap_or(RowsArg::All).into(),
        threads,
        writer: WriterOptions {
            zstd_level: o.zstd_level,
            chunk_bytes: o.chunk_kib * 1024,
            fsync: !o.no_fsync,
        },
        flush_seconds: o.flush_seconds,
        progress: !o.quiet,
        stall_seconds: o.stall_seconds,
    })
}

/// Most compute threads per process: far more than any node's cores, and few enough
/// that every thread can be started (16k threads aborted the process here).
const MAX_THREADS: usize = 4096;

/// The file layout of `cfg`'s rows for `n` patches: threshold rows alone may hold up
/// to n entries.
fn layout_of(cfg: &FormFactorConfig, n: usize) -> Layout {
    match (cfg.top_k, cfg.min_ff) {
        (Some(k), _) => Layout::TopK { k },
        (None, Some(_)) => Layout::TopK {
            k: u32::try_from(n).unwrap_or(u32::MAX).max(1),
        },
        (None, None) => Layout::Dense,
    }
}

/// The edge (`--max-edge`, or the one that gives about `--patches`) and the number of
/// patches it makes, refused before anything is allocated when there would be too many.
fn patch_budget(input: &SceneInput, scene: &Scene) -> anyhow::Result<(usize, f64)> {
    let max_edge = input
        .max_edge
        .unwrap_or_else(|| default_max_edge(scene, input.patches));
    // Refuse before allocating: a tiny --max-edge (or a huge --patches) would otherwise
    // abort on a failed allocation instead of giving an error.
    let count = patch_count(scene, max_edge);
    if count > MAX_PATCHES {
        bail!(
            "{}: max edge {max_edge:e} gives {count} patches, more than the {MAX_PATCHES} \
             supported (row ids are 32-bit and the patch table is held in memory); \
             use a larger --max-edge or a smaller --patches",
            input.scene
        );
    }
    Ok((count, max_edge))
}

/// The patches of `scene` at `max_edge` (announced when `announce`); an error when
/// there are none.
fn subdivided(
    input: &SceneInput,
    scene: &Scene,
    max_edge: f64,
    announce: bool,
) -> anyhow::Result<Arc<PatchSet>> {
    let patches =
        Arc::new(tracing::info_span!("subdivide").in_scope(|| subdivide(scene, max_edge)));
    if announce {
        let how = if input.max_edge.is_some() {
            "given"
        } else {
            "chosen for about --patches"
        };
        // Six decimals as always, but never the 309 digits of 1.8e308.
        let edge = match max_edge {
            e if (1e-4..1e6).contains(&e) => format!("{e:.6}"),
            e => ffstream::brief_number(e),
        };
        super::say(&format!(
            "ffstream: {} faces -> {} patches (max edge {edge} scene units, {how})",
            scene.faces.len(),
            patches.len()
        ));
    }
    if patches.is_empty() {
        bail!("{}: the scene has no patches", input.scene);
    }
    Ok(patches)
}

/// The preset with the options given explicitly on top, validated. An explicit
/// `--samples` without `--first-batch` casts all its rays: the early stop is only ever
/// asked for, never inherited from a preset's first batch.
fn form_factor_config(o: &ComputeOptions) -> anyhow::Result<FormFactorConfig> {
    let mut cfg = FormFactorConfig::preset(o.preset.into());
    if let Some(m) = o.method {
        cfg.method = m.into();
    }
    if let Some(v) = o.visibility {
        cfg.visibility = v.into();
    }
    if let Some(t) = o.shadow_tol {
        if cfg.visibility != Visibility::Exact {
            bail!("--shadow-tol applies to exact visibility: add --visibility exact (this preset's visibility is rays)");
        }
        cfg.shadow_tol = t;
    }
    if let Some(t) = o.quad_tol {
        if cfg.method != Method::Contour {
            bail!("--quad-tol applies to --method contour only");
        }
        cfg.quad_tol = t;
    }
    if o.visibility.is_some() && cfg.method != Method::Contour {
        bail!(
            "--visibility applies to --method contour only ({} finds visibility by its own rays)",
            cfg.method
        );
    }
    if let Some(s) = o.samples {
        if s == 0 {
            bail!("--samples must be at least 1");
        }
        cfg.samples = s;
        cfg.first_batch = s;
    }
    if let Some(b) = o.first_batch {
        if b == 0 {
            bail!("--first-batch must be at least 1");
        }
        cfg.first_batch = b;
    }
    cfg.seed = o.seed;
    cfg.top_k = match o.top_k {
        Some(0) => bail!("--top-k must be at least 1"),
        k => k,
    };
    cfg.min_ff = o.min_ff;
    if !cfg.sparse_rows() && (o.top_k_search.is_some() || o.top_k_tail.is_some()) {
        bail!(
            "--top-k-search and --top-k-tail apply to sparse rows: add --top-k K or --min-ff EPS"
        );
    }
    if let Some(search) = o.top_k_search {
        cfg.top_k_search = search.into();
    }
    if let Some(LinksArg(links)) = o.links {
        cfg.links = links;
    }
    if let Some(tol) = o.link_tol {
        cfg.link_tol = tol;
    }
    if o.symmetric == SymmetricArg::On {
        // Half rows are cut to top-k after their merge, without the tree.
        cfg.links = None;
    }
    if let Some(tail) = o.top_k_tail {
        cfg.top_k_tail = tail;
    }
    if cfg.top_k_search == TopKSearch::Tree && cfg.top_k_tail == TopKTail::Exact {
        bail!(
            "--top-k-tail exact evaluates every column, which the tree search exists to \
             avoid: add --top-k-search exhaustive, or give a sample count"
        );
    }
    cfg.validate()?;
    Ok(cfg)
}

/// The row engine of a process that computes (none for the I/O master, which only
/// needs the header's description), and that description.
fn engine_for(
    role: Role,
    o: &ComputeOptions,
    scene: &Scene,
    patches: &PatchSet,
    cfg: &FormFactorConfig,
    announce: bool,
) -> anyhow::Result<(Option<Arc<RowEngine>>, String)> {
    let occluder_triangles: Vec<_> = match &o.occluders {
        Some(path) => scene::load_file(path, scene::SceneFormat::of_path(path))?
            .triangles()
            .collect(),
        None => scene.triangles().collect(),
    };
    // A foreign occluder mesh is not in the scene hash: its content goes into the
    // header (a resume compares it; where it was read from it does not).
    let foreign = match &o.occluders {
        Some(_) => format!(
            " occluders_hash={:#018x}",
            triangles_hash(&occluder_triangles)
        ),
        None => String::new(),
    };
    // Coplanar triangles merged (they then belong to no one face: foreign); the header
    // keeps the count as given and records the merged count beside it.
    let mesh = tracing::info_span!("merge_occluders").in_scope(|| {
        OccluderMesh::prepare(
            occluder_triangles,
            o.occluders.is_some(),
            !o.no_merge_occluders,
        )
    });
    if let (Some((groups, kept)), true) = (mesh.merged, announce) {
        super::say(&format!(
            "ffstream: occluders: {} triangles, those of {groups} planes merged: {kept} \
             triangles block the same (--no-merge-occluders keeps them as given)",
            mesh.given
        ));
    }
    let description =
        RowEngine::description(cfg, mesh.given, mesh.other_mesh) + &mesh.header_note() + &foreign;
    if role == Role::Master {
        return Ok((None, description));
    }
    let occluders = Arc::new(tracing::info_span!("build_bvh").in_scope(|| mesh.build()));
    let engine = tracing::info_span!("prepare_engine")
        .in_scope(|| RowEngine::new(patches, occluders, cfg.clone()));
    // Under mpirun rank 0 builds no engine: the first worker says it (every rank
    // finds the same solids in the same scene).
    let who = match role {
        Role::Worker(1) => "rank 1: ",
        _ => "",
    };
    if let (Some((solids, triangles)), true) =
        (engine.solids_found(), announce || role == Role::Worker(1))
    {
        super::say(&format!(
            "ffstream: {who}exact visibility: {solids} convex solids ({triangles} occluder \
             triangles) cast their shadows whole"
        ));
    }
    Ok((Some(Arc::new(engine)), description))
}

/// `s` as one token of the header's params (spec §3.2: space-separated `key=value`):
/// `%`, white space and `=` percent-encoded.
fn param_value(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '%' | '=' => out.push_str(&format!("%{:02X}", c as u32)),
            c if c.is_whitespace() => {
                let mut b = [0; 4];
                for byte in c.encode_utf8(&mut b).bytes() {
                    out.push_str(&format!("%{byte:02X}"));
                }
            }
            c => out.push(c),
        }
    }
    out
}

/// XXH3-64 of triangles (their ids and the bits of their coordinates, in order).
fn triangles_hash(triangles: &[(u32, [glam::DVec3; 3])]) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    for (id, t) in triangles {
        h.update(&id.to_le_bytes());
        for c in t.iter().flat_map(|v| v.to_array()) {
            h.update(&c.to_bits().to_le_bytes());
        }
    }
    h.digest()
}

/// Whether the run computes half rows (`--symmetric`, see its help).
fn symmetric_mode(o: &ComputeOptions, cfg: &FormFactorConfig) -> anyhow::Result<bool> {
    // Half rows mirror F_ij into F_ji = F_ij A_i / A_j. That is the other direction
    // only for `contour` (exact unoccluded part, symmetric visibility estimate): the
    // `point` and `mc` baselines clamp each direction to 1 on their own, and a mirrored
    // clamped value can exceed 1 (row sums of 4.5 seen on the Cornell box with mc).
    let halves_ok = cfg.method == Method::Contour;
    Ok(match (o.symmetric, o.gather) {
        (SymmetricArg::On, true) => bail!(
            "--gather is the paper's full-row baseline: it cannot be combined with --symmetric on"
        ),
        (SymmetricArg::On, false) if !halves_ok => bail!(
            "--symmetric on needs --method contour: the {} kernel clamps each direction to 1, so its mirror is not its other direction",
            cfg.method
        ),
        (SymmetricArg::On, false) if cfg.min_ff.is_some() => bail!(
            "--symmetric on cannot be combined with --min-ff: a half row does not know which \
             of its mirrored entries will pass the threshold (use --symmetric off)"
        ),
        (SymmetricArg::On, false) => true,
        (SymmetricArg::Off, _) | (SymmetricArg::Auto, true) => false,
        (SymmetricArg::Auto, false) => !cfg.sparse_rows() && halves_ok,
    })
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

/// "ffstream VERSION, YYYY-MM-DD HH:MM:SS UTC, host HOST": for the file header.
fn creation_info() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    let (year, month, day) = ffstream::daylight::sun::civil_from_days(days);
    let host = std::fs::read_to_string("/etc/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default();
    format!(
        "ffstream {}, {year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC, host {}",
        env!("CARGO_PKG_VERSION"),
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        if host.is_empty() { "unknown" } else { &host }
    )
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
    if o.gather && o.min_ff.is_some() {
        bail!("--gather reproduces the paper's dense design and cannot be combined with --min-ff");
    }
    if o.gather && o.top_k.is_some() {
        bail!("--gather reproduces the paper's dense design and cannot be combined with --top-k");
    }
    if o.gather && o.resume {
        bail!("--gather writes the file at the end only: it cannot resume");
    }
    #[cfg(feature = "mpi")]
    if ffstream::service::mpi::launched_by_mpi() {
        return execute_mpi(input, output, o);
    }
    let job = build_job(input, output, o, Role::Alone)?;
    let report = if o.gather {
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

/// How long a failed rank waits for rank 0 to abort the job (it takes milliseconds:
/// rank 0 finishes the file first) before leaving on its own.
#[cfg(feature = "mpi")]
const AWAIT_ABORT: std::time::Duration = std::time::Duration::from_secs(120);

#[cfg(feature = "mpi")]
fn execute_mpi(input: &SceneInput, output: PathBuf, o: &ComputeOptions) -> anyhow::Result<Outcome> {
    use ffstream::service::mpi::{agree_on_job, run, run_gather, MpiContext};
    let ctx = MpiContext::init()?;
    if ctx.size() == 1 {
        // `mpirun -n 1`: nobody to compute for a pure master; run embedded.
        let job = build_job(input, output, o, Role::Alone)?;
        drop(ctx);
        return Ok(Outcome::Master(embedded(&job)?));
    }
    let rank = ctx.rank();
    let input = scene_for_rank(input, rank);
    let role = match (rank, o.gather) {
        (0, true) => Role::Alone, // the paper's baseline: rank 0 computes its share
        (0, false) => Role::Master,
        (rank, _) => Role::Worker(rank),
    };
    let built = build_job(&input, output, o, role).map_err(|e| format!("{e:#}"));
    let result = agree_on_job(&ctx, built).and_then(|job| {
        if o.gather {
            run_gather(&ctx, &job)
        } else {
            interrupt::while_computing(|| run(&ctx, &job))
                .map_err(|e| ServiceError::Transport(format!("{HANDLER}: {e}")))?
        }
    });
    match result {
        Ok(Some(report)) => Ok(Outcome::Master(report)),
        Ok(None) => Ok(Outcome::Worker),
        // Every rank has stopped cleanly and the file is closed: no abort.
        Err(e @ ServiceError::Interrupted { .. }) => Err(e.into()),
        Err(e) if rank == 0 => {
            // Rank 0 has finished the file with what it had; stop every rank.
            let mut message = format!("ffstream: error: {e}");
            if matches!(
                e,
                ServiceError::WorkerFailed { .. }
                    | ServiceError::WorkerStalled { .. }
                    | ServiceError::Transport(_)
            ) {
                message += "\nffstream: rows written so far are kept: rerun with --resume to complete the file";
            }
            // One write, then a moment for mpirun to forward it: on MPI_Abort, Open MPI
            // stops forwarding a rank's stderr, and a message written piece by piece was
            // seen cut after "ffstream: error: rank " (1 run in about 40).
            super::say(&message);
            std::thread::sleep(std::time::Duration::from_millis(300));
            ctx.abort(1)
        }
        Err(e) => {
            // Rank 0 names the failure and aborts the job: wait for that. A failed row
            // was sent to rank 0, which prints it: saying it here too would print it
            // twice.
            match e {
                ServiceError::WorkerFailed { .. } => {}
                ServiceError::Setup { .. } => super::say(&format!("ffstream: {e}")),
                _ => super::say(&format!("ffstream: rank {rank}: {e}")),
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
