//! The MPI service: rank 0 is the I/O master and computes nothing; ranks 1..P-1 are
//! workers with `--threads` compute threads each (docs/architecture.md §3).
//!
//! Start-up is collective and explicit, so a bad rank is named before any work starts:
//!
//! 1. every rank builds the job itself (loads the scene, subdivides, builds the Bvh:
//!    milliseconds to seconds, far cheaper than broadcasting the patch table and Bvh, and
//!    it keeps ranks independent);
//! 2. rank 0 gathers `(ok, scene hash, n)` from everyone; a rank that failed sends its
//!    reason (`SETUP`); any failure or hash mismatch aborts with a message naming the rank;
//! 3. rank 0 opens (or resumes) the file and broadcasts the verdict and, for the folded
//!    schedule, the rows to compute;
//! 4. rank 0 runs [`run_master`], the workers [`run_worker`].
//!
//! Errors after start-up: rank 0 prints the one-line cause, finishes the file (so
//! `--resume` can complete it) and calls `MPI_Abort`, which stops every rank with a
//! non-zero exit code. A failed worker, having told rank 0, waits for that abort
//! rather than finalising ([`MpiContext::await_abort`] says why).

mod gather_ranks;
pub(crate) mod links;
pub(crate) mod protocol;

use mpi::collective::Root;
use mpi::environment::Universe;
use mpi::point_to_point::{Destination, Source};
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::Threading;

pub use gather_ranks::run_gather;
use links::{MpiMasterLink, MpiWorkerLink};

use crate::service::master::{prepare, report, run_master};
use crate::service::schedule::{folded_share, Schedule};
use crate::service::worker::{run_worker, WorkerConfig};
use crate::service::{ComputeJob, ComputeReport, ServiceError};

/// True when this process was started by an MPI launcher (mpirun/mpiexec/srun). Without
/// one, ffstream does not initialise MPI at all and runs embedded.
pub fn launched_by_mpi() -> bool {
    [
        "OMPI_COMM_WORLD_SIZE",
        "PMI_SIZE",
        "PMIX_RANK",
        "PMI_RANK",
        "MPI_LOCALNRANKS",
    ]
    .iter()
    .any(|v| std::env::var_os(v).is_some())
}

/// An initialised MPI environment (finalised on drop).
pub struct MpiContext {
    _universe: Universe,
    pub(crate) world: SimpleCommunicator,
}

impl MpiContext {
    /// Initialise MPI with `Threading::Funneled`: compute threads never call MPI; only
    /// the main thread does.
    ///
    /// # Errors
    /// MPI was already initialised, or the library cannot provide Funneled threading.
    pub fn init() -> Result<Self, ServiceError> {
        let (universe, provided) = mpi::initialize_with_threading(Threading::Funneled)
            .ok_or_else(|| ServiceError::Transport("MPI was already initialised".into()))?;
        if provided < Threading::Funneled {
            return Err(ServiceError::Transport(format!(
                "the MPI library provides only {provided:?} threading; ffstream needs Funneled"
            )));
        }
        let world = universe.world();
        Ok(MpiContext {
            _universe: universe,
            world,
        })
    }

    pub fn rank(&self) -> i32 {
        self.world.rank()
    }

    pub fn size(&self) -> i32 {
        self.world.size()
    }

    /// Stop every rank with `code` (after printing the cause).
    pub fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }

    /// For a rank other than 0 that has failed: wait for rank 0's `MPI_Abort` (which
    /// ends this process) instead of finalising. With Open MPI 4.1 and PMIx 3, a rank
    /// that finalises and exits non-zero while rank 0 aborts leaves `mpirun` hung for
    /// good in its own shutdown, every rank already gone: 10 of 160 runs of the
    /// failing-worker job did, none of those that waited (210 when this was written,
    /// 310 by the README's later count). Should no abort come within
    /// `limit` (rank 0 never learnt of this failure), the process exits with code 1
    /// without finalising, and `mpirun` ends the job for that.
    pub fn await_abort(self, limit: std::time::Duration) -> ! {
        std::thread::sleep(limit);
        eprintln!(
            "ffstream: rank {}: no abort from rank 0 within {limit:?}; exiting",
            self.rank()
        );
        // exit runs no destructor: MPI_Finalize is skipped on purpose.
        std::process::exit(1)
    }
}

/// A worker that has sent its last chunk waits for rank 0's `FINISH` before it
/// finalises. Rank 0 may still fail (disk full at the index, another worker stalled or
/// failed) and then calls `MPI_Abort`; with Open MPI 4.1 an abort while a rank sits in
/// `MPI_Finalize` leaves `mpirun` hung in its own teardown (5 of 20 runs of the stalled
/// worker test did before this wait, none after). The wait probes and sleeps, so it
/// costs no core.
fn await_finish(world: &SimpleCommunicator) {
    let root = world.process_at_rank(0);
    let mut nap = std::time::Duration::from_micros(50);
    loop {
        if let Some((msg, _)) = root.immediate_matched_probe_with_tag(protocol::FINISH) {
            let mut nothing: [u8; 0] = [];
            msg.matched_receive_into(&mut nothing[..]);
            return;
        }
        std::thread::sleep(nap);
        nap = (nap * 2).min(std::time::Duration::from_millis(10));
    }
}

