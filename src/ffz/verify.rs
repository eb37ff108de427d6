//! Whole-file checks (spec §10): every chunk's checksums and structure (all bad chunks
//! are listed, not just the first), index consistency, row sums, reciprocity, and the
//! row-by-row comparison of two files.
//!
//! Everything here is out of core. Memory is bounded by [`VerifyOptions::block_bytes`]:
//! reciprocity and comparison hold one block of rows at a time (rows per block =
//! `block_bytes / row bound`, the row bound being 4n bytes for a dense file and 8k for
//! top-k, known from the header). Cost: `verify` decompresses the file once for the
//! checks, then B + 1 more times for reciprocity, B = ceil(n / rows per block); `compare`
//! decompresses each file B times. A dense file of 2 GB with the default 256 MiB budget
//! gives B = 8.

use super::chunk::DecodedChunk;
use super::error::Result;
use super::meta::Layout;
use super::presence::RowState;
use super::reader::FfzReader;
use super::spec;
use crate::rows::{Link, Row, RowValues};

/// Options of [`FfzReader::verify_with`] and [`compare`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifyOptions {
    /// Memory for one block of rows held during reciprocity and comparison passes.
    pub block_bytes: usize,
    /// Compute the reciprocity error (costs B + 1 more passes over the file).
    pub reciprocity: bool,
    /// A row whose stored entries sum above 1 + this is a fault: more light would
    /// leave a patch towards the others than leaves it. (A sparse row whose stored +
    /// dropped mass passes it is reported: the dropped mass is an estimate.)
    pub row_sum_tol: f64,
}

/// Default of [`VerifyOptions::row_sum_tol`]: above the error of the default kernels
/// (16 visibility rays per partly hidden pair put rows up to 6e-3 above 1: the room of
/// 16 boxes at 2k patches 1.0060, the Cornell box 1.0013; exact visibility 1.0000037
/// on the Cornell box at 400 patches), far below a fault (a duplicated face doubles
/// its column; View3D users have seen rows sum to 1.56).
pub const ROW_SUM_TOL: f64 = 1e-2;

impl Default for VerifyOptions {
    fn default() -> Self {
        VerifyOptions {
            block_bytes: 256 << 20,
            reciprocity: true,
            row_sum_tol: ROW_SUM_TOL,
        }
    }
}

/// A chunk (or an unreadable region found by a recovery scan) that failed a check.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadChunk {
    /// Chunk number, `None` for a region a recovery scan could not read as a chunk.
    pub chunk: Option<u64>,
    /// Byte offset of the chunk (or region) in the file.
    pub offset: u64,
    pub what: String,
}

/// Reciprocity over stored pairs: max and mean over i < j of
/// |A_i F_ij − A_j F_ji| / max(A_i F_ij, A_j F_ji), for pairs where both entries are
/// stored (always in a dense file; both kept by top-k in a sparse one) and not both 0.
///
/// Each pair counts alike in the max and the mean, so a pair exchanging almost nothing,
/// whose few rays saw each other from one side only, reaches 1 there. The weighted
/// error has no such floor problem: Σ |A_i F_ij − A_j F_ji| / Σ max(A_i F_ij, A_j F_ji)
/// over the same pairs, the share of the exchanged flux that is not reciprocal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Reciprocity {
    pub pairs: u64,
    pub max_rel_error: f64,
    pub(crate) mean_rel_error: f64,
    pub weighted_rel_error: f64,
    /// (i, j) of the worst pair.
    pub worst: Option<(u32, u32)>,
    /// Passes over the file it took.
    pub passes: u32,
}

