//! `export --udales`: the view factors in the files the urban-climate model uDALES reads
//! as they are (github.com/uDALES/u-dales), so ffstream can stand in for View3D in its
//! preprocessing.
//!
//! What uDALES reads (checked against its sources: `src/initfac.f90` reads the files,
//! `tools/python/udgeom/view3d.py` writes them, `src/modEB.f90` uses them):
//! - `vfsparse.inp.NNN`: no header; one `i j F` line per entry, read with the
//!   list-directed `read(unit, *) i, j, F` exactly `nnz` times, where `nnz` is set in
//!   the `&ENERGYBALANCE` group of `namoptions.NNN` (with `lvfsparse = .true.`). `i` and
//!   `j` are 1-based facet numbers in the order of the STL file; `F` is the view factor
//!   from facet `i` to facet `j` (the energy balance adds `F * emission(j)` to facet
//!   `i`'s incoming long wave), ffstream's `F_ij`. uDALES's own writer keeps entries
//!   ≥ 5e-7, sorted by row; the reader needs no order, so rows come in file order here.
//! - `svf.inp.NNN`: one header line (the reader skips it with `read(unit, '(a80)')`),
//!   then one sky view factor per facet, `max(0, 1 − row sum)` as udprep's `compute_svf`
//!   takes it. ffstream's row sum includes what top-k dropped (spec §5.6, §5.7), so the
//!   sky view factor is that of the whole row, not of the thresholded entries.
//! - `NNN` is the experiment number, three digits (`cexpnr` is `character(3)`).
//!
//! The facets must be the STL's triangles in order, one patch each: the export refuses
//! a file computed from another format, with subdivision, or from an STL whose loading
//! dropped degenerate facets (those would shift every later facet number), and checks
//! the STL's facets against the patch table. A file computed with `--min-ff` or
//! `--top-k` keeps a row's small entries as its dropped mass, placed by links to
//! clusters of patches (spec §5.6, §5.7): uDALES's reader has no place for either, so
//! `vfsparse` holds the stored patch entries only and the dropped share is reported
//! (with `--min-ff 5e-7` it is the mass uDALES's own threshold drops), never silently
//! lost; the sky view factor counts it as surface, as uDALES's does.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::ffz::FfzError;

use super::staged::Staged;
use super::Result;
use crate::ffz::FfzReader;
use crate::rows::RowValues;
use crate::scene::{self, SceneFormat};

/// The threshold uDALES's preprocessing keeps view factors above by default
/// (`write_vfsparse(..., threshold=5e-7)` in `tools/python/udgeom/view3d.py`).
pub const UDALES_MIN_FF: f32 = 5e-7;

/// Where and how `export --udales` writes.
#[derive(Clone, Copy, Debug)]
pub struct UdalesTarget<'a> {
    /// Directory that receives `vfsparse.inp.NNN` and `svf.inp.NNN` (the experiment's).
    pub dir: &'a Path,
    /// Experiment number: three digits.
    pub expnr: &'a str,
    /// Entries below this are left out of `vfsparse` (uDALES: [`UDALES_MIN_FF`]).
    pub min_ff: f32,
    /// The STL the file was computed from, when not at the path its header records.
    pub stl: Option<&'a Path>,
}

/// What `export --udales` wrote and what the files leave out.
#[derive(Clone, Debug, PartialEq)]
pub struct UdalesReport {
    /// Facets (rows).
    pub n: u32,
    /// Lines of `vfsparse`: the `nnz` of `namoptions`.
    pub nnz: u64,
    pub vfsparse: PathBuf,
    pub svf: PathBuf,
    /// Σ_i A_i (entries of row i below the threshold) / Σ A_i: the share of the
    /// emitted energy whose entries are left out as too small.
    pub below_min_ff: f64,
    /// Σ_i A_i dropped_i / Σ A_i: the share sent through links to clusters or dropped
    /// by top-k, which `vfsparse` cannot hold.
    pub dropped: f64,
    /// The largest dropped mass of a row, and the row (0-based).
    pub dropped_max: (u32, f32),
    /// Rows with links to clusters (spec §5.7).
    pub linked_rows: u64,
    /// Rows whose sum is above 1, written with sky view factor 0.
    pub svf_clamped: u64,
}

impl UdalesReport {
    /// The lines to put in `namoptions.NNN`.
    pub fn namoptions(&self) -> String {
        format!(
            "&WALLS\nnfcts = {}\n/\n&ENERGYBALANCE\nlEB = .true.\nlvfsparse = .true.\nnnz = {}\n/",
            self.n, self.nnz
        )
    }
}

