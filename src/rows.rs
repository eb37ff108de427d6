//! Rows: what the compute side produces and the `.ffz` file stores.
//!
//! Row `i` holds F_ij for all j (the fraction of the power leaving patch i that
//! arrives at patch j). Dense rows hold all n values; top-k rows hold the k largest
//! entries with their columns (sorted ascending) and the mass dropped by top-k, so
//! that `stored_sum() + dropped` is the true row sum (see `formats/ffz-v1.md`).

/// Values of one row.
#[derive(Clone, Debug, PartialEq)]
pub enum RowValues {
    /// All n values, column j at index j.
    Dense(Vec<f32>),
    /// Kept entries only: `cols` strictly ascending, `vals[k]` is the entry in column
    /// `cols[k]`.
    Sparse { cols: Vec<u32>, vals: Vec<f32> },
    /// Deliberately not computed (`--rows needed`: the patch neither reflects nor
    /// emits). Different from a row that is missing after a crash.
    Skipped,
}

/// One row of the form-factor matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Row index i (the emitting patch).
    pub index: u32,
    pub values: RowValues,
    /// Σ of the entries that top-k dropped (0 for dense rows). A reader that wants
    /// "no light lost" scales the kept entries by (stored + dropped) / stored.
    pub dropped: f32,
}

impl Row {
    pub fn dense(index: u32, vals: Vec<f32>) -> Self {
        Row {
            index,
            values: RowValues::Dense(vals),
            dropped: 0.0,
        }
    }

    pub fn skipped(index: u32) -> Self {
        Row {
            index,
            values: RowValues::Skipped,
            dropped: 0.0,
        }
    }

    /// Σ of the stored values, accumulated in f64.
    pub fn stored_sum(&self) -> f64 {
        match &self.values {
            RowValues::Dense(v) => v.iter().map(|&x| x as f64).sum(),
            RowValues::Sparse { vals, .. } => vals.iter().map(|&x| x as f64).sum(),
            RowValues::Skipped => 0.0,
        }
    }

    /// The true row sum: stored values plus the mass dropped by top-k.
    pub fn true_sum(&self) -> f64 {
        self.stored_sum() + self.dropped as f64
    }

    /// Visit the stored non-zero entries `(j, F_ij)` in ascending column order.
    pub fn for_each_nonzero(&self, mut f: impl FnMut(u32, f32)) {
        match &self.values {
            RowValues::Dense(v) => {
                for (j, &x) in v.iter().enumerate() {
                    if x != 0.0 {
                        f(j as u32, x);
                    }
                }
            }
            RowValues::Sparse { cols, vals } => {
                for (&j, &x) in cols.iter().zip(vals) {
                    f(j, x);
                }
            }
            RowValues::Skipped => {}
        }
    }

    /// The row as n dense values (zeros where nothing is stored).
    pub fn to_dense(&self, n: usize) -> Vec<f32> {
        let mut out = vec![0.0; n];
        self.for_each_nonzero(|j, x| out[j as usize] = x);
        out
    }
}
