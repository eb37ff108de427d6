//! What a compute job is asked, as typed settings: the scene and its patch budget,
//! the form-factor settings as a preset plus the values given explicitly
//! ([`FormSettings`], merged in one place, [`FormSettings::config`]), the row mode,
//! half rows, the service's and the writer's settings ([`JobSettings`]).
//!
//! Every rule about which settings go together lives here: the command line only
//! converts its arguments into these structures. The refusals name the command-line
//! options, which these settings mirror one for one.

use std::path::PathBuf;

use crate::ffz::{Layout, WriterOptions};
use crate::formfactor::{FormFactorConfig, Method, Preset, TopKSearch, TopKTail, Visibility};
use crate::geometry::subdivide::DEFAULT_TARGET_PATCHES;
use crate::scene::SceneSpec;
use crate::service::{RowSelection, Schedule};

use super::JobError;

/// How fine the scene is cut into patches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PatchBudget {
    /// About this many patches (the longest edge is chosen for it).
    Target(usize),
    /// No patch edge longer than this, in scene units.
    MaxEdge(f64),
}

/// Which entries a row keeps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum RowMode {
    /// Every entry (`Layout::Dense`).
    #[default]
    Dense,
    /// The k largest (`--top-k K`).
    TopK(u32),
    /// The entries of at least `min_ff` (`--min-ff`), the k largest of them with
    /// `top_k`.
    Threshold { min_ff: f64, top_k: Option<u32> },
}

impl RowMode {
    /// The mode of `--top-k` and `--min-ff` as given.
    pub fn of(top_k: Option<u32>, min_ff: Option<f64>) -> Self {
        match (top_k, min_ff) {
            (None, None) => RowMode::Dense,
            (Some(k), None) => RowMode::TopK(k),
            (top_k, Some(min_ff)) => RowMode::Threshold { min_ff, top_k },
        }
    }

    fn top_k(self) -> Option<u32> {
        match self {
            RowMode::Dense => None,
            RowMode::TopK(k) => Some(k),
            RowMode::Threshold { top_k, .. } => top_k,
        }
    }

    fn min_ff(self) -> Option<f64> {
        match self {
            RowMode::Threshold { min_ff, .. } => Some(min_ff),
            _ => None,
        }
    }
}

/// Half rows (`--symmetric`): each unordered pair computed once and mirrored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HalfRows {
    /// On for dense `contour` rows, off otherwise (see [`JobSettings::half_rows`]).
    #[default]
    Auto,
    On,
    Off,
}

/// The form-factor settings: a preset and the values given explicitly on top of it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FormSettings {
    pub preset: Preset,
    pub method: Option<Method>,
    pub visibility: Option<Visibility>,
    pub shadow_tol: Option<f64>,
    pub quad_tol: Option<f64>,
    /// Visibility samples per pair; alone, all of them are cast (no early stop).
    pub samples: Option<u32>,
    pub first_batch: Option<u32>,
    pub seed: u64,
    pub rows: RowMode,
    pub top_k_search: Option<TopKSearch>,
    pub top_k_tail: Option<TopKTail>,
    /// The most links a row carries (`Some(None)`: no links); None: the preset's.
    pub links: Option<Option<u32>>,
    pub link_tol: Option<f64>,
}