/// What [`FfzReader::verify`] found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VerifyReport {
    pub(crate) n: u32,
    pub(crate) chunks_checked: u64,
    pub bad_chunks: Vec<BadChunk>,
    /// Warnings from opening (footer/index unusable, recovery scan).
    pub(crate) open_warnings: Vec<String>,
    pub(crate) rows_present: u64,
    pub(crate) rows_skipped: u64,
    pub rows_missing: u64,
    /// Rows decoded and checked (present rows in good chunks).
    pub rows_checked: u64,
    /// True row sums (stored + dropped) over checked rows: min, max, mean.
    pub row_sum_min: f64,
    pub row_sum_max: f64,
    pub(crate) row_sum_mean: f64,
    /// Largest dropped mass of a row (top-k).
    pub(crate) dropped_max: f64,
    /// The tolerance rows were judged with ([`VerifyOptions::row_sum_tol`]).
    pub(crate) row_sum_tol: f64,
    /// Rows whose stored entries sum above 1 + `row_sum_tol`, and the largest sum.
    pub rows_above_one: u64,
    pub(crate) worst_above_one: Option<(u32, f64)>,
    /// Sparse rows whose stored entries stay below that but whose stored + dropped
    /// mass does not (an overestimated tail), and the largest such sum.
    pub dropped_above_one: u64,
    pub(crate) worst_dropped_above_one: Option<(u32, f64)>,
    pub(crate) negative_entries: u64,
    pub(crate) non_finite_entries: u64,
    /// Finite entries above [`crate::rows::MAX_FORM_FACTOR`].
    pub(crate) too_large_entries: u64,
    /// Rows whose dropped mass is not finite, negative or above the same bound.
    pub(crate) bad_dropped_rows: u64,
    /// Sparse rows that store nothing but have dropped mass (it cannot be put back:
    /// reported, not a failure), and the first of them with the sum of that mass.
    pub(crate) lost_mass_rows: u64,
    pub(crate) lost_mass: Option<(u32, f64)>,
    /// The first faulty row and what is wrong with it ([`Row::faults`]).
    pub(crate) first_row_fault: Option<(u32, String)>,
    pub reciprocity: Option<Reciprocity>,
    /// The writer's link errors (spec §5.7, LINK_ERROR): rows that have one, their
    /// sum, and the largest with its row.
    pub(crate) link_error_rows: u64,
    pub(crate) link_error_sum: f64,
    pub(crate) link_error_max: Option<(u32, f32)>,
}

impl VerifyReport {
    /// True when nothing is wrong: every chunk good, index usable, no row missing, no
    /// row with faulty numbers ([`Row::faults`]: negative, non-finite or impossible
    /// entries, bad or unrecoverable dropped mass), no row whose stored entries sum
    /// above 1 + [`VerifyOptions::row_sum_tol`]. (Reciprocity and a dropped-mass
    /// estimate that takes a row above that are reported, not judged.)
    pub fn ok(&self) -> bool {
        self.bad_chunks.is_empty()
            && self.open_warnings.is_empty()
            && self.rows_missing == 0
            && self.first_row_fault.is_none()
            && self.rows_above_one == 0
    }

    /// Sky view factors (1 − true row sum) over the checked rows: min, max, mean (the
    /// share of a patch's hemisphere that sees no surface).
    pub fn sky_view(&self) -> (f64, f64, f64) {
        (
            1.0 - self.row_sum_max,
            1.0 - self.row_sum_min,
            1.0 - self.row_sum_mean,
        )
    }
}

/// A block of rows held in memory: its row range and the rows (None: not in the file).
type Block = ((u32, u32), Vec<Option<Row>>);

/// Largest bytes a row of this file can take in memory (for block sizing).
fn row_bound(n: u32, layout: Layout) -> usize {
    64 + match layout {
        Layout::Dense => 4 * n as usize,
        Layout::TopK { k } => 8 * k.min(n) as usize,
    }
}

/// Row ranges of at most `block_bytes` of rows each.
fn blocks(n: u32, layout: Layout, block_bytes: usize) -> Vec<(u32, u32)> {
    let per = (block_bytes / row_bound(n, layout)).clamp(1, u32::MAX as usize) as u32;
    let mut out = Vec::new();
    let mut b0 = 0u32;
    while b0 < n {
        let b1 = b0.saturating_add(per).min(n);
        out.push((b0, b1));
        b0 = b1;
    }
    out
}

/// Stored value F_ij of a held row, `None` when a sparse row does not store column j.
fn stored(row: &Row, j: u32) -> Option<f32> {
    match &row.values {
        RowValues::Dense(v) => v.get(j as usize).copied(),
        RowValues::Sparse { cols, vals } => cols.binary_search(&j).ok().map(|k| vals[k]),
        RowValues::Skipped => None,
    }
}

