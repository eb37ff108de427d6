//! The linear system every solver works on, validated once.
//!
//! B = E + ρ F B is solved for `m = 3K` right-hand sides at once (K emission cases ×
//! RGB). All per-patch vectors are stored row-major as `n × m` f64 arrays: entry
//! `i * m + c` is patch `i`, column `c = 3 k + channel` (case `k`). Keeping the columns of
//! one patch together means one read of F_ij serves every case and channel: each
//! iteration is a single pass over the rows, whatever K is.

use crate::patch::PatchSet;

use super::error::SolveError;
use super::pool::{Pool, PoolScan};
use super::source::RowSource;
use super::DroppedMass;

/// Validated inputs of one solve.
#[derive(Debug)]
pub(crate) struct System {
    pub(crate) n: usize,
    pub(crate) cases: usize,
    /// Columns: 3 × cases.
    pub(crate) m: usize,
    pub(crate) area: Vec<f64>,
    /// Patch centroids (what links' slopes lean along, spec §5.7).
    centroid: Vec<glam::DVec3>,
    /// Emission, `n × m`.
    pub(crate) e: Vec<f64>,
    /// Reflectance per patch and channel.
    pub(crate) rho: Vec<[f64; 3]>,
    /// ρ > 0 in some channel: the patch's row is needed by a gathering solve.
    pub(crate) reflects: Vec<bool>,
    /// E > 0 in some column: the patch emits in some case.
    pub(crate) emits: Vec<bool>,
    /// Patches that reflect nothing (`!reflects`), in index order.
    pub(crate) dark: Vec<u32>,
    /// What the solve does with the mass top-k rows dropped.
    dropped: DroppedMass,
    /// The pool of light top-k rows do not carry ([`super::DroppedMass::Pool`]), once
    /// measured ([`System::prepare_pool`]).
    pub(crate) pool: Option<Pool>,
    /// Rows seen that store nothing but have dropped mass (their light cannot be
    /// kept, spec §5.6), by row: their dropped mass (0: none, or not seen).
    lost_mass: Vec<std::sync::atomic::AtomicU32>,
    /// The cluster order of a source whose rows link to clusters (spec §5.7).
    pub(crate) links: Option<super::links::LinkSpace>,
    /// Rows whose values have been checked ([`crate::rows::Row::faults`]): the rows of
    /// a source do not change between sweeps, so each is checked the first time only.
    checked: Vec<std::sync::atomic::AtomicBool>,
}

impl System {
    /// Check and lay out the inputs.
    ///
    /// # Errors
    /// [`SolveError::InvalidInput`] naming the patch when an emission set or the
    /// reflectance table has the wrong length, an emission is negative or not finite, a
    /// reflectance is outside [0, 1), or an area is not positive and finite (shooting and
    /// the reciprocity relation A_i F_ij = A_j F_ji divide by areas).
    pub(crate) fn new(
        patches: &PatchSet,
        emission_sets: &[Vec<[f32; 3]>],
        rho: &[[f32; 3]],
        dropped: DroppedMass,
    ) -> Result<Self, SolveError> {
        let n = patches.len();
        let cases = emission_sets.len();
        if cases == 0 {
            return Err(SolveError::InvalidInput(
                "no emission case given (pass the scene's own emission as one case)".into(),
            ));
        }
        if rho.len() != n {
            return Err(SolveError::InvalidInput(format!(
                "{} reflectances for {n} patches",
                rho.len()
            )));
        }
        let m = 3 * cases;
        let mut area = Vec::with_capacity(n);
        for (i, p) in patches.patches.iter().enumerate() {
            if !(p.area.is_finite() && p.area > 0.0) {
                return Err(SolveError::InvalidInput(format!(
                    "patch {i} (group \"{}\") has area {}",
                    patches.group_name(i),
                    p.area
                )));
            }
            area.push(p.area);
        }
        let mut rho64 = Vec::with_capacity(n);
        let mut reflects = Vec::with_capacity(n);
        for (i, r) in rho.iter().enumerate() {
            if r.iter().any(|&x| !(0.0..1.0).contains(&x)) {
                return Err(SolveError::InvalidInput(format!(
                    "patch {i}: reflectance {r:?} is outside [0, 1) (the solve would not converge)"
                )));
            }
            rho64.push(r.map(f64::from));
            reflects.push(r.iter().any(|&x| x > 0.0));
        }
        let mut e = vec![0.0; n * m];
        let mut emits = vec![false; n];
        for (k, set) in emission_sets.iter().enumerate() {
            if set.len() != n {
                return Err(SolveError::InvalidInput(format!(
                    "emission case {k} has {} values for {n} patches",
                    set.len()
                )));
            }
            for (i, v) in set.iter().enumerate() {
                for (ch, &x) in v.iter().enumerate() {
                    if !(x.is_finite() && x >= 0.0) {
                        return Err(SolveError::InvalidInput(format!(
                            "emission case {k}, patch {i}: exitance {v:?} must be finite and ≥ 0"
                        )));
                    }
                    e[i * m + 3 * k + ch] = x as f64;
                    emits[i] |= x > 0.0;
                }
            }
        }
        let dark = (0..n as u32).filter(|&i| !reflects[i as usize]).collect();
        Ok(System {
            n,
            cases,
            m,
            area,
            centroid: patches.patches.iter().map(|p| p.centroid()).collect(),
            e,
            rho: rho64,
            reflects,
            emits,
            dark,
            dropped,
            pool: None,
            links: None,
            lost_mass: (0..n)
                .map(|_| std::sync::atomic::AtomicU32::new(0))
                .collect(),
            checked: (0..n)
                .map(|_| std::sync::atomic::AtomicBool::new(false))
                .collect(),
        })
    }

