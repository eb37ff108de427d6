//! One stored row as the solver uses it: checked once, scaled for top-k, and read by
//! two kernels (gather: Σ_j F_ij B_j; visit: every entry, for shooting and scatter).
//!
//! Top-k rows. A top-k row keeps the k largest F_ij and records in `Row::dropped` the
//! mass it left out (see `src/rows.rs`). With [`super::DroppedMass::Scale`] the solver
//! multiplies the kept entries by s_i = (stored + dropped) / stored, so the row it uses
//! sums to the true row sum: the light patch i lacks from its dropped senders is taken
//! from the kept ones in proportion to their share. This is the renormalisation the
//! paper proposes as future work ("keeping only the top 10-20 % ... renormalised so no
//! light is lost"); it sums rows right but not columns, so power is not conserved
//! (`pool.rs` does that). Otherwise s = 1 and the view carries the row's dropped mass
//! for the pool. Dense rows have `dropped = 0` and s = 1.

use crate::rows::{Row, RowValues};

use super::error::SolveError;

/// The stored entries of a row.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Entries<'r> {
    Dense(&'r [f32]),
    Sparse(&'r [u32], &'r [f32]),
}

/// A validated, scaled view of one stored row.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowView<'r> {
    pub(crate) index: u32,
    pub(crate) entries: Entries<'r>,
    /// The row's links to clusters (spec §5.7; empty for rows without), with the
    /// cluster order (with areas and centroids) that gives them their patches.
    pub(crate) links: &'r [crate::rows::Link],
    pub(crate) space: Option<&'r super::links::LinkSpace>,
    /// Factor applied to every stored entry (1 unless renormalising a top-k row).
    pub(crate) scale: f64,
    /// Dropped mass that the scale cannot put back (a row that stores nothing), when
    /// renormalizing; else 0.
    pub(crate) lost: f32,
    /// The row's dropped mass D_i (the pool's weight, `pool.rs`).
    pub(crate) dropped: f64,
}

impl<'r> RowView<'r> {
    /// View `row` of a matrix with `n` columns; `None` for a Skipped row.
    ///
    /// # Errors
    /// [`SolveError::BadRow`] for a dense row whose length is not n, a sparse row whose
    /// column and value lists differ in length, or a row with [`Row::faults`]. Column
    /// indices are checked where they are used.
    pub(crate) fn new(
        row: &'r Row,
        n: usize,
        renormalize: bool,
        check_values: bool,
    ) -> Result<Option<Self>, SolveError> {
        let bad = |message: String| SolveError::BadRow {
            row: row.index,
            message,
        };
        let entries = match &row.values {
            RowValues::Skipped => return Ok(None),
            RowValues::Dense(v) => {
                if v.len() != n {
                    return Err(bad(format!(
                        "dense row has {} values, expected {n}",
                        v.len()
                    )));
                }
                Entries::Dense(v)
            }
            RowValues::Sparse { cols, vals } => {
                if cols.len() != vals.len() {
                    return Err(bad(format!(
                        "sparse row has {} columns but {} values",
                        cols.len(),
                        vals.len()
                    )));
                }
                Entries::Sparse(cols, vals)
            }
        };
        // The same checks as `verify` (negative, non-finite or impossible values, bad
        // or unrecoverable dropped mass), so what one accepts the other does; a pass
        // over the row, so the caller asks for it once per row, not once per sweep.
        if check_values {
            if let Some(what) = row.faults().first {
                return Err(bad(what));
            }
        }
        let mut scale = 1.0;
        let mut lost = 0.0;
        // A row with links places its dropped mass itself: nothing to scale.
        if renormalize && row.dropped > 0.0 && row.links.is_empty() {
            let stored = row.stored_sum();
            // A row whose kept entries sum to 0 has nowhere to put the dropped light:
            // it stays as stored and the solve reports the light lost.
            if stored > 0.0 {
                scale = (stored + row.dropped as f64) / stored;
            } else {
                lost = row.dropped;
            }
        }
        Ok(Some(RowView {
            index: row.index,
            entries,
            links: &row.links,
            space: None,
            scale,
            lost,
            dropped: f64::from(row.dropped.max(0.0)),
        }))
    }

    fn out_of_range(&self, j: u32, n: usize) -> SolveError {
        SolveError::OutOfRange {
            row: self.index,
            index: j as u64,
            n,
        }
    }

