//! Library side of `ffstream info`, `verify` and `export` (the CLI wires its flags to
//! these functions; output formats are docs/architecture.md §7).

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::ffz::FfzError;

use super::npz::NpzSpill;
use super::staged::Staged;
use super::Result;
use crate::ffz::spec;
use crate::ffz::FfzReader;
use crate::ffz::{compare, VerifyOptions};
use crate::table::TableWriter;

fn out_err(path: &Path) -> impl Fn(std::io::Error) -> FfzError + '_ {
    move |e| FfzError::io(path, "write report", e)
}

/// Print what a file holds: header, layout, n, rows present/skipped/missing, chunks,
/// bytes on disk against raw bytes, compression ratio, the sky view factors (min, max,
/// mean of 1 − row sum: one decompressing pass, no checksums), and any recovery
/// warnings.
///
/// # Errors
/// Opening errors of [`FfzReader::open`]; `Io` when `out` fails.
pub fn info(path: &Path, out: &mut dyn Write) -> Result<()> {
    let r = FfzReader::open(path)?;
    let m = r.meta();
    let h = r.header();
    let p = r.presence();
    let mut raw = 0u64;
    let mut compressed = 0u64;
    let mut unreadable = 0u64;
    for k in 0..r.chunk_count() as u32 {
        match r.chunk_header(k) {
            Some(c) => {
                raw += c.raw_len;
                compressed += spec::CHUNK_HEADER_LEN as u64 + c.compressed_len;
            }
            None => unreadable += 1,
        }
    }
    let n = r.n() as u64;
    let e = out_err(path);
    writeln!(out, "file:          {}", path.display()).map_err(&e)?;
    writeln!(out, "format:        ffz version {}", spec::VERSION).map_err(&e)?;
    writeln!(
        out,
        "n:             {n} patches in {} groups",
        m.patches.groups.len()
    )
    .map_err(&e)?;
    writeln!(out, "layout:        {}", m.layout).map_err(&e)?;
    writeln!(out, "method:        {}", m.method).map_err(&e)?;
    writeln!(out, "params:        {}", m.params).map_err(&e)?;
    writeln!(out, "scene hash:    {:#018x}", m.scene_hash).map_err(&e)?;
    writeln!(out, "created:       {}", m.created).map_err(&e)?;
    writeln!(out, "zstd level:    {}", h.zstd_level).map_err(&e)?;
    writeln!(
        out,
        "rows:          {} present, {} skipped, {} missing (of {n})",
        p.present_count(),
        p.skipped_count(),
        p.missing_count()
    )
    .map_err(&e)?;
    writeln!(
        out,
        "chunks:        {}{}",
        r.chunk_count(),
        if unreadable > 0 {
            format!(" ({unreadable} with unreadable headers)")
        } else {
            String::new()
        }
    )
    .map_err(&e)?;
    writeln!(
        out,
        "bytes on disk: {} (meta block {}, chunks {}, index and footer {})",
        r.file_len(),
        h.meta_len,
        compressed,
        r.file_len() - r.chunk_area_end()
    )
    .map_err(&e)?;
    writeln!(
        out,
        "raw row bytes: {raw} (dense f32 matrix would be {})",
        n * n * 4
    )
    .map_err(&e)?;
    let ratio = if compressed > 0 {
        raw as f64 / compressed as f64
    } else {
        0.0
    };
    writeln!(
        out,
        "compression:   {ratio:.3} (raw row bytes / chunk bytes)"
    )
    .map_err(&e)?;
    writeln!(
        out,
        "index:         {}",
        if r.is_indexed() {
            "ok"
        } else {
            "missing or bad: rows recovered by scanning"
        }
    )
    .map_err(&e)?;
    // How the pairs got their visibility (spec §6.1): what `compute` printed at its
    // end, kept in the index and added up over the runs that finished the file.
    match r.routes() {
        Some(rt) => writeln!(
            out,
            "routes:        over the {} rows computed by runs that finished (half rows with --symmetric), {}",
            rt.rows,
            rt.pairs.summary()
        ),
        None => writeln!(
            out,
            "routes:        not recorded (a file from before ffstream kept them, a run that did not finish, or an index rebuilt by a scan)"
        ),
    }
    .map_err(&e)?;
    writeln!(out, "{}", sky_view_summary(&r)).map_err(&e)?;
    for w in r.warnings() {
        writeln!(out, "warning: {w}").map_err(&e)?;
    }
    Ok(())
}

