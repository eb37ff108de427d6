//! The worker driver: one per embedded process or MPI worker rank.
//!
//! Its thread is the only one that talks to the master (for MPI: the only thread that
//! calls MPI, `Threading::Funneled`). It feeds row ids to `threads` compute threads over
//! a crossbeam channel; each compute thread computes rows with the shared
//! [`RowEngine`], gathers them into a chunk and compresses it itself (so the master only
//! appends bytes), then hands the chunk back to the driver, which forwards it.
//!
//! A compute thread flushes its pending rows when they reach the chunk size or when
//! `flush_seconds` have passed, so a killed run loses at most that much work per thread.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam::channel::{bounded, unbounded, Receiver, RecvTimeoutError, Sender};

use crate::ffz::{encode_chunk, raw_row_len, EncodedChunk, Layout};
use crate::formfactor::{RowEngine, Scratch};
use crate::rows::Row;
use crate::service::job::LinkErrors;
use crate::service::link::WorkerLink;
use crate::service::rss::peak_rss_bytes;
use crate::service::symmetric::{in_run, HalfRowBuffer, PIECE_ZSTD_LEVEL};
use crate::service::{ComputeJob, PairRoutes, ServiceError, WorkerStats};

/// Environment variable that makes a worker fail on purpose when it reaches this row
/// (fault-injection for tests of the failure path; read only with the `test-hooks`
/// feature, tests/README.md).
#[cfg(feature = "test-hooks")]
pub(crate) const FAIL_ROW_ENV: &str = "FFSTREAM_FAIL_ROW";

/// Environment variable that makes the worker process that reaches this row stop
/// itself with SIGSTOP, as an operator's `kill -STOP` would (a hung or lost rank looks
/// the same to rank 0): for the test of the liveness limit, `--stall-seconds`. Read
/// only with the `test-hooks` feature.
#[cfg(feature = "test-hooks")]
pub(crate) const STOP_ROW_ENV: &str = "FFSTREAM_TEST_STOP_ROW";

/// How one worker runs.
#[derive(Clone, Debug)]
pub(crate) struct WorkerConfig {
    pub(crate) rank: i32,
    pub(crate) threads: usize,
    pub(crate) layout: Layout,
    pub(crate) n: u32,
    pub(crate) zstd_level: i32,
    /// Target uncompressed bytes per chunk.
    pub(crate) chunk_bytes: usize,
    pub(crate) flush_seconds: f64,
    /// `--symmetric`: compute half rows; `in_run[i]` says whether row i is computed in
    /// this run (see [`RowEngine::half_row`]).
    pub(crate) symmetric: Option<Arc<Vec<bool>>>,
    /// The driver tells the master it is alive when it has sent nothing for this long.
    pub(crate) heartbeat: Duration,
}

impl WorkerConfig {
    /// The configuration of worker `rank` for `job`, whose run computes the rows `todo`
    /// (needed with `--symmetric`, where a half row depends on which rows are in the run).
    pub(crate) fn for_job(job: &ComputeJob, rank: i32, todo: &[u32]) -> Self {
        let n = job.patches.len() as u32;
        WorkerConfig {
            rank,
            threads: job.threads.max(1),
            layout: job.meta.layout,
            n,
            zstd_level: job.writer.zstd_level,
            chunk_bytes: job.writer.chunk_bytes,
            flush_seconds: job.flush_seconds,
            symmetric: job.symmetric.then(|| Arc::new(in_run(todo, n))),
            heartbeat: heartbeat(job.stall_seconds),
        }
    }
}

/// How often a quiet worker says it is alive, for a liveness limit of `stall_seconds`:
/// four times per limit, at least every 5 s (tiny messages; a thousand ranks send a few
/// hundred a second at most), and no more often than every 50 ms.
fn heartbeat(stall_seconds: f64) -> Duration {
    Duration::try_from_secs_f64((stall_seconds / 4.0).clamp(0.05, 5.0))
        .unwrap_or(Duration::from_secs(5))
}

/// What a compute thread hands back to the driver.
enum FromCompute {
    Chunk(EncodedChunk),
    /// `--symmetric`: pieces for the spill, then the half rows they complete.
    Pieces {
        pieces: Vec<EncodedChunk>,
        rows: Vec<u32>,
    },
    Failed {
        row: Option<u32>,
        message: String,
    },
}

