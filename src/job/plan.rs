//! The plan a job says before any heavy work: patches, pairs, the file's size for
//! the row mode, free disk, memory. It refuses a run whose file the disk cannot hold
//! and warns when the patch count is far above the target or memory looks short: a
//! rule of the job, so the library applies it wherever a job is built.

use std::path::Path;

use crate::ffz::size::{file_bytes_bound, human_bytes, spill_bytes_bound};
use crate::ffz::Layout;

use super::JobError;

/// What the plan is made of (known before the scene is subdivided).
pub struct Plan<'a> {
    pub scene: &'a str,
    pub output: &'a Path,
    /// Patches the subdivision will make, and how they were chosen.
    pub n: u64,
    pub faces: u64,
    /// `Some(target)` when the count came from `--patches` (no `--max-edge`).
    pub target: Option<u64>,
    pub layout: Layout,
    /// `--min-ff`: rows keep the entries at or above it.
    pub threshold: Option<f64>,
    pub symmetric: bool,
    pub threads: u64,
    pub chunk_bytes: u64,
    /// Triangles of the occluder hierarchy each computing process holds: the scene's
    /// (an `--occluders` mesh, usually coarser, is loaded later, so this overstates).
    pub occluder_triangles: u64,
    pub resume: bool,
    /// `--no-space-check`: print the plan, refuse nothing.
    pub no_space_check: bool,
}

/// A patch count this many times above `--patches` gets a warning.
const FAR_ABOVE: u64 = 2;

/// Bytes a computing process holds per patch: the patch table twice (the job's and the
/// header's copy), the engine's per-patch geometry and far-field data, the row
/// buffers of two threads, allocator slack. Measured: bench/PERF.md §15 (peak RSS of
/// `room` runs at 2k, 10k and 30k patches: 12.2, 25.2 and 55.0 MB, slope 1.5 kB per
/// patch over a base of about 10 MB).
const BYTES_PER_PATCH: u64 = 1500;
/// The process itself (binary, libraries, thread stacks, chunk buffers).
const BASE_BYTES: u64 = 10_000_000;
/// Bytes per occluder triangle in the hierarchy (node boxes and the triangle record).
const BYTES_PER_TRIANGLE: u64 = 160;
/// Per compute thread beyond the two of the measurement, and patch: its dense row (f64
/// work, f32 output).
const ROW_BYTES_PER_PATCH: u64 = 12;

impl Plan<'_> {
    /// The most the file can take (before compression; see [`file_bytes_bound`]).
    fn file_bytes(&self) -> u64 {
        file_bytes_bound(self.n, self.layout, self.chunk_bytes)
    }

    /// Entries a row may hold.
    fn k(&self) -> u32 {
        match self.layout {
            Layout::Dense => u32::try_from(self.n).unwrap_or(u32::MAX),
            Layout::TopK { k } => k,
        }
    }

    /// About the peak memory of one computing process (embedded, or an MPI worker).
    pub fn memory_bytes(&self) -> u64 {
        let per_patch = BYTES_PER_PATCH + self.threads.saturating_sub(2) * ROW_BYTES_PER_PATCH;
        self.n
            .saturating_mul(per_patch)
            .saturating_add(BASE_BYTES)
            .saturating_add(self.occluder_triangles * BYTES_PER_TRIANGLE)
    }

    /// Say the plan (and its warnings) through `say` and check it.
    ///
    /// # Errors
    /// [`JobError::Plan`] when the disk cannot hold the file (and the space check is
    /// on).
    pub fn check(&self, say: &dyn Fn(&str)) -> Result<(), JobError> {
        let n = self.n;
        if let Some(target) = self.target {
            if n > FAR_ABOVE * target && self.faces > target {
                say(&format!(
                    "ffstream: warning: {}: {n} patches, {:.0}× the --patches target {target}: \
                     the scene has {} faces and a face is never merged with another, so each \
                     is at least one patch (only a coarser mesh makes fewer)",
                    self.scene,
                    n as f64 / target as f64,
                    self.faces
                ));
            }
        }
        let pairs = if self.symmetric {
            format!(
                "{} unordered pairs (half rows)",
                count(n * n.saturating_sub(1) / 2)
            )
        } else {
            format!("{} pairs", count(n.saturating_mul(n)))
        };
        let rows = match (self.layout, self.threshold) {
            (Layout::Dense, _) => "dense f32 rows".to_string(),
            (Layout::TopK { k }, None) => format!("top-{k} rows"),
            (Layout::TopK { k }, Some(eps)) if u64::from(k) >= n => {
                format!("rows of the entries ≥ {eps:e}, at most all of them")
            }
            (Layout::TopK { k }, Some(eps)) => format!("top-{k} rows of the entries ≥ {eps:e}"),
        };
        let file = self.file_bytes();
        let spill = if self.symmetric {
            format!(
                " plus a spill file of up to {}",
                human_bytes(spill_bytes_bound(n))
            )
        } else {
            String::new()
        };
        let disk = free_disk(self.output);
        let mem = self.memory_bytes();
        let available = mem_available();
        say(&format!(
            "ffstream: plan: {n} patches, {pairs}; file up to {} ({rows}, before compression){spill}; {}; memory about {} per computing process ({} threads){}",
            human_bytes(file),
            match &disk {
                Some(d) => format!("{} free in {}", human_bytes(d.free), d.dir),
                None => "free disk unknown".to_string(),
            },
            human_bytes(mem),
            self.threads,
            available.map_or(String::new(), |a| format!(", {} available here", human_bytes(a)))
        ));
        if let Some(a) = available {
            if mem > a {
                say(&format!(
                    "ffstream: warning: a computing process needs about {} and this machine has {} available: the run may be killed for memory (fewer --threads, --top-k, or ranks on more nodes)",
                    human_bytes(mem),
                    human_bytes(a)
                ));
            }
        }
        let Some(d) = disk else { return Ok(()) };
        // A resumed file already holds part of what it needs.
        let needed = file.saturating_sub(if self.resume { d.existing } else { 0 });
        if needed > d.free && !self.no_space_check {
            let fewer = match (self.layout, self.threshold) {
                (Layout::Dense, _) | (Layout::TopK { .. }, Some(_)) if u64::from(self.k()) >= n => {
                    format!(
                        ", keep fewer entries per row (--top-k 64: up to {})",
                        human_bytes(file_bytes_bound(
                            n,
                            Layout::TopK { k: 64 },
                            self.chunk_bytes
                        ))
                    )
                }
                _ => String::new(),
            };
            return Err(JobError::Plan(format!(
                "{}: the file needs up to {} ({rows} of {n} patches, before compression) and {} has {} free: free space, write elsewhere{fewer}, use fewer patches, or add --no-space-check to start anyway (zstd may make it fit; if the disk fills, the run stops with a clear error and its rows kept for --resume)",
                self.output.display(),
                human_bytes(needed),
                d.dir,
                human_bytes(d.free)
            )));
        }
        Ok(())
    }
}