/// Visit the stored entries (j, F_ij) of `row` with j in `lo..hi`, zeros included.
fn for_stored_in(row: &Row, lo: u32, hi: u32, mut f: impl FnMut(u32, f32)) {
    match &row.values {
        RowValues::Dense(v) => {
            for j in lo..hi.min(v.len() as u32) {
                f(j, v[j as usize]);
            }
        }
        RowValues::Sparse { cols, vals } => {
            let s = cols.partition_point(|&c| c < lo);
            for (&c, &x) in cols[s..].iter().zip(&vals[s..]) {
                if c >= hi {
                    break;
                }
                f(c, x);
            }
        }
        RowValues::Skipped => {}
    }
}

impl FfzReader {
    /// [`FfzReader::verify_with`] with default options.
    pub fn verify(&self) -> VerifyReport {
        self.verify_with(VerifyOptions::default())
    }

    /// Check every chunk (listing all bad ones), the index against the chunks, row
    /// sums, entry signs, and (optionally) reciprocity. Never fails: every fault ends up
    /// in the report.
    pub fn verify_with(&self, opts: VerifyOptions) -> VerifyReport {
        let n = self.n();
        let p = self.presence();
        let mut rep = VerifyReport {
            n,
            open_warnings: self.warnings().to_vec(),
            rows_present: p.present_count(),
            rows_skipped: p.skipped_count(),
            rows_missing: p.missing_count(),
            row_sum_min: f64::INFINITY,
            row_sum_max: f64::NEG_INFINITY,
            row_sum_tol: opts.row_sum_tol,
            ..Default::default()
        };
        for b in self.bad_regions() {
            rep.bad_chunks.push(BadChunk {
                chunk: None,
                offset: b.start,
                what: format!(
                    "bytes {}..{} are not a readable chunk: {}",
                    b.start, b.end, b.reason
                ),
            });
        }
        let mut seen = vec![false; n as usize];
        let mut good = vec![false; self.chunk_count()];
        let mut sum_total = 0.0;
        let offsets = self.chunk_offsets().to_vec();
        self.for_each_chunk(|k, res| {
            rep.chunks_checked += 1;
            let offset = offsets[k as usize];
            let mut faults = Vec::new();
            let ok = match res {
                Err(e) => {
                    faults.push(e.to_string());
                    false
                }
                Ok(d) => {
                    // In an indexed file, chunks tile the area between meta block and
                    // index.
                    if self.is_indexed() {
                        let end = offsets
                            .get(k as usize + 1)
                            .copied()
                            .unwrap_or(self.chunk_area_end());
                        let len = spec::CHUNK_HEADER_LEN as u64 + d.header.compressed_len;
                        if offset + len != end {
                            faults.push(format!(
                                "chunk ends at byte {} but the next record starts at {end}",
                                offset + len
                            ));
                        }
                    }
                    // A chunk that ends where it should not still serves its rows: only
                    // faults in the rows make it bad.
                    self.check_rows(k, &d, &mut rep, &mut seen, &mut sum_total, &mut faults)
                }
            };
            rep.bad_chunks
                .extend(faults.into_iter().map(|what| BadChunk {
                    chunk: Some(k as u64),
                    offset,
                    what,
                }));
            good[k as usize] = ok;
        });
        for i in 0..n {
            if let (false, Some(k)) = (seen[i as usize], self.chunk_of(i)) {
                if good[k as usize] {
                    rep.bad_chunks.push(BadChunk {
                        chunk: Some(k as u64),
                        offset: offsets[k as usize],
                        what: format!(
                            "the index places row {i} here but the chunk does not hold it"
                        ),
                    });
                }
            }
        }
        if rep.rows_checked > 0 {
            rep.row_sum_mean = sum_total / rep.rows_checked as f64;
        } else {
            rep.row_sum_min = 0.0;
            rep.row_sum_max = 0.0;
        }
        if opts.reciprocity {
            rep.reciprocity = Some(self.reciprocity(&good, opts.block_bytes));
        }
        rep
    }