/// Compute rows until the master says there are no more (dynamic), or `static_rows`
/// are all done (folded), forwarding compressed chunks over `link`.
///
/// # Errors
/// A failed row (reported to the master first) or a broken link.
pub(crate) fn run_worker(
    engine: &RowEngine,
    cfg: &WorkerConfig,
    link: &mut dyn WorkerLink,
    static_rows: Option<Vec<u32>>,
) -> Result<WorkerStats, ServiceError> {
    let _span = tracing::info_span!("worker", rank = cfg.rank, threads = cfg.threads).entered();
    let faults = Faults::from_env();
    let threads = cfg.threads.max(1);
    let (jobs_tx, jobs_rx) = unbounded::<u32>();
    let (out_tx, out_rx) = bounded::<FromCompute>(2 * threads);
    let computed = AtomicU64::new(0);
    let busy_nanos = AtomicU64::new(0);
    let stop = AtomicBool::new(false);
    let pairs = Mutex::new(PairRoutes::default());
    let links = Mutex::new(LinkErrors::default());

    let result = std::thread::scope(|s| {
        for t in 0..threads {
            let jobs_rx = jobs_rx.clone();
            let out_tx = out_tx.clone();
            let counters = WorkerTally {
                computed: &computed,
                busy_nanos: &busy_nanos,
                stop: &stop,
                pairs: &pairs,
                links: &links,
            };
            std::thread::Builder::new()
                .name(format!("compute-{t}"))
                .spawn_scoped(s, move || {
                    compute_thread(engine, cfg, faults, &jobs_rx, &out_tx, counters)
                })
                .map_err(|e| {
                    ServiceError::Transport(format!("cannot start a compute thread: {e}"))
                })?;
        }
        drop(out_tx);
        // `out_rx` moves into the driver and is dropped when it returns: on an error the
        // compute threads then see closed channels and `stop`, and exit promptly.
        let driven = drive(cfg, link, jobs_tx, out_rx, &computed, static_rows);
        stop.store(true, Ordering::Relaxed);
        driven
    });

    let stats = WorkerStats {
        rank: cfg.rank,
        rows: computed.load(Ordering::Relaxed),
        busy_seconds: busy_nanos.load(Ordering::Relaxed) as f64 * 1e-9,
        threads: threads as u32,
        peak_rss: peak_rss_bytes(),
        pairs: *pairs.lock().unwrap_or_else(|e| e.into_inner()),
        links: *links.lock().unwrap_or_else(|e| e.into_inner()),
    };
    result?;
    link.done(stats.clone())?;
    Ok(stats)
}

/// The driver loop: hand out rows, forward chunks, ask for more before threads starve.
fn drive(
    cfg: &WorkerConfig,
    link: &mut dyn WorkerLink,
    jobs_tx: Sender<u32>,
    out_rx: Receiver<FromCompute>,
    computed: &AtomicU64,
    static_rows: Option<Vec<u32>>,
) -> Result<(), ServiceError> {
    let mut jobs_tx = Some(jobs_tx);
    let mut assigned = 0u64;
    let mut requested = false;
    let low_water = 2 * cfg.threads.max(1) as u64;
    // When the driver last sent anything: a quiet worker (long rows) says it is alive.
    let mut last_word = Instant::now();
    if let Some(rows) = static_rows {
        if let Some(tx) = jobs_tx.take() {
            for r in rows {
                // The receivers live until every job is taken: send cannot fail here.
                let _ = tx.send(r);
            }
        }
    }
    loop {
        if let Some(tx) = &jobs_tx {
            if !requested && assigned.saturating_sub(computed.load(Ordering::Relaxed)) <= low_water
            {
                link.request()?;
                requested = true;
                last_word = Instant::now();
            }
            if requested {
                if let Some(rows) = link.try_assignment()? {
                    requested = false;
                    if rows.is_empty() {
                        jobs_tx = None; // no more work: threads flush and exit
                    } else {
                        assigned += rows.len() as u64;
                        for r in rows {
                            let _ = tx.send(r);
                        }
                    }
                }
            }
        }
        match out_rx.recv_timeout(Duration::from_millis(2)) {
            Ok(FromCompute::Chunk(chunk)) => {
                link.send_chunk(chunk)?;
                last_word = Instant::now();
            }
            Ok(FromCompute::Pieces { pieces, rows }) => {
                for p in pieces {
                    link.send_piece(p)?;
                }
                link.half_rows_done(rows)?;
                last_word = Instant::now();
            }
            Ok(FromCompute::Failed { row, message }) => {
                link.failed(row, &message)?;
                return Err(ServiceError::WorkerFailed {
                    rank: cfg.rank,
                    row,
                    message,
                });
            }
            Err(RecvTimeoutError::Timeout) => {
                if last_word.elapsed() >= cfg.heartbeat {
                    link.alive()?;
                    last_word = Instant::now();
                }
            }
            Err(RecvTimeoutError::Disconnected) => return Ok(()), // every thread finished
        }
    }
}

