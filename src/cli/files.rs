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
    /// A row whose sum (stored + dropped mass) exceeds 1 + TOL fails the file (exit 3):
    /// more light would leave a patch towards the others than leaves it. A finite
    /// number ≥ 0.
    #[arg(long, value_name = "TOL", default_value_t = ffstream::ffz::ROW_SUM_TOL, value_parser = super::choices::number::non_negative)]
    pub row_sum_tol: f64,
    /// Also check every stored entry against its unoccluded form factor F0, recomputed
    /// from the patch table (contour kernel, no occluders): an entry above F0 (1 + TOL)
    /// fails the file, since visibility can only lower a form factor. Costs about a
    /// compute without visibility, on every core. TOL (default 1e-3) covers the float32
    /// rounding and the kernel error of the file's method.
    #[arg(long, value_name = "TOL", num_args = 0..=1, default_missing_value = "1e-3", value_parser = super::choices::number::non_negative)]
    pub unoccluded: Option<f64>,
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
    /// Write the matrix as a NumPy .npz of CSR arrays (data float32, indices, indptr,
    /// shape, format), the archive `scipy.sparse.save_npz` writes:
    /// `scipy.sparse.load_npz("F.npz")` opens it without ffstream's reader. Goes
    /// through a spill file of 8 bytes per entry beside it, or in TMPDIR when F.npz is
    /// a device (removed afterwards). Not to a pipe: the archive is written with seeks.
    #[arg(long, value_name = "F.npz")]
    pub npz: Option<PathBuf>,
    /// Leave entries below EPS out of --matrix, --sparse and --npz (uDALES keeps F ≥ 5e-7);
    /// default 0: every non-zero entry. A finite number ≥ 0.
    #[arg(long, value_name = "EPS", default_value_t = 0.0, value_parser = super::choices::number::non_negative)]
    pub min_ff: f64,
    /// Write the patch table as CSV (patch,group,area,cx,cy,cz,nx,ny,nz,rho_*,e_*,row_sum,sky_view;
    /// row_sum is the stored entries plus any top-k dropped mass, sky_view is 1 - row_sum).
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
    let checks = ffstream::ffz::tools::VerifyChecks {
        against: a.against.as_deref(),
        row_sum_tol: a.row_sum_tol,
        unoccluded_tol: a.unoccluded,
    };
    let ok = ffstream::ffz::tools::verify_with(&a.file, checks, &mut out)?;
    Ok(if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(3)
    })
}

pub(super) fn export(a: ExportArgs) -> anyhow::Result<ExitCode> {
    if a.matrix.is_none() && a.sparse.is_none() && a.npz.is_none() && a.patches_csv.is_none() {
        anyhow::bail!(
            "nothing to export: give --matrix F.mtx, --sparse F.txt, --npz F.npz and/or --patches-csv patches.csv"
        );
    }
    let outputs: Vec<_> = [
        ("--matrix", &a.matrix),
        ("--sparse", &a.sparse),
        ("--npz", &a.npz),
        ("--patches-csv", &a.patches_csv),
    ]
    .into_iter()
    .filter_map(|(o, p)| Some((o, p.as_deref()?)))
    .collect();
    super::outputs::check(&[("FILE", &a.file)], &outputs)?;
    warn_of_gaps(&a.file)?;
    let targets = ffstream::ffz::tools::ExportTargets {
        matrix: a.matrix.as_deref(),
        sparse: a.sparse.as_deref(),
        npz: a.npz.as_deref(),
        min_ff: a.min_ff as f32,
        patches_csv: a.patches_csv.as_deref(),
    };
    ffstream::ffz::tools::export(&a.file, targets)?;
    Ok(ExitCode::SUCCESS)
}

/// Says what an export of `file` will lack: the reader's warnings (an index unusable,
/// rows recovered by a scan) and the rows missing, which every output holds as empty
/// rows. A `.mtx` or `.txt` header names them, but an `.npz` archive has no place to
/// (issue 48, item 18: an export of a partial file exited 0 without a word). A
/// warning, not an error: exporting what a run has so far is a use. Opening the file
/// costs a scan when it has no index (the export's own pass is of the same order).
fn warn_of_gaps(file: &std::path::Path) -> anyhow::Result<()> {
    let r = ffstream::ffz::FfzReader::open(file)?;
    for w in r.warnings() {
        eprintln!("ffstream: warning: {w}");
    }
    let p = r.presence();
    if p.missing_count() > 0 {
        eprintln!(
            "ffstream: warning: {}: {} of its {} rows are missing (a run that did not finish; compute --resume completes it): the export holds them as empty rows",
            file.display(),
            p.missing_count(),
            r.n()
        );
    }
    Ok(())
}
