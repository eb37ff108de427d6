//! The link between the I/O master and its workers, behind two traits so the same
//! master and worker code runs over crossbeam channels (embedded) and MPI.

use std::time::Duration;

use crate::ffz::EncodedChunk;
use crate::service::{ServiceError, WorkerStats};

/// A message a worker sends to the master.
#[derive(Debug)]
pub(crate) enum ToMaster {
    /// Worker `worker` wants more rows (dynamic schedule).
    Request { worker: usize },
    /// Compressed rows, ready to append.
    Chunk { chunk: EncodedChunk },
    /// `--symmetric`: a piece of partial rows for the spill (service::symmetric).
    Piece { chunk: EncodedChunk },
    /// `--symmetric`: these half rows are complete (all their pieces were sent before).
    HalfRowsDone { worker: usize, rows: Vec<u32> },
    /// The worker failed, computing `row` if any.
    Failed {
        rank: i32,
        row: Option<u32>,
        message: String,
    },
    /// The worker computed all its rows and sent every chunk.
    Done { stats: WorkerStats },
    /// Nothing else to say for a while: the worker is alive (the liveness limit,
    /// `--stall-seconds`, counts the time since a worker's last message of any kind).
    Alive,
}

/// The master's side of the link.
pub(crate) trait MasterLink {
    /// Number of workers (embedded: 1 pool; MPI: P-1 ranks).
    fn workers(&self) -> usize;
    /// Wait up to `timeout` for the next message and the worker (0-based) that sent it.
    /// Waiting must not burn a core: the master shares the machine with compute threads.
    fn poll(&mut self, timeout: Duration) -> Result<Option<(usize, ToMaster)>, ServiceError>;
    /// The rank of `worker`, for messages (MPI: worker + 1; embedded: 0).
    fn rank_of(&self, worker: usize) -> i32;
    /// Give `rows` to `worker`; an empty list means "no more work".
    fn assign(&mut self, worker: usize, rows: Vec<u32>) -> Result<(), ServiceError>;
}

/// A worker's side of the link.
pub(crate) trait WorkerLink {
    /// Ask for more rows (dynamic schedule); the answer arrives via `try_assignment`.
    fn request(&mut self) -> Result<(), ServiceError>;
    /// The answer to the last request if it has arrived; `Some(vec![])` = no more work.
    fn try_assignment(&mut self) -> Result<Option<Vec<u32>>, ServiceError>;
    fn send_chunk(&mut self, chunk: EncodedChunk) -> Result<(), ServiceError>;
    /// `--symmetric`: a spill piece; then, after a row's pieces, `half_rows_done`.
    fn send_piece(&mut self, piece: EncodedChunk) -> Result<(), ServiceError>;
    fn half_rows_done(&mut self, rows: Vec<u32>) -> Result<(), ServiceError>;
    fn failed(&mut self, row: Option<u32>, message: &str) -> Result<(), ServiceError>;
    fn done(&mut self, stats: WorkerStats) -> Result<(), ServiceError>;
    /// Tell the master this worker is alive (sent when it has said nothing else for a
    /// while, see [`ToMaster::Alive`]).
    fn alive(&mut self) -> Result<(), ServiceError>;
}