    /// The rows of chunk `k` (decoded `d`) for [`FfzReader::verify_with`]: marks them
    /// `seen`, adds their sums and entry faults to `rep` and `sum_total`, and pushes a
    /// line per inconsistency with the index to `faults`. False when the chunk has one.
    fn check_rows(
        &self,
        k: u32,
        d: &DecodedChunk,
        rep: &mut VerifyReport,
        seen: &mut [bool],
        sum_total: &mut f64,
        faults: &mut Vec<String>,
    ) -> bool {
        let (n, p) = (self.n(), self.presence());
        let mut chunk_ok = true;
        for e in d.entries() {
            if !self.owns(k, e.row) {
                if self.is_indexed() {
                    faults.push(format!(
                        "holds row {} which the index places elsewhere",
                        e.row
                    ));
                    chunk_ok = false;
                }
                continue;
            }
            seen[e.row as usize] = true;
            let skipped = e.flags & spec::ROW_FLAG_SKIPPED != 0;
            if skipped != (p.get(e.row) == RowState::Skipped) {
                faults.push(format!(
                    "row {}: skipped flag disagrees with the index",
                    e.row
                ));
                chunk_ok = false;
            }
            if skipped {
                continue;
            }
            let row = match d.row(e, n) {
                Ok(r) => r,
                Err(w) => {
                    faults.push(w);
                    chunk_ok = false;
                    continue;
                }
            };
            let f = row.faults();
            rep.negative_entries += f.negative;
            rep.non_finite_entries += f.non_finite;
            rep.too_large_entries += f.too_large;
            rep.bad_dropped_rows += u64::from(f.bad_dropped);
            if f.lost_mass {
                rep.lost_mass_rows += 1;
                rep.lost_mass.get_or_insert((row.index, 0.0)).1 += f64::from(row.dropped);
            }
            if let (None, Some(what)) = (&rep.first_row_fault, f.first) {
                rep.first_row_fault = Some((row.index, what));
            }
            let s = row.true_sum();
            rep.rows_checked += 1;
            rep.dropped_max = rep.dropped_max.max(row.dropped as f64);
            if let Some(x) = row.link_error {
                rep.link_error_rows += 1;
                rep.link_error_sum += f64::from(x);
                if rep.link_error_max.is_none_or(|(_, m)| x > m) {
                    rep.link_error_max = Some((row.index, x));
                }
            }
            rep.row_sum_min = rep.row_sum_min.min(s);
            rep.row_sum_max = rep.row_sum_max.max(s);
            *sum_total += s;
            // The stored entries are the computed numbers: above 1 they are a fault. The
            // dropped mass of a sparse row is an estimate (the top-k tail): pushing the
            // row above 1 it is reported, not failed.
            let stored = s - f64::from(row.dropped);
            if stored > 1.0 + rep.row_sum_tol {
                rep.rows_above_one += 1;
                if rep.worst_above_one.is_none_or(|(_, w)| stored > w) {
                    rep.worst_above_one = Some((row.index, stored));
                }
            } else if s > 1.0 + rep.row_sum_tol {
                rep.dropped_above_one += 1;
                if rep.worst_dropped_above_one.is_none_or(|(_, w)| s > w) {
                    rep.worst_dropped_above_one = Some((row.index, s));
                }
            }
        }
        chunk_ok
    }

    /// Visit the rows of good chunks in file order (rows of bad chunks are left out:
    /// `verify` has reported them).
    fn scan_good(&self, good: &[bool], mut f: impl FnMut(Row)) {
        let n = self.n();
        self.for_each_chunk(|k, res| {
            let Ok(d) = res else { return };
            if !good[k as usize] {
                return;
            }
            for e in d.entries() {
                if self.owns(k, e.row) && e.flags & spec::ROW_FLAG_SKIPPED == 0 {
                    if let Ok(r) = d.row(e, n) {
                        f(r);
                    }
                }
            }
        });
    }

