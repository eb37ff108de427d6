//! `--symmetric`: each unordered pair is computed once and its mirror follows from
//! reciprocity (the paper's trick, docs/architecture.md §1 and §4), without any process holding
//! the matrix. Design and measurements: bench/PERF.md section 6.
//!
//! * A worker computes the *half row* of each row i it is given
//!   ([`RowEngine::half_row`](crate::formfactor::RowEngine::half_row)): its own entries
//!   F_ij for j > i (and for j < i when row j is not in the run) and the mirrored
//!   entries F_ji = F_ij A_i / A_j of the rows j > i. [`HalfRowBuffer`] buckets them by
//!   destination *row block* (`block_rows(n)` consecutive rows) and compresses each
//!   bucket as a *piece*: a chunk record (formats/ffz-v1.md §5) of partial sparse rows.
//!   After the pieces, the worker says which half rows they complete.
//! * The I/O master appends pieces unread to a spill file next to the output
//!   ([`Spill`], `OUT.ffz.spill`) and keeps, per block, where its pieces are: a few
//!   bytes per piece, never the entries. Row j receives entries from every row i ≤ j,
//!   so block J is complete once every row of the run up to its last row has reported
//!   ([`Frontier`]). The master then merges the block's pieces into whole rows (dense,
//!   or top-k selected from the whole row, with the dropped mass) and writes them to
//!   the `.ffz` file like any other rows. Peak memory: one block of dense rows.
//! * The dynamic schedule hands out rows in increasing order, so blocks complete early
//!   and in order. A killed run keeps the merged blocks; `--resume` computes the rest,
//!   and since a pair's value does not depend on which rows are in the run, the resumed
//!   rows are bitwise those of an uninterrupted run.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use crate::ffz::{check_record, decode_record, encode_chunk, EncodedChunk, FfzError, Layout};
use crate::formfactor::topk::top_k_row;
use crate::rows::{Row, RowValues};

/// Rows per block: the merge holds one block of dense f32 rows, so a block has at most
/// about 2^22 entries (16 MB); and a matrix has at least ~16 blocks, so that rows reach
/// the file (and survive a kill) while the run goes on. Between 8 and 4096 rows. A
/// function of n only: workers and master agree on it without a message.
pub(crate) fn block_rows(n: u32) -> u32 {
    let n = u64::from(n.max(1));
    ((1u64 << 22) / n).min(n / 16).clamp(8, 4096) as u32
}

/// Where the master spills pieces for the run writing `output`.
pub fn spill_path(output: &Path) -> PathBuf {
    let mut s = output.as_os_str().to_os_string();
    s.push(".spill");
    PathBuf::from(s)
}

/// `in_run[i]`: whether row i is one of `todo` (the rows computed in this run).
pub(crate) fn in_run(todo: &[u32], n: u32) -> Vec<bool> {
    let mut v = vec![false; n as usize];
    for &r in todo {
        v[r as usize] = true;
    }
    v
}

/// The rows of one bucket (entries of rows `base..base + len`), each with its columns
/// ascending: the entries are counted and placed per row in the order they came (a
/// counting sort), and a row whose columns did not come in order is sorted. A
/// comparison sort of the whole bucket took a tenth of a dense symmetric run's CPU
/// (bench/PERF.md §25). The same rows whatever order the entries came in.
fn rows_of_bucket(bucket: &[(u32, u32, f32)], base: u32, len: u32) -> Vec<Row> {
    let mut slot = vec![0u32; len as usize];
    for &(r, _, _) in bucket {
        slot[(r - base) as usize] += 1;
    }
    let mut rows: Vec<Row> = Vec::new();
    for (o, s) in slot.iter_mut().enumerate() {
        let count = *s as usize;
        if count > 0 {
            *s = rows.len() as u32;
            rows.push(Row {
                index: base + o as u32,
                values: RowValues::Sparse {
                    cols: Vec::with_capacity(count),
                    vals: Vec::with_capacity(count),
                },
                dropped: 0.0,
                links: Vec::new(),
                link_error: None,
            });
        }
    }
    for &(r, c, v) in bucket {
        if let RowValues::Sparse { cols, vals } =
            &mut rows[slot[(r - base) as usize] as usize].values
        {
            cols.push(c);
            vals.push(v);
        }
    }
    for row in &mut rows {
        if let RowValues::Sparse { cols, vals } = &mut row.values {
            if !cols.is_sorted() {
                let mut pairs: Vec<(u32, f32)> =
                    cols.iter().copied().zip(vals.iter().copied()).collect();
                pairs.sort_unstable_by_key(|p| p.0);
                (*cols, *vals) = pairs.into_iter().unzip();
            }
        }
    }
    rows
}

