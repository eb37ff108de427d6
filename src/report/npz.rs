//! `export --npz`: the matrix as the NumPy `.npz` archive that `scipy.sparse.save_npz`
//! writes for a CSR matrix, so `scipy.sparse.load_npz` opens it without our reader.
//!
//! The archive (a zip file, entries stored uncompressed, zip64 where an entry passes
//! 4 GiB) holds five `.npy` arrays, the keys `load_npz` reads: `format` (the bytes
//! `csr`, dtype `|S3`), `shape` (`<i8`, `[n, n]`), `indptr` (n + 1 offsets), `indices`
//! (column of each entry, ascending within a row) and `data` (`<f4`, F_ij). `indptr`
//! and `indices` are `<i4` when every offset fits in 31 bits, else `<i8` (what
//! scipy picks). The `.npy` header is format version 1.0, padded with spaces so the
//! data starts on a 64-byte boundary.
//!
//! Streaming: a CSR matrix lists rows in order, the file holds them in any order.
//! The export's entry pass appends each row's kept entries to a spill file beside the
//! output ([`spill_path`]: in TMPDIR when the output is a device; its
//! columns, then its values) and notes where each row starts (n numbers);
//! this module then writes `indices` and `data` by reading the spill file back in
//! row order (positioned reads, one row at a time). Memory is O(n) whatever the number of entries; disk is the
//! archive plus a spill of 8 bytes per entry, removed afterwards.

use std::cell::Cell;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::rc::Rc;

use crate::ffz::FfzError;

use super::Result;

/// True when `path` exists and is no regular file (a device such as `/dev/full`): it
/// is written to, never removed or synced, and gets no spill beside it.
fn is_device(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file())
}

/// Where the spill for an archive written to `npz` goes: `NAME.npz.PID-K.spill` beside
/// it, or, when `npz` exists and is no regular file (`/dev/stdout`, `/dev/full`),
/// `ffstream-PID-K-NAME.spill` in the temporary directory (`TMPDIR`), not beside a
/// device. PID is this process and K counts the spills it made, so two exports to the
/// same archive (two processes, or one process twice) never share a spill: with one
/// name for all, each truncated and rewrote the other's entries (issue 48).
pub(crate) fn spill_path(npz: &Path) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static MADE: AtomicU64 = AtomicU64::new(0);
    let tag = format!(
        "{}-{}",
        std::process::id(),
        MADE.fetch_add(1, Ordering::Relaxed)
    );
    if is_device(npz) {
        let mut name = std::ffi::OsString::from(format!("ffstream-{tag}-"));
        name.push(npz.file_name().unwrap_or(npz.as_os_str()));
        name.push(".spill");
        return std::env::temp_dir().join(name);
    }
    let mut name = npz.as_os_str().to_owned();
    name.push(format!(".{tag}.spill"));
    PathBuf::from(name)
}

/// Where each row's entries are in the spill file, and how many it kept.
#[derive(Debug)]
pub(crate) struct NpzSpill {
    path: PathBuf,
    out: BufWriter<File>,
    len: u64,
    /// Byte offset of each row's entries (rows without entries: unused).
    offsets: Vec<u64>,
    /// Entries kept of each row.
    counts: Vec<u64>,
}

impl NpzSpill {
    /// A spill file for an `n`-row matrix written to `npz` ([`spill_path`]).
    pub(crate) fn create(npz: &Path, n: u32) -> Result<Self> {
        let path = spill_path(npz);
        let f = File::create(&path).map_err(|e| FfzError::io(&path, "create", e))?;
        Ok(NpzSpill {
            out: BufWriter::with_capacity(1 << 20, f),
            path,
            len: 0,
            offsets: vec![0; n as usize],
            counts: vec![0; n as usize],
        })
    }

    /// Append row `i`'s kept entries (ascending columns). Each row once.
    pub(crate) fn push(&mut self, i: u32, cols: &[u32], vals: &[f32]) -> Result<()> {
        let e = |err| FfzError::io(&self.path, "write", err);
        self.offsets[i as usize] = self.len;
        self.counts[i as usize] = cols.len() as u64;
        for c in cols {
            self.out.write_all(&c.to_le_bytes()).map_err(e)?;
        }
        for v in vals {
            self.out.write_all(&v.to_le_bytes()).map_err(e)?;
        }
        self.len += 8 * cols.len() as u64;
        Ok(())
    }

    /// Write the archive to `npz` and remove the spill file.
    ///
    /// # Errors
    /// `Io` naming the archive or the spill file.
    pub(crate) fn finish(mut self, npz: &Path) -> Result<()> {
        let result = self.write_archive(npz);
        let _ = std::fs::remove_file(&self.path);
        result
    }

    /// Remove the spill file without writing the archive (the export failed).
    pub(crate) fn discard(self) {
        let _ = std::fs::remove_file(&self.path);
    }