/// The `sky view:` line of `info` and `verify`.
fn sky_view_line(lo: f64, hi: f64, mean: f64) -> String {
    format!("sky view:    min {lo:.7} max {hi:.7} mean {mean:.7} (1 - row sum: the share of a patch's hemisphere that sees no surface)")
}

/// `info`'s sky view factors from one pass over the rows (none for a file without
/// rows; the chunk error in place of the figures when a chunk is corrupt: `verify`
/// lists them all).
fn sky_view_summary(r: &FfzReader) -> String {
    let (mut lo, mut hi, mut total, mut rows) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0u64);
    let (mut linked, mut links, mut most) = (0u64, 0u64, 0usize);
    let scanned = r.scan(|row| {
        if !row.links.is_empty() {
            linked += 1;
            links += row.links.len() as u64;
            most = most.max(row.links.len());
        }
        if !matches!(row.values, crate::rows::RowValues::Skipped) {
            let sky = 1.0 - row.true_sum();
            lo = lo.min(sky);
            hi = hi.max(sky);
            total += sky;
            rows += 1;
        }
    });
    match scanned {
        Err(err) => format!("sky view:    not computed: {err}"),
        Ok(()) if rows == 0 => "sky view:    no rows".to_string(),
        Ok(()) => {
            let sky = sky_view_line(lo, hi, total / rows as f64);
            match r.meta().clusters {
                None => sky,
                Some(_) => format!(
                    "links:         {linked} of {rows} rows link to clusters of the cluster order (spec §4.3, §5.7): {links} links, {:.1} a linked row, at most {most}\n{sky}",
                    links as f64 / linked.max(1) as f64
                ),
            }
        }
    }
}

/// What `verify` checks beyond the structure of the file.
#[derive(Clone, Copy, Debug)]
pub struct VerifyChecks<'a> {
    /// Compare row by row with this file.
    pub against: Option<&'a Path>,
    /// Rows summing above 1 + this fail ([`VerifyOptions::row_sum_tol`]).
    pub row_sum_tol: f64,
    /// Check every stored entry against its unoccluded form factor with this relative
    /// tolerance ([`super::unoccluded_excess`]); `None`: not checked (it costs about an
    /// unoccluded compute).
    pub unoccluded_tol: Option<f64>,
}

impl Default for VerifyChecks<'_> {
    fn default() -> Self {
        VerifyChecks {
            against: None,
            row_sum_tol: crate::ffz::ROW_SUM_TOL,
            unoccluded_tol: None,
        }
    }
}

/// [`print_checks`] with the default checks and `against`.
///
/// # Errors
/// As [`print_checks`].
pub fn print_verify(path: &Path, against: Option<&Path>, out: &mut dyn Write) -> Result<bool> {
    let checks = VerifyChecks {
        against,
        ..VerifyChecks::default()
    };
    print_checks(path, checks, out)
}

