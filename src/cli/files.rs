//! `ffstream info | verify | export`: thin wrappers over `ffstream::report::tools`.

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
    /// Compare row by row with this file (same scene): reports identical rows (every
    /// stored bit: entries, dropped mass, links with their slopes, link error), the
    /// largest difference of the entries, and rows present in only one of them.
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
    /// Leave entries below EPS out of --matrix, --sparse, --npz and --udales; default 0
    /// (every non-zero entry), and 5e-7 for --udales (the threshold uDALES keeps). A
    /// finite number ≥ 0.
    #[arg(long, value_name = "EPS", value_parser = super::choices::number::non_negative)]
    pub min_ff: Option<f64>,
    /// Write the files uDALES's energy balance reads into DIR (its experiment
    /// directory): vfsparse.inp.NNN (`i j F` lines, 1-based facets in STL order, no
    /// header, entries ≥ --min-ff, default 5e-7) and svf.inp.NNN (a header line, then
    /// each facet's sky view factor max(0, 1 - row sum)); prints the nnz and nfcts lines
    /// for namoptions.NNN. The file must be computed from an STL, one patch per facet
    /// (--max-edge longer than every edge, e.g. 1e9): anything else is refused.
    /// Light a row sends to clusters (links) or drops (top-k) has no place in
    /// vfsparse: its share is printed. docs/consumers.md §1.
    #[arg(long, value_name = "DIR")]
    pub udales: Option<PathBuf>,
    /// The experiment number NNN of the --udales files (as in namoptions.001; 1 to 3
    /// digits, written with three: 7 gives 007).
    #[arg(long, value_name = "NNN", default_value = "001", requires = "udales", value_parser = expnr)]
    pub expnr: String,
    /// The STL the file was computed from, when it is not at the path the file's header
    /// records (--udales checks every facet against the patch table).
    #[arg(long, value_name = "SCENE.stl", requires = "udales")]
    pub stl: Option<PathBuf>,
    /// Write the patches as a VTK unstructured grid (ParaView, meshio): one cell per
    /// patch with cell data patch, group, area, reflectance, emitted_exitance (RGB),
    /// row_sum, sky_view and dropped_mass (NaN for a missing row).
    #[arg(long, value_name = "patches.vtu")]
    pub vtu: Option<PathBuf>,
    /// Write the patch table as CSV (patch,group,area,cx,cy,cz,nx,ny,nz,rho_*,e_*,row_sum,sky_view;
    /// row_sum is the stored entries plus any top-k dropped mass, sky_view is 1 - row_sum).
    /// (`--patches` is the old spelling, kept for one release.)
    #[arg(long, alias = "patches", value_name = "patches.csv")]
    pub patches_csv: Option<PathBuf>,
}

pub(super) fn info(a: InfoArgs) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    ffstream::report::tools::info(&a.file, &mut out)?;
    Ok(ExitCode::SUCCESS)
}

pub(super) fn verify(a: VerifyArgs) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    let checks = ffstream::report::tools::VerifyChecks {
        against: a.against.as_deref(),
        row_sum_tol: a.row_sum_tol,
        unoccluded_tol: a.unoccluded,
    };
    let ok = ffstream::report::tools::print_checks(&a.file, checks, &mut out)?;
    Ok(if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(3)
    })
}