    /// Reciprocity error by row blocks: pass t compares every row j against the block
    /// held from pass t − 1 and collects block t (B + 1 passes).
    fn reciprocity(&self, good: &[bool], block_bytes: usize) -> Reciprocity {
        let n = self.n();
        let areas: Vec<f64> = self.meta().patches.patches.iter().map(|p| p.area).collect();
        let blocks = blocks(n, self.layout(), block_bytes);
        let mut rec = Reciprocity::default();
        let (mut sum_rel, mut sum_diff, mut sum_max) = (0.0, 0.0, 0.0);
        let mut held: Option<Block> = None;
        for t in 0..=blocks.len() {
            let next = blocks.get(t).copied();
            let mut collecting: Option<Block> =
                next.map(|(b0, b1)| ((b0, b1), vec![None; (b1 - b0) as usize]));
            rec.passes += 1;
            self.scan_good(good, |row| {
                let j = row.index;
                if let Some(((b0, b1), rows)) = &held {
                    // Pairs (i, j) with i < j and i in the held block.
                    for_stored_in(&row, *b0, (*b1).min(j), |i, f_ji| {
                        let Some(ri) = &rows[(i - b0) as usize] else {
                            return;
                        };
                        let Some(f_ij) = stored(ri, j) else { return };
                        let a = areas[i as usize] * f_ij as f64;
                        let b = areas[j as usize] * f_ji as f64;
                        let m = a.abs().max(b.abs());
                        if m == 0.0 || !m.is_finite() {
                            return;
                        }
                        let rel = (a - b).abs() / m;
                        rec.pairs += 1;
                        sum_rel += rel;
                        sum_diff += (a - b).abs();
                        sum_max += m;
                        if rel > rec.max_rel_error || rec.worst.is_none() {
                            rec.max_rel_error = rel;
                            rec.worst = Some((i, j));
                        }
                    });
                }
                if let Some(((b0, b1), rows)) = &mut collecting {
                    if (*b0..*b1).contains(&j) {
                        rows[(j - *b0) as usize] = Some(row);
                    }
                }
            });
            held = collecting;
        }
        if rec.pairs > 0 {
            rec.mean_rel_error = sum_rel / rec.pairs as f64;
            rec.weighted_rel_error = sum_diff / sum_max;
        }
        rec
    }
}

/// Row-by-row comparison of two files (`verify --against`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompareReport {
    pub(crate) n_a: u32,
    pub(crate) n_b: u32,
    /// Header fields that differ (scene hash, layout, method, params).
    pub(crate) meta_differences: Vec<String>,
    /// Rows held (present or skipped) by both files.
    pub(crate) rows_compared: u64,
    /// Of those, bitwise equal (values, columns, dropped mass, skipped state, links
    /// with their slopes, link error).
    pub identical_rows: u64,
    pub differing_rows: u64,
    /// Of the differing rows, those whose entries and dropped mass are bitwise equal:
    /// they differ in their links or link error alone.
    pub links_only_rows: u64,
    /// Largest |F_ij(a) − F_ij(b)| over rows present in both (absent entries count as 0),
    /// and |dropped(a) − dropped(b)|.
    pub max_abs_diff: f64,
    pub worst_row: Option<u32>,
    pub only_in_a: u64,
    pub only_in_b: u64,
    /// The first few row ids only in a / only in b.
    pub first_only_in_a: Vec<u32>,
    pub(crate) first_only_in_b: Vec<u32>,
    /// Chunk errors met while comparing (those rows count as differing).
    pub(crate) errors: Vec<String>,
}

impl CompareReport {
    /// True when both files hold exactly the same rows with bitwise equal contents.
    pub fn identical(&self) -> bool {
        self.n_a == self.n_b
            && self.differing_rows == 0
            && self.only_in_a == 0
            && self.only_in_b == 0
            && self.errors.is_empty()
            && self
                .meta_differences
                .iter()
                .all(|d| !d.starts_with("scene hash") && !d.starts_with("layout"))
    }
}

/// max |a_j − b_j| over the union of stored columns (absent = 0); ∞ for NaN mismatches.
fn max_abs_diff(a: &Row, b: &Row, n: u32) -> f64 {
    let d = |x: f32, y: f32| -> f64 {
        if x.to_bits() == y.to_bits() {
            0.0
        } else {
            let v = (x as f64 - y as f64).abs();
            if v.is_nan() {
                f64::INFINITY
            } else {
                v
            }
        }
    };
    let mut m = d(a.dropped, b.dropped);
    match (&a.values, &b.values) {
        (RowValues::Sparse { cols: ca, vals: va }, RowValues::Sparse { cols: cb, vals: vb }) => {
            let (mut p, mut q) = (0, 0);
            while p < ca.len() || q < cb.len() {
                let (x, y) = match (ca.get(p), cb.get(q)) {
                    (Some(&i), Some(&j)) if i == j => {
                        p += 1;
                        q += 1;
                        (va[p - 1], vb[q - 1])
                    }
                    (Some(&i), Some(&j)) if i < j => {
                        p += 1;
                        (va[p - 1], 0.0)
                    }
                    (Some(_), None) => {
                        p += 1;
                        (va[p - 1], 0.0)
                    }
                    _ => {
                        q += 1;
                        (0.0, vb[q - 1])
                    }
                };
                m = m.max(d(x, y));
            }
        }
        _ => {
            let (x, y) = (a.to_dense(n as usize), b.to_dense(n as usize));
            for (&x, &y) in x.iter().zip(&y) {
                m = m.max(d(x, y));
            }
        }
    }
    m
}