fn refuse(path: &Path, why: String) -> FfzError {
    FfzError::NotUdales {
        path: path.to_owned(),
        why,
    }
}

/// The value of `key=` in the header's params (spec §3.2), decoded.
fn param(params: &str, key: &str) -> Option<String> {
    crate::ffz::ParamList::parse(params)
        .get(key)
        .map(crate::ffz::params::decode_value)
}

/// The path of the STL a scene spec (as `compute` took it) names, or why it is none.
fn stl_of_spec(spec: &str) -> std::result::Result<PathBuf, String> {
    if spec.starts_with("builtin:") {
        return Err(format!(
            "it was computed from the built-in scene {spec}, not an STL file"
        ));
    }
    let (format, path) = match spec.split_once(':') {
        Some((name, p)) if SceneFormat::from_name(name).is_some() && !Path::new(spec).exists() => (
            SceneFormat::from_name(name).unwrap_or(SceneFormat::Obj),
            Path::new(p),
        ),
        _ => (SceneFormat::of_path(Path::new(spec)), Path::new(spec)),
    };
    match format {
        SceneFormat::Stl => Ok(path.to_owned()),
        _ => Err(format!(
            "it was computed from {spec}, not an STL file: uDALES numbers its facets in the order of its STL"
        )),
    }
}

/// Check that the patches of `r` are the facets of an STL in order, one patch each
/// (module docs), loading the STL from `stl` or from the path the header records.
fn check_facets(path: &Path, r: &FfzReader, stl: Option<&Path>) -> Result<()> {
    let m = r.meta();
    let spec = param(&m.params, "scene_path").ok_or_else(|| {
        refuse(
            path,
            "its header records no scene_path (a file from before ffstream kept it)".into(),
        )
    })?;
    let recorded = stl_of_spec(&spec).map_err(|why| refuse(path, why))?;
    let max_edge = param(&m.params, "max_edge").unwrap_or_else(|| "?".into());
    for (i, p) in m.patches.patches.iter().enumerate() {
        if p.face as usize != i || p.n_corners != 3 {
            return Err(refuse(
                path,
                format!(
                    "patch {i} is cut from facet {} ({} corners): the file was computed with subdivision (max_edge={max_edge}), and uDALES needs one patch per STL facet; compute with a --max-edge longer than every facet edge (e.g. --max-edge 1e9)",
                    p.face + 1,
                    p.n_corners
                ),
            ));
        }
    }
    let p = r.presence();
    if p.missing_count() > 0 || p.skipped_count() > 0 {
        return Err(refuse(
            path,
            format!(
                "{} rows are missing and {} skipped, and uDALES needs every facet's row (finish a run with compute --resume; compute with --rows all)",
                p.missing_count(),
                p.skipped_count()
            ),
        ));
    }
    let stl = stl.map_or(recorded, Path::to_owned);
    let scene = scene::load_file(&stl, SceneFormat::Stl).map_err(|e| {
        refuse(
            path,
            format!("its STL cannot be read to check the facet order ({e}); give it with --stl"),
        )
    })?;
    let s = stl.display();
    if scene.dropped > 0 {
        return Err(refuse(
            path,
            format!(
                "{s} has {} degenerate facets, which ffstream drops and uDALES counts: the facet numbers would differ; remove them from the STL",
                scene.dropped
            ),
        ));
    }
    if scene.faces.len() != m.patches.len() {
        return Err(refuse(
            path,
            format!(
                "{s} has {} facets, the file {} patches: not the STL it was computed from",
                scene.faces.len(),
                m.patches.len()
            ),
        ));
    }
    for (i, (f, p)) in scene.faces.iter().zip(&m.patches.patches).enumerate() {
        if f.corners[..] != p.corners[..3] {
            return Err(refuse(
                path,
                format!("facet {} of {s} is not patch {i} of the file: not the STL it was computed from", i + 1),
            ));
        }
    }
    Ok(())
}

