//! What a compute run is asked to do and what it reports.

use std::path::PathBuf;
use std::sync::Arc;

use crate::ffz::{FileMeta, PairRoutes, StoredRoutes, WriterOptions};
use crate::formfactor::RowEngine;
use crate::patch::PatchSet;
use crate::service::schedule::Schedule;

/// Which rows a run computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowSelection {
    /// Every row.
    All,
    /// Only rows a gathering solve needs: patches that neither reflect nor emit get a
    /// row marked *skipped* in the file (docs/numerics.md §9, "work that is skipped").
    Needed,
}

/// A fully validated compute job: everything every rank needs to take part.
#[derive(Clone)]
pub struct ComputeJob {
    pub output: PathBuf,
    pub meta: FileMeta,
    pub patches: Arc<PatchSet>,
    /// The row engine; None on the rank 0 of a streaming MPI run, which computes
    /// nothing and so builds neither the occluder hierarchy nor the per-patch data.
    pub engine: Option<Arc<RowEngine>>,
    pub resume: bool,
    /// Replace an existing output file. Without it (and without `resume`) an existing
    /// file is an error, so a rerun cannot destroy a long computation by accident.
    pub overwrite: bool,
    pub schedule: Schedule,
    pub rows: RowSelection,
    /// Compute each unordered pair once and mirror it by reciprocity (service::symmetric).
    pub symmetric: bool,
    /// Compute threads per process (embedded) or per worker rank (MPI).
    pub threads: usize,
    pub writer: WriterOptions,
    /// A compute thread flushes its pending rows as a chunk at least this often, so a
    /// killed run loses little work.
    pub flush_seconds: f64,
    /// Show a progress bar / periodic progress lines.
    pub progress: bool,
    /// MPI: rank 0 ends the job when a worker has sent nothing for this long (workers
    /// send a heartbeat when quiet, so a long row does not count as silence).
    pub stall_seconds: f64,
}

impl ComputeJob {
    /// The row engine of a process that computes rows.
    ///
    /// # Panics
    /// On a job built without one (an I/O master's): a caller bug.
    pub(crate) fn engine(&self) -> &Arc<RowEngine> {
        self.engine
            .as_ref()
            .expect("this job was built for the I/O master, which computes no rows")
    }
}

/// What one worker (embedded pool or MPI rank) did.
#[derive(Clone, Debug, Default)]
pub struct WorkerStats {
    pub(crate) rank: i32,
    pub(crate) rows: u64,
    /// Seconds the compute threads spent computing rows, summed over threads.
    pub(crate) busy_seconds: f64,
    pub(crate) threads: u32,
    /// Peak resident set size of the worker process in bytes (0 if unknown).
    pub(crate) peak_rss: u64,
    /// How the visibility of its pairs was found.
    pub(crate) pairs: PairRoutes,
    /// The link errors of its rows (spec §5.7).
    pub(crate) links: LinkErrors,
}

/// The writer's link errors of the rows computed (spec §5.7, `Row::link_error`): how
/// many rows have one, their sum and the largest with its row.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct LinkErrors {
    pub(crate) rows: u64,
    pub(crate) sum: f64,
    pub(crate) max: Option<(u32, f32)>,
}

impl LinkErrors {
    pub(crate) fn add(&mut self, row: u32, e: f32) {
        self.merge(&LinkErrors {
            rows: 1,
            sum: f64::from(e),
            max: Some((row, e)),
        });
    }

    /// Both together; of equal largest errors the lower row, so that the result does
    /// not depend on the order rows were added in.
    pub(crate) fn merge(&mut self, o: &LinkErrors) {
        self.rows += o.rows;
        self.sum += o.sum;
        self.max = match (self.max, o.max) {
            (Some(a), Some(b)) => Some(
                if (b.1, std::cmp::Reverse(b.0)) > (a.1, std::cmp::Reverse(a.0)) {
                    b
                } else {
                    a
                },
            ),
            (a, b) => a.or(b),
        };
    }

    /// The report's line, if any row has a link error.
    pub(crate) fn summary(&self) -> Option<String> {
        let (row, max) = self.max?;
        Some(format!(
            "link error: mean {:.3e} max {max:.3e} (row {row}) over {} rows: the estimated relative error links make in what a row gathers (spec §5.7; stored per row, `verify` reads it back)",
            self.sum / self.rows.max(1) as f64,
            self.rows
        ))
    }
}

impl WorkerStats {
    /// The rows of `workers` and how their pairs got their visibility, together: what
    /// the report prints and the file's index keeps (spec §6.1).
    pub(crate) fn routes(workers: &[WorkerStats]) -> StoredRoutes {
        let mut all = StoredRoutes::default();
        for w in workers {
            all.add(&StoredRoutes {
                rows: w.rows,
                pairs: w.pairs,
            });
        }
        all
    }
}

/// What a finished compute run reports.
#[derive(Clone, Debug, Default)]
pub struct ComputeReport {
    pub(crate) n: usize,
    pub(crate) rows_computed: u64,
    pub(crate) rows_skipped: u64,
    pub(crate) rows_already_present: u64,
    pub(crate) wall_seconds: f64,
    /// Fraction of the master's wall time spent waiting for messages.
    pub(crate) master_idle_fraction: f64,
    pub(crate) bytes_on_disk: u64,
    pub(crate) raw_bytes: u64,
    /// `--symmetric`: bytes of half rows that went through the spill file (deleted at
    /// the end; its peak size on disk).
    pub(crate) spill_bytes: u64,
    pub(crate) master_peak_rss: u64,
    pub(crate) workers: Vec<WorkerStats>,
}

impl ComputeReport {
    /// Human-readable summary (several lines, no trailing newline).
    pub fn summary(&self) -> String {
        let ratio = if self.bytes_on_disk > 0 {
            self.raw_bytes as f64 / self.bytes_on_disk as f64
        } else {
            0.0
        };
        let mut s = format!(
            "rows: {} computed, {} skipped (not needed), {} already present, n = {}\n\
             wall {:.2} s, {:.1} rows/s; file {:.2} MB on disk ({:.2} MB raw, ratio {:.2})\n\
             I/O master: idle {:.1}% of wall time, peak RSS {:.1} MB",
            self.rows_computed,
            self.rows_skipped,
            self.rows_already_present,
            self.n,
            self.wall_seconds,
            self.rows_computed as f64 / self.wall_seconds.max(1e-9),
            self.bytes_on_disk as f64 / 1e6,
            self.raw_bytes as f64 / 1e6,
            ratio,
            100.0 * self.master_idle_fraction,
            self.master_peak_rss as f64 / 1e6,
        );
        if self.spill_bytes > 0 {
            s.push_str(&format!(
                "\nhalf rows (--symmetric): {:.2} MB went through the spill file (now removed)",
                self.spill_bytes as f64 / 1e6
            ));
        }
        s.push('\n');
        s.push_str(&WorkerStats::routes(&self.workers).pairs.summary());
        let mut links = LinkErrors::default();
        for w in &self.workers {
            links.merge(&w.links);
        }
        if let Some(line) = links.summary() {
            s.push('\n');
            s.push_str(&line);
        }
        for w in &self.workers {
            s.push_str(&format!(
                "\nworker rank {}: {} rows, {} threads, busy {:.2} s ({:.0}% of wall x threads), peak RSS {:.1} MB",
                w.rank,
                w.rows,
                w.threads,
                w.busy_seconds,
                100.0 * w.busy_seconds / (self.wall_seconds * w.threads.max(1) as f64).max(1e-9),
                w.peak_rss as f64 / 1e6
            ));
        }
        s
    }
}