/// Collective start-up check. `job` is this rank's attempt to build the job. Returns the
/// job on every rank when all ranks agree.
///
/// # Errors
/// Names the first rank that failed or disagrees.
pub fn agree_on_job(
    ctx: &MpiContext,
    job: Result<ComputeJob, String>,
) -> Result<ComputeJob, ServiceError> {
    let world = &ctx.world;
    let root = world.process_at_rank(0);
    let mine: [u64; 3] = match &job {
        Ok(j) => [1, j.meta.scene_hash, j.patches.len() as u64],
        Err(_) => [0, 0, 0],
    };
    let mut verdict = [0u8; 1]; // 1 = go
    if ctx.rank() == 0 {
        let mut all = vec![0u64; 3 * ctx.size() as usize];
        root.gather_into_root(&mine[..], &mut all[..]);
        let mut problem: Option<ServiceError> = job.as_ref().err().map(|m| ServiceError::Setup {
            rank: 0,
            message: m.clone(),
        });
        for (rank, s) in all.chunks_exact(3).enumerate().skip(1) {
            let rank = rank as i32;
            let e = if s[0] == 0 {
                let (bytes, _) = world
                    .process_at_rank(rank)
                    .receive_vec_with_tag::<u8>(protocol::SETUP);
                Some(ServiceError::Setup {
                    rank,
                    message: String::from_utf8_lossy(&bytes).into_owned(),
                })
            } else if s[1] != mine[1] || s[2] != mine[2] {
                Some(ServiceError::Setup {
                    rank,
                    message: format!(
                        "its scene differs from rank 0's ({} patches, hash {:016x}; rank 0 has {} patches, hash {:016x}): every rank must see the same scene file and options",
                        s[2], s[1], mine[2], mine[1]
                    ),
                })
            } else {
                None
            };
            if problem.is_none() {
                problem = e;
            }
        }
        verdict[0] = problem.is_none() as u8;
        root.broadcast_into(&mut verdict[..]);
        match problem {
            Some(e) => Err(e),
            None => job.map_err(|m| ServiceError::Setup {
                rank: 0,
                message: m,
            }),
        }
    } else {
        root.gather_into(&mine[..]);
        if let Err(m) = &job {
            root.send_with_tag(m.as_bytes(), protocol::SETUP);
        }
        root.broadcast_into(&mut verdict[..]);
        match (verdict[0], job) {
            (1, Ok(j)) => Ok(j),
            (_, Err(m)) => Err(ServiceError::Setup {
                rank: ctx.rank(),
                message: m,
            }),
            (_, Ok(_)) => Err(ServiceError::Setup {
                rank: ctx.rank(),
                message: "stopped: another rank failed to set up (rank 0 says which)".into(),
            }),
        }
    }
}

/// Rank 0: the file is closed; lets the workers finalise (they wait for this word).
fn finish_workers(ctx: &MpiContext) {
    let nothing: [u8; 0] = [];
    for w in 1..ctx.size() {
        ctx.world
            .process_at_rank(w)
            .send_with_tag(&nothing[..], protocol::FINISH);
    }
}

/// Run the streaming service on every rank. Rank 0 returns its report; workers return
/// `None`.
///
/// # Errors
/// As the embedded service; on rank 0 the caller prints the cause and aborts the job
/// (except after a stop by a signal, [`ServiceError::Interrupted`], where every rank
/// has stopped and the workers are already let go).
pub fn run(ctx: &MpiContext, job: &ComputeJob) -> Result<Option<ComputeReport>, ServiceError> {
    let world = &ctx.world;
    let root = world.process_at_rank(0);
    let workers = (ctx.size() - 1) as usize;
    if workers == 0 {
        return Err(ServiceError::Config(
            "mpirun with one rank has no worker: use -n 2 or more, or run without mpirun".into(),
        ));
    }
    if ctx.rank() == 0 {
        let prepared = prepare(job, job.threads.max(1));
        // [ok, rows to broadcast]
        let mut head = [0u32; 2];
        if let Ok((_, plan, _)) = &prepared {
            head[0] = 1;
            head[1] = if plan.schedule == Schedule::Folded || plan.spill.is_some() {
                plan.todo.len() as u32
            } else {
                0
            };
        }
        root.broadcast_into(&mut head[..]);
        let (writer, mut plan, present) = prepared?;
        // The command line bounds --stall-seconds; a library caller's huge value means
        // no limit, not a panic.
        plan.stall = std::time::Duration::try_from_secs_f64(job.stall_seconds).ok();
        if head[1] > 0 {
            let mut todo = plan.todo.clone();
            root.broadcast_into(&mut todo[..]);
        }
        let mut link = MpiMasterLink { world };
        // A stop by a signal ends like a run: every worker has said done and the file
        // is closed. Any other error leaves the workers to the caller's abort.
        let outcome = run_master(&mut link, writer, &plan).inspect_err(|e| {
            if matches!(e, ServiceError::Interrupted { .. }) {
                finish_workers(ctx);
            }
        })?;
        finish_workers(ctx);
        Ok(Some(report(job, &plan, present, outcome)))
    } else {
        let mut head = [0u32; 2];
        root.broadcast_into(&mut head[..]);
        if head[0] == 0 {
            return Err(ServiceError::Setup {
                rank: ctx.rank(),
                message: "stopped: rank 0 could not open the output file".into(),
            });
        }
        // Rank 0 sends the rows of the run when workers need them: the folded schedule
        // splits them statically; `--symmetric` needs to know which rows are in the run.
        let mut todo = vec![0u32; head[1] as usize];
        if head[1] > 0 {
            root.broadcast_into(&mut todo[..]);
        }
        let static_rows = (job.schedule == Schedule::Folded)
            .then(|| folded_share(&todo, workers, (ctx.rank() - 1) as usize));
        let cfg = WorkerConfig::for_job(job, ctx.rank(), &todo);
        let mut link = MpiWorkerLink { world };
        run_worker(job.engine(), &cfg, &mut link, static_rows)?;
        await_finish(world);
        Ok(None)
    }
}