    /// ρ of patch `i` in column `c`.
    #[inline]
    pub(crate) fn rho_col(&self, i: usize, c: usize) -> f64 {
        self.rho[i][c % 3]
    }

    /// Emitted power per column, Σ_i A_i E_ic.
    pub(crate) fn emitted_power(&self) -> Vec<f64> {
        let mut p = vec![0.0; self.m];
        for i in 0..self.n {
            for (c, p) in p.iter_mut().enumerate() {
                *p += self.area[i] * self.e[i * self.m + c];
            }
        }
        p
    }
}

/// What a sweep's gathers need of the current radiosity besides each row's entries.
pub(crate) struct Ambient {
    /// The pool's β per column.
    pub(crate) pool: Vec<f64>,
    /// Prefix sums over the cluster order of A·b, for links (`links.rs`).
    prefix: Option<Vec<f64>>,
}

impl std::ops::Index<usize> for Ambient {
    type Output = f64;
    fn index(&self, c: usize) -> &f64 {
        &self.pool[c]
    }
}

/// Which rows arrived in one scan: catches duplicates and names the first missing row.
pub(crate) struct Presence {
    seen: Vec<bool>,
}

impl Presence {
    pub(crate) fn new(n: usize) -> Self {
        Presence {
            seen: vec![false; n],
        }
    }

    /// Record row `i` (already range-checked).
    ///
    /// # Errors
    /// [`SolveError::DuplicateRow`] when it was seen before in this scan.
    pub(crate) fn mark(&mut self, i: u32) -> Result<(), SolveError> {
        let s = &mut self.seen[i as usize];
        if *s {
            return Err(SolveError::DuplicateRow { row: i });
        }
        *s = true;
        Ok(())
    }

    pub(crate) fn seen(&self, i: usize) -> bool {
        self.seen[i]
    }

    /// The first row with `needed(i)` that was not seen, and how many such rows.
    pub(crate) fn missing(&self, needed: impl Fn(usize) -> bool) -> Option<(u32, usize)> {
        let mut first = None;
        let mut count = 0;
        for (i, &s) in self.seen.iter().enumerate() {
            if !s && needed(i) {
                first.get_or_insert(i as u32);
                count += 1;
            }
        }
        first.map(|f| (f, count))
    }
}

/// Check a row index against n.
///
/// # Errors
/// [`SolveError::OutOfRange`].
#[inline]
pub(crate) fn check_index(i: u32, n: usize) -> Result<usize, SolveError> {
    if (i as usize) < n {
        Ok(i as usize)
    } else {
        Err(SolveError::OutOfRange {
            row: i,
            index: i as u64,
            n,
        })
    }
}

/// Per column, the largest |v| over patches.
pub(crate) fn column_max_abs(v: &[f64], m: usize) -> Vec<f64> {
    let mut out = vec![0.0f64; m];
    for chunk in v.chunks_exact(m) {
        for (o, x) in out.iter_mut().zip(chunk) {
            *o = nan_max(*o, x.abs());
        }
    }
    out
}

