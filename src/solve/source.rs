//! Where the solver's rows come from.
//!
//! The solver never holds the matrix: it asks a [`RowSource`] for one row at a time,
//! either all of them in storage order ([`RowSource::scan`], the fast sequential path
//! that the gathering solvers use once per iteration) or one by index
//! ([`RowSource::row`], random access, used by progressive shooting). The `.ffz` reader
//! implements it in `ffz_source.rs`; [`MemoryRows`] holds rows in memory for tests and
//! small scenes.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

use crate::patch::PatchSet;
use crate::rows::{Row, RowValues};

use super::error::SolveError;

/// A stored form-factor matrix, read one row at a time.
pub trait RowSource {
    /// The patches the rows belong to (row and column `i` are patch `i`).
    fn patches(&self) -> &PatchSet;

    /// Visit all stored rows, in storage order (sequential: the fast path). Rows that
    /// the file marks Skipped are delivered as [`crate::rows::RowValues::Skipped`];
    /// rows that are missing are not delivered at all. An error returned by `f` stops
    /// the scan and is returned.
    ///
    /// # Errors
    /// The error of `f`, or the source's own read error.
    fn scan(&self, f: &mut dyn FnMut(&Row) -> Result<(), SolveError>) -> Result<(), SolveError>;

    /// Row `i` if stored (random access); `None` when it is missing.
    ///
    /// # Errors
    /// The source's read error (corrupt data, I/O).
    fn row(&self, i: u32) -> Result<Option<Row>, SolveError>;

    /// Whether row `i` is stored (present or skipped), without reading it: how a
    /// random-access solve counts the missing rows it needs when it meets the first.
    fn has_row(&self, i: u32) -> bool;

    /// Whether rows may carry dropped mass (top-k or threshold rows). A source that
    /// answers false spares the solve the scan that measures the pool of dropped light
    /// (`pool.rs`); the default answers true.
    fn may_drop(&self) -> bool {
        true
    }

    /// The cluster order the rows' links name ranges of (spec §4.3), if they link.
    fn cluster_order(&self) -> Option<&[u32]> {
        None
    }
}

/// A source whose scans after the first read the rows from memory, when they fit in
/// `budget` bytes (else every scan reads the source, as without it). The first scan
/// that completes without error keeps what it read; a source's rows do not change
/// between scans. Random access ([`RowSource::row`]) goes to the source.
pub(crate) struct Held<'s> {
    inner: &'s dyn RowSource,
    budget: usize,
    rows: OnceLock<Vec<Row>>,
    /// A first scan has been made (the rows are held, or did not fit).
    tried: AtomicBool,
}

impl<'s> Held<'s> {
    pub(crate) fn new(inner: &'s dyn RowSource, budget: usize) -> Self {
        Held {
            inner,
            budget,
            rows: OnceLock::new(),
            tried: AtomicBool::new(budget == 0),
        }
    }
}

/// Bytes a row holds in memory.
fn row_bytes(row: &Row) -> usize {
    use std::mem::size_of;
    let values = match &row.values {
        RowValues::Dense(v) => v.capacity() * size_of::<f32>(),
        RowValues::Sparse { cols, vals } => {
            cols.capacity() * size_of::<u32>() + vals.capacity() * size_of::<f32>()
        }
        RowValues::Skipped => 0,
    };
    size_of::<Row>() + values + row.links.capacity() * size_of::<crate::rows::Link>()
}

impl RowSource for Held<'_> {
    fn patches(&self) -> &PatchSet {
        self.inner.patches()
    }

    fn scan(&self, f: &mut dyn FnMut(&Row) -> Result<(), SolveError>) -> Result<(), SolveError> {
        if let Some(rows) = self.rows.get() {
            return rows.iter().try_for_each(f);
        }
        if self.tried.swap(true, Ordering::Relaxed) {
            return self.inner.scan(f);
        }
        let (mut held, mut bytes, mut fits) = (Vec::new(), 0, true);
        self.inner.scan(&mut |row| {
            if fits {
                bytes += row_bytes(row);
                fits = bytes <= self.budget;
                match fits {
                    true => held.push(row.clone()),
                    false => held = Vec::new(),
                }
            }
            f(row)
        })?;
        if fits {
            let _ = self.rows.set(held);
        }
        Ok(())
    }

    fn row(&self, i: u32) -> Result<Option<Row>, SolveError> {
        self.inner.row(i)
    }

    fn has_row(&self, i: u32) -> bool {
        self.inner.has_row(i)
    }

    fn may_drop(&self) -> bool {
        self.inner.may_drop()
    }

    fn cluster_order(&self) -> Option<&[u32]> {
        self.inner.cluster_order()
    }
}

/// Rows held in memory, in the order given (that order is the "file order" of
/// [`RowSource::scan`]).
#[derive(Clone, Debug)]
pub struct MemoryRows {
    patches: PatchSet,
    rows: Vec<Row>,
    /// `position[i]` = index into `rows` of row `i`.
    position: Vec<Option<usize>>,
    /// The cluster order of linked rows.
    clusters: Option<Vec<u32>>,
}

