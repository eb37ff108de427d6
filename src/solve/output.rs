//! Results as files and tables: the radiosity CSV (one per emission case) and the
//! per-group summary.
//!
//! Radiosity CSV: header [`CSV_HEADER`], then one line per patch in patch order:
//! patch index (0-based, as the matrix rows), group name (quoted per RFC 4180 if
//! needed), area, B, E (the case's exitance), ρ (as solved with), H. Floats are written in the shortest
//! form that reads back to the same value. With K > 1 emission cases each case goes to
//! its own file ([`case_path`]): every file is then a complete radiosity table that
//! `render --radiosity` can take, with no case column to filter on.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::patch::PatchSet;

use super::error::SolveError;
use super::Solution;
use crate::table::{self, TableWriter};

/// Header of the radiosity CSV (docs/architecture.md §7 fixes the first six names).
pub const CSV_HEADER: &str =
    "patch,group,area,B_r,B_g,B_b,E_r,E_g,E_b,rho_r,rho_g,rho_b,H_r,H_g,H_b";

/// File name for case `case` of `cases`: `base` itself when there is one case,
/// otherwise `STEM_caseK.EXT` beside it (`radiosity.csv` → `radiosity_case0.csv`).
pub fn case_path(base: &Path, case: usize, cases: usize) -> PathBuf {
    if cases <= 1 {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match base.extension() {
        Some(ext) => format!("{stem}_case{case}.{}", ext.to_string_lossy()),
        None => format!("{stem}_case{case}"),
    };
    base.with_file_name(name)
}

/// Write case `case` of `solution` as a radiosity CSV.
///
/// # Errors
/// [`SolveError::InvalidInput`] when `case` is out of range or the solution does not
/// match the patches; [`SolveError::Io`] naming the file.
pub fn write_csv(
    path: &Path,
    patches: &PatchSet,
    solution: &Solution,
    case: usize,
) -> Result<(), SolveError> {
    check_case(patches, solution, case)?;
    let io = |e| SolveError::io(path, e);
    let mut w = TableWriter::create(path).map_err(io)?;
    w.record(CSV_HEADER.split(',')).map_err(io)?;
    let (b, h, e) = (&solution.b[case], &solution.h[case], &solution.e[case]);
    for (i, p) in patches.patches.iter().enumerate() {
        let mut fields = vec![
            i.to_string(),
            patches.group_name(i).to_string(),
            p.area.to_string(),
        ];
        fields.extend(b[i].iter().map(f64::to_string));
        // E came from f32 input: print it as f32 so 0.1 reads back as 0.1.
        fields.extend(e[i].iter().map(|&x| (x as f32).to_string()));
        fields.extend(solution.rho[i].iter().map(|x| x.to_string()));
        fields.extend(h[i].iter().map(f64::to_string));
        w.record(&fields).map_err(io)?;
    }
    w.finish().map_err(io)
}

/// Write case `case` of `solution` as a VTK unstructured grid ([`crate::vtu`]) with the
/// radiosity CSV's values as cell data: radiosity (B), irradiance (H),
/// emitted_exitance (E), reflectance (RGB each), area, patch, group; then `extra`
/// (`solve --vtu` adds the rows' sums, sky view factors and dropped mass).
///
/// # Errors
/// As [`write_csv`].
pub fn write_vtu(
    path: &Path,
    patches: &PatchSet,
    solution: &Solution,
    case: usize,
    extra: &[crate::vtu::CellArray],
) -> Result<(), SolveError> {
    use crate::vtu::{self, CellArray};
    check_case(patches, solution, case)?;
    let mut arrays = vtu::patch_arrays(patches);
    arrays.push(CellArray::rgb_f64(
        "radiosity",
        solution.b[case].iter().copied(),
    ));
    arrays.push(CellArray::rgb_f64(
        "irradiance",
        solution.h[case].iter().copied(),
    ));
    // E came from f32 input, as in the CSV.
    arrays.push(CellArray::rgb_f32(
        "emitted_exitance",
        solution.e[case].iter().map(|e| e.map(|x| x as f32)),
    ));
    arrays.push(CellArray::rgb_f32(
        "reflectance",
        solution.rho.iter().copied(),
    ));
    arrays.extend_from_slice(extra);
    vtu::write_vtu(path, patches, arrays)
        .map_err(|e| SolveError::io(path, std::io::Error::other(e.cause)))
}

fn check_case(patches: &PatchSet, solution: &Solution, case: usize) -> Result<(), SolveError> {
    if case >= solution.cases() {
        return Err(SolveError::InvalidInput(format!(
            "case {case} requested, the solution has {}",
            solution.cases()
        )));
    }
    if solution.b[case].len() != patches.len() || solution.rho.len() != patches.len() {
        return Err(SolveError::InvalidInput(format!(
            "solution has {} patches, the scene {}",
            solution.b[case].len(),
            patches.len()
        )));
    }
    Ok(())
}

/// Read the radiosity B of `n` patches back from a radiosity CSV (any file whose
/// header starts `patch,group,area,B_r,B_g,B_b`).
///
/// # Errors
/// [`SolveError::Io`]; [`SolveError::Parse`] naming the line for a wrong header, a bad
/// number, a patch index out of range or repeated, or a patch missing from the file
/// (line 0).
pub fn read_radiosity_csv(path: &Path, n: usize) -> Result<Vec<[f32; 3]>, SolveError> {
    let text = std::fs::read_to_string(path).map_err(|e| SolveError::io(path, e))?;
    let err = |line: usize, message: String| SolveError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut records = table::records(&text);
    let header_ok = match records.next() {
        Some(Ok(h)) => {
            h.line == 1
                && h.fields
                    .join(",")
                    .starts_with("patch,group,area,B_r,B_g,B_b")
        }
        _ => false,
    };
    if !header_ok {
        return Err(err(
            1,
            "expected a header starting `patch,group,area,B_r,B_g,B_b`".into(),
        ));
    }
    let mut out: Vec<Option<[f32; 3]>> = vec![None; n];
    for record in records {
        let table::Record {
            line: line_no,
            fields: f,
        } = record.map_err(|(line, m)| err(line, m))?;
        if f.len() < 6 {
            return Err(err(
                line_no,
                format!("expected ≥ 6 fields, found {}", f.len()),
            ));
        }
        let i: usize = f[0]
            .parse()
            .map_err(|_| err(line_no, format!("patch index \"{}\" is not a number", f[0])))?;
        let mut b = [0.0f32; 3];
        for (c, s) in f[3..6].iter().enumerate() {
            b[c] = s
                .parse()
                .map_err(|_| err(line_no, format!("\"{s}\" is not a number")))?;
        }
        let slot = out.get_mut(i).ok_or_else(|| {
            err(
                line_no,
                format!("patch {i} is out of range for {n} patches"),
            )
        })?;
        if slot.replace(b).is_some() {
            return Err(err(line_no, format!("patch {i} appears twice")));
        }
    }
    out.iter()
        .enumerate()
        .map(|(i, b)| b.ok_or_else(|| err(0, format!("patch {i} is missing from the file"))))
        .collect()
}

/// Area-weighted averages of one group.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupRow {
    pub(crate) group: String,
    pub patches: usize,
    pub area: f64,
    /// Σ A_i B_i / Σ A_i over the group's patches.
    pub b: [f64; 3],
    /// Σ A_i H_i / Σ A_i.
    pub(crate) h: [f64; 3],
}