impl FormSettings {
    /// The preset with the values given on top, validated; `half_rows` is the job's
    /// choice (half rows carry no links). An explicit `samples` without `first_batch`
    /// casts all its rays: the early stop is only ever asked for, never inherited from
    /// a preset's first batch.
    ///
    /// # Errors
    /// [`JobError::Refused`] for a value that does not apply to the method, the
    /// visibility or the row mode chosen, or is out of range.
    pub fn config(&self, half_rows: HalfRows) -> Result<FormFactorConfig, JobError> {
        let refuse = |m: &str| Err(JobError::Refused(m.to_string()));
        let mut cfg = FormFactorConfig::preset(self.preset);
        if let Some(m) = self.method {
            cfg.method = m;
        }
        if let Some(v) = self.visibility {
            cfg.visibility = v;
        }
        if let Some(t) = self.shadow_tol {
            if cfg.visibility != Visibility::Exact {
                return refuse("--shadow-tol applies to exact visibility: add --visibility exact (this preset's visibility is rays)");
            }
            cfg.shadow_tol = t;
        }
        if let Some(t) = self.quad_tol {
            if cfg.method != Method::Contour {
                return refuse("--quad-tol applies to --method contour only");
            }
            cfg.quad_tol = t;
        }
        if self.visibility.is_some() && cfg.method != Method::Contour {
            return refuse(&format!(
                "--visibility applies to --method contour only ({} finds visibility by its own rays)",
                cfg.method
            ));
        }
        if let Some(s) = self.samples {
            if s == 0 {
                return refuse("--samples must be at least 1");
            }
            cfg.samples = s;
            cfg.first_batch = s;
        }
        if let Some(b) = self.first_batch {
            if b == 0 {
                return refuse("--first-batch must be at least 1");
            }
            cfg.first_batch = b;
        }
        cfg.seed = self.seed;
        cfg.top_k = match self.rows.top_k() {
            Some(0) => return refuse("--top-k must be at least 1"),
            k => k,
        };
        cfg.min_ff = self.rows.min_ff();
        if !cfg.sparse_rows() && (self.top_k_search.is_some() || self.top_k_tail.is_some()) {
            return refuse(
                "--top-k-search and --top-k-tail apply to sparse rows: add --top-k K or --min-ff EPS",
            );
        }
        if let Some(search) = self.top_k_search {
            cfg.top_k_search = search;
        }
        if let Some(links) = self.links {
            cfg.links = links;
        }
        if let Some(tol) = self.link_tol {
            cfg.link_tol = tol;
        }
        if half_rows == HalfRows::On {
            // Half rows are cut to top-k after their merge, without the tree.
            cfg.links = None;
        }
        if let Some(tail) = self.top_k_tail {
            cfg.top_k_tail = tail;
        }
        if cfg.top_k_search == TopKSearch::Tree && cfg.top_k_tail == TopKTail::Exact {
            return refuse(
                "--top-k-tail exact evaluates every column, which the tree search exists to \
                 avoid: add --top-k-search exhaustive, or give a sample count",
            );
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

/// The file layout of `cfg`'s rows for `n` patches: threshold rows alone may hold up
/// to n entries.
pub fn layout_of(cfg: &FormFactorConfig, n: usize) -> Layout {
    match (cfg.top_k, cfg.min_ff) {
        (Some(k), _) => Layout::TopK { k },
        (None, Some(_)) => Layout::TopK {
            k: u32::try_from(n).unwrap_or(u32::MAX).max(1),
        },
        (None, None) => Layout::Dense,
    }
}

/// The defaults of the settings that do not change the rows, held here once for the
/// library ([`JobSettings::new`]) and the command line (its options' defaults).
pub mod defaults {
    /// zstd level of the row chunks.
    pub const ZSTD_LEVEL: i32 = 1;
    /// Target uncompressed size of a row chunk, in KiB.
    pub const CHUNK_KIB: usize = 1024;
    /// Seconds after which a compute thread sends its pending rows.
    pub const FLUSH_SECONDS: f64 = 5.0;
    /// MPI: seconds of silence after which rank 0 ends the job.
    pub const STALL_SECONDS: f64 = 600.0;
}

/// `threads`, or one per core.
pub fn threads_or_all(threads: Option<usize>) -> usize {
    threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// Everything a compute job is asked.
#[derive(Clone, Debug)]
pub struct JobSettings {
    /// The scene as named, and what the name stands for (a mesh file in a format, or a
    /// built-in scene and its parameter); the header records the name as `scene_path`.
    pub scene: SceneSpec,
    pub budget: PatchBudget,
    /// A scene that loads with warnings is refused.
    pub strict: bool,
    /// The scene is lit by daylight (`annual`): no emitter is no fault.
    pub daylight: bool,
    pub output: PathBuf,
    pub form: FormSettings,
    pub half_rows: HalfRows,
    /// The paper's dense baseline (`--gather`): rank 0 gathers the matrix in memory.
    pub gather: bool,
    /// Visibility against this mesh instead of the scene's own faces.
    pub occluders: Option<PathBuf>,
    /// Merge each plane's occluder triangles into fewer (off: `--no-merge-occluders`).
    pub merge_occluders: bool,
    /// Compute threads per process or worker rank; None: one per core.
    pub threads: Option<usize>,
    pub schedule: Schedule,
    pub rows: RowSelection,
    pub resume: bool,
    pub overwrite: bool,
    pub writer: WriterOptions,
    pub flush_seconds: f64,
    pub stall_seconds: f64,
    pub progress: bool,
    /// Refuse a run whose file the free disk cannot hold (off: `--no-space-check`).
    pub space_check: bool,
}

impl JobSettings {
    /// The settings `ffstream compute SCENE -o OUTPUT` runs with when no other option
    /// is given (the accurate preset, dense rows, about 2000 patches, all cores).
    pub fn new(scene: SceneSpec, output: impl Into<PathBuf>) -> Self {
        JobSettings {
            scene,
            budget: PatchBudget::Target(DEFAULT_TARGET_PATCHES),
            strict: false,
            daylight: false,
            output: output.into(),
            form: FormSettings::default(),
            half_rows: HalfRows::Auto,
            gather: false,
            occluders: None,
            merge_occluders: true,
            threads: None,
            schedule: Schedule::Dynamic,
            rows: RowSelection::All,
            resume: false,
            overwrite: false,
            writer: WriterOptions {
                zstd_level: defaults::ZSTD_LEVEL,
                chunk_bytes: defaults::CHUNK_KIB * 1024,
                fsync: true,
            },
            flush_seconds: defaults::FLUSH_SECONDS,
            stall_seconds: defaults::STALL_SECONDS,
            progress: true,
            space_check: true,
        }
    }

    /// The compute threads: as set, or one per core.
    pub fn threads_or_all(&self) -> usize {
        threads_or_all(self.threads)
    }

    /// Refuses what `--gather` (the paper's dense design, written at the end) cannot
    /// do: sparse rows and resuming.
    ///
    /// # Errors
    /// [`JobError::Refused`] naming the option.
    pub fn check_gather(&self) -> Result<(), JobError> {
        let refuse = |m: &str| Err(JobError::Refused(m.to_string()));
        if self.gather && self.form.rows.min_ff().is_some() {
            return refuse(
                "--gather reproduces the paper's dense design and cannot be combined with --min-ff",
            );
        }
        if self.gather && self.form.rows.top_k().is_some() {
            return refuse(
                "--gather reproduces the paper's dense design and cannot be combined with --top-k",
            );
        }
        if self.gather && self.resume {
            return refuse("--gather writes the file at the end only: it cannot resume");
        }
        Ok(())
    }

    /// Whether the run computes half rows (`--symmetric`) with `cfg`.
    ///
    /// # Errors
    /// [`JobError::Refused`] when half rows are asked for where they cannot be.
    pub fn half_rows(&self, cfg: &FormFactorConfig) -> Result<bool, JobError> {
        // Half rows mirror F_ij into F_ji = F_ij A_i / A_j. That is the other direction
        // only for `contour` (exact unoccluded part, symmetric visibility estimate): the
        // `point` and `mc` baselines clamp each direction to 1 on their own, and a
        // mirrored clamped value can exceed 1 (row sums of 4.5 seen on the Cornell box
        // with mc).
        let halves_ok = cfg.method == Method::Contour;
        let refuse = |m: String| Err(JobError::Refused(m));
        match (self.half_rows, self.gather) {
            (HalfRows::On, true) => refuse(
                "--gather is the paper's full-row baseline: it cannot be combined with --symmetric on".into(),
            ),
            (HalfRows::On, false) if !halves_ok => refuse(format!(
                "--symmetric on needs --method contour: the {} kernel clamps each direction to 1, so its mirror is not its other direction",
                cfg.method
            )),
            (HalfRows::On, false) if cfg.min_ff.is_some() => refuse(
                "--symmetric on cannot be combined with --min-ff: a half row does not know which \
                 of its mirrored entries will pass the threshold (use --symmetric off)"
                    .into(),
            ),
            (HalfRows::On, false) => Ok(true),
            (HalfRows::Off, _) | (HalfRows::Auto, true) => Ok(false),
            (HalfRows::Auto, false) => Ok(!cfg.sparse_rows() && halves_ok),
        }
    }
}
