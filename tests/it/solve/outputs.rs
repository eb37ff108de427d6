//! What a solve reports and writes: the energy report of an open scene, the CSV and
//! group table read back, a multi-case solve from an emission cases file, the PLY
//! mesh read back, and the summary.

use std::path::Path;

use ffstream::render::{write_ply_with, PlyEncoding, PlyOptions};
use ffstream::solve::{
    case_path, format_group_table, group_table, parse_emission_cases, read_radiosity_csv,
    write_csv, CSV_HEADER,
};

use super::*;

/// An open scene: every row sums to 0.8 (20 % of the light leaves). With uniform ρ,
/// P = Σ A B = Φ / (1 − 0.8 ρ), incident = 0.8 P, escaped = 0.2 P.
#[test]
fn energy_report_of_an_open_scene() {
    let n = 32;
    let areas = vec![2.0; n];
    let rows: Vec<Row> = (0..n as u32)
        .map(|i| Row::dense(i, vec![0.8 / n as f32; n]))
        .collect();
    let src = source(&areas, rows);
    let mut e = vec![[0.0f32; 3]; n];
    e[3] = [1.0, 1.0, 1.0];
    let rho = 0.75;
    let s = solve(
        &src,
        &[e.clone()],
        &vec![[rho as f32; 3]; n],
        &cfg(SolveMethod::Jacobi, 1e-12),
    )
    .unwrap();
    let phi = 2.0;
    let p = phi / (1.0 - 0.8 * rho);
    let rep = &s.energy[0];
    for c in 0..3 {
        assert!((rep.total[c] - p).abs() < 1e-6 * p, "{rep}");
        assert!((rep.incident[c] - 0.8 * p).abs() < 1e-6 * p, "{rep}");
        assert!((rep.escaped[c] - 0.2 * p).abs() < 1e-6 * p, "{rep}");
        assert!((rep.reflected[c] - (p - phi)).abs() < 1e-6 * p, "{rep}");
        assert!(
            (rep.absorbed[c] - (1.0 - rho) * 0.8 * p).abs() < 1e-6 * p,
            "{rep}"
        );
        assert!(rep.imbalance()[c].abs() < 1e-6, "{rep}");
    }
}

// ---------------------------------------------------------------- outputs

/// CSV: exact header, one line per patch, values read back bit for bit; group table
/// gives area-weighted averages.
#[test]
fn csv_round_trip_and_group_table() {
    let dir = tempfile::tempdir().unwrap();
    let mut ps = patch_set(&[1.0, 3.0, 2.0, 2.0]);
    ps.groups = vec!["floor, east".into(), "lamp".into()];
    ps.patches[2].group = 1;
    ps.patches[3].group = 1;
    let rows: Vec<Row> = (0..4u32)
        .map(|i| Row::dense(i, vec![0.1, 0.2, 0.3, 0.1]))
        .collect();
    let src = MemoryRows::new(ps.clone(), rows).unwrap();
    let e = vec![[0.0; 3], [0.0; 3], [1.5, 0.1, 0.0], [0.0; 3]];
    let rho = vec![[0.5f32, 0.25, 0.125]; 4];
    let s = solve(
        &src,
        &[e.clone(), e.clone()],
        &rho,
        &cfg(SolveMethod::GaussSeidel, 1e-12),
    )
    .unwrap();
    let path = case_path(&dir.path().join("radiosity.csv"), 1, 2);
    assert!(path.ends_with("radiosity_case1.csv"));
    assert_eq!(case_path(Path::new("r.csv"), 0, 1), Path::new("r.csv"));
    write_csv(&path, &ps, &s, 1).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], CSV_HEADER);
    assert!(lines[0].starts_with("patch,group,area,B_r,B_g,B_b"));
    assert_eq!(lines.len(), 5);
    assert!(lines[1].starts_with("0,\"floor, east\",1,"), "{}", lines[1]);
    let back = read_radiosity_csv(&path, 4).unwrap();
    assert_eq!(back, s.radiosity_f32(1));
    // The other columns: E, rho and H read back exactly.
    let fields: Vec<&str> = lines[3].rsplitn(10, ',').collect();
    let tail: Vec<&str> = fields[..9].iter().rev().copied().collect();
    let as_f32 = |x: &str| x.parse::<f32>().unwrap();
    assert_eq!(
        tail[..3].iter().map(|x| as_f32(x)).collect::<Vec<_>>(),
        e[2]
    );
    assert_eq!(
        tail[3..6].iter().map(|x| as_f32(x)).collect::<Vec<_>>(),
        rho[2]
    );
    assert_eq!(tail[8].parse::<f64>().unwrap(), s.h[1][2][2]);
    // Group table: Σ A B / Σ A.
    let table = group_table(&ps, &s, 0).unwrap();
    assert_eq!(table.len(), 2);
    let b = &s.b[0];
    let want_floor = (1.0 * b[0][0] + 3.0 * b[1][0]) / 4.0;
    assert!((table[0].b[0] - want_floor).abs() < 1e-15 * want_floor);
    assert_eq!(table[1].area, 4.0);
    assert_eq!(table[1].patches, 2);
    let text = format_group_table(&table);
    assert!(text.lines().next().unwrap().starts_with("group"));
    assert!(text.contains("floor, east") && text.contains("lamp"));
    // A file with a patch missing is refused, naming the patch.
    std::fs::write(&path, format!("{CSV_HEADER}\n0,g,1,1,1,1\n")).unwrap();
    let err = read_radiosity_csv(&path, 2).unwrap_err();
    assert!(err.to_string().contains("patch 1"), "{err}");
}

