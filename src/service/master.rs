//! The I/O master: receives compressed chunks from workers and streams them into the
//! `.ffz` file; hands out rows under the dynamic schedule. It computes nothing.
//!
//! Receiving and writing overlap: the master thread only moves messages; a writer thread
//! owns the [`FfzWriter`] and appends chunks handed to it over a bounded crossbeam
//! channel. When the disk is slower than the workers the channel fills, the master stops
//! receiving, and the backpressure reaches the workers (their sends block): memory at
//! the master is bounded by the channel capacity, whatever n is.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crossbeam::channel::{bounded, Sender};

use crate::ffz::{encode_chunk, EncodedChunk, FfzWriter, Layout, StoredRoutes, WriterStats};
use crate::rows::Row;
use crate::service::link::{MasterLink, ToMaster};
use crate::service::progress::Progress;
use crate::service::schedule::{DynamicQueue, Schedule};
use crate::service::symmetric::{Frontier, Spill};
use crate::service::{ServiceError, WorkerStats};

/// Chunks queued between the master thread and the writer thread.
const WRITER_QUEUE: usize = 8;

/// What the master is told to do.
pub(crate) struct MasterPlan {
    /// Rows the workers compute (already excludes rows present in a resumed file).
    pub(crate) todo: Vec<u32>,
    /// Rows to record as skipped on purpose (not needed by a gathering solve).
    pub(crate) skipped: Vec<u32>,
    pub(crate) schedule: Schedule,
    /// Smallest dynamic batch (usually the threads per worker).
    pub(crate) min_batch: usize,
    pub(crate) layout: Layout,
    pub(crate) n: u32,
    pub(crate) zstd_level: i32,
    pub(crate) progress: bool,
    /// `--symmetric`: workers send half rows as spill pieces, kept in this file until
    /// their row block is complete (service::symmetric).
    pub(crate) spill: Option<std::path::PathBuf>,
    /// The liveness limit: a worker silent this long (counted while the master listens)
    /// ends the job. None: no limit (embedded, where the workers are threads of this
    /// process and cannot stop on their own).
    pub(crate) stall: Option<Duration>,
}

/// What the master observed.
#[derive(Debug, Default)]
pub(crate) struct MasterOutcome {
    pub(crate) writer: WriterStats,
    /// `--symmetric`: bytes that went through the spill file.
    pub(crate) spill_bytes: u64,
    pub(crate) rows_received: u64,
    pub(crate) idle_seconds: f64,
    pub(crate) wall_seconds: f64,
    pub(crate) workers: Vec<WorkerStats>,
}

enum WriterJob {
    Chunk(EncodedChunk),
    /// `--symmetric`: append to the spill.
    Piece(EncodedChunk),
    /// `--symmetric`: this row block is complete; merge it into rows and write them.
    Merge(u32),
    /// The run is over: how the pairs of the rows its workers reported got their
    /// visibility, for the index (spec §6.1).
    Routes(StoredRoutes),
}

/// Shared counters the writer thread updates for the progress display.
#[derive(Default)]
struct WriterCounters {
    disk: AtomicU64,
    raw: AtomicU64,
}