/// Check a file (every chunk, index, row sums, sky view factors, reciprocity; with
/// `checks.unoccluded_tol` every entry against its unoccluded bound) and, with
/// `checks.against`, compare it row by row with another file. Prints a report; returns
/// `false` when something failed (bad chunks, unusable index, missing rows, negative or
/// non-finite entries, rows summing above 1 + tolerance, entries above their
/// unoccluded bound, or rows that differ from `against`).
///
/// # Errors
/// Opening errors of either file; `Io` when `out` fails.
pub fn print_checks(path: &Path, checks: VerifyChecks<'_>, out: &mut dyn Write) -> Result<bool> {
    let against = checks.against;
    let r = FfzReader::open(path)?;
    let rep = r.verify_with(VerifyOptions {
        row_sum_tol: checks.row_sum_tol,
        ..VerifyOptions::default()
    });
    let e = out_err(path);
    writeln!(out, "file:        {}", path.display()).map_err(&e)?;
    for w in &rep.open_warnings {
        writeln!(out, "FAIL: {w}").map_err(&e)?;
    }
    writeln!(
        out,
        "chunks:      {} checked, {} bad",
        rep.chunks_checked,
        rep.bad_chunks.len()
    )
    .map_err(&e)?;
    for b in &rep.bad_chunks {
        match b.chunk {
            Some(k) => writeln!(out, "FAIL: chunk {k} at byte {}: {}", b.offset, b.what),
            None => writeln!(out, "FAIL: {}", b.what),
        }
        .map_err(&e)?;
    }
    writeln!(
        out,
        "rows:        {} present, {} skipped, {} missing; {} checked",
        rep.rows_present, rep.rows_skipped, rep.rows_missing, rep.rows_checked
    )
    .map_err(&e)?;
    if rep.rows_missing > 0 {
        writeln!(
            out,
            "FAIL: {} rows missing (finish them with compute --resume)",
            rep.rows_missing
        )
        .map_err(&e)?;
    }
    if let Some((row, what)) = &rep.first_row_fault {
        writeln!(
            out,
            "FAIL: {} negative, {} non-finite and {} impossible (> {}) entries, {} rows with bad dropped mass; first: row {row}: {what}",
            rep.negative_entries,
            rep.non_finite_entries,
            rep.too_large_entries,
            crate::rows::MAX_FORM_FACTOR,
            rep.bad_dropped_rows,
        )
        .map_err(&e)?;
    }
    if let Some((first, total)) = rep.lost_mass {
        writeln!(
            out,
            "warning:     {} top-k rows store nothing but have dropped mass (first: row {first}; total {total:.3e}): a solve cannot redistribute it (spec §5.6)",
            rep.lost_mass_rows
        )
        .map_err(&e)?;
    }
    writeln!(
        out,
        "row sums:    min {:.7} max {:.7} mean {:.7} (stored + dropped; max dropped {:.3e})",
        rep.row_sum_min, rep.row_sum_max, rep.row_sum_mean, rep.dropped_max
    )
    .map_err(&e)?;
    if rep.rows_checked > 0 {
        let (lo, hi, mean) = rep.sky_view();
        writeln!(out, "{}", sky_view_line(lo, hi, mean)).map_err(&e)?;
    }
    if let Some((row, max)) = rep.link_error_max {
        writeln!(
            out,
            "link error:  mean {:.3e} max {max:.3e} (row {row}) over {} rows: the writer's estimate of the relative error links make in what a row gathers (spec §5.7)",
            rep.link_error_sum / rep.link_error_rows as f64,
            rep.link_error_rows
        )
        .map_err(&e)?;
    }
    if let Some((row, sum)) = rep.worst_above_one {
        writeln!(
            out,
            "FAIL: {} rows sum above 1 + {:e} (largest: row {row}, {sum:.7}): more light would leave those patches towards the others than leaves them (duplicate faces? a kernel fault?)",
            rep.rows_above_one, rep.row_sum_tol
        )
        .map_err(&e)?;
    }
    if let Some((row, sum)) = rep.worst_dropped_above_one {
        writeln!(
            out,
            "warning:     {} top-k rows sum above 1 + {:e} only with their dropped mass (largest: row {row}, {sum:.7}): the estimate of what top-k left out is too high there",
            rep.dropped_above_one, rep.row_sum_tol
        )
        .map_err(&e)?;
    }
    if let Some(rc) = &rep.reciprocity {
        let worst = rc
            .worst
            .map(|(i, j)| format!(" at ({i}, {j})"))
            .unwrap_or_default();
        writeln!(
            out,
            "reciprocity: max |A_i F_ij - A_j F_ji| / max(A_i F_ij, A_j F_ji) = {:.3e}{worst}, mean {:.3e}, weighted (sum of differences / sum of maxima) {:.3e}, over {} stored pairs ({} passes)",
            rc.max_rel_error, rc.mean_rel_error, rc.weighted_rel_error, rc.pairs, rc.passes
        )
        .map_err(&e)?;
    }
    let mut ok = rep.ok();
    if let Some(tol) = checks.unoccluded_tol {
        ok &= print_unoccluded(path, &r, tol, out)?;
    }
    if let Some(other) = against {
        ok &= print_against(path, &r, other, out)?;
    }
    writeln!(out, "{}", if ok { "OK" } else { "FAILED" }).map_err(&e)?;
    Ok(ok)
}

