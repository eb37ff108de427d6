//! Out-of-core radiosity: solve B = E + ρ F B from a stored form-factor matrix.
//!
//! The matrix never sits in memory. Rows come one at a time from a [`RowSource`] (the
//! `.ffz` reader, or [`MemoryRows`]); the solver keeps only vectors of n × 3K values
//! (K emission cases × RGB, all solved together so one pass over the file serves every
//! case and channel). Radiosity B and irradiance H are per unit area; E is the emitted
//! exitance (MTL `Ke`), ρ the diffuse reflectance (`Kd`) (docs/numerics.md §3).
//!
//! # Methods ([`SolveMethod`])
//! - `jacobi`: full sweeps B ← E + ρ F B, rows in file order (`jacobi.rs`).
//! - `gauss-seidel` (default): the same, updating B in place, rows in file order
//!   (`gauss_seidel.rs`): about half the sweeps of Jacobi, still one sequential scan
//!   per sweep.
//! - `shooting`: progressive refinement, one random-access row read per shot
//!   (`shooting.rs`); stops when the unshot power is below tolerance × emitted power.
//!
//! Convergence: the relative residual max_c ‖B − E − ρ F B‖∞ / ‖B‖∞ per column c
//! (case × channel), computed exactly on the returned B (see each method for how),
//! must be within [`SolveConfig::tolerance`].
//!
//! # Rows the solve reads
//! A patch that reflects nothing (ρ = 0 in every channel) has B = E: gathering never
//! reads its row (they are counted in [`Solution::rows_skipped`]), shooting never shoots
//! from it unless it emits. Rows of patches that neither reflect nor emit in any case
//! are never read at all, so files computed with only the needed rows suffice; their
//! irradiance comes by reciprocity (`check.rs`). A needed row that is missing or marked
//! Skipped is an error naming the row. The light top-k rows dropped goes into a pool
//! shared by the receivers that dropped it, so no light is lost (`pool.rs`; one more
//! scan before the solve), or the rows are scaled to their true sums (`rowview.rs`), or
//! it is absorbed ([`DroppedMass`]).
//!
//! # Files
//! - Radiosity CSV ([`write_csv`]): one file per case (`radiosity.csv`, or
//!   `radiosity_case0.csv`, ... for K > 1, see [`case_path`]), header
//!   `patch,group,area,B_r,B_g,B_b,E_r,E_g,E_b,rho_r,rho_g,rho_b,H_r,H_g,H_b`.
//! - Emission cases CSV ([`read_emission_cases`]), header `case,group,e_r,e_g,e_b`: one
//!   line per (case, group) giving that group's exitance in that case; groups a case
//!   does not list emit nothing in it; cases are numbered in order of first appearance
//!   and may be named by any string. Blank lines and lines starting with `#` are ignored.
//! - The lit mesh as PLY is written by the render layer (`render::write_ply`), with
//!   the vertices, colours and tone map of the picture.

mod adjoint;
mod cases;
mod check;
mod energy;
mod error;
mod ffz_source;
mod gauss_seidel;
mod jacobi;
mod links;
mod output;
mod pool;
mod rowview;
mod shooting;
mod source;
mod system;

use std::fmt;

use tracing::info_span;

pub use adjoint::{solve_adjoint, Adjoint};
pub use cases::{parse_emission_cases, read_emission_cases, EmissionCases, CASES_HEADER};
pub(crate) use energy::EnergyReport;
pub use error::SolveError;
pub use output::{
    case_path, format_group_table, group_table, read_radiosity_csv, write_csv, write_vtu, GroupRow,
    CSV_HEADER,
};
pub use source::{MemoryRows, RowSource};

use check::{final_pass, FinalPass, Mode};
use system::{column_max_abs, max_of, relative, System};

/// The iterative method.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SolveMethod {
    /// Progressive refinement (random access to rows).
    Shooting,
    /// Jacobi sweeps (sequential).
    Jacobi,
    /// Gauss–Seidel sweeps in file order (sequential).
    #[default]
    GaussSeidel,
}

impl SolveMethod {
    pub const ALL: [SolveMethod; 3] = [
        SolveMethod::Jacobi,
        SolveMethod::GaussSeidel,
        SolveMethod::Shooting,
    ];

    pub(crate) fn name(self) -> &'static str {
        match self {
            SolveMethod::Shooting => "shooting",
            SolveMethod::Jacobi => "jacobi",
            SolveMethod::GaussSeidel => "gauss-seidel",
        }
    }
}