/// Faults injected on purpose by the test hooks `FFSTREAM_FAIL_ROW` and
/// `FFSTREAM_TEST_STOP_ROW` (`test-hooks` feature).
#[derive(Clone, Copy)]
struct Faults {
    fail_row: Option<u32>,
    stop_row: Option<u32>,
}

impl Faults {
    /// The faults the environment asks for, with the `test-hooks` feature; none
    /// without it (the product binary reads no test variable).
    fn from_env() -> Self {
        #[cfg(feature = "test-hooks")]
        {
            let row_of = |var: &str| -> Option<u32> { std::env::var(var).ok()?.parse().ok() };
            Faults {
                fail_row: row_of(FAIL_ROW_ENV),
                stop_row: row_of(STOP_ROW_ENV),
            }
        }
        #[cfg(not(feature = "test-hooks"))]
        Faults {
            fail_row: None,
            stop_row: None,
        }
    }
}

/// `FFSTREAM_TEST_STOP_ROW`: stop this whole process with SIGSTOP, as `kill -STOP` would.
fn stop_process() {
    #[cfg(unix)]
    // SAFETY: raise(3) with a valid signal number has no memory-safety preconditions.
    unsafe {
        libc::raise(libc::SIGSTOP);
    }
}

/// The tallies shared by the compute threads of one worker (rows done, busy time).
#[derive(Clone, Copy)]
struct WorkerTally<'a> {
    computed: &'a AtomicU64,
    busy_nanos: &'a AtomicU64,
    /// Set when the driver gave up: threads stop taking rows.
    stop: &'a AtomicBool,
    /// The pair counts of every thread, added when it finishes.
    pairs: &'a Mutex<PairRoutes>,
    /// The link errors of every thread's rows, added when it finishes.
    links: &'a Mutex<LinkErrors>,
}

/// What a compute thread has computed and not yet handed to the driver.
enum Pending {
    /// Whole rows, compressed into one chunk when flushed.
    Rows { rows: Vec<Row>, bytes: usize },
    /// `--symmetric`: half rows bucketed by destination block.
    Half {
        buf: HalfRowBuffer,
        in_run: Arc<Vec<bool>>,
        own: Vec<(u32, f64)>,
        mirrored: Vec<(u32, f64)>,
    },
}

impl Pending {
    fn new(cfg: &WorkerConfig) -> Self {
        match &cfg.symmetric {
            Some(in_run) => Pending::Half {
                buf: HalfRowBuffer::new(cfg.n),
                in_run: Arc::clone(in_run),
                own: Vec::new(),
                mirrored: Vec::new(),
            },
            None => Pending::Rows {
                rows: Vec::new(),
                bytes: 0,
            },
        }
    }

    /// Compute row i (or its half) into the pending work; its link error, if any.
    fn compute(&mut self, engine: &RowEngine, i: u32, scratch: &mut Scratch) -> Option<f32> {
        match self {
            Pending::Rows { rows, bytes } => {
                let row = engine.compute_row(i, scratch);
                *bytes += raw_row_len(&row);
                let error = row.link_error;
                rows.push(row);
                error
            }
            Pending::Half {
                buf,
                in_run,
                own,
                mirrored,
            } => {
                engine.half_row(i, in_run, scratch, own, mirrored);
                buf.add(i, own, mirrored);
                None
            }
        }
    }

    fn is_empty(&self) -> bool {
        match self {
            Pending::Rows { rows, .. } => rows.is_empty(),
            Pending::Half { buf, .. } => buf.rows() == 0,
        }
    }