    /// `acc[c] = s Σ_j F_ij b[j m + c]` for c < m (acc is overwritten); returns the
    /// scaled row sum of |F_ij| (used by the Gauss–Seidel residual bound).
    ///
    /// # Errors
    /// [`SolveError::OutOfRange`] for a column ≥ n, [`SolveError::BadRow`] when the
    /// result is not finite (the row holds NaN or Inf).
    pub(crate) fn gather(&self, b: &[f64], m: usize, acc: &mut [f64]) -> Result<f64, SolveError> {
        debug_assert_eq!(acc.len(), m);
        debug_assert_eq!(b.len() % m, 0);
        acc.fill(0.0);
        let mut abs_sum = 0.0;
        match self.entries {
            Entries::Dense(v) => {
                // Length checked in `new`, so b has exactly one chunk per value.
                if m == 3 {
                    // The common single-case path: three accumulators in registers.
                    let (mut a0, mut a1, mut a2) = (0.0, 0.0, 0.0);
                    for (&f, bj) in v.iter().zip(b.chunks_exact(3)) {
                        let f = f as f64;
                        a0 += f * bj[0];
                        a1 += f * bj[1];
                        a2 += f * bj[2];
                        abs_sum += f.abs();
                    }
                    acc.copy_from_slice(&[a0, a1, a2]);
                } else {
                    for (&f, bj) in v.iter().zip(b.chunks_exact(m)) {
                        let f = f as f64;
                        for (a, &x) in acc.iter_mut().zip(bj) {
                            *a += f * x;
                        }
                        abs_sum += f.abs();
                    }
                }
            }
            Entries::Sparse(cols, vals) => {
                let n = b.len() / m;
                for (&j, &f) in cols.iter().zip(vals) {
                    let start = j as usize * m;
                    let bj = b
                        .get(start..start + m)
                        .ok_or_else(|| self.out_of_range(j, n))?;
                    let f = f as f64;
                    for (a, &x) in acc.iter_mut().zip(bj) {
                        *a += f * x;
                    }
                    abs_sum += f.abs();
                }
            }
        }
        for a in acc.iter_mut() {
            *a *= self.scale;
        }
        if !(abs_sum.is_finite() && acc.iter().all(|a| a.is_finite())) {
            return Err(SolveError::BadRow {
                row: self.index,
                message: "the row holds values that are not finite".into(),
            });
        }
        Ok(abs_sum * self.scale)
    }

    /// Call `f(j, s F_ij)` for every stored non-zero entry, in column order, and then
    /// for every patch of the row's links (expanded, spec §5.7).
    ///
    /// # Errors
    /// [`SolveError::OutOfRange`] for a column ≥ n, [`SolveError::BadRow`] for an entry
    /// that is not finite.
    pub(crate) fn visit(&self, n: usize, mut f: impl FnMut(usize, f64)) -> Result<(), SolveError> {
        self.visit_entries(n, &mut f)?;
        if let (false, Some(space), Entries::Sparse(cols, _)) =
            (self.links.is_empty(), self.space, self.entries)
        {
            space.expand(self.links, self.index, cols, f);
        }
        Ok(())
    }

    /// [`RowView::visit`] of the stored entries alone, the links left out.
    ///
    /// # Errors
    /// As [`RowView::visit`].
    pub(crate) fn visit_entries(
        &self,
        n: usize,
        mut f: impl FnMut(usize, f64),
    ) -> Result<(), SolveError> {
        let bad_value = |x: f32| SolveError::BadRow {
            row: self.index,
            message: format!("value {x} is not finite"),
        };
        match self.entries {
            Entries::Dense(v) => {
                for (j, &x) in v.iter().enumerate() {
                    if x != 0.0 {
                        if !x.is_finite() {
                            return Err(bad_value(x));
                        }
                        f(j, x as f64 * self.scale);
                    }
                }
            }
            Entries::Sparse(cols, vals) => {
                for (&j, &x) in cols.iter().zip(vals) {
                    if (j as usize) >= n {
                        return Err(self.out_of_range(j, n));
                    }
                    if !x.is_finite() {
                        return Err(bad_value(x));
                    }
                    if x != 0.0 {
                        f(j as usize, x as f64 * self.scale);
                    }
                }
            }
        }
        Ok(())
    }