impl fmt::Display for SolveMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What the solve does with the mass that top-k rows dropped (`Row::dropped`, the part
/// of a row's sum that no stored entry carries). Dense rows drop nothing and every
/// choice gives them the same answer. See `pool.rs` and `rowview.rs`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DroppedMass {
    /// The light that stored entries do not carry goes into one pool, shared among the
    /// reflecting patches in proportion to what each row dropped (an ambient term, as
    /// in Cohen, Chen, Wallace and Greenberg 1988). Conserves power exactly: a closed
    /// scene whose rows sum to 1 loses nothing.
    #[default]
    Pool,
    /// Scale each top-k row's kept entries by (stored + dropped) / stored: the row sums
    /// right, but the light the receiver lacks is taken from its kept senders only, and
    /// the columns no longer balance, so power is neither conserved nor well placed.
    Scale,
    /// Use the kept entries as stored: the dropped light is absorbed.
    Absorb,
}

impl DroppedMass {
    pub const ALL: [DroppedMass; 3] = [DroppedMass::Pool, DroppedMass::Scale, DroppedMass::Absorb];

    pub(crate) fn name(self) -> &'static str {
        match self {
            DroppedMass::Pool => "pool",
            DroppedMass::Scale => "scale",
            DroppedMass::Absorb => "absorb",
        }
    }
}

impl fmt::Display for DroppedMass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Settings of one solve.
#[derive(Clone, Debug)]
pub struct SolveConfig {
    pub method: SolveMethod,
    /// Relative residual to reach (shooting: unshot power / emitted power). Default 1e-6.
    pub tolerance: f64,
    /// Most sweeps (Jacobi, Gauss–Seidel) or shots / n (shooting). Default 10 000.
    pub max_iterations: usize,
    /// What to do with the mass top-k rows dropped. Default [`DroppedMass::Pool`].
    pub dropped: DroppedMass,
    /// Bytes the solve may hold to make its sweeps faster: the rows as read, and rows'
    /// links made ready to gather once instead of at every sweep (`links.rs`), half
    /// each. Default [`DEFAULT_CACHE_BYTES`]; 0 holds nothing (the same answer,
    /// slower).
    pub cache_bytes: usize,
    /// Called after every sweep (shooting: every n shots) with where the solve stands,
    /// for a progress display; `None` (the default) reports nothing. The command line
    /// prints one line a sweep unless `--quiet`.
    pub progress: Option<fn(&SweepProgress)>,
}

/// Where an iterative solve stands, given to [`SolveConfig::progress`].
#[derive(Clone, Copy, Debug)]
pub struct SweepProgress {
    pub method: SolveMethod,
    /// Sweeps done (shooting: shots).
    pub sweep: usize,
    /// The relative residual after it (Gauss–Seidel: its bound; shooting: the unshot
    /// power over the emitted), to compare with [`SolveConfig::tolerance`].
    pub residual: f64,
    /// Since the solve started.
    pub elapsed: std::time::Duration,
}

/// [`SolveConfig::cache_bytes`] by default: 2 GiB. At 100k patches with 256 links a
/// row both halves fit (the solve then holds 1.4 GB, bench/LINKS.md); at 1M part of
/// the rows is read from the file every sweep. There 2 GiB held the solve to 3.2 GB
/// peak against 4.2 GB with 3 GiB, and was not slower (8 min 25 s against 9 min 12 s,
/// the same answer to the bit).
pub const DEFAULT_CACHE_BYTES: usize = 2 << 30;

impl SolveConfig {
    /// Tells [`SolveConfig::progress`], if set, where the solve stands.
    pub(crate) fn report(
        &self,
        method: SolveMethod,
        sweep: usize,
        residual: f64,
        start: std::time::Instant,
    ) {
        if let Some(f) = self.progress {
            f(&SweepProgress {
                method,
                sweep,
                residual,
                elapsed: start.elapsed(),
            });
        }
    }
}

impl Default for SolveConfig {
    fn default() -> Self {
        SolveConfig {
            method: SolveMethod::default(),
            tolerance: 1e-6,
            max_iterations: 10_000,
            dropped: DroppedMass::Pool,
            cache_bytes: DEFAULT_CACHE_BYTES,
            progress: None,
        }
    }
}