impl MemoryRows {
    /// Hold `rows` (any order, any subset) for `patches`.
    ///
    /// # Errors
    /// [`SolveError::OutOfRange`] for a row index ≥ n, [`SolveError::DuplicateRow`] when
    /// an index occurs twice.
    pub fn new(patches: PatchSet, rows: Vec<Row>) -> Result<Self, SolveError> {
        let n = patches.len();
        let mut position = vec![None; n];
        for (k, r) in rows.iter().enumerate() {
            let slot = position
                .get_mut(r.index as usize)
                .ok_or(SolveError::OutOfRange {
                    row: r.index,
                    index: r.index as u64,
                    n,
                })?;
            if slot.is_some() {
                return Err(SolveError::DuplicateRow { row: r.index });
            }
            *slot = Some(k);
        }
        Ok(MemoryRows {
            patches,
            rows,
            position,
            clusters: None,
        })
    }

    /// The same rows with the cluster order their links name ranges of.
    pub fn with_clusters(mut self, order: Option<Vec<u32>>) -> Self {
        self.clusters = order;
        self
    }

    /// The rows, in scan order.
    pub fn rows(&self) -> &[Row] {
        &self.rows
    }
}

impl RowSource for MemoryRows {
    fn patches(&self) -> &PatchSet {
        &self.patches
    }

    fn scan(&self, f: &mut dyn FnMut(&Row) -> Result<(), SolveError>) -> Result<(), SolveError> {
        self.rows.iter().try_for_each(f)
    }

    fn row(&self, i: u32) -> Result<Option<Row>, SolveError> {
        Ok(self
            .position
            .get(i as usize)
            .copied()
            .flatten()
            .map(|k| self.rows[k].clone()))
    }

    fn has_row(&self, i: u32) -> bool {
        self.position.get(i as usize).copied().flatten().is_some()
    }

    fn may_drop(&self) -> bool {
        self.rows.iter().any(|r| r.dropped != 0.0)
    }

    fn cluster_order(&self) -> Option<&[u32]> {
        self.clusters.as_deref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_patches() -> PatchSet {
        let mut p = crate::patch::Patch {
            corners: [glam::DVec3::ZERO; 4],
            n_corners: 3,
            normal: glam::DVec3::Z,
            area: 1.0,
            group: 0,
            face: 0,
            rho: [0.5; 3],
            emission: [0.0; 3],
        };
        let q = p.clone();
        p.face = 1;
        PatchSet {
            patches: vec![q, p],
            groups: vec!["g".into()],
        }
    }

    #[test]
    fn memory_rows_random_access_and_scan_order() {
        let rows = vec![
            Row::dense(1, vec![0.25, 0.0]),
            Row::dense(0, vec![0.0, 0.5]),
        ];
        let m = MemoryRows::new(two_patches(), rows).unwrap();
        assert_eq!(m.row(0).unwrap().unwrap().to_dense(2), vec![0.0, 0.5]);
        assert_eq!(m.row(1).unwrap().unwrap().index, 1);
        assert!(m.row(2).unwrap().is_none());
        let mut order = Vec::new();
        m.scan(&mut |r| {
            order.push(r.index);
            Ok(())
        })
        .unwrap();
        assert_eq!(order, vec![1, 0]);
    }

    #[test]
    fn memory_rows_rejects_duplicates_and_out_of_range() {
        let dup = vec![Row::dense(0, vec![0.0; 2]), Row::dense(0, vec![0.0; 2])];
        assert!(matches!(
            MemoryRows::new(two_patches(), dup),
            Err(SolveError::DuplicateRow { row: 0 })
        ));
        let far = vec![Row::dense(7, vec![0.0; 2])];
        assert!(matches!(
            MemoryRows::new(two_patches(), far),
            Err(SolveError::OutOfRange { row: 7, .. })
        ));
    }

    /// Scans of a held source deliver the rows of the source, in its order, every time:
    /// from memory when they fit the budget, from the source when they do not.
    #[test]
    fn a_held_source_scans_as_its_source_whether_the_rows_fit_or_not() {
        let rows = vec![
            Row::dense(1, vec![0.25, 0.0]),
            Row::dense(0, vec![0.0, 0.5]),
        ];
        let m = MemoryRows::new(two_patches(), rows.clone()).unwrap();
        for (budget, fits) in [(0, false), (1, false), (1 << 20, true)] {
            let held = Held::new(&m, budget);
            for _ in 0..3 {
                let mut seen = Vec::new();
                held.scan(&mut |r| {
                    seen.push(r.clone());
                    Ok(())
                })
                .unwrap();
                assert_eq!(seen, rows, "budget {budget}");
            }
            assert_eq!(held.rows.get().is_some(), fits, "budget {budget}");
        }
        // A first scan stopped by an error keeps nothing.
        let held = Held::new(&m, 1 << 20);
        let stop = held.scan(&mut |_| Err(SolveError::DuplicateRow { row: 0 }));
        assert!(stop.is_err());
        assert!(held.rows.get().is_none());
    }
}
