//! Rows the solver need not read: the rows of patches that neither reflect nor emit
//! are skipped and never read (a poisoning row source proves it), and a row that is
//! needed but missing or skipped is an error.

use ffstream::solve::SolveError;

use super::*;

/// A row source that poisons the rows of patches that neither reflect nor emit: the
/// scan hands them over as NaN (or Skipped) and random access to them is an error. A
/// solve that used them would fail or produce NaN.
struct Poisoned {
    inner: MemoryRows,
    inert: Vec<bool>,
    skipped: bool,
}

impl RowSource for Poisoned {
    fn patches(&self) -> &PatchSet {
        self.inner.patches()
    }
    fn scan(&self, f: &mut dyn FnMut(&Row) -> Result<(), SolveError>) -> Result<(), SolveError> {
        let n = self.inert.len();
        self.inner.scan(&mut |r| {
            if self.inert[r.index as usize] {
                let poison = if self.skipped {
                    Row::skipped(r.index)
                } else {
                    Row::dense(r.index, vec![f32::NAN; n])
                };
                f(&poison)
            } else {
                f(r)
            }
        })
    }
    fn has_row(&self, i: u32) -> bool {
        self.inner.has_row(i)
    }
    fn row(&self, i: u32) -> Result<Option<Row>, SolveError> {
        if self.inert[i as usize] {
            return Err(SolveError::InvalidInput(format!(
                "row {i} of an inert patch must not be read"
            )));
        }
        self.inner.row(i)
    }
}

/// Non-reflecting patches: rows never read (counted as skipped), B = E, and their
/// irradiance (a black sensor) obtained by reciprocity equals the closed form.
#[test]
fn non_reflecting_rows_are_skipped_and_never_read() {
    let mut rng = SplitMix64::new(0xda4c);
    let n = 200;
    let areas = sphere_areas(n, 512, &mut rng);
    let total: f64 = areas.iter().sum();
    let mut rho = vec![[0.7f32, 0.6, 0.5]; n];
    let mut e = vec![[0.0f32; 3]; n];
    let mut inert = vec![false; n];
    // 40 black sensors (inert), one black emitter (row needed to shoot, and for the
    // sensors' H), one reflecting emitter.
    for i in 0..40 {
        rho[i] = [0.0; 3];
        inert[i] = true;
    }
    rho[40] = [0.0; 3];
    e[40] = [5.0, 5.0, 5.0];
    e[100] = [1.0, 0.0, 2.0];
    let exact_h: [f64; 3] = std::array::from_fn(|c| {
        let phi = emitted(&areas, &e, c);
        let a_rho: f64 = areas.iter().zip(&rho).map(|(a, r)| a * r[c] as f64).sum();
        phi / (total - a_rho)
    });
    let tol = 1e-10;
    for skipped in [false, true] {
        let src = Poisoned {
            inner: source(&areas, sphere_rows(&areas)),
            inert: inert.clone(),
            skipped,
        };
        for method in SolveMethod::ALL {
            let s = solve(&src, &[e.clone()], &rho, &cfg(method, tol)).unwrap();
            assert_finite(&s);
            assert_eq!(s.rows_skipped, 41, "{method}");
            assert!(s.warnings.is_empty(), "{:?}", s.warnings);
            // Errors relative to ‖B‖∞ (see sphere_closed_form_every_method).
            let b_max = (0..n)
                .flat_map(|i| (0..3).map(move |c| (i, c)))
                .map(|(i, c)| e[i][c] as f64 + rho[i][c] as f64 * exact_h[c])
                .fold(0.0f64, f64::max);
            for i in 0..n {
                for c in 0..3 {
                    let b_exact = e[i][c] as f64 + rho[i][c] as f64 * exact_h[c];
                    let err = (s.b[0][i][c] - b_exact).abs() / b_max;
                    assert!(err < error_bound(tol, 0.7), "{method} B[{i}][{c}]: {err:e}");
                    let err = (s.h[0][i][c] - exact_h[c]).abs() / b_max;
                    assert!(err < error_bound(tol, 0.7), "{method} H[{i}][{c}]: {err:e}");
                }
                if rho[i] == [0.0; 3] {
                    assert_eq!(s.b[0][i], e[i].map(f64::from), "dark patches keep B = E");
                }
            }
        }
    }
}

/// A black emitter whose row the file skipped: gathering still solves B (its B = E)
/// but warns that the sensors' H misses its direct light; shooting cannot shoot from
/// it and says which row.
#[test]
fn skipped_row_of_a_black_emitter() {
    let areas = [1.0; 6];
    let mut rows = cube_rows();
    rows[0] = Row::skipped(0);
    let src = source(&areas, rows);
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0; 3];
    let mut rho = vec![[0.5f32; 3]; 6];
    rho[0] = [0.0; 3];
    rho[1] = [0.0; 3]; // a black sensor opposite the emitter
    for method in [SolveMethod::Jacobi, SolveMethod::GaussSeidel] {
        let s = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap();
        assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
        assert!(s.warnings[0].contains("row 0"), "{}", s.warnings[0]);
    }
    let err = solve(&src, &[e], &rho, &cfg(SolveMethod::Shooting, 1e-9)).unwrap_err();
    assert!(
        matches!(err, SolveError::SkippedRow { row: 0, .. }),
        "{err}"
    );
}

/// Needed rows that are missing or Skipped are errors naming the row, and every solver
/// counts all the needed rows that are missing (shooting, which reads rows at random,
/// said "1 needed rows missing" when 427 were).
#[test]
fn missing_or_skipped_needed_rows_are_errors() {
    let areas = [1.0; 6];
    let mut e = vec![[0.0f32; 3]; 6];
    e[0] = [1.0; 3];
    let rho = vec![[0.5f32; 3]; 6];
    let missing: Vec<Row> = cube_rows()
        .into_iter()
        .filter(|r| ![1, 3, 4].contains(&r.index))
        .collect();
    let src = source(&areas, missing);
    for method in SolveMethod::ALL {
        let err = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap_err();
        assert!(
            matches!(err, SolveError::MissingRow { missing: 3, .. }),
            "{method}: {err}"
        );
        assert!(err.to_string().contains("3 needed rows missing"), "{err}");
    }
    let missing: Vec<Row> = cube_rows().into_iter().filter(|r| r.index != 3).collect();
    let src = source(&areas, missing);
    for method in SolveMethod::ALL {
        let err = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap_err();
        assert!(
            matches!(err, SolveError::MissingRow { row: 3, .. }),
            "{method}: {err}"
        );
        assert!(err.to_string().contains("row 3"), "{err}");
    }
    let mut rows = cube_rows();
    rows[2] = Row::skipped(2);
    let src = source(&areas, rows);
    for method in SolveMethod::ALL {
        let err = solve(&src, &[e.clone()], &rho, &cfg(method, 1e-9)).unwrap_err();
        assert!(
            matches!(err, SolveError::SkippedRow { row: 2, .. }),
            "{method}: {err}"
        );
    }
    // Inputs that cannot be solved.
    let src = source(&areas, cube_rows());
    let bad_rho = vec![[1.0f32; 3]; 6];
    assert!(matches!(
        solve(&src, &[e.clone()], &bad_rho, &SolveConfig::default()),
        Err(SolveError::InvalidInput(_))
    ));
    assert!(matches!(
        solve(&src, &[vec![[0.0; 3]; 5]], &rho, &SolveConfig::default()),
        Err(SolveError::InvalidInput(_))
    ));
}
