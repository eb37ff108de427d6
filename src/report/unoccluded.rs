//! `verify --unoccluded`: every stored entry against its unoccluded form factor.
//!
//! Visibility can only take light away, so an occluded form factor never exceeds the
//! unoccluded one of the same pair, F_ij ≤ F⁰_ij. An entry above it is a fault of the
//! visibility estimate (a ratio estimator whose weights do not match the domain of
//! F⁰, a sampler drawing outside the patch) that row sums cannot reveal: F⁰ comes from
//! the patch table alone, recomputed with the contour kernel at the `accurate` preset's
//! tolerance (relative 1e-8) and no occluders.
//!
//! Cost: one unoccluded evaluation per stored non-zero entry, about the CPU of a
//! `compute` without visibility, on every core; memory is one row per thread.

use std::sync::Arc;

use super::Result;
use crate::ffz::FfzReader;
use crate::formfactor::{FormFactorConfig, RowEngine, Scratch};
use crate::geometry::occluders::Occluders;
use crate::rows::Row;

/// Absolute slack of the check: the contour kernel's error is relative to the pair's
/// geometry, not to its value, so entries of grazing or distant pairs (F ~ 1e-10) can
/// differ from a second evaluation by more than any relative tolerance (measured on
/// the Cornell box at 400 patches: 1.5e-10 against 4.9e-11); far below what a float32
/// entry of a row that sums to 1 resolves.
pub const UNOCCLUDED_ABS_TOL: f64 = 1e-9;

/// What [`unoccluded_excess`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UnoccludedReport {
    /// Stored non-zero entries checked.
    pub entries: u64,
    /// Entries with F_ij > F⁰_ij (1 + tol) + [`UNOCCLUDED_ABS_TOL`].
    pub above: u64,
    /// The entry furthest above its bound (largest F / F⁰): (i, j, F_ij, F⁰_ij).
    pub worst: Option<(u32, u32, f32, f64)>,
}

impl UnoccludedReport {
    fn merge(&mut self, o: UnoccludedReport) {
        self.entries += o.entries;
        self.above += o.above;
        if let Some(w) = o.worst {
            if self.worst.is_none_or(|s| worse(w, s)) {
                self.worst = Some(w);
            }
        }
    }
}

/// Whether entry `a` is further above its bound than `b` (ties: the lower (i, j), so
/// the report does not depend on the thread count).
fn worse(a: (u32, u32, f32, f64), b: (u32, u32, f32, f64)) -> bool {
    let ratio = |e: (u32, u32, f32, f64)| f64::from(e.2) / e.3;
    match ratio(a).total_cmp(&ratio(b)) {
        std::cmp::Ordering::Equal => (a.0, a.1) < (b.0, b.1),
        o => o.is_gt(),
    }
}

/// Check every stored non-zero entry of `r` against its unoccluded form factor F⁰
/// (module docs); an entry counts as above when F_ij > F⁰_ij (1 + `tol`) + 1e-9, `tol`
/// covering the float32 rounding of the entry and the kernel error of the file's
/// method. `threads` compute threads (0: one per core).
///
/// # Errors
/// The first corrupt chunk, as [`FfzReader::scan`].
pub fn unoccluded_excess(r: &FfzReader, tol: f64, threads: usize) -> Result<UnoccludedReport> {
    let threads = if threads == 0 {
        std::thread::available_parallelism().map_or(1, |t| t.get())
    } else {
        threads
    };
    let engine = RowEngine::new(
        &r.meta().patches,
        Arc::new(Occluders::new(Vec::new())),
        FormFactorConfig::accurate(),
    );
    let (tx, rx) = crossbeam::channel::bounded::<Row>(4 * threads);
    std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                let rx = rx.clone();
                let engine = &engine;
                s.spawn(move || {
                    let mut scratch = Scratch::new();
                    let mut rep = UnoccludedReport::default();
                    for row in rx {
                        let i = row.index;
                        row.for_each_nonzero(|j, f| {
                            let f0 = engine.pair_value(i, j, &mut scratch);
                            rep.entries += 1;
                            if f64::from(f) > f0 * (1.0 + tol) + UNOCCLUDED_ABS_TOL {
                                rep.above += 1;
                                let e = (i, j, f, f0);
                                if rep.worst.is_none_or(|w| worse(e, w)) {
                                    rep.worst = Some(e);
                                }
                            }
                        });
                    }
                    rep
                })
            })
            .collect();
        drop(rx);
        let scanned = r.scan(|row| {
            // The workers only stop when the channel closes, so this send cannot fail.
            let _ = tx.send(row.clone());
        });
        drop(tx);
        let mut total = UnoccludedReport::default();
        for w in workers {
            total.merge(w.join().expect("an unoccluded-check thread panicked"));
        }
        scanned.map(|()| total)
    })
}
