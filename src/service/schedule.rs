//! Which worker computes which rows.
//!
//! * `dynamic` (default): workers ask the master for batches; batch size follows guided
//!   self-scheduling (a fraction of what is left, shrinking toward the end) so the last
//!   rows are spread thin and no worker finishes long after the others.
//! * `folded`: the paper's static assignment, no requests. Rows are taken in folded order
//!   (first half ascending interleaved with the second half descending: 0, n-1, 1, n-2, ...)
//!   and dealt to workers in pairs, so each worker gets rows i and n-1-i together. With
//!   the paper's upper-half computation (row i costs n-i pairs) every pair costs the same;
//!   with full rows it still spreads cheap and expensive regions evenly.

/// Work distribution strategy (`--schedule`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Schedule {
    #[default]
    Dynamic,
    Folded,
}

impl std::fmt::Display for Schedule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Schedule::Dynamic => "dynamic",
            Schedule::Folded => "folded",
        })
    }
}

/// The paper's folded order of `rows`: first half ascending interleaved with the second
/// half descending.
pub(crate) fn folded_order(rows: &[u32]) -> Vec<u32> {
    let n = rows.len();
    let mut out = Vec::with_capacity(n);
    let (mut lo, mut hi) = (0usize, n);
    while lo < hi {
        out.push(rows[lo]);
        lo += 1;
        if lo < hi {
            hi -= 1;
            out.push(rows[hi]);
        }
    }
    out
}

/// The rows worker `w` of `workers` computes under the folded schedule: pairs of the
/// folded order dealt round robin.
pub(crate) fn folded_share(rows: &[u32], workers: usize, w: usize) -> Vec<u32> {
    debug_assert!(w < workers);
    folded_order(rows)
        .chunks(2)
        .enumerate()
        .filter(|(k, _)| k % workers == w)
        .flat_map(|(_, pair)| pair.iter().copied())
        .collect()
}

/// Guided self-scheduling queue for the dynamic schedule (lives at the master).
#[derive(Debug)]
pub(crate) struct DynamicQueue {
    rows: Vec<u32>,
    next: usize,
    workers: usize,
    min_batch: usize,
    max_batch: usize,
}

impl DynamicQueue {
    /// `min_batch` is usually the compute threads per worker, so one request keeps
    /// every thread of a worker busy. When it exceeds `max_batch` (more threads per
    /// worker than the cap, e.g. `--threads 300` against 256) the floor wins: a
    /// batch is never smaller than one row per thread.
    pub(crate) fn new(rows: Vec<u32>, workers: usize, min_batch: usize, max_batch: usize) -> Self {
        let min_batch = min_batch.max(1);
        DynamicQueue {
            rows,
            next: 0,
            workers: workers.max(1),
            min_batch,
            max_batch: max_batch.max(min_batch),
        }
    }

    pub(crate) fn remaining(&self) -> usize {
        self.rows.len() - self.next
    }

    /// Next batch: a quarter of the per-worker remainder, clamped; empty when done.
    pub(crate) fn next_batch(&mut self) -> Vec<u32> {
        let remaining = self.remaining();
        let size = (remaining / (4 * self.workers))
            .clamp(self.min_batch, self.max_batch)
            .min(remaining);
        let batch = self.rows[self.next..self.next + size].to_vec();
        self.next += size;
        batch
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folded_order_pairs_i_with_n_minus_1_minus_i() {
        let rows: Vec<u32> = (0..7).collect();
        assert_eq!(folded_order(&rows), vec![0, 6, 1, 5, 2, 4, 3]);
    }

    #[test]
    fn folded_shares_partition_the_rows_and_balance_the_triangle() {
        let n = 1000u32;
        let rows: Vec<u32> = (0..n).collect();
        for workers in 1..6 {
            let mut all: Vec<u32> = (0..workers)
                .flat_map(|w| folded_share(&rows, workers, w))
                .collect();
            all.sort_unstable();
            assert_eq!(all, rows, "workers = {workers}");
            // Upper-half cost of row i is n - i: shares must be within one pair's cost.
            let costs: Vec<u64> = (0..workers)
                .map(|w| {
                    folded_share(&rows, workers, w)
                        .iter()
                        .map(|&i| (n - i) as u64)
                        .sum()
                })
                .collect();
            let spread = costs.iter().max().unwrap() - costs.iter().min().unwrap();
            assert!(
                spread <= (n + 1) as u64,
                "workers = {workers}: costs {costs:?}"
            );
        }
    }

    #[test]
    fn dynamic_batches_cover_all_rows_once_and_shrink() {
        let rows: Vec<u32> = (0..10_000).collect();
        let mut q = DynamicQueue::new(rows.clone(), 3, 2, 256);
        let mut seen = Vec::new();
        let mut sizes = Vec::new();
        loop {
            let b = q.next_batch();
            if b.is_empty() {
                break;
            }
            sizes.push(b.len());
            seen.extend(b);
        }
        assert_eq!(seen, rows);
        assert!(sizes.first() >= sizes.last());
        assert!(*sizes.iter().max().unwrap() <= 256);
    }

    /// `--threads 300` gave a floor of 300 above the cap of 256 and `clamp` panicked
    /// ("min > max"): the floor wins, every row is dealt once.
    #[test]
    fn a_batch_floor_above_the_cap_does_not_panic() {
        let rows: Vec<u32> = (0..1000).collect();
        let mut q = DynamicQueue::new(rows.clone(), 2, 300, 256);
        let mut seen = Vec::new();
        loop {
            let b = q.next_batch();
            if b.is_empty() {
                break;
            }
            assert!(b.len() >= 300 || q.remaining() == 0, "batch {}", b.len());
            seen.extend(b);
        }
        assert_eq!(seen, rows);
    }
}