/// Run the master until every worker is done, then finish the file (index + footer).
///
/// On a worker failure the master stops handing out rows, finishes the file with what
/// it has (so `--resume` can complete it) and returns [`ServiceError::WorkerFailed`].
///
/// # Errors
/// A worker failure, a broken link, or a file error (disk full, ...). In every case the
/// chunks written so far stay recoverable.
pub(crate) fn run_master(
    link: &mut dyn MasterLink,
    writer: FfzWriter,
    plan: &MasterPlan,
) -> Result<MasterOutcome, ServiceError> {
    let _span = tracing::info_span!("io_master", rows = plan.todo.len()).entered();
    let start = Instant::now();
    let counters = Arc::new(WriterCounters::default());
    let (tx, rx) = bounded::<WriterJob>(WRITER_QUEUE);

    let spill = match &plan.spill {
        Some(path) => Some(Spill::create(
            path.clone(),
            plan.n,
            &plan.todo,
            plan.layout,
        )?),
        None => None,
    };
    let writer_counters = Arc::clone(&counters);
    let writer_thread = std::thread::Builder::new()
        .name("ffz-writer".into())
        .spawn(move || -> Result<(WriterStats, u64), ServiceError> {
            let mut writer = writer;
            let mut spill = spill;
            let written = write_jobs(&mut writer, spill.as_mut(), rx, &writer_counters);
            // A spill is of no use after the run, whatever happened: `--resume`
            // recomputes the blocks that were not merged.
            let spilled = spill.as_ref().map_or(0, Spill::bytes);
            if let Some(s) = spill {
                s.remove();
            }
            written?;
            Ok((writer.finish()?, spilled))
        })
        .map_err(|e| ServiceError::Transport(format!("cannot start the writer thread: {e}")))?;

    let result = master_loop(link, &tx, &counters, plan, start);
    // Only the workers that reported count: the rows of one that failed stay in the
    // file, uncounted (the record says how many rows it covers). Half rows of a run
    // that did not finish count none, whatever stopped it (a signal to every rank or
    // to one worker, a failed worker, rows lost): the workers' counts include half
    // rows whose blocks were never merged, which `--resume` computes again, so they
    // would count rows not in the file (issue 48, item 4: 2,831 counted of 748
    // present, then 5,077 of n = 2,994 after the resume). (A writer thread that has
    // stopped has its own error to report.)
    let unfinished_half = plan.spill.is_some() && result.1.is_some();
    if !unfinished_half {
        let _ = tx.send(WriterJob::Routes(WorkerStats::routes(&result.0.workers)));
    }
    drop(tx);
    let written = writer_thread
        .join()
        .map_err(|_| ServiceError::Transport("the writer thread panicked".into()))?;
    let (mut outcome, failure) = result;
    // A file error is the root cause when both fail (the master saw a closed channel).
    (outcome.writer, outcome.spill_bytes) = written?;
    outcome.wall_seconds = start.elapsed().as_secs_f64();
    match failure {
        Some(e) => Err(e),
        None => Ok(outcome),
    }
}

/// The writer thread's work: append chunks; for `--symmetric`, spill pieces and merge
/// complete blocks into rows.
fn write_jobs(
    writer: &mut FfzWriter,
    mut spill: Option<&mut Spill>,
    rx: crossbeam::channel::Receiver<WriterJob>,
    counters: &WriterCounters,
) -> Result<(), ServiceError> {
    for job in rx {
        match (job, spill.as_deref_mut()) {
            (WriterJob::Chunk(chunk), _) => writer.append_chunk(chunk)?,
            (WriterJob::Piece(piece), Some(s)) => s.append(&piece)?,
            (WriterJob::Merge(j), Some(s)) => s.merge(j, |row| writer.push_row(row))?,
            (WriterJob::Routes(r), _) => writer.add_routes(&r),
            (WriterJob::Piece(_) | WriterJob::Merge(_), None) => {
                return Err(ServiceError::Transport(
                    "a half-row piece reached a run without --symmetric".into(),
                ))
            }
        }
        let s = writer.stats();
        counters.disk.store(s.bytes_on_disk, Ordering::Relaxed);
        counters.raw.store(s.raw_bytes, Ordering::Relaxed);
    }
    Ok(())
}