/// Per group (in group order, groups without patches left out), the area-weighted
/// average radiosity and irradiance of case `case`.
///
/// # Errors
/// [`SolveError::InvalidInput`] when `case` is out of range or the solution does not
/// match the patches.
pub fn group_table(
    patches: &PatchSet,
    solution: &Solution,
    case: usize,
) -> Result<Vec<GroupRow>, SolveError> {
    check_case(patches, solution, case)?;
    let mut acc: Vec<(usize, f64, [f64; 3], [f64; 3])> =
        vec![(0, 0.0, [0.0; 3], [0.0; 3]); patches.groups.len()];
    for (i, p) in patches.patches.iter().enumerate() {
        let Some(a) = acc.get_mut(p.group as usize) else {
            return Err(SolveError::InvalidInput(format!(
                "patch {i} refers to group {} of {}",
                p.group,
                patches.groups.len()
            )));
        };
        a.0 += 1;
        a.1 += p.area;
        for c in 0..3 {
            a.2[c] += p.area * solution.b[case][i][c];
            a.3[c] += p.area * solution.h[case][i][c];
        }
    }
    Ok(acc
        .into_iter()
        .enumerate()
        .filter(|(_, a)| a.0 > 0)
        .map(|(g, (count, area, b, h))| GroupRow {
            group: patches.groups[g].clone(),
            patches: count,
            area,
            b: b.map(|x| x / area),
            h: h.map(|x| x / area),
        })
        .collect())
}

/// The group table as aligned text: group, patches, area, B_r, B_g, B_b.
pub fn format_group_table(rows: &[GroupRow]) -> String {
    let width = rows
        .iter()
        .map(|r| r.group.chars().count())
        .chain(std::iter::once(5))
        .max()
        .unwrap_or(5);
    let mut s = format!(
        "{:<width$}  {:>7}  {:>12}  {:>12}  {:>12}  {:>12}\n",
        "group", "patches", "area", "B_r", "B_g", "B_b"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<width$}  {:>7}  {:>12.5e}  {:>12.5e}  {:>12.5e}  {:>12.5e}",
            r.group, r.patches, r.area, r.b[0], r.b[1], r.b[2]
        );
    }
    s
}
