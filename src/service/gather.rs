//! The `--gather` baseline (the paper's design) shared by the embedded and MPI modes:
//! compute rows as `f64`, hold the whole dense matrix in memory, write it at the end.
//! It exists to be measured against the streaming design; see `mpi/gather_ranks.rs` for the
//! MPI variant.

use crate::ffz::FfzWriter;
use crate::formfactor::Scratch;
use crate::rows::Row;
use crate::service::rss::peak_rss_bytes;
use crate::service::{ComputeJob, ComputeReport, ServiceError};

/// Compute `rows` on `job.threads` threads; call `sink(i, row_as_f64)` for each, on the
/// calling thread.
pub(crate) fn compute_rows_f64(job: &ComputeJob, rows: &[u32], mut sink: impl FnMut(u32, &[f64])) {
    let threads = job.threads.max(1);
    let n = job.patches.len();
    let (tx, rx) = crossbeam::channel::bounded::<(u32, Vec<f64>)>(2 * threads);
    let (jobs_tx, jobs_rx) = crossbeam::channel::unbounded::<u32>();
    for &r in rows {
        let _ = jobs_tx.send(r);
    }
    drop(jobs_tx);
    std::thread::scope(|s| {
        for _ in 0..threads {
            let (tx, jobs_rx) = (tx.clone(), jobs_rx.clone());
            let engine = job.engine();
            s.spawn(move || {
                let mut scratch = Scratch::default();
                for i in jobs_rx {
                    let row = engine.compute_row(i, &mut scratch);
                    let dense: Vec<f64> = row.to_dense(n).into_iter().map(f64::from).collect();
                    if tx.send((i, dense)).is_err() {
                        return;
                    }
                }
            });
        }
        drop(tx);
        for (i, row) in rx {
            sink(i, &row);
        }
    });
}

/// Write a dense `f64` matrix (rows of n) to `job.output` as f32 rows, at the end of the
/// run, as the paper did.
///
/// # Errors
/// File errors.
pub(crate) fn write_dense(job: &ComputeJob, matrix: &[f64]) -> Result<ComputeReport, ServiceError> {
    let n = job.patches.len();
    if !job.overwrite && job.output.exists() {
        return Err(ServiceError::Config(format!(
            "{} already exists: add --force to overwrite it",
            job.output.display()
        )));
    }
    let mut writer = FfzWriter::create(&job.output, &job.meta, job.writer)?;
    for i in 0..n {
        let vals: Vec<f32> = matrix[i * n..(i + 1) * n]
            .iter()
            .map(|&x| x as f32)
            .collect();
        writer.push_row(Row::dense(i as u32, vals))?;
    }
    let stats = writer.finish()?;
    Ok(ComputeReport {
        n,
        rows_computed: n as u64,
        bytes_on_disk: stats.bytes_on_disk,
        raw_bytes: stats.raw_bytes,
        master_peak_rss: peak_rss_bytes(),
        ..ComputeReport::default()
    })
}

/// The embedded gather baseline: one process computes every row into the dense matrix.
///
/// # Errors
/// File errors.
pub fn run_gather_embedded(job: &ComputeJob) -> Result<ComputeReport, ServiceError> {
    let start = std::time::Instant::now();
    let n = job.patches.len();
    let mut matrix = vec![0f64; n * n];
    let all: Vec<u32> = (0..n as u32).collect();
    compute_rows_f64(job, &all, |i, row| {
        matrix[i as usize * n..(i as usize + 1) * n].copy_from_slice(row)
    });
    let mut report = write_dense(job, &matrix)?;
    report.wall_seconds = start.elapsed().as_secs_f64();
    Ok(report)
}