    /// Whether the pending work has reached its flush size: one chunk of rows, or for
    /// half rows four chunks' worth (spread over many blocks, so pieces stay large).
    fn full(&self, chunk_bytes: usize) -> bool {
        match self {
            Pending::Rows { bytes, .. } => *bytes >= chunk_bytes,
            Pending::Half { buf, .. } => buf.pending_bytes() >= 4 * chunk_bytes,
        }
    }

    /// Compress the pending work into the message for the driver.
    fn flush(&mut self, cfg: &WorkerConfig) -> FromCompute {
        match self {
            Pending::Rows { rows, bytes } => {
                let msg = match encode_chunk(rows, cfg.layout, cfg.n, cfg.zstd_level) {
                    Ok(chunk) => FromCompute::Chunk(chunk),
                    Err(e) => FromCompute::Failed {
                        row: Some(rows[0].index),
                        message: e.to_string(),
                    },
                };
                rows.clear();
                *bytes = 0;
                msg
            }
            Pending::Half { buf, .. } => match buf.flush(PIECE_ZSTD_LEVEL) {
                Ok((pieces, rows)) => FromCompute::Pieces { pieces, rows },
                Err(e) => FromCompute::Failed {
                    row: None,
                    message: e.to_string(),
                },
            },
        }
    }
}

/// One compute thread: rows in, compressed chunks (or spill pieces) out. Leaves the
/// loop when the rows run out, the driver stops or a row fails, then adds its pair
/// counts to the worker's.
fn compute_thread(
    engine: &RowEngine,
    cfg: &WorkerConfig,
    faults: Faults,
    jobs: &Receiver<u32>,
    out: &Sender<FromCompute>,
    counters: WorkerTally<'_>,
) {
    let WorkerTally {
        computed,
        busy_nanos,
        stop,
        pairs,
        links,
    } = counters;
    let mut errors = LinkErrors::default();
    let mut scratch = Scratch::default();
    let mut pending = Pending::new(cfg);
    let mut oldest: Option<Instant> = None;
    // The command line bounds --flush-seconds; a library caller's huge value means
    // "never", not a panic.
    let flush_after =
        Duration::try_from_secs_f64(cfg.flush_seconds.max(0.01)).unwrap_or(Duration::MAX);
    loop {
        let wait = oldest.map_or(flush_after, |t| flush_after.saturating_sub(t.elapsed()));
        let (next, finished) = match jobs.recv_timeout(wait) {
            Ok(i) => (Some(i), false),
            Err(RecvTimeoutError::Timeout) => (None, false),
            Err(RecvTimeoutError::Disconnected) => (None, true),
        };
        if stop.load(Ordering::Relaxed) {
            break;
        }
        // A stop asked for by a signal: no new row; what is finished is handed over.
        let interrupted = super::interrupt::interrupted().is_some();
        let finished = finished || interrupted;
        if let Some(i) = next.filter(|_| !interrupted) {
            let t0 = Instant::now();
            if faults.stop_row == Some(i) {
                stop_process();
            }
            let done = if faults.fail_row == Some(i) {
                Err(format!("failure injected by a test hook at row {i}"))
            } else {
                catch_unwind(AssertUnwindSafe(|| {
                    pending.compute(engine, i, &mut scratch)
                }))
                .map_err(|p| panic_message(p.as_ref()))
            };
            busy_nanos.fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
            if let Err(message) = done {
                let _ = out.send(FromCompute::Failed {
                    row: Some(i),
                    message,
                });
                break;
            }
            if let Ok(Some(e)) = done {
                errors.add(i, e);
            }
            oldest.get_or_insert_with(Instant::now);
            computed.fetch_add(1, Ordering::Relaxed);
        }
        let due = oldest.is_some_and(|t| t.elapsed() >= flush_after);
        if !pending.is_empty() && (finished || due || pending.full(cfg.chunk_bytes)) {
            let msg = pending.flush(cfg);
            oldest = None;
            if out.send(msg).is_err() {
                break; // the driver stopped (failure elsewhere)
            }
        }
        if finished {
            break;
        }
    }
    pairs
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .add(&PairRoutes::of(&scratch.counters()));
    links
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .merge(&errors);
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        format!("panic: {s}")
    } else if let Some(s) = p.downcast_ref::<String>() {
        format!("panic: {s}")
    } else {
        "panic".to_string()
    }
}
