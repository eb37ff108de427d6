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

/// Whether a row's `dropped` (f32) is the sum `linked` of its links' values (f32 each,
/// summed in f64), up to the rounding of both: the writer stores the f32 of the f64 sum.
pub fn links_match_dropped(linked: f64, dropped: f32) -> bool {
    (linked - f64::from(dropped)).abs() <= 1e-6 * linked.abs().max(f64::from(dropped).abs()) + 1e-30
}

/// One link of a sparse row to a cluster of patches (spec §5.7): the form factor from
/// the row patch to the patches at positions `start .. start + len` of the file's
/// cluster order that the row neither keeps as patch entries nor is itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    /// First position in the cluster order.
    pub start: u32,
    /// Number of positions (≥ 1).
    pub len: u32,
    /// F from the row patch to the link's patches, together.
    pub value: f32,
    /// How the link's mass leans inside its cluster (spec §5.7): patch j of the link
    /// weighs A_j (1 + slope · (x_j − x̄)), x̄ the area-weighted mean centroid of the
    /// whole range. Zero: by area alone.
    pub slope: [f32; 3],
}

impl Link {
    /// One past the last position.
    pub fn end(&self) -> u64 {
        u64::from(self.start) + u64::from(self.len)
    }
}

/// One row of the form-factor matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Row index i (the emitting patch).
    pub index: u32,
    pub values: RowValues,
    /// Σ of the entries that top-k dropped (0 for dense rows). A reader that wants
    /// "no light lost" scales the kept entries by (stored + dropped) / stored. In a
    /// file with links it is the sum of the links' values (spec §5.7).
    pub dropped: f32,
    /// Where the dropped mass goes: links to clusters of patches, disjoint and in
    /// ascending order (empty for rows of files without a cluster order).
    pub links: Vec<Link>,
    /// With links: the writer's estimate of the relative error the links make in the
    /// radiosity the row gathers (spec §5.7, LINK_ERROR), a finite number ≥ 0; `None`
    /// when the writer made none.
    pub link_error: Option<f32>,
}

impl Row {
    pub fn dense(index: u32, vals: Vec<f32>) -> Self {
        Row {
            index,
            values: RowValues::Dense(vals),
            dropped: 0.0,
            links: Vec::new(),
            link_error: None,
        }
    }

    pub fn skipped(index: u32) -> Self {
        Row {
            index,
            values: RowValues::Skipped,
            dropped: 0.0,
            links: Vec::new(),
            link_error: None,
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
        for (m, l) in self.links.iter().enumerate() {
            let x = l.value;
            if !x.is_finite() {
                f.non_finite += 1;
                note(&mut f, format!("link {m}'s value {x} is not finite"));
            } else if x < 0.0 {
                f.negative += 1;
                note(&mut f, format!("link {m}'s value {x:e} is negative"));
            } else if x > MAX_FORM_FACTOR {
                f.too_large += 1;
                note(
                    &mut f,
                    format!("link {m}'s value {x:e} is above {MAX_FORM_FACTOR}: not a form factor"),
                );
            }
            if let Some(c) = l.slope.iter().find(|c| !c.is_finite()) {
                f.non_finite += 1;
                note(
                    &mut f,
                    format!("link {m}'s slope component {c} is not finite"),
                );
            }
        }
        let d = self.dropped;
        let linked: f64 = self.links.iter().map(|l| f64::from(l.value)).sum();
        if !self.links.is_empty() && !links_match_dropped(linked, d) {
            f.bad_dropped = true;
            note(
                &mut f,
                format!("dropped mass {d:e} is not the sum of the row's links ({linked:e})"),
            );
        } else if !(d.is_finite() && (0.0..=MAX_FORM_FACTOR).contains(&d)) {
            f.bad_dropped = true;
            note(
                &mut f,
                format!("dropped mass {d:e} is not a finite number in [0, {MAX_FORM_FACTOR}]"),
            );
        } else if self.faults_lost_mass() {
            f.lost_mass = true;
        }
        f
    }

    /// Whether the row stores no mass but has dropped mass and no links to place it
    /// ([`RowFaults::lost_mass`] without the other checks).
    pub fn faults_lost_mass(&self) -> bool {
        self.dropped > 0.0
            && self.links.is_empty()
            && matches!(self.values, RowValues::Sparse { .. })
            && self.stored_sum() == 0.0
    }

    /// The sum of the links' values, accumulated in f64.
    pub fn linked_sum(&self) -> f64 {
        self.links.iter().map(|l| f64::from(l.value)).sum()
    }

    /// The row as n dense values (zeros where nothing is stored).
    pub fn to_dense(&self, n: usize) -> Vec<f32> {
        let mut out = vec![0.0; n];
        self.for_each_nonzero(|j, x| out[j as usize] = x);
        out
    }
}
