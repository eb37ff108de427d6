//! Progress of a compute run at the I/O master: rows done / total, rows/s, ETA, MB
//! written, compression ratio. Half rows (`--symmetric`) cost less as the row index
//! grows: their ETA follows the pairs done, not the rows.
//!
//! On a terminal it draws an indicatif bar; otherwise (batch jobs, CI logs) it prints one
//! line every `log_every` seconds. Nothing is shown for runs shorter than a second.

use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub(crate) struct Progress {
    enabled: bool,
    total: u64,
    done: u64,
    /// Work units when rows differ in cost (half rows: pairs): rate and ETA follow the
    /// work, not the row count. `None`: every row costs the same.
    work: Option<(u64, u64)>,
    start: Instant,
    bar: Option<ProgressBar>,
    last_line: Instant,
    log_every: Duration,
    is_terminal: bool,
    lines: u64,
}

impl Progress {
    pub(crate) fn new(total: u64, enabled: bool) -> Self {
        use std::io::IsTerminal;
        let now = Instant::now();
        Progress {
            enabled,
            total,
            done: 0,
            work: None,
            start: now,
            bar: None,
            last_line: now,
            log_every: Duration::from_secs(10),
            is_terminal: std::io::stderr().is_terminal(),
            lines: 0,
        }
    }

    /// Rows of unequal cost: `total_work` units in all; pass each row's units to
    /// [`Progress::advance_work`] (half rows: row i holds about n − i pairs).
    pub(crate) fn with_work(mut self, total_work: u64) -> Self {
        self.work = Some((0, total_work.max(1)));
        self
    }

    /// `rows` more rows holding `work` units are done (see [`Progress::with_work`]).
    pub(crate) fn advance_work(&mut self, rows: u64, work: u64, disk: u64, raw: u64) {
        if let Some((done, _)) = &mut self.work {
            *done += work;
        }
        self.advance(rows, disk, raw);
    }

    /// `rows` more rows are done; `disk`/`raw` are the file's bytes so far.
    pub(crate) fn advance(&mut self, rows: u64, disk: u64, raw: u64) {
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
            let (pos, len, template) = match self.work {
                // Position in work units; the row count goes into the message.
                Some((done, total)) => {
                    (done, total, "{bar:30} {percent}% of pairs, ETA {eta} {msg}")
                }
                None => (
                    self.done,
                    self.total,
                    "{bar:30} {pos}/{len} rows {per_sec} ETA {eta} {msg}",
                ),
            };
            let bar = self.bar.get_or_insert_with(|| {
                let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
                bar.set_style(
                    ProgressStyle::with_template(template)
                        .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                bar
            });
            bar.set_position(pos);
            bar.set_message(if self.work.is_some() {
                format!("{}/{} half rows, {msg}", self.done, self.total)
            } else {
                msg
            });
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
        // ETA from the work done when rows differ in cost, else from rows.
        let (done, total) = self.work.unwrap_or((self.done, self.total));
        let work_rate = done as f64 / secs.max(1e-9);
        let eta = if work_rate > 0.0 {
            (total.saturating_sub(done)) as f64 / work_rate
        } else {
            f64::NAN
        };
        let (unit, what) = if self.work.is_some() {
            ("half rows", "of pairs")
        } else {
            ("rows", "")
        };
        format!(
            "progress: {}/{} {unit} ({:.1}%{}{what}), {:.1} {unit}/s, ETA {:.0} s, {}",
            self.done,
            self.total,
            100.0 * done as f64 / total.max(1) as f64,
            if what.is_empty() { "" } else { " " },
            rate,
            eta,
            self.message(disk, raw)
        )
    }

    pub(crate) fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