/// Compare two files row by row, a block of rows of `b` in memory at a time.
///
/// # Errors
/// None in practice: chunk faults are listed in the report. (`Result` leaves room for
/// I/O on future back ends.)
pub fn compare(a: &FfzReader, b: &FfzReader, opts: VerifyOptions) -> Result<CompareReport> {
    let mut rep = CompareReport {
        n_a: a.n(),
        n_b: b.n(),
        ..Default::default()
    };
    let (ma, mb) = (a.meta(), b.meta());
    if a.n() != b.n() {
        // Say it first: with different n no row is compared at all.
        rep.meta_differences
            .push(format!("n {} vs {} (no rows compared)", a.n(), b.n()));
    }
    if ma.scene_hash != mb.scene_hash {
        rep.meta_differences.push(format!(
            "scene hash {:#018x} vs {:#018x}",
            ma.scene_hash, mb.scene_hash
        ));
    }
    if ma.layout != mb.layout {
        rep.meta_differences
            .push(format!("layout {} vs {}", ma.layout, mb.layout));
    }
    if ma.method != mb.method {
        rep.meta_differences
            .push(format!("method '{}' vs '{}'", ma.method, mb.method));
    }
    if ma.params != mb.params {
        rep.meta_differences
            .push(format!("params '{}' vs '{}'", ma.params, mb.params));
    }
    let n = a.n().min(b.n());
    let (pa, pb) = (a.presence(), b.presence());
    for i in 0..a.n().max(b.n()) {
        let ha = pa.get(i) != RowState::Missing;
        let hb = pb.get(i) != RowState::Missing;
        if ha && !hb {
            rep.only_in_a += 1;
            if rep.first_only_in_a.len() < 10 {
                rep.first_only_in_a.push(i);
            }
        } else if hb && !ha {
            rep.only_in_b += 1;
            if rep.first_only_in_b.len() < 10 {
                rep.first_only_in_b.push(i);
            }
        }
    }
    if a.n() != b.n() {
        return Ok(rep);
    }
    let bound = row_bound(n, ma.layout).max(row_bound(n, mb.layout));
    let per = (opts.block_bytes / bound).max(1);
    let mut b0 = 0u32;
    while b0 < n {
        let b1 = (b0 as usize + per).min(n as usize) as u32;
        let mut held: Vec<Option<Row>> = vec![None; (b1 - b0) as usize];
        collect_rows(b, b0, b1, &mut held, &mut rep.errors);
        let mut done = vec![false; (b1 - b0) as usize];
        a.for_each_chunk(|k, res| {
            let d = match res {
                Ok(d) => d,
                Err(e) => {
                    if b0 == 0 {
                        rep.errors.push(format!("a: {e}"));
                    }
                    return;
                }
            };
            for e in d.entries() {
                if !(b0..b1).contains(&e.row) || !a.owns(k, e.row) {
                    continue;
                }
                let slot = (e.row - b0) as usize;
                let Some(rb) = &held[slot] else { continue };
                done[slot] = true;
                rep.rows_compared += 1;
                let ra = match d.row(e, n) {
                    Ok(r) => r,
                    Err(w) => {
                        rep.errors.push(format!("a: row {}: {w}", e.row));
                        rep.differing_rows += 1;
                        continue;
                    }
                };
                if bitwise_eq(&ra, rb) {
                    rep.identical_rows += 1;
                } else {
                    rep.differing_rows += 1;
                    rep.links_only_rows += u64::from(entries_eq(&ra, rb));
                    let m = max_abs_diff(&ra, rb, n);
                    if m > rep.max_abs_diff || rep.worst_row.is_none() {
                        rep.max_abs_diff = rep.max_abs_diff.max(m);
                        rep.worst_row = Some(e.row);
                    }
                }
            }
        });
        // Rows both files claim but one could not deliver (a corrupt chunk).
        for (slot, &d) in done.iter().enumerate() {
            let i = b0 + slot as u32;
            let both = pa.get(i) != RowState::Missing && pb.get(i) != RowState::Missing;
            if both && !d {
                rep.rows_compared += 1;
                rep.differing_rows += 1;
            }
        }
        b0 = b1;
    }
    Ok(rep)
}