/// Emission cases from a CSV drive a multi-case solve: a case lighting group "lamp"
/// equals the scene whose lamp emits the same.
#[test]
fn emission_cases_file_drives_a_multi_case_solve() {
    let areas = [1.0; 6];
    let mut ps = patch_set(&areas);
    ps.groups = vec!["walls".into(), "lamp".into()];
    ps.patches[5].group = 1;
    let src = MemoryRows::new(ps.clone(), cube_rows()).unwrap();
    let text = "case,group,e_r,e_g,e_b\nnight,lamp,2,2,2\nday,walls,0.5,0.5,0.5\n";
    let cases = parse_emission_cases(text, Path::new("cases.csv"), &ps).unwrap();
    assert_eq!(cases.names, ["night", "day"]);
    let rho = vec![[0.5f32; 3]; 6];
    let s = solve(&src, &cases.sets, &rho, &cfg(SolveMethod::Jacobi, 1e-12)).unwrap();
    // Night: only face 5 emits; Σ A B = 2 / (1 − 0.5 S) with S the stored row sum.
    let s_row = cube_rows()[0].stored_sum();
    let night = total_power(&areas, &s.b[0], 0);
    assert!((night - 2.0 / (1.0 - 0.5 * s_row)).abs() < 1e-9);
    // Day: five walls at 0.5: Σ A B = 2.5 / (1 − 0.5 S).
    let day = total_power(&areas, &s.b[1], 1);
    assert!((day - 2.5 / (1.0 - 0.5 * s_row)).abs() < 1e-9);
}

/// Parse a PLY file written by `write_ply_with` (either encoding): vertices with
/// colours, faces.
type PlyMesh = (Vec<[f32; 3]>, Vec<[u8; 3]>, Vec<Vec<i32>>);

