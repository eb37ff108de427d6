//! The job layer: what a compute run is asked, as typed settings, and the building of
//! the job the service runs from them. It sits above the scene, geometry,
//! form-factor, file and service layers and below the command line, which only turns
//! its arguments into [`JobSettings`] and calls [`build_job`]; tests and benchmarks
//! build their jobs the same way.
//!
//! [`settings`] holds what a job is asked and which settings go together, [`params`]
//! the header's run parameters, [`plan`] the plan and its disk check, `build.rs` the
//! building itself (the files are listed in docs/architecture.md §6).

mod build;
pub mod params;
pub mod plan;
pub mod settings;

pub use build::{build_job, scene_warnings};
pub use params::{EngineParams, RunParams};
pub use settings::{
    layout_of, threads_or_all, FormSettings, HalfRows, JobSettings, PatchBudget, RowMode,
};

use crate::formfactor::FormFactorError;
use crate::scene::SceneError;

/// Most patches a job may have: 2^26 (row ids are u32; the patch table alone is then
/// about 10 GB, and a dense f32 row 256 MiB per compute thread).
pub const MAX_PATCHES: usize = 1 << 26;

/// Most compute threads per process: far more than any node's cores, and few enough
/// that every thread can be started (16k threads aborted the process here).
pub const MAX_THREADS: usize = 4096;

/// Why a job could not be built (the error type of this layer). The messages name
/// the command-line options the settings mirror.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// Settings that do not go together or are out of range, a scene refused under
    /// `strict`, a patch count that is too large or zero.
    #[error("{0}")]
    Refused(String),
    /// The plan's disk check: the file would not fit.
    #[error("{0}")]
    Plan(String),
    /// A params string that does not read as [`RunParams`].
    #[error("run parameters: {0}")]
    Params(String),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    FormFactor(#[from] FormFactorError),
}
