//! Progress of a compute run at the I/O master: rows done / total, rows/s, ETA, MB
//! written, compression ratio.
//!
//! On a terminal it draws an indicatif bar; otherwise (batch jobs, CI logs) it prints one
//! line every `log_every` seconds. Nothing is shown for runs shorter than a second.

use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub struct Progress {
    enabled: bool,
    total: u64,
    done: u64,
    start: Instant,
    bar: Option<ProgressBar>,
    last_line: Instant,
    log_every: Duration,
    is_terminal: bool,
    lines: u64,
}

impl Progress {
    pub fn new(total: u64, enabled: bool) -> Self {
        use std::io::IsTerminal;
        let now = Instant::now();
        Progress {
            enabled,
            total,
            done: 0,
            start: now,
            bar: None,
            last_line: now,
            log_every: Duration::from_secs(10),
            is_terminal: std::io::stderr().is_terminal(),
            lines: 0,
        }
    }

    /// `rows` more rows are done; `disk`/`raw` are the file's bytes so far.
    pub fn advance(&mut self, rows: u64, disk: u64, raw: u64) {
        self.done += rows;
        if !self.enabled {
            return;
        }
        let elapsed = self.start.elapsed();
        if elapsed < Duration::from_secs(1) {
            return;
        }
        let msg = self.message(disk, raw);
        if self.is_terminal {
            let bar = self.bar.get_or_insert_with(|| {
                let bar =
                    ProgressBar::with_draw_target(Some(self.total), ProgressDrawTarget::stderr());
                bar.set_style(
                    ProgressStyle::with_template(
                        "{bar:30} {pos}/{len} rows {per_sec} ETA {eta} {msg}",
                    )
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                bar
            });
            bar.set_position(self.done);
            bar.set_message(msg);
        } else if self.lines == 0 || self.last_line.elapsed() >= self.log_every {
            // Not a terminal (batch job, log file): a first line after a second, then one
            // line every `log_every`.
            self.lines += 1;
            self.last_line = Instant::now();
            eprintln!("{}", self.line(disk, raw));
        }
    }

    fn message(&self, disk: u64, raw: u64) -> String {
        let ratio = if disk > 0 {
            raw as f64 / disk as f64
        } else {
            0.0
        };
        format!("{:.1} MB written, ratio {:.2}", disk as f64 / 1e6, ratio)
    }

    fn line(&self, disk: u64, raw: u64) -> String {
        let secs = self.start.elapsed().as_secs_f64();
        let rate = self.done as f64 / secs.max(1e-9);
        let eta = if rate > 0.0 {
            (self.total.saturating_sub(self.done)) as f64 / rate
        } else {
            f64::NAN
        };
        format!(
            "progress: {}/{} rows ({:.1}%), {:.1} rows/s, ETA {:.0} s, {}",
            self.done,
            self.total,
            100.0 * self.done as f64 / self.total.max(1) as f64,
            rate,
            eta,
            self.message(disk, raw)
        )
    }

    pub fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