/// `verify --unoccluded`: prints how many stored entries lie above their unoccluded
/// form factor and the worst; returns `false` when one does.
fn print_unoccluded(path: &Path, r: &FfzReader, tol: f64, out: &mut dyn Write) -> Result<bool> {
    let e = out_err(path);
    let u = super::unoccluded::unoccluded_excess(r, tol, 0)?;
    writeln!(
        out,
        "unoccluded:  {} of {} stored entries above their unoccluded form factor F0 (1 + {tol:e}) (F0 from the patch table: contour kernel, no occluders)",
        u.above, u.entries
    )
    .map_err(&e)?;
    if let Some((i, j, f, f0)) = u.worst {
        writeln!(
            out,
            "FAIL: entry ({i}, {j}) = {f:e} exceeds its unoccluded value {f0:e} by {:.3e} (relative): visibility can only lower a form factor",
            f64::from(f) / f0 - 1.0
        )
        .map_err(&e)?;
        return Ok(false);
    }
    Ok(true)
}

/// `verify --against`: compares the file with `other` row by row and prints the
/// differences; returns `false` when the files differ.
fn print_against(path: &Path, r: &FfzReader, other: &Path, out: &mut dyn Write) -> Result<bool> {
    let e = out_err(path);
    let b = FfzReader::open(other)?;
    let c = compare(r, &b, VerifyOptions::default())?;
    writeln!(out, "against:     {}", other.display()).map_err(&e)?;
    for d in &c.meta_differences {
        writeln!(out, "  header differs: {d}").map_err(&e)?;
    }
    writeln!(
        out,
        "  rows compared {}: {} identical, {} differ ({}max abs diff {:.3e}{}); only in this file {} {:?}, only in the other {} {:?}",
        c.rows_compared,
        c.identical_rows,
        c.differing_rows,
        match c.links_only_rows {
            0 => String::new(),
            k => format!("{k} of them in their links or link error alone; "),
        },
        c.max_abs_diff,
        c.worst_row.map(|r| format!(" in row {r}")).unwrap_or_default(),
        c.only_in_a,
        c.first_only_in_a,
        c.only_in_b,
        c.first_only_in_b
    )
    .map_err(&e)?;
    for x in &c.errors {
        writeln!(out, "FAIL: {x}").map_err(&e)?;
    }
    if !c.identical() {
        writeln!(out, "FAIL: the files differ").map_err(&e)?;
        return Ok(false);
    }
    Ok(true)
}

