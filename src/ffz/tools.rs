//! Library side of `ffstream info`, `verify` and `export` (the CLI wires its flags to
//! these functions; output formats are docs/architecture.md §7).

use std::io::{BufWriter, Write};
use std::path::Path;

use super::error::{FfzError, Result};
use super::reader::FfzReader;
use super::spec;
use super::verify::{compare, VerifyOptions};
use crate::table::TableWriter;

fn out_err(path: &Path) -> impl Fn(std::io::Error) -> FfzError + '_ {
    move |e| FfzError::io(path, "write report", e)
}

/// Print what a file holds: header, layout, n, rows present/skipped/missing, chunks,
/// bytes on disk against raw bytes, compression ratio, and any recovery warnings.
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
    for w in r.warnings() {
        writeln!(out, "warning: {w}").map_err(&e)?;
    }
    Ok(())
}

/// Check a file (every chunk, index, row sums, reciprocity) and, with `against`,
/// compare it row by row with another file. Prints a report; returns `false` when
/// something failed (bad chunks, unusable index, missing rows, negative or non-finite
/// entries, or rows that differ from `against`).
///
/// # Errors
/// Opening errors of either file; `Io` when `out` fails.
pub fn verify(path: &Path, against: Option<&Path>, out: &mut dyn Write) -> Result<bool> {
    let r = FfzReader::open(path)?;
    let rep = r.verify();
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
    if let Some(other) = against {
        let b = FfzReader::open(other)?;
        let c = compare(&r, &b, VerifyOptions::default())?;
        writeln!(out, "against:     {}", other.display()).map_err(&e)?;
        for d in &c.meta_differences {
            writeln!(out, "  header differs: {d}").map_err(&e)?;
        }
        writeln!(
            out,
            "  rows compared {}: {} identical, {} differ (max abs diff {:.3e}{}); only in this file {} {:?}, only in the other {} {:?}",
            c.rows_compared,
            c.identical_rows,
            c.differing_rows,
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
            ok = false;
        }
    }
    writeln!(out, "{}", if ok { "OK" } else { "FAILED" }).map_err(&e)?;
    Ok(ok)
}

/// Write to each `(path, head)` its head, then `i j F_ij` (1-based) for every entry
/// `kept` accepts, row by row: one pass over the chunks for all of them.
fn write_entries(
    r: &FfzReader,
    outputs: &[(&Path, String)],
    kept: impl Fn(f32) -> bool,
) -> Result<()> {
    let mut sinks = Vec::with_capacity(outputs.len());
    for (out, head) in outputs {
        let f = std::fs::File::create(out).map_err(|e| FfzError::io(out, "create", e))?;
        let mut w = BufWriter::with_capacity(1 << 20, f);
        w.write_all(head.as_bytes())
            .map_err(|e| FfzError::io(out, "write", e))?;
        sinks.push((*out, w));
    }
    let mut werr: Option<(&Path, std::io::Error)> = None;
    r.scan(|row| {
        let i = row.index as u64 + 1;
        row.for_each_nonzero(|j, x| {
            if werr.is_none() && kept(x) {
                for (out, w) in sinks.iter_mut() {
                    if let Err(err) = writeln!(w, "{i} {} {x:e}", j as u64 + 1) {
                        werr = Some((out, err));
                        return;
                    }
                }
            }
        });
    })?;
    if let Some((out, err)) = werr {
        return Err(FfzError::io(out, "write", err));
    }
    for (out, mut w) in sinks {
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
    /// Entries below this are left out of both matrix outputs (0: every non-zero).
    pub min_ff: f32,
    /// The patch table as CSV (0-based patch ids).
    pub patches_csv: Option<&'a Path>,
}

/// Export the matrix as Matrix Market and/or sparse text (rows in file order; dense
/// rows give their entries ≥ `min_ff` and non-zero, top-k rows those of their stored
/// entries), and/or the patch table as CSV. Streams: at most two passes over the
/// chunks, never the whole matrix in memory.
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
        "rows missing {} and skipped {} have no entries; top-k dropped mass not included; entries below {:e} left out",
        p.missing_count(),
        p.skipped_count(),
        to.min_ff
    );
    // At most two passes over the chunks, whatever is asked: one for what the headers
    // need (Matrix Market's entry count, the patch table's row sums: n numbers, never
    // the rows), one writing the entries of both matrix outputs.
    let mut nnz = 0u64;
    let mut sums: Vec<Option<f64>> = Vec::new();
    if to.matrix.is_some() || to.patches_csv.is_some() {
        if to.patches_csv.is_some() {
            sums = vec![None; r.n() as usize];
        }
        r.scan(|row| {
            if to.matrix.is_some() {
                row.for_each_nonzero(|_, x| nnz += u64::from(kept(x)));
            }
            if let Some(s) = sums.get_mut(row.index as usize) {
                if !matches!(row.values, crate::rows::RowValues::Skipped) {
                    *s = Some(row.true_sum());
                }
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
    if !outputs.is_empty() {
        write_entries(&r, &outputs, kept)?;
    }
    if let Some(csv) = to.patches_csv {
        let e = |err| FfzError::io(csv, "write", err);
        let mut w = TableWriter::create(csv).map_err(|err| FfzError::io(csv, "create", err))?;
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
                Some(sum) => fields.extend([sum.to_string(), (1.0 - sum).to_string()]),
                None => fields.extend([String::new(), String::new()]),
            }
            w.record(&fields).map_err(e)?;
        }
        w.finish().map_err(e)?;
    }
    Ok(())
}