/// zstd level of the half-row pieces. They are transient (rank 0 spills them, then
/// decodes them into whole rows that it compresses at the file's level), so a fast
/// level of zstd's negative range serves: they are compressed once and decoded once,
/// and only the spill file and the messages grow a little (bench/PERF.md §25).
pub(crate) const PIECE_ZSTD_LEVEL: i32 = -3;

/// Worker side: entries of finished half rows, bucketed by destination block.
pub(crate) struct HalfRowBuffer {
    n: u32,
    block: u32,
    /// Per block: (destination row, column, value).
    buckets: Vec<Vec<(u32, u32, f32)>>,
    entries: usize,
    /// Half rows whose entries are all in the buckets.
    sources: Vec<u32>,
}

impl HalfRowBuffer {
    pub(crate) fn new(n: u32) -> Self {
        let block = block_rows(n);
        HalfRowBuffer {
            n,
            block,
            buckets: vec![Vec::new(); n.div_ceil(block) as usize],
            entries: 0,
            sources: Vec::new(),
        }
    }

    /// Add the half row of row `i` (the two lists of `RowEngine::half_row`).
    pub(crate) fn add(&mut self, i: u32, own: &[(u32, f64)], mirrored: &[(u32, f64)]) {
        let home = &mut self.buckets[(i / self.block) as usize];
        home.extend(own.iter().map(|&(j, f)| (i, j, f as f32)));
        for &(j, f) in mirrored {
            self.buckets[(j / self.block) as usize].push((j, i, f as f32));
        }
        self.entries += own.len() + mirrored.len();
        self.sources.push(i);
    }

    /// Half rows held.
    pub(crate) fn rows(&self) -> usize {
        self.sources.len()
    }

    /// Uncompressed bytes the pieces would take (8 per entry).
    pub(crate) fn pending_bytes(&self) -> usize {
        8 * self.entries
    }

    /// Compress every non-empty bucket into one piece and empty the buffer. Returns the
    /// pieces and the half rows they complete (send the pieces first).
    ///
    /// # Errors
    /// As [`encode_chunk`] (only a zstd failure in practice).
    pub(crate) fn flush(
        &mut self,
        zstd_level: i32,
    ) -> Result<(Vec<EncodedChunk>, Vec<u32>), FfzError> {
        let mut pieces = Vec::new();
        // A piece's rows hold at most n entries: the top-k layout with k = n is the
        // partial-row container (never written to the .ffz file itself).
        let layout = Layout::TopK { k: self.n };
        for (k, bucket) in self.buckets.iter_mut().enumerate() {
            if bucket.is_empty() {
                continue;
            }
            let base = k as u32 * self.block;
            let rows = rows_of_bucket(bucket, base, self.block.min(self.n - base));
            // Free the bucket rather than keep its capacity: which blocks receive the
            // most entries shifts as the run goes on, and kept capacities would add up.
            *bucket = Vec::new();
            pieces.push(encode_chunk(&rows, layout, self.n, zstd_level)?);
        }
        self.entries = 0;
        Ok((pieces, std::mem::take(&mut self.sources)))
    }
}

/// Master side: which blocks are complete, from the half rows reported so far.
pub(crate) struct Frontier {
    /// Rows of the run, ascending.
    todo: Vec<u32>,
    done: Vec<bool>,
    /// `todo[..pos]` are all done.
    pos: usize,
    block: u32,
    /// Blocks below this one were already released.
    next_block: u32,
    blocks: u32,
}

impl Frontier {
    pub(crate) fn new(n: u32, todo: &[u32]) -> Self {
        let mut todo = todo.to_vec();
        todo.sort_unstable();
        let block = block_rows(n);
        Frontier {
            todo,
            done: vec![false; n as usize],
            pos: 0,
            block,
            next_block: 0,
            blocks: n.div_ceil(block),
        }
    }