/// Write to each `(path, head)` its head, then `i j F_ij` (1-based) for every entry
/// `kept` accepts, row by row: one pass over the chunks for all of them.
/// With `spill`, each row's kept entries go there too (for `--npz`).
fn write_entries(
    r: &FfzReader,
    outputs: &[(&Path, String)],
    kept: impl Fn(f32) -> bool,
    spill: Option<&mut NpzSpill>,
) -> Result<()> {
    let mut staged = Vec::with_capacity(outputs.len());
    let mut sinks = Vec::with_capacity(outputs.len());
    let written = (|| {
        for (out, head) in outputs {
            let (s, f) = Staged::create(out)?;
            staged.push(s);
            let mut w = BufWriter::with_capacity(1 << 20, f);
            w.write_all(head.as_bytes())
                .map_err(|e| FfzError::io(out, "write", e))?;
            sinks.push((*out, w));
        }
        fill_entries(r, &mut sinks, kept, spill)
    })();
    match written {
        Ok(()) => staged.into_iter().try_for_each(Staged::commit),
        Err(e) => {
            drop(sinks);
            staged.into_iter().for_each(Staged::discard);
            Err(e)
        }
    }
}

/// The entry pass of [`write_entries`] into its open `sinks`, flushed at the end.
fn fill_entries(
    r: &FfzReader,
    sinks: &mut Vec<(&Path, BufWriter<std::fs::File>)>,
    kept: impl Fn(f32) -> bool,
    mut spill: Option<&mut NpzSpill>,
) -> Result<()> {
    let mut werr: Option<(&Path, std::io::Error)> = None;
    let mut serr: Option<FfzError> = None;
    let (mut cols, mut vals) = (Vec::new(), Vec::new());
    r.scan(|row| {
        let i = row.index as u64 + 1;
        cols.clear();
        vals.clear();
        row.for_each_nonzero(|j, x| {
            if werr.is_none() && kept(x) {
                if spill.is_some() {
                    cols.push(j);
                    vals.push(x);
                }
                for (out, w) in sinks.iter_mut() {
                    if let Err(err) = writeln!(w, "{i} {} {x:e}", j as u64 + 1) {
                        werr = Some((out, err));
                        return;
                    }
                }
            }
        });
        if let (Some(s), None) = (spill.as_deref_mut(), &serr) {
            if let Err(e) = s.push(row.index, &cols, &vals) {
                serr = Some(e);
            }
        }
    })?;
    if let Some((out, err)) = werr {
        return Err(FfzError::io(out, "write", err));
    }
    if let Some(e) = serr {
        return Err(e);
    }
    for (out, w) in sinks.iter_mut() {
        w.flush().map_err(|e| FfzError::io(out, "write", e))?;
    }
    Ok(())
}

/// Header of the patch table of `export --patches-csv` (docs/architecture.md §7).
/// `row_sum` is the row's stored entries plus its dropped mass, `sky_view` = 1 − row_sum
/// (the share of the patch's hemisphere that sees no surface: the sky of an open scene,
/// about 0 in a closed one); both empty for a missing or skipped row.
pub const PATCHES_CSV_HEADER: &str =
    "patch,group,area,cx,cy,cz,nx,ny,nz,rho_r,rho_g,rho_b,e_r,e_g,e_b,row_sum,sky_view";

/// What `export` writes: each output is optional.
#[derive(Clone, Copy, Debug, Default)]
pub struct ExportTargets<'a> {
    /// Matrix Market `coordinate real general`, 1-based `i j F_ij`.
    pub matrix: Option<&'a Path>,
    /// Sparse text, View3D/uDALES style: `#` header lines, then one `i j F_ij` per line
    /// (1-based).
    pub sparse: Option<&'a Path>,
    /// NumPy `.npz` of the CSR arrays, as `scipy.sparse.save_npz` writes them
    /// ([`super::npz`]).
    pub npz: Option<&'a Path>,
    /// Entries below this are left out of the matrix outputs (0: every non-zero).
    pub min_ff: f32,
    /// The patch table as CSV (0-based patch ids).
    pub patches_csv: Option<&'a Path>,
    /// The patches as a VTK unstructured grid ([`crate::vtu`]) with the patch table's
    /// values as cell data (row sums, sky view factors and dropped mass NaN for a
    /// missing or skipped row).
    pub vtu: Option<&'a Path>,
}