/// Relative residual per column: `abs[c] / scale[c]`, 0 for an all-zero column that
/// is solved exactly, infinite when a zero column has a non-zero residual.
pub(crate) fn relative(abs: &[f64], scale: &[f64]) -> Vec<f64> {
    abs.iter()
        .zip(scale)
        .map(|(&a, &s)| {
            if s > 0.0 {
                a / s
            } else if a == 0.0 {
                0.0
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// The largest value of a slice of non-negative numbers (0 when empty, NaN if any is).
pub(crate) fn max_of(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, nan_max)
}

/// `max` that keeps a NaN instead of hiding it (`f64::max` drops NaN operands), so a
/// broken value shows up in the reported residual.
#[inline]
pub(crate) fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Why a gathering solve needs a row.
pub(crate) const FOR_GATHER: &str = "to gather light (the patch reflects)";
/// Why progressive shooting needs a row.
pub(crate) const FOR_SHOOT: &str = "to shoot light (the patch emits or reflects light it received)";

/// The error for row `i` marked Skipped although it is needed.
pub(crate) fn skipped_error(patches: &PatchSet, i: usize, needed_for: &'static str) -> SolveError {
    SolveError::SkippedRow {
        row: i as u32,
        group: patches.group_name(i).to_string(),
        needed_for,
    }
}

/// The error for needed rows that a scan did not deliver.
pub(crate) fn missing_error(
    patches: &PatchSet,
    (row, missing): (u32, usize),
    needed_for: &'static str,
) -> SolveError {
    SolveError::MissingRow {
        row,
        group: patches.group_name(row as usize).to_string(),
        needed_for,
        missing,
    }
}

impl System {
    /// [`super::rowview::RowView::new`] for this system, checking a row's values the
    /// first time it is seen only, and noting a row whose dropped mass cannot be put back ([`crate::rows::RowFaults::lost_mass`]) for [`System::lost_mass`].
    ///
    /// # Errors
    /// As [`super::rowview::RowView::new`].
    /// The view of `row` in a gathering sweep, with its patch index: `None` when the
    /// patch reflects nothing (its row is not needed). Marks the row in `presence`.
    ///
    /// # Errors
    /// An index out of range, a row seen twice in the sweep, a Skipped row, a malformed
    /// row.
    pub(crate) fn gather_view<'r>(
        &'r self,
        row: &'r crate::rows::Row,
        presence: &mut Presence,
        patches: &PatchSet,
    ) -> Result<Option<(usize, super::rowview::RowView<'r>)>, SolveError> {
        let i = check_index(row.index, self.n)?;
        if !self.reflects[i] {
            return Ok(None);
        }
        presence.mark(row.index)?;
        let view = self
            .view(row)?
            .ok_or_else(|| skipped_error(patches, i, FOR_GATHER))?;
        Ok(Some((i, view)))
    }

    pub(crate) fn view<'r>(
        &'r self,
        row: &'r crate::rows::Row,
    ) -> Result<Option<super::rowview::RowView<'r>>, SolveError> {
        let first_look = self
            .checked
            .get(row.index as usize)
            .is_none_or(|c| !c.swap(true, std::sync::atomic::Ordering::Relaxed));
        let scale = self.dropped == DroppedMass::Scale;
        let mut view = super::rowview::RowView::new(row, self.n, scale, first_look)?;
        if let Some(v) = &mut view {
            if !v.links.is_empty() {
                let space = self.links.as_ref().ok_or_else(|| SolveError::BadRow {
                    row: row.index,
                    message: "the row links to clusters but the source has no cluster order".into(),
                })?;
                v.space = Some(space);
            }
        }
        if let Some(v) = &view {
            // A row that stores nothing but has dropped mass and no links (spec §5.6):
            // rescaling loses its light, the pool carries it; either way it is noted.
            let empty = v.lost > 0.0 || (row.faults_lost_mass() && self.pool.is_some());
            if empty {
                if let Some(slot) = self.lost_mass.get(row.index as usize) {
                    slot.store(row.dropped.to_bits(), std::sync::atomic::Ordering::Relaxed);
                }
            }
        }
        Ok(view)
    }

    /// With [`super::DroppedMass::Pool`] and a source whose rows may drop mass, measure
    /// the pool with one scan of `src`; returns the scans made (0 or 1).
    ///
    /// # Errors
    /// As [`System::measure_pool`].
    pub(crate) fn prepare_pool(&mut self, src: &dyn RowSource) -> Result<usize, SolveError> {
        if self.dropped != DroppedMass::Pool || !src.may_drop() || self.links.is_some() {
            return Ok(0);
        }
        self.pool = Some(self.measure_pool(src)?);
        Ok(1)
    }

    /// Measure the pool from one scan of `src` (the sums of [`PoolScan`]).
    ///
    /// # Errors
    /// A row index out of range or seen twice, a malformed row, the source's error.
    pub(crate) fn measure_pool(&self, src: &dyn RowSource) -> Result<Pool, SolveError> {
        let sys = self;
        let n = sys.n;
        // Σ over reflecting rows, and over every row read, of A_r F_rx per column x.
        let mut carried = vec![0.0f64; n];
        let mut shot_at = vec![0.0f64; n];
        let mut total: Vec<Option<f64>> = vec![None; n];
        let mut weight = 0.0;
        let mut presence = Presence::new(n);
        src.scan(&mut |row| {
            let r = check_index(row.index, n)?;
            if !sys.reflects[r] && !sys.emits[r] {
                return Ok(());
            }
            presence.mark(row.index)?;
            let Some(view) = sys.view(row)? else {
                return Ok(());
            };
            let a = sys.area[r];
            let (mut stored, mut to_dark) = (0.0, 0.0);
            let reflecting = sys.reflects[r];
            view.visit(n, |x, f| {
                if reflecting {
                    carried[x] += a * f;
                }
                shot_at[x] += a * f;
                stored += f;
                if !sys.reflects[x] {
                    to_dark += f;
                }
            })?;
            if reflecting {
                weight += a * view.dropped;
            }
            total[r] = Some(a * (stored + view.dropped - to_dark));
            Ok(())
        })?;
        let missing = presence.missing(|i| sys.emits[i] && total[i].is_none());
        let scan = PoolScan {
            carried,
            shot_at,
            total,
            weight,
        };
        Ok(Pool::from_scan(scan, &self.reflects, missing))
    }

    /// With a source whose rows link to clusters, the cluster order's gathering data
    /// (`links.rs`), keeping rows' links ready to gather in up to `cache_bytes`.
    pub(crate) fn prepare_links(&mut self, src: &dyn RowSource, cache_bytes: usize) {
        self.links = src.cluster_order().map(|order| {
            super::links::LinkSpace::new(order, &self.area, &self.centroid).with_cache(cache_bytes)
        });
    }

    /// What every row's gather needs of radiosity `b` beyond its own entries: the
    /// pool's β (zeros without a pool) and the prefix sums of the links.
    pub(crate) fn beta(&self, b: &[f64]) -> Ambient {
        Ambient {
            pool: self.pool_beta(b),
            prefix: self.links.as_ref().map(|l| l.prefix(b, self.m)),
        }
    }

    /// The pool's β of radiosity `b` (zeros without a pool).
    pub(crate) fn pool_beta(&self, b: &[f64]) -> Vec<f64> {
        match &self.pool {
            Some(p) => p.beta(b, self.m),
            None => vec![0.0; self.m],
        }
    }

    /// `acc = H_i` of the gathering form for row view `view` of patch i: the stored
    /// entries (scaled as the view says) against `b`, plus the pool's share D_i β.
    /// Returns the sum of |F_ij| of the stored entries (the Gauss–Seidel bound's).
    ///
    /// # Errors
    /// As [`super::rowview::RowView::gather`].
    pub(crate) fn gather(
        &self,
        view: &super::rowview::RowView<'_>,
        b: &[f64],
        beta: &Ambient,
        acc: &mut [f64],
    ) -> Result<f64, SolveError> {
        let mut abs_sum = view.gather(b, self.m, acc)?;
        if let (false, Some(space), Some(prefix)) =
            (view.links.is_empty(), &self.links, &beta.prefix)
        {
            abs_sum += space.gather(view.links, view.index, view.cols(), prefix, acc);
        } else if self.pool.is_some() && view.dropped > 0.0 {
            for (a, x) in acc.iter_mut().zip(&beta.pool) {
                *a += view.dropped * x;
            }
        }
        Ok(abs_sum)
    }

    /// Rows that store nothing but have dropped mass, among those seen: (count, first
    /// row, total dropped mass), or None.
    pub(crate) fn lost_mass(&self) -> Option<(usize, u32, f64)> {
        let mut out: Option<(usize, u32, f64)> = None;
        for (i, slot) in self.lost_mass.iter().enumerate() {
            let d = f32::from_bits(slot.load(std::sync::atomic::Ordering::Relaxed));
            if d > 0.0 {
                let o = out.get_or_insert((0, i as u32, 0.0));
                o.0 += 1;
                o.2 += f64::from(d);
            }
        }
        out
    }
}