/// The result of a solve. Vectors are indexed `[case][patch]`, RGB inside.
#[derive(Clone, Debug)]
pub struct Solution {
    pub method: SolveMethod,
    /// Radiosity B.
    pub b: Vec<Vec<[f64; 3]>>,
    /// Irradiance H = F B (what a sensor facing along the normal measures).
    pub h: Vec<Vec<[f64; 3]>>,
    /// The emission solved for (copied from the input, for the outputs).
    pub(crate) e: Vec<Vec<[f64; 3]>>,
    /// The reflectance solved with, per patch (copied from the input).
    pub(crate) rho: Vec<[f32; 3]>,
    /// Sweeps (Jacobi, Gauss–Seidel) or shots (shooting).
    pub iterations: usize,
    /// Sequential scans of the row source, final pass included.
    pub passes: usize,
    /// Rows read by random access (shooting).
    pub(crate) rows_read: u64,
    /// Relative residual max ‖B − E − ρ F B‖∞ / ‖B‖∞ over cases and channels.
    pub residual: f64,
    /// The stopping criterion was met (not just the iteration limit).
    pub converged: bool,
    /// Patches that reflect nothing, whose rows gathering does not read (per sweep).
    pub rows_skipped: usize,
    /// Power balance per case.
    pub energy: Vec<EnergyReport>,
    /// Things the user should know (incomplete irradiance, iteration limit, ...).
    pub warnings: Vec<String>,
}

impl Solution {
    pub fn cases(&self) -> usize {
        self.b.len()
    }

    /// Radiosity of one case as f32 (what the renderer takes).
    pub fn radiosity_f32(&self, case: usize) -> Vec<[f32; 3]> {
        self.b[case].iter().map(|v| v.map(|x| x as f32)).collect()
    }

    /// A few lines for the terminal: method, iterations, residual, energy per case.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "{}: {} {} ({} passes over the rows, {} random reads), residual {:.3e}{}, \
             {} non-reflecting rows skipped\n",
            self.method,
            self.iterations,
            if self.method == SolveMethod::Shooting {
                "shots"
            } else {
                "sweeps"
            },
            self.passes,
            self.rows_read,
            self.residual,
            if self.converged {
                ""
            } else {
                " (NOT converged)"
            },
            self.rows_skipped
        );
        for (k, e) in self.energy.iter().enumerate() {
            s += &format!("case {k} power (R G B):\n{e}\n");
        }
        for w in &self.warnings {
            s += &format!("warning: {w}\n");
        }
        s
    }
}

/// What a method hands back besides B.
pub(crate) struct Iterate {
    pub(crate) b: Vec<f64>,
    pub(crate) h: Vec<f64>,
    pub(crate) state: HState,
    pub(crate) iterations: usize,
    pub(crate) passes: usize,
    pub(crate) rows_read: u64,
    pub(crate) converged: bool,
}

/// How much of H (and the residual) a method already computed for its B.
pub(crate) enum HState {
    /// Everything (a final pass ran).
    Complete(FinalPass),
    /// H of reflecting patches and the residual per column (Jacobi).
    Reflecting(Vec<f64>),
    /// Nothing (shooting).
    Missing,
}

/// The scene's own emission (MTL `Ke`), as one emission case.
pub fn scene_emission(patches: &crate::patch::PatchSet) -> Vec<[f32; 3]> {
    patches.patches.iter().map(|p| p.emission).collect()
}

/// The scene's own reflectance (MTL `Kd`).
pub fn scene_reflectance(patches: &crate::patch::PatchSet) -> Vec<[f32; 3]> {
    patches.patches.iter().map(|p| p.rho).collect()
}

/// The solve's warnings about what it could not do: the iteration limit reached, light
/// of rows that are not stored, mass top-k rows dropped with nowhere to go.
fn solve_warnings(cfg: &SolveConfig, it: &Iterate, fp: &FinalPass, sys: &System) -> Vec<String> {
    let mut warnings = Vec::new();
    if !it.converged {
        warnings.push(format!(
            "{} stopped at the iteration limit ({} {}) before reaching tolerance {:e}",
            cfg.method,
            it.iterations,
            if cfg.method == SolveMethod::Shooting {
                "shots"
            } else {
                "sweeps"
            },
            cfg.tolerance
        ));
    }
    if let Some((first, count)) = fp.dark_sources_missing {
        warnings.push(format!(
            "irradiance H of non-reflecting patches lacks the light sent directly by {count} \
             non-reflecting emitting patch(es) whose rows are not stored (first: row {first})"
        ));
    }
    if let Some((first, count)) = sys.pool.as_ref().and_then(|p| p.senders_without_rows) {
        warnings.push(format!(
            "{count} emitting patch(es) have no stored row (first: row {first}): the light \
             of theirs that the other rows' kept entries do not carry cannot be pooled \
             and is lost"
        ));
    }
    if let Some((count, first, total)) = sys.lost_mass() {
        warnings.push(match sys.pool {
            Some(_) => format!(
                "{count} top-k row(s) store nothing but have dropped mass (first: row \
                 {first}; total {total:.3e}): their light reaches the other patches only \
                 through the pool, shared by a global rule; a larger --top-k, or links \
                 (--links in compute), place it"
            ),
            None => format!(
                "{count} top-k row(s) store nothing but have dropped mass (first: row \
                 {first}; total {total:.3e}): that light cannot be redistributed and is \
                 lost (absorbed); a larger --top-k keeps it"
            ),
        });
    }
    warnings
}