fn master_loop(
    link: &mut dyn MasterLink,
    tx: &Sender<WriterJob>,
    counters: &WriterCounters,
    plan: &MasterPlan,
    start: Instant,
) -> (MasterOutcome, Option<ServiceError>) {
    let workers = link.workers();
    let frontier = plan
        .spill
        .as_ref()
        .map(|_| Frontier::new(plan.n, &plan.todo));
    let mut progress = Progress::new(plan.todo.len() as u64, plan.progress);
    if let Some(f) = &frontier {
        progress = progress.with_work(f.total_work());
    }
    let mut state = MasterState {
        outcome: MasterOutcome::default(),
        progress,
        queue: match plan.schedule {
            Schedule::Dynamic => DynamicQueue::new(plan.todo.clone(), workers, plan.min_batch, 256),
            Schedule::Folded => DynamicQueue::new(Vec::new(), workers, 1, 1),
        },
        failure: None,
        stopping: false,
        done: 0,
        frontier,
        tx,
        counters,
    };
    if let Err(e) = record_skipped(plan, tx) {
        return (state.outcome, Some(e));
    }
    let mut liveness = Liveness::new(workers, plan.stall);
    while state.done < workers {
        if !state.stopping {
            if let Some(signal) = super::interrupt::interrupted() {
                // From now on every request gets "no more work"; the workers hand over
                // what they have finished and say done, and the file is closed. Whether
                // the run then counts as stopped depends on what is missing at the end.
                tracing::warn!(
                    "{}: finishing the rows in progress, then closing the file (the same signal again stops at once)",
                    super::interrupt::signal_name(signal)
                );
                state.stopping = true;
            }
        }
        let t0 = Instant::now();
        let msg = match link.poll(Duration::from_millis(100)) {
            Ok(m) => m,
            Err(e) => {
                state.failure.get_or_insert(e);
                break;
            }
        };
        let waited = t0.elapsed();
        state.outcome.idle_seconds += waited.as_secs_f64();
        liveness.listened(waited);
        if let Some((worker, m)) = &msg {
            liveness.heard(*worker, matches!(m, ToMaster::Done { .. }));
        }
        if let Some((worker, silent)) = liveness.stalled() {
            state.failure.get_or_insert(ServiceError::WorkerStalled {
                rank: link.rank_of(worker),
                seconds: silent.as_secs_f64(),
            });
            break;
        }
        let Some((_, msg)) = msg else { continue };
        if let Err(e) = state.handle(msg, link) {
            state.failure.get_or_insert(e);
            break;
        }
        if matches!(state.failure, Some(ServiceError::WorkerFailed { .. })) {
            // Stop now: the remaining workers are stopped by the caller (MPI abort, or
            // the embedded pool seeing its channels close). What was written stays.
            break;
        }
    }
    let MasterState {
        mut outcome,
        mut failure,
        frontier,
        mut progress,
        ..
    } = state;
    let incomplete = match &frontier {
        Some(f) => !f.complete(),
        None => outcome.rows_received < plan.todo.len() as u64,
    };
    if failure.is_none() && incomplete {
        // Every worker said done but some rows (or half rows, whose blocks then cannot
        // be merged) never reported: stopped by a signal (which the workers may have
        // seen before the loop did), else lost. Either way, say so rather than finish a
        // file with rows missing as if it were complete. A run that got every row is
        // complete, signal or not.
        failure = Some(match super::interrupt::interrupted() {
            Some(signal) => ServiceError::Interrupted { signal },
            None => ServiceError::Transport(
                "the workers finished but some rows never reported; the file lacks them (rerun with --resume)".into(),
            ),
        });
    }
    progress.finish();
    outcome.wall_seconds = start.elapsed().as_secs_f64();
    outcome.workers.sort_by_key(|w| w.rank);
    (outcome, failure)
}

/// When each worker was last heard from, on a clock that runs only while the master
/// listens: while the writer queue is full the master stops receiving and the workers'
/// sends wait, and that wait is not their silence.
struct Liveness {
    limit: Option<Duration>,
    /// Time spent listening (in `poll`) since the start.
    clock: Duration,
    /// Per worker: the clock at its last message; None once it said it is done.
    last: Vec<Option<Duration>>,
}

impl Liveness {
    fn new(workers: usize, limit: Option<Duration>) -> Self {
        Liveness {
            limit,
            clock: Duration::ZERO,
            last: vec![Some(Duration::ZERO); workers],
        }
    }

    fn listened(&mut self, d: Duration) {
        self.clock += d;
    }

    fn heard(&mut self, worker: usize, finished: bool) {
        if let Some(l) = self.last.get_mut(worker) {
            *l = (!finished).then_some(self.clock);
        }
    }

    /// The first worker silent for longer than the limit, and for how long.
    fn stalled(&self) -> Option<(usize, Duration)> {
        let limit = self.limit?;
        self.last.iter().enumerate().find_map(|(w, l)| {
            let silent = self.clock.saturating_sub((*l)?);
            (silent > limit).then_some((w, silent))
        })
    }
}

