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

/// Largest value a stored form factor, or a row's dropped mass, may have. No form
/// factor and no row's total exceeds 1; the margin is far beyond any honest numerical
/// error (sampled visibility gives row sums of 1.0014), so a value above it is damage
/// or a bug, not noise (spec §5.6, §10).
pub const MAX_FORM_FACTOR: f32 = 1.5;

/// What is wrong with the numbers of one row, if anything (all zero / false / None for
/// a row that can be a row of form factors). `verify` fails a file with any fault and
/// `solve` refuses it, so the two agree; both report [`RowFaults::lost_mass`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RowFaults {
    pub negative: u64,
    pub non_finite: u64,
    /// Finite values above [`MAX_FORM_FACTOR`].
    pub too_large: u64,
    /// The dropped mass is not finite, negative, or above [`MAX_FORM_FACTOR`].
    pub bad_dropped: bool,
    /// A sparse row that stores nothing (or only zeros) but has dropped mass > 0. Not
    /// a fault (all of a row's k largest entries can be hidden by occluders while its
    /// tail is not), but its mass cannot be put back by rescaling: readers report it
    /// (spec §5.6), and it is not counted in [`RowFaults::first`].
    pub lost_mass: bool,
    /// The first fault (not [`RowFaults::lost_mass`]), in words (column and value).
    pub first: Option<String>,
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

    /// Checks every stored value and the dropped mass ([`RowFaults`]).
    pub fn faults(&self) -> RowFaults {
        let mut f = RowFaults::default();
        let note = |f: &mut RowFaults, what: String| {
            f.first.get_or_insert(what);
        };
        self.for_each_nonzero(|j, x| {
            if !x.is_finite() {
                f.non_finite += 1;
                note(&mut f, format!("value {x} at column {j} is not finite"));
            } else if x < 0.0 {
                f.negative += 1;
                note(&mut f, format!("value {x:e} at column {j} is negative"));
            } else if x > MAX_FORM_FACTOR {
                f.too_large += 1;
                note(
                    &mut f,
                    format!(
                        "value {x:e} at column {j} is above {MAX_FORM_FACTOR}: not a form factor"
                    ),
                );
            }
        });
        let d = self.dropped;
        if !(d.is_finite() && (0.0..=MAX_FORM_FACTOR).contains(&d)) {
            f.bad_dropped = true;
            note(
                &mut f,
                format!("dropped mass {d:e} is not a finite number in [0, {MAX_FORM_FACTOR}]"),
            );
        } else if d > 0.0
            && matches!(self.values, RowValues::Sparse { .. })
            && self.stored_sum() == 0.0
        {
            f.lost_mass = true;
        }
        f
    }

    /// The row as n dense values (zeros where nothing is stored).
    pub fn to_dense(&self, n: usize) -> Vec<f32> {
        let mut out = vec![0.0; n];
        self.for_each_nonzero(|j, x| out[j as usize] = x);
        out
    }
}