/// Write `vfsparse.inp.NNN` and `svf.inp.NNN` for uDALES into `to.dir` (module docs):
/// one pass over the chunks, each file renamed into place once complete.
///
/// # Errors
/// Opening errors; [`FfzError::NotUdales`] when the patches are not the facets of an
/// STL in order, one each, or rows are missing (module docs; the error says why);
/// `Chunk` for a corrupt chunk; `Io` naming the output file.
pub fn export_udales(path: &Path, to: UdalesTarget<'_>) -> Result<UdalesReport> {
    if to.expnr.len() != 3 || !to.expnr.bytes().all(|b| b.is_ascii_digit()) {
        return Err(refuse(
            path,
            format!("experiment number `{}` is not three digits (uDALES's cexpnr, as in namoptions.001)", to.expnr),
        ));
    }
    let r = FfzReader::open(path)?;
    check_facets(path, &r, to.stl)?;
    let vfsparse = to.dir.join(format!("vfsparse.inp.{}", to.expnr));
    let svf = to.dir.join(format!("svf.inp.{}", to.expnr));
    let n = r.n();
    let mut report = UdalesReport {
        n,
        nnz: 0,
        vfsparse: vfsparse.clone(),
        svf: svf.clone(),
        below_min_ff: 0.0,
        dropped: 0.0,
        dropped_max: (0, 0.0),
        linked_rows: 0,
        svf_clamped: 0,
    };
    let (vf_staged, vf_file) = Staged::create(&vfsparse)?;
    let (svf_staged, svf_file) = match Staged::create(&svf) {
        Ok(s) => s,
        Err(e) => {
            vf_staged.discard();
            return Err(e);
        }
    };
    let mut sky = vec![0f64; n as usize];
    let written = write_vfsparse(&r, &vfsparse, vf_file, to.min_ff, &mut sky, &mut report)
        .and_then(|()| write_svf(&svf, svf_file, &sky));
    match written {
        Ok(()) => {
            vf_staged.commit()?;
            svf_staged.commit()?;
        }
        Err(e) => {
            vf_staged.discard();
            svf_staged.discard();
            return Err(e);
        }
    }
    report.svf_clamped = sky.iter().filter(|&&s| s < 0.0).count() as u64;
    let total_area: f64 = r.meta().patches.patches.iter().map(|p| p.area).sum();
    if total_area > 0.0 {
        report.below_min_ff /= total_area;
        report.dropped /= total_area;
    }
    Ok(report)
}

/// The entries of every row ≥ `min_ff` as `i j F` lines into `f` (the file at `out`);
/// each row's `1 − row sum` into `sky`, its losses into `report`.
fn write_vfsparse(
    r: &FfzReader,
    out: &Path,
    f: std::fs::File,
    min_ff: f32,
    sky: &mut [f64],
    report: &mut UdalesReport,
) -> Result<()> {
    let patches = &r.meta().patches.patches;
    let mut w = BufWriter::with_capacity(1 << 20, f);
    let mut werr = None;
    r.scan(|row| {
        let i = row.index as usize;
        let area = patches[i].area;
        let mut below = 0f64;
        row.for_each_nonzero(|j, x| {
            if x < min_ff {
                below += f64::from(x);
            } else if werr.is_none() {
                report.nnz += 1;
                if let Err(e) = writeln!(w, "{} {} {x:e}", i + 1, j as u64 + 1) {
                    werr = Some(e);
                }
            }
        });
        report.below_min_ff += area * below;
        report.dropped += area * f64::from(row.dropped);
        if row.dropped > report.dropped_max.1 {
            report.dropped_max = (row.index, row.dropped);
        }
        report.linked_rows += u64::from(!row.links.is_empty());
        debug_assert!(!matches!(row.values, RowValues::Skipped), "checked before");
        sky[i] = 1.0 - row.true_sum();
    })?;
    if let Some(e) = werr {
        return Err(FfzError::io(out, "write", e));
    }
    w.flush().map_err(|e| FfzError::io(out, "write", e))
}

/// `svf.inp`: the header line uDALES's reader skips, then `max(0, sky)` per facet.
fn write_svf(out: &Path, f: std::fs::File, sky: &[f64]) -> Result<()> {
    let e = |err| FfzError::io(out, "write", err);
    let mut w = BufWriter::new(f);
    writeln!(
        w,
        "# sky view factors (ffstream: max(0, 1 - row sum), one per STL facet)"
    )
    .map_err(e)?;
    for s in sky {
        writeln!(w, "{:.8}", s.max(0.0)).map_err(e)?;
    }
    w.flush().map_err(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_are_percent_decoded() {
        let p = "samples=16 max_edge=1000000000 scene_path=my%20city.stl pairs=half";
        assert_eq!(param(p, "scene_path").as_deref(), Some("my city.stl"));
        assert_eq!(param(p, "max_edge").as_deref(), Some("1000000000"));
        assert_eq!(param(p, "occluders_path"), None);
    }

    #[test]
    fn only_stl_scenes_number_facets_as_udales_does() {
        assert_eq!(stl_of_spec("city.STL"), Ok(PathBuf::from("city.STL")));
        assert_eq!(stl_of_spec("stl:city.dat"), Ok(PathBuf::from("city.dat")));
        assert!(stl_of_spec("builtin:city:3")
            .unwrap_err()
            .contains("built-in"));
        assert!(stl_of_spec("city.obj").unwrap_err().contains("not an STL"));
    }
}
