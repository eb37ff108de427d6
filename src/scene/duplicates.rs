//! Coincident duplicate faces: the same polygon twice, facing the same way.
//!
//! Each copy is a surface of its own to the form factors, so a duplicated face takes its
//! share of every row twice: a closed box with duplicated walls showed row sums of 1.44
//! and a solve reported a negative "escaped" power. A copy facing the other way (the
//! same corners in reverse order) is not a duplicate: back to back, the two sides of a
//! thin wall see different half-spaces. Corners are compared exactly (their f64 bits,
//! −0 taken as +0), so two corners written with the same coordinates match whether or
//! not they share an OBJ vertex; a polygon split differently (a quad and its two
//! triangles) is not detected.

use std::collections::HashMap;

use super::Face;

/// The faces that repeat an earlier face, each with the index of the face it repeats.
pub(crate) fn coincident_duplicates(faces: &[Face]) -> Vec<(usize, usize)> {
    let mut first: HashMap<Vec<[u64; 3]>, usize> = HashMap::with_capacity(faces.len());
    let mut out = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        let key = canonical(face);
        match first.get(&key) {
            Some(&g) => out.push((f, g)),
            None => {
                first.insert(key, f);
            }
        }
    }
    out
}

/// The corners' bits, rotated to start at the smallest corner: the same key for every
/// starting corner of the same cycle, a different one for the reversed cycle.
fn canonical(face: &Face) -> Vec<[u64; 3]> {
    let bits: Vec<[u64; 3]> = face
        .corners
        .iter()
        .map(|c| (*c + glam::DVec3::ZERO).to_array().map(f64::to_bits))
        .collect();
    let start = (0..bits.len()).min_by_key(|&k| bits[k]).unwrap_or(0);
    bits[start..]
        .iter()
        .chain(&bits[..start])
        .copied()
        .collect()
}

/// The warning for `dups` in a scene read from `path` (None when there are none): the
/// count, the first pair's lines and the groups involved.
pub(crate) fn duplicates_warning(
    path: &str,
    faces: &[Face],
    groups: &[String],
    dups: &[(usize, usize)],
    unit: &str,
) -> Option<String> {
    let &(f, g) = dups.first()?;
    let mut names: Vec<&str> = Vec::new();
    for &(d, _) in dups {
        let name = groups
            .get(faces[d].group as usize)
            .map_or("?", String::as_str);
        if !names.contains(&name) {
            names.push(name);
        }
    }
    let shown = names.len().min(5);
    let more = match names.len() - shown {
        0 => String::new(),
        m => format!(" and {m} more"),
    };
    let at = |face: usize| match faces[face].line {
        0 => format!("face {face}"),
        l => format!("{unit} {l}"),
    };
    Some(format!(
        "{path}: {} face(s) repeat another face exactly (same corners, same facing; first {} repeats {}), in group(s) {}{more}: each copy counts as a surface of its own, so its light is counted twice (row sums above 1 in a closed scene); remove the copies, or use --strict to refuse such scenes",
        dups.len(),
        at(f),
        at(g),
        names[..shown].join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn face(c: &[[f64; 3]], group: u32) -> Face {
        Face {
            corners: c.iter().map(|&a| DVec3::from_array(a)).collect(),
            group,
            material: 0,
            line: 0,
        }
    }

    #[test]
    fn same_polygon_from_any_corner_is_a_duplicate_and_the_reversed_one_is_not() {
        let a = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let rotated = [a[2], a[3], a[0], a[1]];
        let reversed = [a[3], a[2], a[1], a[0]];
        let negative_zero = [[-0.0, 0.0, 0.0], a[1], a[2], a[3]];
        let moved = [[0.0, 0.0, 1e-12], a[1], a[2], a[3]];
        let faces = vec![
            face(&a, 0),
            face(&rotated, 1),
            face(&reversed, 2),
            face(&negative_zero, 3),
            face(&moved, 4),
            face(&a[..3], 5),
        ];
        assert_eq!(coincident_duplicates(&faces), vec![(1, 0), (3, 0)]);
        let groups: Vec<String> = (0..6).map(|g| format!("g{g}")).collect();
        let w = duplicates_warning(
            "s.obj",
            &faces,
            &groups,
            &coincident_duplicates(&faces),
            "line",
        )
        .unwrap();
        assert!(w.contains("2 face(s)") && w.contains("g1, g3"), "{w}");
        assert!(w.contains("face 1 repeats face 0"), "{w}");
        assert_eq!(
            duplicates_warning("s.obj", &faces, &groups, &[], "line"),
            None
        );
    }
}