    /// The cols of the kept entries (empty for dense rows).
    pub(crate) fn cols(&self) -> &'r [u32] {
        match self.entries {
            Entries::Sparse(cols, _) => cols,
            Entries::Dense(_) => &[],
        }
    }

    /// The value of column `j` (0 when not stored). Dense rows only answer in O(1);
    /// sparse rows by binary search (columns are ascending per the row format).
    pub(crate) fn get(&self, j: usize) -> f64 {
        let x = match self.entries {
            Entries::Dense(v) => v.get(j).copied().unwrap_or(0.0),
            Entries::Sparse(cols, vals) => match cols.binary_search(&(j as u32)) {
                Ok(k) => vals[k],
                Err(_) => 0.0,
            },
        };
        x as f64 * self.scale
    }

    /// True for dense storage (the scatter pass reads dense rows by index instead of
    /// walking every entry).
    pub(crate) fn is_dense(&self) -> bool {
        matches!(self.entries, Entries::Dense(_))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn top_k_scale_restores_true_row_sum() {
        let row = Row {
            index: 0,
            values: RowValues::Sparse {
                cols: vec![1, 3],
                vals: vec![0.25, 0.5],
            },
            dropped: 0.25,
            links: Vec::new(),
            link_error: None,
        };
        let v = RowView::new(&row, 4, true, true).unwrap().unwrap();
        assert!((v.scale - 1.0 / 0.75).abs() < 1e-15);
        let mut sum = 0.0;
        v.visit(4, |_, f| sum += f).unwrap();
        assert!((sum - 1.0).abs() < 1e-15, "{sum}");
        let off = RowView::new(&row, 4, false, true).unwrap().unwrap();
        assert_eq!(off.scale, 1.0);
    }

    #[test]
    fn gather_matches_dense_product_for_several_columns() {
        // F row = (0.1, 0.2, 0.3); B with m = 6 columns: b[j][c] = j + 10 c.
        let row = Row::dense(0, vec![0.1, 0.2, 0.3]);
        let m = 6;
        let b: Vec<f64> = (0..3)
            .flat_map(|j| (0..m).map(move |c| j as f64 + 10.0 * c as f64))
            .collect();
        let v = RowView::new(&row, 3, true, true).unwrap().unwrap();
        let mut acc = vec![0.0; m];
        let abs = v.gather(&b, m, &mut acc).unwrap();
        for (c, a) in acc.iter().enumerate() {
            let want = (0..3)
                .map(|j| [0.1f32, 0.2, 0.3][j] as f64 * (j as f64 + 10.0 * c as f64))
                .sum::<f64>();
            assert!((a - want).abs() < 1e-12, "column {c}: {a} vs {want}");
        }
        assert!((abs - 0.6).abs() < 1e-7);
    }

    #[test]
    fn bad_rows_are_named() {
        let short = Row::dense(5, vec![0.0; 2]);
        assert!(matches!(
            RowView::new(&short, 3, true, true),
            Err(SolveError::BadRow { row: 5, .. })
        ));
        let far = Row {
            index: 2,
            values: RowValues::Sparse {
                cols: vec![9],
                vals: vec![0.5],
            },
            dropped: 0.0,
            links: Vec::new(),
            link_error: None,
        };
        let v = RowView::new(&far, 3, true, true).unwrap().unwrap();
        let mut acc = vec![0.0; 3];
        assert!(matches!(
            v.gather(&[0.0; 9], 3, &mut acc),
            Err(SolveError::OutOfRange {
                row: 2,
                index: 9,
                ..
            })
        ));
        // Refused when viewed (the checks `verify` makes), naming row and column.
        for (x, words) in [
            (f32::NAN, "value NaN at column 0 is not finite"),
            (-0.5, "value -5e-1 at column 0 is negative"),
            (1e30, "value 1e30 at column 0 is above 1.5"),
        ] {
            let bad = Row::dense(1, vec![x, 0.0, 0.0]);
            match RowView::new(&bad, 3, true, true) {
                Err(SolveError::BadRow { row: 1, message }) => {
                    assert!(message.contains(words), "{message}")
                }
                other => panic!("{x}: {:?}", other.map(|v| v.is_some())),
            }
        }
    }
}
