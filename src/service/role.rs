//! What a process does in a run ([`Role`]) and, under MPI, what a rank does when the
//! run fails ([`after_failure`]: the abort policy). Both are rules of the service, so
//! that every caller (the command line, a test) launches and stops a job alike.

use std::time::Duration;

use super::ServiceError;

/// What a process does in a run, which decides what the job layer builds and says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Computes rows and writes the file: an embedded run, or rank 0 of `--gather`.
    Alone,
    /// Rank 0 of a streaming MPI run: writes the file and computes nothing, so it
    /// builds no occluder hierarchy and no row engine (only what the file header
    /// needs, e.g. the number of occluder triangles).
    Master,
    /// An MPI worker (its rank): computes rows and says nothing of the set-up but
    /// what only an engine knows (the first worker says which convex solids it found).
    Worker(i32),
}

impl Role {
    /// The role of `rank` in an MPI run of more than one rank: with `gather` (the
    /// paper's baseline) rank 0 computes its share too.
    pub fn of_rank(rank: i32, gather: bool) -> Role {
        match (rank, gather) {
            (0, true) => Role::Alone,
            (0, false) => Role::Master,
            (rank, _) => Role::Worker(rank),
        }
    }

    /// Whether this process says what was chosen (the plan, the patches, the
    /// set-up's time): every process but a worker rank.
    pub fn announces(self) -> bool {
        !matches!(self, Role::Worker(_))
    }
}

/// How long a failed rank waits for rank 0 to abort the job (it takes milliseconds:
/// rank 0 finishes the file first) before leaving on its own.
pub const AWAIT_ABORT: Duration = Duration::from_secs(120);

/// How long rank 0 waits after saying why it aborts: on MPI_Abort, Open MPI stops
/// forwarding a rank's stderr, and a message written piece by piece was seen cut
/// after "ffstream: error: rank " (1 run in about 40).
pub const BEFORE_ABORT: Duration = Duration::from_millis(300);

/// What a rank of an MPI run does once its part has failed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AfterFailure {
    /// Every rank has stopped cleanly (a signal) and the file is closed: pass the
    /// error on, abort nothing.
    PassOn,
    /// Rank 0, which has finished the file with what it had: say `message` in one
    /// write, wait [`BEFORE_ABORT`], then abort every rank.
    Abort { message: String },
    /// Any other rank: say `message` if there is one, then wait up to
    /// [`AWAIT_ABORT`] for rank 0 to abort the job.
    AwaitAbort { message: Option<String> },
}

/// The abort policy: what `rank` does after its part of the run failed with `e`.
pub fn after_failure(rank: i32, e: &ServiceError) -> AfterFailure {
    match e {
        ServiceError::Interrupted { .. } => AfterFailure::PassOn,
        _ if rank == 0 => {
            let mut message = format!("ffstream: error: {e}");
            if matches!(
                e,
                ServiceError::WorkerFailed { .. }
                    | ServiceError::WorkerStalled { .. }
                    | ServiceError::Transport(_)
            ) {
                message += "\nffstream: rows written so far are kept: rerun with --resume to complete the file";
            }
            AfterFailure::Abort { message }
        }
        // A failed row was sent to rank 0, which prints it: saying it here too would
        // print it twice.
        ServiceError::WorkerFailed { .. } => AfterFailure::AwaitAbort { message: None },
        ServiceError::Setup { .. } => AfterFailure::AwaitAbort {
            message: Some(format!("ffstream: {e}")),
        },
        _ => AfterFailure::AwaitAbort {
            message: Some(format!("ffstream: rank {rank}: {e}")),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rank_0_aborts_and_says_the_file_can_be_resumed_after_a_worker_failed() {
        let e = ServiceError::Transport("gone".into());
        match after_failure(0, &e) {
            AfterFailure::Abort { message } => {
                assert!(message.ends_with("rerun with --resume to complete the file"))
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            after_failure(2, &e),
            AfterFailure::AwaitAbort {
                message: Some(format!("ffstream: rank 2: {e}"))
            }
        );
        assert_eq!(
            after_failure(0, &ServiceError::Interrupted { signal: 15 }),
            AfterFailure::PassOn
        );
        assert_eq!(Role::of_rank(0, false), Role::Master);
        assert_eq!(Role::of_rank(0, true), Role::Alone);
        assert!(!Role::of_rank(3, false).announces());
    }
}