fn parse_ply(bytes: &[u8]) -> PlyMesh {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("end_header")
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let mut nv = 0;
    let mut nf = 0;
    let mut binary = false;
    for l in header.lines() {
        let w: Vec<&str> = l.split_whitespace().collect();
        match w.as_slice() {
            ["format", "ascii", "1.0"] => binary = false,
            ["format", "binary_little_endian", "1.0"] => binary = true,
            ["element", "vertex", k] => nv = k.parse().unwrap(),
            ["element", "face", k] => nf = k.parse().unwrap(),
            _ => {}
        }
    }
    assert_eq!(header.lines().next(), Some("ply"));
    let (mut pos, mut col, mut faces) = (Vec::new(), Vec::new(), Vec::new());
    let body = &bytes[end..];
    if binary {
        let mut at = 0;
        let f32_at = |at: usize| f32::from_le_bytes(body[at..at + 4].try_into().unwrap());
        for _ in 0..nv {
            pos.push([f32_at(at), f32_at(at + 4), f32_at(at + 8)]);
            col.push([body[at + 12], body[at + 13], body[at + 14]]);
            at += 15;
        }
        for _ in 0..nf {
            let k = body[at] as usize;
            at += 1;
            let f = (0..k)
                .map(|q| i32::from_le_bytes(body[at + 4 * q..at + 4 * q + 4].try_into().unwrap()))
                .collect();
            at += 4 * k;
            faces.push(f);
        }
        assert_eq!(at, body.len(), "trailing bytes");
    } else {
        let text = std::str::from_utf8(body).unwrap();
        let mut lines = text.lines();
        for _ in 0..nv {
            let w: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
            pos.push(std::array::from_fn(|c| w[c].parse().unwrap()));
            col.push(std::array::from_fn(|c| w[3 + c].parse().unwrap()));
        }
        for _ in 0..nf {
            let w: Vec<i32> = lines
                .next()
                .unwrap()
                .split_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            assert_eq!(w[0] as usize, w.len() - 1);
            faces.push(w[1..].to_vec());
        }
        assert!(lines.next().is_none(), "trailing lines");
    }
    (pos, col, faces)
}

/// A unit cube cut into 2 × 2 quads per face (24 patches), one group per face: 26
/// distinct points (8 corners, 12 edge midpoints, 6 face centres), 9 vertices per face
/// once faces are not smoothed into each other (groups, and 90° creases).
fn subdivided_cube() -> PatchSet {
    let mut patches = Vec::new();
    let mut groups = Vec::new();
    for axis in 0..3 {
        for side in [0.0, 1.0] {
            let g = groups.len() as u32;
            groups.push(format!("face{axis}{side}"));
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for a in 0..2 {
                for b in 0..2 {
                    let corner = |du: f64, dv: f64| {
                        let mut p = [0.0; 3];
                        p[axis] = side;
                        p[u] = (a as f64 + du) * 0.5;
                        p[v] = (b as f64 + dv) * 0.5;
                        DVec3::from_array(p)
                    };
                    let mut p = patch(0.25, g);
                    p.n_corners = 4;
                    p.corners = [
                        corner(0., 0.),
                        corner(1., 0.),
                        corner(1., 1.),
                        corner(0., 1.),
                    ];
                    patches.push(p);
                }
            }
        }
    }
    PatchSet { patches, groups }
}

/// sRGB transfer function (IEC 61966-2-1) and 8-bit code, written out here.
fn srgb8(linear: f64) -> u8 {
    let x = linear.clamp(0.0, 1.0);
    let e = if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round() as u8
}

#[test]
fn ply_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let ps = subdivided_cube();
    let b = [0.2f32, 0.1, 0.05];
    let radiosity = vec![b; ps.len()];
    let mut decoded = Vec::new();
    for encoding in [PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian] {
        let path = dir.path().join(format!("lit-{encoding:?}.ply"));
        let opts = PlyOptions {
            encoding,
            exposure: None,
        };
        let exposure = write_ply_with(&path, &ps, &radiosity, &opts).unwrap();
        // The picture's automatic exposure: 0.8 over the luminance (BT.709) of the
        // (uniform) non-emitting patches.
        let y = 0.2126 * 0.2 + 0.7152 * 0.1 + 0.0722 * 0.05;
        assert!((f64::from(exposure) - 0.8 / y).abs() < 1e-5 * exposure as f64);
        let (pos, col, faces) = parse_ply(&std::fs::read(&path).unwrap());
        assert_eq!(pos.len(), 6 * 9, "9 vertices per face");
        assert_eq!(faces.len(), 24);
        for f in &faces {
            assert_eq!(f.len(), 4);
            assert!(f.iter().all(|&i| i >= 0 && (i as usize) < pos.len()));
        }
        // Every vertex lies on the half-unit lattice; 26 distinct points.
        let mut points: Vec<[f32; 3]> = Vec::new();
        for p in &pos {
            assert!(p.iter().all(|x| [0.0, 0.5, 1.0].contains(x)), "{p:?}");
            if !points.contains(p) {
                points.push(*p);
            }
        }
        assert_eq!(points.len(), 26);
        // No two vertices of one face's quads coincide: each face's 4 quads use 9.
        for face in faces.chunks(4) {
            let mut ids: Vec<i32> = face.iter().flatten().copied().collect();
            ids.sort_unstable();
            ids.dedup();
            assert_eq!(ids.len(), 9);
        }
        let want = b.map(|x| srgb8(f64::from(x) * 0.8 / y));
        assert!(col.iter().all(|c| *c == want), "{:?} vs {want:?}", col[0]);
        decoded.push((pos, col, faces));
    }
    assert_eq!(
        decoded[0], decoded[1],
        "ASCII and binary hold the same mesh"
    );
    // Explicit exposure 2.5: linear 0.5, 0.25, 0.125 → 188, 137, 99.
    let path = dir.path().join("exposed.ply");
    let opts = PlyOptions {
        encoding: PlyEncoding::Ascii,
        exposure: Some(2.5),
    };
    write_ply_with(&path, &ps, &radiosity, &opts).unwrap();
    let (_, col, _) = parse_ply(&std::fs::read(&path).unwrap());
    assert!(col.iter().all(|c| *c == [188, 137, 99]), "{:?}", col[0]);
    assert!(write_ply_with(&path, &ps, &radiosity[1..], &opts).is_err());
}