/// Solve B = E + ρ F B per RGB channel for every emission case in `emission_sets`
/// (each n values), with reflectance `rho` (n values), reading F from `src`.
///
/// # Errors
/// [`SolveError::InvalidInput`] for inconsistent inputs or settings; a needed row
/// missing, Skipped or malformed ([`SolveError::MissingRow`], [`SolveError::SkippedRow`],
/// [`SolveError::BadRow`], ...); the row source's own error.
pub fn solve(
    src: &dyn RowSource,
    emission_sets: &[Vec<[f32; 3]>],
    rho: &[[f32; 3]],
    cfg: &SolveConfig,
) -> Result<Solution, SolveError> {
    let _span = info_span!("solve", method = %cfg.method, cases = emission_sets.len()).entered();
    if !(cfg.tolerance.is_finite() && cfg.tolerance >= 0.0) {
        return Err(SolveError::InvalidInput(format!(
            "tolerance {} must be a finite number ≥ 0",
            cfg.tolerance
        )));
    }
    // Half the memory allowed for the rows as read, half for their links made ready.
    let held = source::Held::new(src, cfg.cache_bytes / 2);
    let src: &dyn RowSource = &held;
    let mut sys = System::new(src.patches(), emission_sets, rho, cfg.dropped)?;
    sys.prepare_links(src, cfg.cache_bytes / 2);
    if sys.links.is_some() && cfg.method == SolveMethod::Shooting {
        // Shooting reads row i as where i's light lands, which is the gathering rows'
        // transpose only for reciprocal rows: a link spreads its mass by area over the
        // cluster, which is the gather's model, not the shot's.
        return Err(SolveError::InvalidInput(
            "this file's rows link to clusters of patches (spec §5.7), which gathering \
             solvers read: use --solver gauss-seidel (the default) or jacobi"
                .into(),
        ));
    }
    let pool_passes = sys.prepare_pool(src)?;
    let mut it = match cfg.method {
        SolveMethod::Jacobi => jacobi::run(&sys, src, cfg)?,
        SolveMethod::GaussSeidel => gauss_seidel::run(&sys, src, cfg)?,
        SolveMethod::Shooting => shooting::run(&sys, src, cfg)?,
    };
    it.passes += pool_passes;
    let state = std::mem::replace(&mut it.state, HState::Missing);
    let fp = match state {
        HState::Complete(fp) => fp,
        HState::Reflecting(residual_abs) => {
            let mut fp = FinalPass {
                residual_abs,
                dark_sources_missing: None,
            };
            if !sys.dark.is_empty() {
                let dark = final_pass(&sys, src, &it.b, &mut it.h, Mode::DarkOnly)?;
                it.passes += 1;
                fp.dark_sources_missing = dark.dark_sources_missing;
            }
            fp
        }
        HState::Missing => {
            let fp = final_pass(&sys, src, &it.b, &mut it.h, Mode::Full)?;
            it.passes += 1;
            fp
        }
    };
    let residual_cols = relative(&fp.residual_abs, &column_max_abs(&it.b, sys.m));
    let mut warnings = solve_warnings(cfg, &it, &fp, &sys);
    let energy = energy::energy_reports(&sys, &it.b, &it.h);
    if let Some((case, fraction)) = energy::created_light(&energy) {
        warnings.push(format!(
            "case {case}: the escaped power is negative ({fraction:.2e} of the total): more light \
             arrives at the surfaces than leaves them, so some rows sum above 1 (faces that \
             repeat or overlap another, or rows that were not computed for this scene); \
             `ffstream verify` shows the row sums"
        ));
    }
    let split = |v: &[f64]| -> Vec<Vec<[f64; 3]>> {
        (0..sys.cases)
            .map(|k| {
                (0..sys.n)
                    .map(|i| std::array::from_fn(|ch| v[i * sys.m + 3 * k + ch]))
                    .collect()
            })
            .collect()
    };
    Ok(Solution {
        method: cfg.method,
        b: split(&it.b),
        h: split(&it.h),
        e: split(&sys.e),
        rho: rho.to_vec(),
        iterations: it.iterations,
        passes: it.passes,
        rows_read: it.rows_read,
        residual: max_of(&residual_cols),
        converged: it.converged,
        rows_skipped: sys.dark.len(),
        energy,
        warnings,
    })
}