/// Rows `b0..b1` of `r` into `held` (one pass over the file).
fn collect_rows(
    r: &FfzReader,
    b0: u32,
    b1: u32,
    held: &mut [Option<Row>],
    errors: &mut Vec<String>,
) {
    let n = r.n();
    r.for_each_chunk(|k, res| {
        let d = match res {
            Ok(d) => d,
            Err(e) => {
                if b0 == 0 {
                    errors.push(format!("b: {e}"));
                }
                return;
            }
        };
        for e in d.entries() {
            if (b0..b1).contains(&e.row) && r.owns(k, e.row) {
                // A row that does not decode stays `None` and counts as differing.
                if let Ok(row) = d.row(e, n) {
                    held[(e.row - b0) as usize] = Some(row);
                }
            }
        }
    });
}

/// Equality of bit patterns (so NaN = NaN and 0.0 ≠ −0.0), which `PartialEq` on f32 is not,
/// of everything a row stores: [`entries_eq`] and [`links_eq`].
fn bitwise_eq(a: &Row, b: &Row) -> bool {
    entries_eq(a, b) && links_eq(a, b)
}

/// Bitwise equality of a row's entries and dropped mass (and its being skipped).
fn entries_eq(a: &Row, b: &Row) -> bool {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    a.index == b.index
        && a.dropped.to_bits() == b.dropped.to_bits()
        && match (&a.values, &b.values) {
            (RowValues::Dense(x), RowValues::Dense(y)) => bits(x) == bits(y),
            (
                RowValues::Sparse { cols: c1, vals: v1 },
                RowValues::Sparse { cols: c2, vals: v2 },
            ) => c1 == c2 && bits(v1) == bits(v2),
            (RowValues::Skipped, RowValues::Skipped) => true,
            _ => false,
        }
}

/// Bitwise equality of a row's links (ranges, values, slopes) and link error.
fn links_eq(a: &Row, b: &Row) -> bool {
    let link_bits = |l: &Link| {
        let s = l.slope.map(f32::to_bits);
        (l.start, l.len, l.value.to_bits(), s)
    };
    a.links
        .iter()
        .map(link_bits)
        .eq(b.links.iter().map(link_bits))
        && a.link_error.map(f32::to_bits) == b.link_error.map(f32::to_bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows that differ only in a link's slope, value or range, or in the link error,
    /// are not identical (their entries and dropped mass are).
    #[test]
    fn rows_that_differ_in_their_links_alone_are_not_identical() {
        let link = Link {
            start: 3,
            len: 5,
            value: 0.25,
            slope: [0.5, 0.0, -1.0],
        };
        let row = Row {
            index: 7,
            values: RowValues::Sparse {
                cols: vec![1, 2],
                vals: vec![0.125, 0.0625],
            },
            dropped: 0.25,
            links: vec![link],
            link_error: Some(0.01),
        };
        assert!(bitwise_eq(&row, &row.clone()));
        let changes: [fn(&mut Row); 5] = [
            |r| r.links[0].slope[1] = 1e-3,
            |r| r.links[0].value = 0.5,
            |r| r.links[0].start = 4,
            |r| r.link_error = Some(0.02),
            |r| r.links.clear(),
        ];
        for change in changes {
            let mut other = row.clone();
            change(&mut other);
            assert!(!bitwise_eq(&row, &other), "{other:?}");
            assert!(
                entries_eq(&row, &other) && !links_eq(&row, &other),
                "{other:?}"
            );
        }
        let mut other = row.clone();
        other.dropped = 0.5;
        assert!(!entries_eq(&row, &other) && links_eq(&row, &other));
    }
}