/// The summary names the method, the counts and every case's power balance.
#[test]
fn summary_reports_iterations_residual_and_energy() {
    let areas = [1.0; 6];
    let src = source(&areas, cube_rows());
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0; 3];
    let rho = vec![[0.5f32; 3]; 6];
    let mut c = cfg(SolveMethod::Jacobi, 1e-12);
    c.max_iterations = 3;
    let s = solve(&src, &[e.clone(), e], &rho, &c).unwrap();
    assert!(!s.converged);
    assert_eq!(s.iterations, 3);
    let text = s.summary();
    eprintln!("{text}");
    assert!(text.starts_with("jacobi: 3 sweeps"), "{text}");
    assert!(
        text.contains("NOT converged") && text.contains("case 1 power"),
        "{text}"
    );
    assert!(
        s.warnings[0].contains("iteration limit"),
        "{:?}",
        s.warnings
    );
}

/// `solve` prints one progress line a sweep on stderr, numbered from 1 without a gap,
/// whose residual falls to the tolerance by the last (Gauss–Seidel: the bound that
/// stops it; Jacobi: the residual itself), and none with `--quiet`; the answer is the
/// same either way.
#[test]
fn solve_reports_each_sweep_unless_quiet() {
    use crate::common::{ffstream, ok, path_str};
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("c.ffz");
    ok(&[
        "compute",
        "builtin:cornell",
        "--patches",
        "300",
        "-q",
        "-o",
        path_str(&file),
    ]);
    for (solver, label) in [("gauss-seidel", "residual bound"), ("jacobi", "residual")] {
        let (loud, quiet) = (dir.path().join("loud.csv"), dir.path().join("quiet.csv"));
        // `solve` of the file with this solver into `out`, after the global `first`.
        let solve = |first: &[&str], out: &Path| {
            let args = [
                "solve",
                path_str(&file),
                "--solver",
                solver,
                "-o",
                path_str(out),
            ];
            let out = ffstream(&[first, &args[..]].concat());
            assert!(out.status.success());
            String::from_utf8_lossy(&out.stderr).into_owned()
        };
        let stderr = solve(&[], &loud);
        let lines: Vec<&str> = stderr
            .lines()
            .filter(|l| l.starts_with("progress:"))
            .collect();
        assert!(lines.len() >= 3, "{solver}: {stderr}");
        let mut last = f64::INFINITY;
        for (k, line) in lines.iter().enumerate() {
            let head = format!("progress: {solver} sweep {}, {label} ", k + 1);
            let rest = line.strip_prefix(&head).unwrap_or_else(|| panic!("{line}"));
            last = rest.split(',').next().unwrap().parse().unwrap();
        }
        assert!(last <= 1e-6, "{solver}: last {last}");
        let stderr = solve(&["-q"], &quiet);
        assert!(!stderr.contains("progress:"), "{stderr}");
        assert_eq!(
            std::fs::read(&loud).unwrap(),
            std::fs::read(&quiet).unwrap()
        );
    }
}