    fn write_archive(&mut self, npz: &Path) -> Result<()> {
        self.out
            .flush()
            .map_err(|e| FfzError::io(&self.path, "write", e))?;
        let spill = File::open(&self.path).map_err(|e| FfzError::io(&self.path, "open", e))?;
        // A device (`/dev/full`, `/dev/null`) is written to but never removed. A pipe
        // cannot take a zip archive (the writer seeks back to its headers).
        let regular = !is_device(npz);
        let f = File::create(npz).map_err(|e| FfzError::io(npz, "create", e))?;
        let failed = Rc::new(Cell::new(false));
        let mut zip = zip::ZipWriter::new(Quiet::new(f, Rc::clone(&failed)));
        let result = self.fill(&mut zip, npz, &spill).and_then(|()| {
            let mut inner = zip.finish().map_err(|err| zip_error(npz, err))?;
            inner
                .flush()
                .map_err(|err| FfzError::io(npz, "write", err))?;
            // A device has nothing to sync (`/dev/null` refuses with EINVAL).
            if !regular {
                return Ok(());
            }
            inner
                .file
                .get_ref()
                .sync_all()
                .map_err(|err| FfzError::io(npz, "write", err))
        });
        if result.is_err() {
            // What was written is no archive: remove it rather than leave a file that
            // looks like one, and keep the zip writer (dropped unfinished when the
            // error came before `finish`) from writing or printing more.
            failed.set(true);
            if regular {
                let _ = std::fs::remove_file(npz);
            }
        }
        result
    }

    /// The five arrays into `zip`, the rows read back from `spill`.
    fn fill(&self, zip: &mut Zip, npz: &Path, spill: &File) -> Result<()> {
        // Row i's columns and values, read back with positioned reads (not a map, so
        // the spill's pages count in the page cache, not in this process's memory).
        let mut buf = Vec::new();
        let read_row = |i: usize, buf: &mut Vec<u8>| -> Result<()> {
            buf.resize(8 * self.counts[i] as usize, 0);
            std::os::unix::fs::FileExt::read_exact_at(spill, buf, self.offsets[i])
                .map_err(|e| FfzError::io(&self.path, "read", e))
        };
        let n = self.counts.len() as u64;
        let nnz: u64 = self.counts.iter().sum();
        let wide = nnz > i32::MAX as u64 || n > i32::MAX as u64;
        let index_type = if wide { "<i8" } else { "<i4" };
        let zerr = |err: zip::result::ZipError| zip_error(npz, err);
        let ioerr = |err| FfzError::io(npz, "write", err);
        let index_bytes = |count: u64| count * if wide { 8 } else { 4 };
        let entry = |zip: &mut Zip, name: &str, descr: &str, shape: &str, data_len: u64| {
            let head = npy_header(descr, shape);
            let options = zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Stored)
                .large_file(head.len() as u64 + data_len >= u32::MAX as u64 - (1 << 20));
            zip.start_file(name, options).map_err(zerr)?;
            zip.write_all(&head).map_err(ioerr)
        };

        entry(zip, "format.npy", "|S3", "()", 3)?;
        zip.write_all(b"csr").map_err(ioerr)?;
        entry(zip, "shape.npy", "<i8", "(2,)", 16)?;
        for _ in 0..2 {
            zip.write_all(&(n as i64).to_le_bytes()).map_err(ioerr)?;
        }
        let put_index = |zip: &mut Zip, x: u64| {
            if wide {
                zip.write_all(&(x as i64).to_le_bytes())
            } else {
                zip.write_all(&(x as i32).to_le_bytes())
            }
        };
        entry(
            zip,
            "indptr.npy",
            index_type,
            &format!("({},)", n + 1),
            index_bytes(n + 1),
        )?;
        let mut at = 0u64;
        put_index(zip, 0).map_err(ioerr)?;
        for &c in &self.counts {
            at += c;
            put_index(zip, at).map_err(ioerr)?;
        }
        // Columns, then values, of each row in row order from the spill.
        entry(
            zip,
            "indices.npy",
            index_type,
            &format!("({nnz},)"),
            index_bytes(nnz),
        )?;
        for i in 0..self.counts.len() {
            read_row(i, &mut buf)?;
            let c = self.counts[i] as usize;
            for w in buf[..4 * c].chunks_exact(4) {
                let c = u32::from_le_bytes(w.try_into().expect("4 bytes"));
                put_index(zip, u64::from(c)).map_err(ioerr)?;
            }
        }
        entry(zip, "data.npy", "<f4", &format!("({nnz},)"), 4 * nnz)?;
        for i in 0..self.counts.len() {
            read_row(i, &mut buf)?;
            let c = self.counts[i] as usize;
            zip.write_all(&buf[4 * c..]).map_err(ioerr)?;
        }
        Ok(())
    }
}

fn zip_error(npz: &Path, err: zip::result::ZipError) -> FfzError {
    FfzError::io(npz, "write", std::io::Error::other(err.to_string()))
}

type Zip = zip::ZipWriter<Quiet>;

