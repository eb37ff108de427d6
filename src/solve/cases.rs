//! Emission cases: several lighting set-ups solved in one pass over the matrix.
//!
//! File format (CSV, header line exactly `case,group,e_r,e_g,e_b`):
//!
//! ```text
//! case,group,e_r,e_g,e_b
//! # morning: only the window glows
//! morning,window,5,5,4.5
//! evening,lamp,20,16,10
//! evening,window,0.5,0.5,0.8
//! ```
//!
//! Each line gives the exitance (radiosity units, like MTL `Ke`) of every patch of one
//! group in one case. A case's emission replaces the scene's own `Ke` entirely: groups
//! it does not list emit nothing. Cases are numbered in order of first appearance; the
//! `case` field is any label. Blank lines and lines starting with `#` are ignored; a
//! group named twice in one case, an unknown group, or a value that is negative or not
//! a number is an error naming the line.

use std::collections::HashMap;
use std::path::Path;

use crate::patch::PatchSet;

use super::error::SolveError;
use crate::table;

/// The header line of an emission-cases file.
pub const CASES_HEADER: &str = "case,group,e_r,e_g,e_b";

/// Parsed emission cases: `names[k]` labels `sets[k]` (n exitances).
#[derive(Clone, Debug, PartialEq)]
pub struct EmissionCases {
    pub names: Vec<String>,
    pub sets: Vec<Vec<[f32; 3]>>,
}

/// Read an emission-cases CSV for `patches` (format in the module docs).
///
/// # Errors
/// [`SolveError::Io`] when the file cannot be read; [`SolveError::Parse`] naming the
/// line for a wrong header, an unknown group, a duplicate or a bad number.
pub fn read_emission_cases(
    path: &Path,
    patches: &PatchSet,
) -> Result<Vec<Vec<[f32; 3]>>, SolveError> {
    let text = std::fs::read_to_string(path).map_err(|e| SolveError::io(path, e))?;
    Ok(parse_emission_cases(&text, path, patches)?.sets)
}