    /// Record finished half rows; returns the blocks (holding rows of the run) that
    /// just became complete, in order.
    ///
    /// # Errors
    /// A row that is not in the run or was reported twice (a protocol error).
    pub(crate) fn finish(&mut self, rows: &[u32]) -> Result<Vec<u32>, String> {
        for &r in rows {
            let ok = self.todo.binary_search(&r).is_ok();
            match self.done.get_mut(r as usize) {
                Some(d) if ok && !*d => *d = true,
                _ => return Err(format!("half row {r} reported twice or not in this run")),
            }
        }
        while self.pos < self.todo.len() && self.done[self.todo[self.pos] as usize] {
            self.pos += 1;
        }
        // Everything below the first unfinished row of the run is complete.
        let limit = self
            .todo
            .get(self.pos)
            .map_or(self.blocks, |&r| r / self.block);
        let mut ready = Vec::new();
        while self.next_block < limit {
            let j = self.next_block;
            let (lo, hi) = (j * self.block, (j + 1) * self.block);
            let first = self.todo.partition_point(|&r| r < lo);
            if self.todo.get(first).is_some_and(|&r| r < hi) {
                ready.push(j);
            }
            self.next_block += 1;
        }
        Ok(ready)
    }
}

impl Frontier {
    /// Pairs the half row of row `i` (of the run) owns: the n − 1 − i columns after it
    /// and the columns before it whose rows are not in the run (`RowEngine::half_row`).
    pub(crate) fn work(&self, i: u32) -> u64 {
        let n = self.done.len() as u64;
        let run_below = self.todo.partition_point(|&r| r < i) as u64;
        (n - 1 - u64::from(i)) + (u64::from(i) - run_below)
    }

    /// Σ of [`Frontier::work`] over the run.
    pub(crate) fn total_work(&self) -> u64 {
        self.todo.iter().map(|&i| self.work(i)).sum()
    }

    /// Every block holding rows of the run has been released.
    pub(crate) fn complete(&self) -> bool {
        self.pos == self.todo.len()
    }
}

/// The master's spill file of pieces, and the merge of a complete block into rows.
pub(crate) struct Spill {
    path: PathBuf,
    file: File,
    end: u64,
    n: u32,
    block: u32,
    /// Per block: (offset, length) of its pieces in the spill file.
    pieces: Vec<Vec<(u64, u64)>>,
    /// Rows of the run (the rows a merge emits).
    in_run: Vec<bool>,
    layout: Layout,
    /// Merge buffer: one block of dense rows.
    buf: Vec<f32>,
}

