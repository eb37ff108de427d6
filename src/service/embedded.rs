//! Embedded mode: the whole service in one process. The calling thread runs the I/O
//! master, one thread runs the worker driver with its compute threads, and they talk
//! over bounded crossbeam channels (the same master and worker code as under MPI).

use std::time::Duration;

use crossbeam::channel::{bounded, Receiver, RecvTimeoutError, Sender, TryRecvError};

use crate::ffz::EncodedChunk;
use crate::service::link::{MasterLink, ToMaster, WorkerLink};
use crate::service::master::{prepare, report, run_master};
use crate::service::schedule::{folded_share, Schedule};
use crate::service::worker::{run_worker, WorkerConfig};
use crate::service::{ComputeJob, ComputeReport, ServiceError, WorkerStats};

struct MasterSide {
    rx: Receiver<ToMaster>,
    assign_tx: Sender<Vec<u32>>,
}

impl MasterLink for MasterSide {
    fn workers(&self) -> usize {
        1
    }

    fn poll(&mut self, timeout: Duration) -> Result<Option<(usize, ToMaster)>, ServiceError> {
        match self.rx.recv_timeout(timeout) {
            Ok(m) => Ok(Some((0, m))),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(ServiceError::Transport(
                "the compute pool stopped without reporting".into(),
            )),
        }
    }

    fn rank_of(&self, _worker: usize) -> i32 {
        0
    }

    fn assign(&mut self, _worker: usize, rows: Vec<u32>) -> Result<(), ServiceError> {
        // A pool that has hung up always says why first: its `Failed` (or `Done`)
        // message is already queued on `rx`, and the next `poll` delivers it (or reports
        // a pool that vanished without a word). Failing here instead would race that
        // message and replace the named row with a vague transport error.
        let _ = self.assign_tx.send(rows);
        Ok(())
    }
}

struct WorkerSide {
    tx: Sender<ToMaster>,
    assign_rx: Receiver<Vec<u32>>,
}

impl WorkerSide {
    fn send(&self, m: ToMaster) -> Result<(), ServiceError> {
        self.tx
            .send(m)
            .map_err(|_| ServiceError::Transport("the I/O master stopped".into()))
    }
}

impl WorkerLink for WorkerSide {
    fn request(&mut self) -> Result<(), ServiceError> {
        self.send(ToMaster::Request { worker: 0 })
    }

    fn try_assignment(&mut self) -> Result<Option<Vec<u32>>, ServiceError> {
        match self.assign_rx.try_recv() {
            Ok(rows) => Ok(Some(rows)),
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => {
                Err(ServiceError::Transport("the I/O master stopped".into()))
            }
        }
    }

    fn send_chunk(&mut self, chunk: EncodedChunk) -> Result<(), ServiceError> {
        self.send(ToMaster::Chunk { chunk })
    }

    fn send_piece(&mut self, chunk: EncodedChunk) -> Result<(), ServiceError> {
        self.send(ToMaster::Piece { chunk })
    }

    fn half_rows_done(&mut self, rows: Vec<u32>) -> Result<(), ServiceError> {
        self.send(ToMaster::HalfRowsDone { worker: 0, rows })
    }

    fn failed(&mut self, row: Option<u32>, message: &str) -> Result<(), ServiceError> {
        self.send(ToMaster::Failed {
            rank: 0,
            row,
            message: message.to_string(),
        })
    }

    fn done(&mut self, stats: WorkerStats) -> Result<(), ServiceError> {
        self.send(ToMaster::Done { stats })
    }

    fn alive(&mut self) -> Result<(), ServiceError> {
        self.send(ToMaster::Alive)
    }
}

/// Run a compute job in this process.
///
/// # Errors
/// As [`run_master`]: file errors, a failed row. The file stays recoverable.
pub fn run_embedded(job: &ComputeJob) -> Result<ComputeReport, ServiceError> {
    let threads = job.threads.max(1);
    let (writer, plan, present) = prepare(job, threads)?;
    let (tx, rx) = bounded(2 * threads + 2);
    let (assign_tx, assign_rx) = bounded(1);
    let cfg = WorkerConfig::for_job(job, 0, &plan.todo);
    let static_rows = (plan.schedule == Schedule::Folded).then(|| folded_share(&plan.todo, 1, 0));
    let engine = job.engine().clone();
    let pool = std::thread::Builder::new()
        .name("worker-driver".into())
        .spawn(move || {
            let mut link = WorkerSide { tx, assign_rx };
            run_worker(&engine, &cfg, &mut link, static_rows)
        })
        .map_err(|e| ServiceError::Transport(format!("cannot start the worker thread: {e}")))?;
    let mut link = MasterSide { rx, assign_tx };
    let outcome = run_master(&mut link, writer, &plan);
    drop(link); // unblocks the pool if the master stopped early
    let pool_result = pool
        .join()
        .map_err(|_| ServiceError::Transport("the worker thread panicked".into()))?;
    let outcome = outcome?;
    pool_result?;
    Ok(report(job, &plan, present, outcome))
}