pub(super) fn export(a: ExportArgs) -> anyhow::Result<ExitCode> {
    let matrix_side = [&a.matrix, &a.sparse, &a.npz, &a.patches_csv, &a.vtu];
    if matrix_side.iter().all(|p| p.is_none()) && a.udales.is_none() {
        anyhow::bail!(
            "nothing to export: give --matrix F.mtx, --sparse F.txt, --npz F.npz, --patches-csv patches.csv, --vtu patches.vtu and/or --udales DIR"
        );
    }
    let udales_files = a
        .udales
        .as_deref()
        .map(|dir| ["vfsparse", "svf"].map(|f| dir.join(format!("{f}.inp.{}", a.expnr))));
    let mut outputs: Vec<_> = [
        ("--matrix", &a.matrix),
        ("--sparse", &a.sparse),
        ("--npz", &a.npz),
        ("--patches-csv", &a.patches_csv),
        ("--vtu", &a.vtu),
    ]
    .into_iter()
    .filter_map(|(o, p)| Some((o, p.as_deref()?)))
    .collect();
    if let Some(files) = &udales_files {
        outputs.extend(files.iter().map(|f| ("--udales", f.as_path())));
    }
    let mut inputs = vec![("FILE", a.file.as_path())];
    if let Some(stl) = &a.stl {
        inputs.push(("--stl", stl));
    }
    super::outputs::check(&inputs, &outputs)?;
    warn_of_gaps(&a.file)?;
    if matrix_side.iter().any(|p| p.is_some()) {
        let targets = ffstream::report::tools::ExportTargets {
            matrix: a.matrix.as_deref(),
            sparse: a.sparse.as_deref(),
            npz: a.npz.as_deref(),
            min_ff: a.min_ff.unwrap_or(0.0) as f32,
            patches_csv: a.patches_csv.as_deref(),
            vtu: a.vtu.as_deref(),
        };
        ffstream::report::tools::export(&a.file, targets)?;
    }
    if let Some(dir) = &a.udales {
        let min_ff = a
            .min_ff
            .map_or(ffstream::report::udales::UDALES_MIN_FF, |x| x as f32);
        udales(&a.file, dir, &a.expnr, min_ff, a.stl.as_deref())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// An experiment number as uDALES writes it (`cexpnr`, three digits): 1 to 3 digits,
/// zero-padded.
fn expnr(s: &str) -> Result<String, String> {
    if (1..=3).contains(&s.len()) && s.bytes().all(|b| b.is_ascii_digit()) {
        Ok(format!("{s:0>3}"))
    } else {
        Err(format!(
            "`{s}` is not an experiment number of 1 to 3 digits (uDALES's cexpnr)"
        ))
    }
}

/// `export --udales`: write the files, say what they leave out, print namoptions' lines.
fn udales(
    file: &std::path::Path,
    dir: &std::path::Path,
    expnr: &str,
    min_ff: f32,
    stl: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    let target = ffstream::report::udales::UdalesTarget {
        dir,
        expnr,
        min_ff,
        stl,
    };
    std::fs::create_dir_all(dir).map_err(|e| {
        anyhow::anyhow!(
            "{}: cannot create the --udales directory: {e}",
            dir.display()
        )
    })?;
    let rep = ffstream::report::udales::export_udales(file, target)?;
    eprintln!(
        "ffstream: wrote {} ({} entries ≥ {min_ff:e} of {} facets) and {}",
        rep.vfsparse.display(),
        rep.nnz,
        rep.n,
        rep.svf.display()
    );
    eprintln!(
        "ffstream: entries below {min_ff:e} left out of vfsparse carry {:.3e} of the emitted energy (area-weighted); the sky view factors count them as surface, as uDALES's do",
        rep.below_min_ff
    );
    if rep.dropped > 0.0 {
        let (row, most) = rep.dropped_max;
        let links = match rep.linked_rows {
            0 => String::new(),
            k => format!(", placed by links to clusters in {k} rows (spec §5.7)"),
        };
        eprintln!(
            "ffstream: the rows' dropped mass (the entries compute's --min-ff or --top-k left out{links}) is {:.3e} of the emitted energy (area-weighted; at most {most:.3e} of facet {}'s): vfsparse has no entries for it, as for the entries below the threshold; svf does not count it as sky",
            rep.dropped,
            row + 1
        );
    }
    if rep.svf_clamped > 0 {
        eprintln!(
            "ffstream: warning: {} facets' rows sum above 1: their sky view factor is written as 0",
            rep.svf_clamped
        );
    }
    println!("{}", rep.namoptions());
    Ok(())
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