/// Rows skipped on purpose are recorded by the master itself, in small chunks.
fn record_skipped(plan: &MasterPlan, tx: &Sender<WriterJob>) -> Result<(), ServiceError> {
    for ids in plan.skipped.chunks(4096) {
        let rows: Vec<Row> = ids.iter().map(|&i| Row::skipped(i)).collect();
        let chunk = encode_chunk(&rows, plan.layout, plan.n, plan.zstd_level)?;
        tx.send(WriterJob::Chunk(chunk))
            .map_err(|_| writer_gone())?;
    }
    Ok(())
}

/// What the master loop keeps between messages.
struct MasterState<'a> {
    outcome: MasterOutcome,
    progress: Progress,
    queue: DynamicQueue,
    failure: Option<ServiceError>,
    /// A signal asked the run to stop ([`super::interrupt`]): no more rows are handed out.
    stopping: bool,
    /// Workers that said they are done.
    done: usize,
    /// `--symmetric`: which half rows have reported, and which blocks are complete.
    frontier: Option<Frontier>,
    tx: &'a Sender<WriterJob>,
    counters: &'a WriterCounters,
}

impl MasterState<'_> {
    /// Acts on one message of a worker; an error stops the loop.
    fn handle(&mut self, msg: ToMaster, link: &mut dyn MasterLink) -> Result<(), ServiceError> {
        let (disk, raw) = (
            self.counters.disk.load(Ordering::Relaxed),
            self.counters.raw.load(Ordering::Relaxed),
        );
        match msg {
            ToMaster::Request { worker } => {
                // After a failure, answer every request with "no more work".
                let batch = if self.failure.is_some() || self.stopping {
                    Vec::new()
                } else {
                    self.queue.next_batch()
                };
                link.assign(worker, batch)
            }
            ToMaster::Chunk { chunk } => {
                let rows = chunk.row_ids.len() as u64;
                self.outcome.rows_received += rows;
                let sent = self
                    .tx
                    .send(WriterJob::Chunk(chunk))
                    .map_err(|_| writer_gone());
                self.progress.advance(rows, disk, raw);
                sent
            }
            ToMaster::Piece { chunk } => self
                .tx
                .send(WriterJob::Piece(chunk))
                .map_err(|_| writer_gone()),
            ToMaster::HalfRowsDone { worker, rows } => {
                let count = rows.len() as u64;
                let (ready, work) = match self.frontier.as_mut() {
                    Some(f) => {
                        let work = rows.iter().map(|&i| f.work(i)).sum();
                        (f.finish(&rows), work)
                    }
                    None => (Err("half rows in a run without --symmetric".to_string()), 0),
                };
                self.outcome.rows_received += count;
                self.progress.advance_work(count, work, disk, raw);
                match ready {
                    Ok(blocks) => blocks.into_iter().try_for_each(|j| {
                        self.tx.send(WriterJob::Merge(j)).map_err(|_| writer_gone())
                    }),
                    Err(e) => Err(ServiceError::Transport(format!("worker {worker}: {e}"))),
                }
            }
            ToMaster::Failed { rank, row, message } => {
                // The caller prints the error once; this is for the log at debug level.
                tracing::debug!(rank, row, "worker failed: {message}");
                self.failure
                    .get_or_insert(ServiceError::WorkerFailed { rank, row, message });
                Ok(())
            }
            ToMaster::Done { stats } => {
                self.done += 1;
                self.outcome.workers.push(stats);
                Ok(())
            }
            ToMaster::Alive => Ok(()),
        }
    }
}

fn writer_gone() -> ServiceError {
    ServiceError::Transport("the writer thread stopped (see the file error)".into())
}