/// A count as digits up to ten million, in e-notation above (1.80e13).
fn count(c: u64) -> String {
    if c < 10_000_000 {
        c.to_string()
    } else {
        format!("{:.2e}", c as f64)
    }
}

/// Free space where the output goes, and the size of an existing output.
struct Disk {
    dir: String,
    free: u64,
    existing: u64,
}

/// None for an output that is not stored (a device such as /dev/null) or a file system
/// that does not say.
fn free_disk(output: &Path) -> Option<Disk> {
    let meta = std::fs::metadata(output).ok();
    if meta.as_ref().is_some_and(|m| !m.is_file()) {
        return None;
    }
    let dir = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let free = statvfs_free(&dir)?;
    Some(Disk {
        dir: dir.display().to_string(),
        free,
        existing: meta.map_or(0, |m| m.len()),
    })
}

/// Bytes an unprivileged user may still write on the file system of `dir`.
fn statvfs_free(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: an all-zero statvfs is a valid value of this plain C struct.
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a NUL-terminated path and `s` a valid out-pointer.
    if unsafe { libc::statvfs(c.as_ptr(), &mut s) } != 0 {
        return None;
    }
    Some((s.f_bavail as u64).saturating_mul(s.f_frsize as u64))
}

/// MemAvailable of /proc/meminfo (Linux), in bytes.
pub fn mem_available() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan<'a>(output: &'a Path, n: u64, no_space_check: bool) -> Plan<'a> {
        Plan {
            scene: "test",
            output,
            n,
            faces: 6,
            target: None,
            layout: Layout::Dense,
            threshold: None,
            symmetric: false,
            threads: 2,
            chunk_bytes: 1 << 20,
            occluder_triangles: 12,
            resume: false,
            no_space_check,
        }
    }

    #[test]
    fn a_file_larger_than_the_free_disk_is_refused_unless_asked_to_start_anyway() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.ffz");
        // 2^25 dense rows: 4.5e15 bytes, more than any disk this runs on.
        let err = plan(&out, 1 << 25, false)
            .check(&|_| {})
            .unwrap_err()
            .to_string();
        for part in [
            "x.ffz",
            "needs up to",
            "free",
            "--top-k 64",
            "--no-space-check",
        ] {
            assert!(err.contains(part), "{part}: {err}");
        }
        plan(&out, 1 << 25, true)
            .check(&|_| {})
            .expect("--no-space-check starts anyway");
        plan(&out, 100, false)
            .check(&|_| {})
            .expect("a small file fits");
        // Output to a device stores nothing: no disk check.
        plan(Path::new("/dev/null"), 1 << 25, false)
            .check(&|_| {})
            .expect("/dev/null holds anything");
    }
}