/// Parse emission cases from `text`; `path` only names the source in errors.
///
/// # Errors
/// As [`read_emission_cases`], without the I/O error.
pub fn parse_emission_cases(
    text: &str,
    path: &Path,
    patches: &PatchSet,
) -> Result<EmissionCases, SolveError> {
    let err = |line: usize, message: String| SolveError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    // A group name may label several group indices (OBJ files can repeat a name).
    let mut groups_by_name: HashMap<&str, Vec<u32>> = HashMap::new();
    for (g, name) in patches.groups.iter().enumerate() {
        groups_by_name
            .entry(name.as_str())
            .or_default()
            .push(g as u32);
    }
    let mut names: Vec<String> = Vec::new();
    let mut per_group: Vec<HashMap<u32, [f32; 3]>> = Vec::new();
    let mut header_seen = false;
    for record in table::records(text) {
        let table::Record {
            line: line_no,
            fields,
        } = record.map_err(|(line, m)| err(line, m))?;
        if !header_seen {
            if fields.join(",") != CASES_HEADER {
                return Err(err(
                    line_no,
                    format!(
                        "expected the header `{CASES_HEADER}`, found `{}`",
                        fields.join(",")
                    ),
                ));
            }
            header_seen = true;
            continue;
        }
        if fields.len() != 5 {
            return Err(err(
                line_no,
                format!("expected 5 fields, found {}", fields.len()),
            ));
        }
        let case = match names.iter().position(|n| *n == fields[0]) {
            Some(c) => c,
            None => {
                names.push(fields[0].clone());
                per_group.push(HashMap::new());
                names.len() - 1
            }
        };
        let group_ids = groups_by_name.get(fields[1].as_str()).ok_or_else(|| {
            err(
                line_no,
                format!(
                    "unknown group \"{}\" (the scene has: {})",
                    fields[1],
                    patches.groups.join(", ")
                ),
            )
        })?;
        let mut e = [0.0f32; 3];
        for (ch, f) in fields[2..5].iter().enumerate() {
            let v: f32 = f
                .parse()
                .map_err(|_| err(line_no, format!("\"{f}\" is not a number")))?;
            if !(v.is_finite() && v >= 0.0) {
                return Err(err(line_no, format!("exitance {v} must be finite and ≥ 0")));
            }
            e[ch] = v;
        }
        for &g in group_ids {
            if per_group[case].insert(g, e).is_some() {
                return Err(err(
                    line_no,
                    format!(
                        "group \"{}\" is given twice in case \"{}\"",
                        fields[1], fields[0]
                    ),
                ));
            }
        }
    }
    if !header_seen {
        return Err(err(
            0,
            format!("empty file: expected the header `{CASES_HEADER}`"),
        ));
    }
    if names.is_empty() {
        return Err(err(0, "no emission case in the file".into()));
    }
    let sets = per_group
        .iter()
        .map(|map| {
            patches
                .patches
                .iter()
                .map(|p| map.get(&p.group).copied().unwrap_or([0.0; 3]))
                .collect()
        })
        .collect();
    Ok(EmissionCases { names, sets })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::patch::Patch;
    use glam::DVec3;

    fn patches() -> PatchSet {
        let p = |group| Patch {
            corners: [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::ZERO],
            n_corners: 3,
            normal: DVec3::Z,
            area: 0.5,
            group,
            face: 0,
            rho: [0.5; 3],
            emission: [9.0; 3],
        };
        PatchSet {
            patches: vec![p(0), p(1), p(1), p(2)],
            groups: vec!["lamp".into(), "window".into(), "floor".into()],
        }
    }

    #[test]
    fn cases_in_order_of_appearance_unlisted_groups_dark() {
        let text = "case,group,e_r,e_g,e_b\n# comment\n\nevening,lamp,20,16,10\n\
                    morning,window,5,5,4.5\nevening,window,0.5,0.5,0.75\n";
        let c = parse_emission_cases(text, Path::new("cases.csv"), &patches()).unwrap();
        assert_eq!(c.names, ["evening", "morning"]);
        assert_eq!(
            c.sets[0],
            vec![
                [20.0, 16.0, 10.0],
                [0.5, 0.5, 0.75],
                [0.5, 0.5, 0.75],
                [0.0; 3]
            ]
        );
        assert_eq!(
            c.sets[1],
            vec![[0.0; 3], [5.0, 5.0, 4.5], [5.0, 5.0, 4.5], [0.0; 3]]
        );
    }

    #[test]
    fn errors_name_the_line() {
        let bad_group = "case,group,e_r,e_g,e_b\na,lamp,1,1,1\na,attic,1,1,1\n";
        let e = parse_emission_cases(bad_group, Path::new("c.csv"), &patches()).unwrap_err();
        assert!(matches!(e, SolveError::Parse { line: 3, .. }), "{e}");
        assert!(e.to_string().contains("attic"), "{e}");
        let dup = "case,group,e_r,e_g,e_b\na,lamp,1,1,1\na,lamp,2,2,2\n";
        let e = parse_emission_cases(dup, Path::new("c.csv"), &patches()).unwrap_err();
        assert!(matches!(e, SolveError::Parse { line: 3, .. }), "{e}");
        let header = "case,group,r,g,b\n";
        let e = parse_emission_cases(header, Path::new("c.csv"), &patches()).unwrap_err();
        assert!(matches!(e, SolveError::Parse { line: 1, .. }), "{e}");
        let negative = "case,group,e_r,e_g,e_b\na,lamp,1,-1,1\n";
        let e = parse_emission_cases(negative, Path::new("c.csv"), &patches()).unwrap_err();
        assert!(matches!(e, SolveError::Parse { line: 2, .. }), "{e}");
    }
}
