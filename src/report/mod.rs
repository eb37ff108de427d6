//! Reports and exports of `.ffz` files, for people and for other programs: what
//! `ffstream info` and `verify` print, `export` (Matrix Market, CSV, `.vtu`, `.npz`,
//! uDALES's files) and `verify --unoccluded`. They read files through the format layer
//! ([`crate::ffz`]) and never the other way round; their errors are the format layer's
//! [`FfzError`] (a report fails where reading or writing a file fails).
//!
//! The files are listed in docs/architecture.md §6.

pub mod npz;
mod staged;
pub mod tools;
pub mod udales;
mod unoccluded;

pub use unoccluded::{unoccluded_excess, UnoccludedReport, UNOCCLUDED_ABS_TOL};

use crate::ffz::FfzError;

/// The result of a report: a file's error on failure.
pub(crate) type Result<T, E = FfzError> = std::result::Result<T, E>;