/// Open (or resume) the output file and work out what to compute.
///
/// Returns the writer, the plan, and how many rows were already present.
///
/// # Errors
/// The file cannot be created, or (with `resume`) belongs to a different scene or
/// layout.
pub(crate) fn prepare(
    job: &crate::service::ComputeJob,
    min_batch: usize,
) -> Result<(FfzWriter, MasterPlan, u64), ServiceError> {
    use crate::ffz::RowState;
    use crate::service::RowSelection;
    let n = job.patches.len() as u32;
    if !job.resume && !job.overwrite && job.output.exists() {
        return Err(ServiceError::Config(format!(
            "{} already exists: add --resume to complete it (only missing rows are computed), or --force to overwrite it",
            job.output.display()
        )));
    }
    let (writer, presence) = if job.resume && job.output.exists() && !torn_own_header(job)? {
        let (w, p) = FfzWriter::resume(&job.output, &job.meta, job.writer)?;
        for note in w.warnings() {
            eprintln!("ffstream: warning: {note}");
        }
        (w, Some(p))
    } else {
        (FfzWriter::create(&job.output, &job.meta, job.writer)?, None)
    };
    let mut todo = Vec::new();
    let mut skipped = Vec::new();
    let mut present = 0u64;
    for i in 0..n {
        match presence.as_ref().map_or(RowState::Missing, |p| p.get(i)) {
            RowState::Present | RowState::Skipped => present += 1,
            RowState::Missing => {
                if job.rows == RowSelection::Needed && job.patches.patches[i as usize].is_inert() {
                    skipped.push(i);
                } else {
                    todo.push(i);
                }
            }
        }
    }
    let plan = MasterPlan {
        todo,
        skipped,
        schedule: job.schedule,
        min_batch,
        layout: job.meta.layout,
        n,
        zstd_level: job.writer.zstd_level,
        progress: job.progress,
        spill: job
            .symmetric
            .then(|| crate::service::symmetric::spill_path(&job.output)),
        stall: None,
    };
    Ok((writer, plan, present))
}

/// True when the file to resume ends inside its own header ([`crate::ffz::torn_header`]):
/// the run that made it was killed while starting, so starting afresh loses nothing.
fn torn_own_header(job: &crate::service::ComputeJob) -> Result<bool, ServiceError> {
    let torn = crate::ffz::torn_header(&job.output)?;
    if let Some(len) = torn {
        eprintln!(
            "ffstream: warning: {} ends inside its header ({len} bytes; killed while starting): no row can be in it, starting afresh",
            job.output.display()
        );
    }
    Ok(torn.is_some())
}

/// Turn what the master saw into the run's report.
pub(crate) fn report(
    job: &crate::service::ComputeJob,
    plan: &MasterPlan,
    present: u64,
    outcome: MasterOutcome,
) -> crate::service::ComputeReport {
    crate::service::ComputeReport {
        n: job.patches.len(),
        rows_computed: outcome.rows_received,
        rows_skipped: plan.skipped.len() as u64,
        rows_already_present: present,
        wall_seconds: outcome.wall_seconds,
        master_idle_fraction: outcome.idle_seconds / outcome.wall_seconds.max(1e-9),
        bytes_on_disk: outcome.writer.bytes_on_disk,
        spill_bytes: outcome.spill_bytes,
        raw_bytes: outcome.writer.raw_bytes,
        master_peak_rss: crate::service::rss::peak_rss_bytes(),
        workers: outcome.workers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn liveness_counts_only_listening_time_and_forgets_finished_workers() {
        let s = Duration::from_secs;
        let mut l = Liveness::new(3, Some(s(10)));
        l.listened(s(6));
        l.heard(0, false);
        l.heard(1, true); // worker 1 is done: never stalled
        assert_eq!(l.stalled(), None);
        l.listened(s(5)); // worker 2 has been silent 11 s of listening
        assert_eq!(l.stalled(), Some((2, s(11))));
        l.heard(2, false);
        l.heard(0, false);
        assert_eq!(l.stalled(), None);
        l.listened(s(10)); // exactly the limit is not past it
        assert_eq!(l.stalled(), None);
        l.listened(Duration::from_millis(1));
        assert_eq!(l.stalled().map(|(w, _)| w), Some(0));
        assert_eq!(Liveness::new(2, None).stalled(), None, "no limit, no stall");
    }
}