/// Export the matrix as Matrix Market, sparse text (rows in file order) and/or `.npz`
/// (rows in row order: dense rows give their entries ≥ `min_ff` and non-zero, top-k
/// rows those of their stored entries), and/or the patch table as CSV. Streams: at
/// most two passes over the chunks, never the whole matrix in memory (`.npz` goes
/// through a spill file of 8 bytes per entry beside it).
///
/// # Errors
/// Opening errors; `Chunk` when a chunk is corrupt; `Io` naming the output file.
pub fn export(path: &Path, to: ExportTargets<'_>) -> Result<()> {
    let r = FfzReader::open(path)?;
    let m = r.meta();
    let p = r.presence();
    let source = format!(
        "ffstream form factors from {}: layout {}, method {}, params {}, scene hash {:#018x}",
        path.display(),
        m.layout,
        m.method,
        m.params,
        m.scene_hash
    );
    let kept = |x: f32| x != 0.0 && x >= to.min_ff;
    let gaps = format!(
        "rows missing {} and skipped {} have no entries; top-k dropped mass not included{}; entries below {:e} left out",
        p.missing_count(),
        p.skipped_count(),
        match m.clusters {
            Some(_) => " (nor the links to clusters that place it, spec §5.7: formats/ffz.py's link_matrix() expands them)",
            None => "",
        },
        to.min_ff
    );
    // At most two passes over the chunks, whatever is asked: one for what the headers
    // need (Matrix Market's entry count, the patch table's row sums: n numbers, never
    // the rows), one writing the entries of both matrix outputs.
    let mut nnz = 0u64;
    let mut sums: Vec<Option<(f64, f32)>> = Vec::new();
    let tables = to.patches_csv.is_some() || to.vtu.is_some();
    if to.matrix.is_some() || tables {
        if tables {
            sums = vec![None; r.n() as usize];
        }
        r.scan(|row| {
            if to.matrix.is_some() {
                row.for_each_nonzero(|_, x| nnz += u64::from(kept(x)));
            }
            if let Some(s) = sums.get_mut(row.index as usize) {
                *s = row_total(row);
            }
        })?;
    }
    let mut outputs = Vec::new();
    if let Some(mtx) = to.matrix {
        let head = format!(
            "%%MatrixMarket matrix coordinate real general\n% {source}\n% entry i j = F_ij (1-based); {gaps}\n{} {} {nnz}\n",
            r.n(),
            r.n()
        );
        outputs.push((mtx, head));
    }
    if let Some(txt) = to.sparse {
        let head = format!(
            "# {source}\n# n = {}; one line per entry: i j F_ij (1-based, F_ij = fraction of the energy leaving patch i that reaches patch j); {gaps}\n",
            r.n()
        );
        outputs.push((txt, head));
    }
    if !outputs.is_empty() || to.npz.is_some() {
        let mut spill = match to.npz {
            Some(npz) => Some(NpzSpill::create(npz, r.n())?),
            None => None,
        };
        let written = write_entries(&r, &outputs, kept, spill.as_mut());
        if let (Some(s), Some(npz)) = (spill, to.npz) {
            match written {
                Ok(()) => s.finish(npz)?,
                Err(e) => {
                    s.discard();
                    return Err(e);
                }
            }
        } else {
            written?;
        }
    }
    if let Some(csv) = to.patches_csv {
        let (staged, f) = Staged::create(csv)?;
        match patches_table(&r, &sums, csv, f) {
            Ok(()) => staged.commit()?,
            Err(e) => {
                staged.discard();
                return Err(e);
            }
        }
    }
    if let Some(vtu) = to.vtu {
        patches_grid(&r, &sums, vtu)?;
    }
    Ok(())
}

