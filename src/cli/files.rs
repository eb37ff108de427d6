//! `ffstream info | verify | export`: thin wrappers over `ffstream::ffz::tools`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

#[derive(Args, Debug)]
pub(crate) struct InfoArgs {
    /// The .ffz file.
    pub file: PathBuf,
}

#[derive(Args, Debug)]
pub(crate) struct VerifyArgs {
    /// The .ffz file.
    pub file: PathBuf,
    /// Compare row by row with this file (same scene): reports identical rows, the
    /// largest difference, and rows present in only one of them.
    #[arg(long, value_name = "OTHER.ffz")]
    pub against: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub(crate) struct ExportArgs {
    /// The .ffz file.
    pub file: PathBuf,
    /// Write the matrix as Matrix Market coordinate real general (1-based i j F_ij).
    #[arg(long, value_name = "F.mtx")]
    pub matrix: Option<PathBuf>,
    /// Write the matrix as sparse text, View3D/uDALES style: `#` header lines (source,
    /// n, what is left out), then one `i j F_ij` line per entry (1-based), rows in file
    /// order.
    #[arg(long, value_name = "F.txt")]
    pub sparse: Option<PathBuf>,
    /// Leave entries below EPS out of --matrix and --sparse (uDALES keeps F ≥ 5e-7);
    /// default 0: every non-zero entry. A finite number ≥ 0.
    #[arg(long, value_name = "EPS", default_value_t = 0.0, value_parser = super::choices::number::non_negative)]
    pub min_ff: f64,
    /// Write the patch table as CSV (patch,group,area,cx,cy,cz,nx,ny,nz,rho_*,e_*).
    /// (`--patches` is the old spelling, kept for one release.)
    #[arg(long, alias = "patches", value_name = "patches.csv")]
    pub patches_csv: Option<PathBuf>,
}

pub(super) fn info(a: InfoArgs) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    ffstream::ffz::tools::info(&a.file, &mut out)?;
    Ok(ExitCode::SUCCESS)
}

pub(super) fn verify(a: VerifyArgs) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    let ok = ffstream::ffz::tools::verify(&a.file, a.against.as_deref(), &mut out)?;
    Ok(if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(3)
    })
}

pub(super) fn export(a: ExportArgs) -> anyhow::Result<ExitCode> {
    if a.matrix.is_none() && a.sparse.is_none() && a.patches_csv.is_none() {
        anyhow::bail!(
            "nothing to export: give --matrix F.mtx, --sparse F.txt and/or --patches-csv patches.csv"
        );
    }
    let targets = ffstream::ffz::tools::ExportTargets {
        matrix: a.matrix.as_deref(),
        sparse: a.sparse.as_deref(),
        min_ff: a.min_ff as f32,
        patches_csv: a.patches_csv.as_deref(),
    };
    ffstream::ffz::tools::export(&a.file, targets)?;
    Ok(ExitCode::SUCCESS)
}