/// The archive's file, quiet once a write to it has failed or the export has: a zip
/// writer dropped unfinished finishes the archive itself and prints to stderr when it
/// cannot (a full disk), which gave a second, unterminated message before ffstream's
/// own. Once failed, writes and seeks only move a position kept here, so that the
/// writer's last finish succeeds into nothing.
struct Quiet {
    file: BufWriter<File>,
    failed: Rc<Cell<bool>>,
    /// Where the next write goes, and the end of what was written.
    pos: u64,
    end: u64,
}

impl Quiet {
    fn new(file: File, failed: Rc<Cell<bool>>) -> Self {
        Quiet {
            file: BufWriter::with_capacity(1 << 20, file),
            failed,
            pos: 0,
            end: 0,
        }
    }

    /// A failed write fails the export (an interrupted one is retried).
    fn note<T>(&self, r: &std::io::Result<T>) {
        if r.as_ref()
            .is_err_and(|e| e.kind() != std::io::ErrorKind::Interrupted)
        {
            self.failed.set(true);
        }
    }

    fn moved(&mut self, to: u64) -> u64 {
        self.pos = to;
        self.end = self.end.max(to);
        to
    }
}

impl Write for Quiet {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        if self.failed.get() {
            self.moved(self.pos + b.len() as u64);
            return Ok(b.len());
        }
        let r = self.file.write(b);
        self.note(&r);
        if let Ok(k) = r {
            self.moved(self.pos + k as u64);
        }
        r
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if self.failed.get() {
            return Ok(());
        }
        let r = self.file.flush();
        self.note(&r);
        r
    }
}

impl Seek for Quiet {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        if self.failed.get() {
            let at = match to {
                SeekFrom::Start(p) => Some(p),
                SeekFrom::Current(d) => self.pos.checked_add_signed(d),
                SeekFrom::End(d) => self.end.checked_add_signed(d),
            };
            return Ok(self.moved(at.unwrap_or(0)));
        }
        // (A seek writes out what the buffer holds: it fails as a write does.)
        let r = self.file.seek(to);
        self.note(&r);
        r.map(|p| self.moved(p))
    }
}

/// A `.npy` version 1.0 header for an array of dtype `descr` and shape `shape` (a
/// Python tuple), padded with spaces and a newline to a multiple of 64 bytes.
fn npy_header(descr: &str, shape: &str) -> Vec<u8> {
    let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    let unpadded = 10 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    let mut h = Vec::with_capacity(total);
    h.extend_from_slice(b"\x93NUMPY\x01\x00");
    h.extend_from_slice(&((total - 10) as u16).to_le_bytes());
    h.extend_from_slice(dict.as_bytes());
    h.resize(total - 1, b' ');
    h.push(b'\n');
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Beside a file (existing or not); in the temporary directory for a device; a
    /// name of its own for every spill.
    #[test]
    fn the_spill_goes_beside_a_file_and_not_beside_a_device() {
        let dir = std::env::temp_dir().join(format!("ffs-spill-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let npz = dir.join("F.npz");
        let name = |p: &Path| p.file_name().unwrap().to_string_lossy().into_owned();
        let pid = std::process::id();
        let a = spill_path(&npz);
        assert_eq!(a.parent(), Some(dir.as_path()));
        assert!(name(&a).starts_with(&format!("F.npz.{pid}-")), "{a:?}");
        assert!(name(&a).ends_with(".spill"), "{a:?}");
        std::fs::write(&npz, b"old").unwrap();
        assert_eq!(spill_path(&npz).parent(), Some(dir.as_path()));
        let dev = spill_path(Path::new("/dev/null"));
        assert_eq!(dev.parent(), Some(std::env::temp_dir().as_path()));
        assert!(
            name(&dev).starts_with(&format!("ffstream-{pid}-")),
            "{dev:?}"
        );
        assert!(name(&dev).ends_with("-null.spill"), "{dev:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Two exports to one archive shared `F.npz.spill`, each truncating the other's
    /// entries (issue 48): every spill now has a name of its own.
    #[test]
    fn two_spills_for_one_archive_are_two_files() {
        let npz = Path::new("/nonexistent-dir/F.npz");
        assert_ne!(spill_path(npz), spill_path(npz));
        let dev = Path::new("/dev/null");
        assert_ne!(spill_path(dev), spill_path(dev));
    }

    #[test]
    fn npy_headers_are_padded_to_64_bytes_and_end_in_a_newline() {
        for (d, s) in [("<f4", "(12345,)"), ("|S3", "()"), ("<i8", "(2,)")] {
            let h = npy_header(d, s);
            assert_eq!(h.len() % 64, 0);
            assert_eq!(&h[..8], b"\x93NUMPY\x01\x00");
            assert_eq!(u16::from_le_bytes([h[8], h[9]]) as usize, h.len() - 10);
            assert_eq!(*h.last().unwrap(), b'\n');
            let text = std::str::from_utf8(&h[10..]).unwrap();
            assert!(text.starts_with(&format!(
                "{{'descr': '{d}', 'fortran_order': False, 'shape': {s}, }}"
            )));
        }
    }
}