impl Spill {
    /// Create (or truncate: a spill left by a killed run is of no use) the spill file.
    ///
    /// # Errors
    /// The file cannot be created.
    pub(crate) fn create(
        path: PathBuf,
        n: u32,
        todo: &[u32],
        layout: Layout,
    ) -> Result<Self, FfzError> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&path)
            .map_err(|e| FfzError::io(&path, "create the spill file", e))?;
        let block = block_rows(n);
        Ok(Spill {
            path,
            file,
            end: 0,
            n,
            block,
            pieces: vec![Vec::new(); n.div_ceil(block) as usize],
            in_run: in_run(todo, n),
            layout,
            buf: Vec::new(),
        })
    }

    #[cfg(test)]
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes written to the spill so far.
    pub(crate) fn bytes(&self) -> u64 {
        self.end
    }

    /// Append a piece (unread: its checksums are checked when the block is merged).
    ///
    /// # Errors
    /// A piece whose rows span blocks or lie outside the run; a write error (disk full).
    pub(crate) fn append(&mut self, piece: &EncodedChunk) -> Result<(), FfzError> {
        let bad = |what: String| FfzError::Spill {
            path: self.path.clone(),
            what,
        };
        let Some(&first) = piece.row_ids.first() else {
            return Err(bad("a spill piece without rows".into()));
        };
        let j = first / self.block;
        if let Some(&r) = piece.row_ids.iter().find(|&&r| {
            r / self.block != j || !self.in_run.get(r as usize).copied().unwrap_or(false)
        }) {
            return Err(bad(format!(
                "spill piece for block {j} holds row {r} (another block, or not in this run)"
            )));
        }
        self.file
            .write_all(&piece.bytes)
            .map_err(|e| FfzError::io(&self.path, "write the spill file", e))?;
        self.pieces[j as usize].push((self.end, piece.bytes.len() as u64));
        self.end += piece.bytes.len() as u64;
        Ok(())
    }

    /// Merge the pieces of complete block `j` into the whole rows of the run in it, in
    /// ascending order, handing each to `emit`.
    ///
    /// # Errors
    /// A read error, a piece whose checksum fails, an entry given twice; or the error
    /// of `emit`.
    pub(crate) fn merge(
        &mut self,
        j: u32,
        mut emit: impl FnMut(Row) -> Result<(), FfzError>,
    ) -> Result<(), FfzError> {
        let n = self.n as usize;
        let lo = j * self.block;
        let hi = ((j + 1) * self.block).min(self.n);
        let rows = (hi - lo) as usize;
        self.buf.clear();
        self.buf.resize(rows * n, 0.0);
        let piece_layout = Layout::TopK { k: self.n };
        let mut rec = Vec::new();
        for &(off, len) in &self.pieces[j as usize] {
            let bad = |what: String| FfzError::Spill {
                path: self.path.clone(),
                what: format!("piece at offset {off}: {what}"),
            };
            rec.resize(len as usize, 0);
            self.file
                .read_exact_at(&mut rec, off)
                .map_err(|e| FfzError::io(&self.path, "read the spill file", e))?;
            let (h, _) = check_record(&rec).map_err(|(_, w)| bad(w))?;
            let chunk = decode_record(h, &rec, self.n, piece_layout).map_err(|(_, w)| bad(w))?;
            for e in chunk.entries() {
                let row = chunk.row(e, self.n).map_err(bad)?;
                // The message said which rows the piece holds; its checked content must
                // agree (a piece is never trusted to index the merge buffer).
                if !(lo..hi).contains(&row.index) || !self.in_run[row.index as usize] {
                    return Err(bad(format!(
                        "holds row {}, outside block {j} (rows {lo}..{hi}) or the run",
                        row.index
                    )));
                }
                let base = (row.index - lo) as usize * n;
                let mut twice = None;
                row.for_each_nonzero(|c, v| {
                    let slot = &mut self.buf[base + c as usize];
                    if *slot != 0.0 {
                        twice = Some(c);
                    }
                    *slot = v;
                });
                if let Some(c) = twice {
                    return Err(bad(format!("entry ({}, {c}) given twice", row.index)));
                }
            }
        }
        self.pieces[j as usize] = Vec::new();
        let mut order = Vec::new();
        let mut values = Vec::new();
        for r in lo..hi {
            if !self.in_run[r as usize] {
                continue;
            }
            let dense = &self.buf[(r - lo) as usize * n..][..n];
            let row = match self.layout {
                Layout::Dense => Row::dense(r, dense.to_vec()),
                Layout::TopK { k } => {
                    values.clear();
                    values.extend(dense.iter().map(|&v| f64::from(v)));
                    top_k_row(r, &values, k as usize, 0.0, &mut order)
                }
            };
            emit(row)?;
        }
        Ok(())
    }

    /// Delete the spill file (the end of a run, successful or not: a spill cannot be
    /// resumed).
    pub(crate) fn remove(self) {
        drop(self.file);
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_hold_about_four_million_entries() {
        assert_eq!(block_rows(1000), 62);
        assert_eq!(block_rows(20), 8);
        assert_eq!(block_rows(8500), 493);
        assert_eq!(block_rows(1_000_000), 8);
    }

    #[test]
    fn frontier_releases_blocks_in_order_once_every_earlier_row_is_done() {
        // n = 20000: blocks of 209 rows. Run = every row except 0..300 (resumed file).
        let n = 20_000;
        let b = block_rows(n);
        let todo: Vec<u32> = (300..n).collect();
        let mut f = Frontier::new(n, &todo);
        // Block 1 holds rows 300..418 of the run; row 300 is the first of the run.
        assert_eq!(f.finish(&[301, 302]).unwrap(), Vec::<u32>::new());
        let upto: Vec<u32> = (300..2 * b).filter(|r| *r > 302).collect();
        assert_eq!(f.finish(&upto).unwrap(), Vec::<u32>::new());
        // Block 0 holds no row of the run and is never released; block 1 is.
        assert_eq!(f.finish(&[300]).unwrap(), vec![1]);
        assert!(f.finish(&[300]).is_err(), "reported twice");
        // Row 300 owns the 19 699 columns after it and the 300 before it (not in run);
        // every pair touching the run is owned once.
        assert_eq!(f.work(300), 19_699 + 300);
        assert_eq!(f.work(n - 1), 300);
        let pairs = u64::from(n) * u64::from(n - 1) / 2 - 300 * 299 / 2;
        assert_eq!(f.total_work(), pairs);
        assert!(f.finish(&[5]).is_err(), "not in the run");
        let rest: Vec<u32> = (2 * b..n).rev().collect();
        let ready = f.finish(&rest).unwrap();
        assert_eq!(ready, (2..n.div_ceil(b)).collect::<Vec<_>>());
    }

    #[test]
    fn a_bucket_gives_the_same_rows_whatever_order_its_entries_came_in() {
        // Rows 10..14 of a bucket; entries of row 11 and 13 arrive out of column order.
        let entries = [
            (11, 7, 1.0),
            (13, 2, 2.0),
            (11, 3, 3.0),
            (10, 1, 4.0),
            (13, 9, 5.0),
            (11, 12, 6.0),
            (13, 0, 7.0),
        ];
        let want = |order: &[(u32, u32, f32)]| {
            let mut sorted = order.to_vec();
            sorted.sort_by_key(|e| (e.0, e.1));
            sorted
        };
        let flat = |rows: Vec<Row>| {
            let mut out = Vec::new();
            for r in rows {
                r.for_each_nonzero(|c, v| out.push((r.index, c, v)));
            }
            out
        };
        let mut reversed = entries;
        reversed.reverse();
        for order in [&entries[..], &reversed[..]] {
            let rows = rows_of_bucket(order, 10, 5);
            assert_eq!(rows.len(), 3);
            assert_eq!(flat(rows), want(order));
        }
    }

    #[test]
    fn pieces_round_trip_through_the_spill_into_whole_rows() {
        let dir = tempfile::tempdir().unwrap();
        let n = 20u32;
        let todo: Vec<u32> = (0..n).collect();
        let mut buf = HalfRowBuffer::new(n);
        // Row i: own entry (i + 1) = 1 + i, mirrored into row i + 1 at column i.
        for i in 0..n - 1 {
            buf.add(i, &[(i + 1, 1.0 + f64::from(i))], &[(i + 1, 0.5)]);
        }
        buf.add(n - 1, &[], &[]);
        let (pieces, sources) = buf.flush(1).unwrap();
        assert_eq!(sources.len(), n as usize);
        assert_eq!(buf.pending_bytes(), 0);
        let mut spill =
            Spill::create(dir.path().join("x.spill"), n, &todo, Layout::TopK { k: 1 }).unwrap();
        for p in &pieces {
            spill.append(p).unwrap();
        }
        let mut rows = Vec::new();
        for j in 0..n.div_ceil(block_rows(n)) {
            spill
                .merge(j, |r| {
                    rows.push(r);
                    Ok(())
                })
                .unwrap();
        }
        assert_eq!(rows.len(), n as usize);
        assert!(rows.iter().enumerate().all(|(i, r)| r.index == i as u32));
        // Row 3 holds 0.5 at column 2 and 4.0 at column 4; top-1 keeps 4.0, drops 0.5.
        assert_eq!(
            rows[3].values,
            RowValues::Sparse {
                cols: vec![4],
                vals: vec![4.0]
            }
        );
        assert_eq!(rows[3].dropped, 0.5);
        // A piece given twice is caught at the merge.
        spill.append(&pieces[0]).unwrap();
        spill.append(&pieces[0]).unwrap();
        let j = pieces[0].row_ids[0] / block_rows(n);
        let e = spill.merge(j, |_| Ok(())).unwrap_err().to_string();
        assert!(e.contains("given twice"), "{e}");
        let path = spill.path().to_path_buf();
        spill.remove();
        assert!(!path.exists());
    }

    #[test]
    fn a_piece_whose_rows_disagree_with_its_message_is_refused_at_the_merge() {
        let dir = tempfile::tempdir().unwrap();
        let n = 40u32; // blocks of 8 rows
        let mut buf = HalfRowBuffer::new(n);
        buf.add(20, &[(30, 0.25)], &[]);
        let (mut pieces, _) = buf.flush(1).unwrap();
        // The message claims block 0; the record holds row 20 (block 2).
        pieces[0].row_ids = vec![1];
        let todo: Vec<u32> = (0..n).collect();
        let mut spill = Spill::create(dir.path().join("m.spill"), n, &todo, Layout::Dense).unwrap();
        spill.append(&pieces[0]).unwrap();
        let e = spill.merge(0, |_| Ok(())).unwrap_err().to_string();
        assert!(e.contains("outside block 0"), "{e}");
    }

    #[test]
    fn a_corrupt_piece_is_an_error_naming_the_spill_file() {
        let dir = tempfile::tempdir().unwrap();
        let n = 10u32;
        let mut buf = HalfRowBuffer::new(n);
        buf.add(0, &[(3, 0.25)], &[(3, 0.125)]);
        let (mut pieces, _) = buf.flush(1).unwrap();
        let last = pieces[0].bytes.len() - 1;
        pieces[0].bytes[last] ^= 0x40;
        let path = dir.path().join("bad.spill");
        let mut spill = Spill::create(path, n, &[0, 3], Layout::Dense).unwrap();
        spill.append(&pieces[0]).unwrap();
        let e = spill.merge(0, |_| Ok(())).unwrap_err().to_string();
        assert!(e.contains("bad.spill") && e.contains("checksum"), "{e}");
    }
}