/// The grid of `export --vtu`: the patch table's values as cell data.
fn patches_grid(r: &FfzReader, sums: &[Option<(f64, f32)>], vtu: &Path) -> Result<()> {
    use crate::vtu::{patch_arrays, write_vtu, CellArray};
    let ps = &r.meta().patches;
    let mut arrays = patch_arrays(ps);
    arrays.push(CellArray::rgb_f32(
        "reflectance",
        ps.patches.iter().map(|p| p.rho),
    ));
    arrays.push(CellArray::rgb_f32(
        "emitted_exitance",
        ps.patches.iter().map(|p| p.emission),
    ));
    arrays.extend(sum_arrays(sums));
    write_vtu(vtu, ps, arrays)
        .map_err(|e| FfzError::io(vtu, "write", std::io::Error::other(e.cause)))
}

/// Cell arrays `row_sum` (stored entries plus dropped mass), `sky_view` (1 − row_sum)
/// and `dropped_mass` of `sums` (per row: true sum and dropped mass; NaN where the row
/// is missing or skipped).
fn sum_arrays(sums: &[Option<(f64, f32)>]) -> [crate::vtu::CellArray; 3] {
    use crate::vtu::{CellArray, CellValues};
    let sum = |f: fn(f64) -> f64| {
        CellValues::F64(
            sums.iter()
                .map(|s| s.map_or(f64::NAN, |(x, _)| f(x)))
                .collect(),
        )
    };
    [
        CellArray::scalar("row_sum", sum(|x| x)),
        CellArray::scalar("sky_view", sum(|x| 1.0 - x)),
        CellArray::scalar(
            "dropped_mass",
            CellValues::F32(
                sums.iter()
                    .map(|s| s.map_or(f32::NAN, |(_, d)| d))
                    .collect(),
            ),
        ),
    ]
}

/// The matrix side of a `.vtu` grid for `solve --vtu`: each row's sum, sky view factor
/// and dropped mass (as `export --vtu` writes them), from one pass over the rows.
///
/// # Errors
/// As [`FfzReader::scan`].
pub fn row_sum_arrays(r: &FfzReader) -> Result<[crate::vtu::CellArray; 3]> {
    let mut sums: Vec<Option<(f64, f32)>> = vec![None; r.n() as usize];
    r.scan(|row| sums[row.index as usize] = row_total(row))?;
    Ok(sum_arrays(&sums))
}

/// A row's true sum (stored entries plus dropped mass) and dropped mass; None for a
/// skipped row.
fn row_total(row: &crate::rows::Row) -> Option<(f64, f32)> {
    match row.values {
        crate::rows::RowValues::Skipped => None,
        _ => Some((row.true_sum(), row.dropped)),
    }
}

/// The patch table of `export --patches-csv` into `f` (the file for `csv`), with each
/// row's sum from `sums`.
fn patches_table(
    r: &FfzReader,
    sums: &[Option<(f64, f32)>],
    csv: &Path,
    f: std::fs::File,
) -> Result<()> {
    let e = |err| FfzError::io(csv, "write", err);
    let mut w = TableWriter::new(BufWriter::new(f));
    w.record(PATCHES_CSV_HEADER.split(',')).map_err(e)?;
    let ps = &r.meta().patches;
    for (i, p) in ps.patches.iter().enumerate() {
        let c = p.centroid();
        let group = ps.groups.get(p.group as usize).map_or("", |s| s.as_str());
        let mut fields = vec![i.to_string(), group.to_string()];
        fields.extend(
            [p.area, c.x, c.y, c.z, p.normal.x, p.normal.y, p.normal.z].map(|x| x.to_string()),
        );
        fields.extend(p.rho.iter().chain(&p.emission).map(|x| x.to_string()));
        match sums[i] {
            Some((sum, _)) => fields.extend([sum.to_string(), (1.0 - sum).to_string()]),
            None => fields.extend([String::new(), String::new()]),
        }
        w.record(&fields).map_err(e)?;
    }
    w.finish().map_err(e)
}
