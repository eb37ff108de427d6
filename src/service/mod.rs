//! The compute service: who computes which rows and how they reach the file.
//!
//! One design serves both launch modes (docs/architecture.md §3):
//!
//! * **Embedded** (no `mpirun`): one process. The calling thread is the I/O master; one
//!   worker driver thread feeds `--threads` compute threads; they talk over bounded
//!   crossbeam channels ([`embedded`]).
//! * **MPI** (`mpirun -n P`, feature `mpi`): rank 0 is the I/O master and computes
//!   nothing; ranks 1..P-1 are workers, each a worker driver on its main thread (the only
//!   thread that calls MPI) plus compute threads ([`mpi`]).
//!
//! Both run the same [`master::run_master`] and [`worker::run_worker`]; only the link
//! between them ([`link::MasterLink`], [`link::WorkerLink`]) differs. Workers compress
//! their own chunks ([`crate::ffz::encode_chunk`]) so the master only appends bytes:
//! its throughput is bounded by the disk, not by its CPU.

pub mod embedded;
pub mod error;
pub mod gather;
pub mod interrupt;
pub(crate) mod job;
pub(crate) mod link;
pub mod master;
#[cfg(feature = "mpi")]
pub mod mpi;
pub(crate) mod progress;
pub mod role;
pub mod rss;
pub mod schedule;
pub mod symmetric;
pub(crate) mod worker;

pub use crate::ffz::PairRoutes;
pub use error::ServiceError;
pub use job::{ComputeJob, ComputeReport, RowSelection, WorkerStats};
pub use role::Role;
pub use schedule::Schedule;
