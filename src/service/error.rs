//! Errors of the compute service (transport and coordination).

use crate::ffz::FfzError;

/// What can go wrong while computing and streaming rows.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The file layer failed (the path is in the inner error).
    #[error(transparent)]
    File(#[from] FfzError),
    /// A worker reported a failure; the run was stopped.
    #[error("rank {rank}: {}{message}", row.map_or(String::new(), |r| format!("row {r}: ")))]
    WorkerFailed {
        rank: i32,
        /// The row being computed, if any.
        row: Option<u32>,
        message: String,
    },
    /// A worker sent nothing, not even its heartbeat, for longer than the liveness
    /// limit (`--stall-seconds`): stopped (SIGSTOP), hung, or its node lost.
    #[error("rank {rank} has sent nothing for {seconds:.0} s (the --stall-seconds limit): it is stopped, hung or lost; the job was ended")]
    WorkerStalled { rank: i32, seconds: f64 },
    /// A worker could not set up (scene missing, different scene, ...).
    #[error("rank {rank}: {message}")]
    Setup { rank: i32, message: String },
    /// The link between master and workers broke (a thread or rank went away).
    #[error("transport: {0}")]
    Transport(String),
    /// SIGINT or SIGTERM asked the run to stop ([`super::interrupt`]): the rows
    /// finished before it are in the file, which is closed with its index.
    #[error("stopped by {}: the rows finished before it are in the file, which is closed and indexed; the same command with --resume computes the rest", super::interrupt::signal_name(*signal))]
    Interrupted { signal: i32 },
    /// The job's settings are inconsistent.
    #[error("{0}")]
    Config(String),
}
