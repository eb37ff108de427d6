//! The `--gather` baseline under MPI: the paper's design, kept honest and simple so the
//! streaming service can be measured against it.
//!
//! Every rank, rank 0 included, computes its static folded share of the rows. Workers
//! send each row as `f64` with a blocking send (`GATHER_ROW`, row id in the payload);
//! rank 0 first computes its own share, then receives every other row with blocking
//! receives into a dense n×n `f64` matrix held in memory, and writes the file at the end.

use mpi::point_to_point::{Destination, Source};
use mpi::topology::Communicator;

use super::protocol as p;
use super::MpiContext;
use crate::service::gather::{compute_rows_f64, write_dense};
use crate::service::schedule::folded_share;
use crate::service::{ComputeJob, ComputeReport, ServiceError};

/// Run the gather baseline on every rank; rank 0 returns the report.
///
/// # Errors
/// File errors at rank 0; a malformed row message.
pub fn run_gather(
    ctx: &MpiContext,
    job: &ComputeJob,
) -> Result<Option<ComputeReport>, ServiceError> {
    let start = std::time::Instant::now();
    let n = job.patches.len();
    let all: Vec<u32> = (0..n as u32).collect();
    let size = ctx.size() as usize;
    let mine = folded_share(&all, size, ctx.rank() as usize);
    let world = &ctx.world;
    if ctx.rank() != 0 {
        let mut buf = vec![0u8; 4 + 8 * n];
        compute_rows_f64(job, &mine, |i, row| {
            buf[..4].copy_from_slice(&i.to_le_bytes());
            for (k, x) in row.iter().enumerate() {
                buf[4 + 8 * k..12 + 8 * k].copy_from_slice(&x.to_le_bytes());
            }
            world
                .process_at_rank(0)
                .send_with_tag(&buf[..], p::GATHER_ROW);
        });
        return Ok(None);
    }
    let _span = tracing::info_span!("gather_master", n).entered();
    let mut matrix = vec![0f64; n * n];
    compute_rows_f64(job, &mine, |i, row| {
        matrix[i as usize * n..(i as usize + 1) * n].copy_from_slice(row)
    });
    let mut buf = vec![0u8; 4 + 8 * n];
    let t_wait = std::time::Instant::now();
    for _ in 0..n - mine.len() {
        let status = world
            .any_process()
            .receive_into_with_tag(&mut buf[..], p::GATHER_ROW);
        let i = u32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]) as usize;
        if i >= n {
            return Err(ServiceError::Transport(format!(
                "rank {} sent row {i} of {n}",
                status.source_rank()
            )));
        }
        for (k, x) in matrix[i * n..(i + 1) * n].iter_mut().enumerate() {
            let o = 4 + 8 * k;
            *x = f64::from_le_bytes([
                buf[o],
                buf[o + 1],
                buf[o + 2],
                buf[o + 3],
                buf[o + 4],
                buf[o + 5],
                buf[o + 6],
                buf[o + 7],
            ]);
        }
    }
    let receive_seconds = t_wait.elapsed().as_secs_f64();
    let mut report = write_dense(job, &matrix)?;
    report.wall_seconds = start.elapsed().as_secs_f64();
    report.master_idle_fraction = receive_seconds / report.wall_seconds.max(1e-9);
    Ok(Some(report))
}
