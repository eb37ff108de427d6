//! Reading input files (scenes, material libraries, glTF buffers, weather and sensor
//! tables): regular files only, and compressed input only up to a size.
//!
//! A path may name a device or a FIFO: `mtllib /dev/zero` or a glTF buffer URI
//! `/dev/zero` read until memory ran out, and a FIFO as `mtllib` blocked the load
//! forever in `open` (issue 48). Such a path is refused before it is opened, naming
//! what it is; a directory is left to the OS's own error ("Is a directory").

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// Refuse `path` when it exists and is neither a regular file nor a directory.
fn regular(path: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::FileTypeExt;
    let Ok(m) = std::fs::metadata(path) else {
        return Ok(()); // the open that follows names the OS's reason
    };
    let t = m.file_type();
    if t.is_file() || t.is_dir() {
        return Ok(());
    }
    let what = if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    };
    Err(Error::new(
        ErrorKind::InvalidInput,
        format!("{what}, not a regular file: refused as input"),
    ))
}

/// Refuses `path` when it names a device, FIFO or socket, as `read` and `open` do:
/// for readers elsewhere (the command line's CSV inputs, `solve --emission` and
/// `render --radiosity`, read by `src/solve/`), checked before they open the file.
///
/// # Errors
/// `InvalidInput` naming what the path is.
pub fn refuse_special_file(path: &Path) -> std::io::Result<()> {
    regular(path)
}

/// The bytes of the regular file `path`.
///
/// # Errors
/// `InvalidInput` for a device, FIFO or socket; the OS's error otherwise.
pub(crate) fn read(path: &Path) -> std::io::Result<Vec<u8>> {
    regular(path)?;
    std::fs::read(path)
}

/// The regular file `path`, opened for reading.
///
/// # Errors
/// As [`read`].
pub(crate) fn open(path: &Path) -> std::io::Result<std::fs::File> {
    regular(path)?;
    std::fs::File::open(path)
}

/// The zstd-compressed `bytes` decompressed, at most `cap` bytes of them: a small file
/// can decompress to gigabytes.
///
/// # Errors
/// `InvalidData` when the output would pass `cap` or the data are not zstd.
pub(crate) fn zstd_capped(bytes: &[u8], cap: u64) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    zstd::stream::read::Decoder::new(bytes)?
        .take(cap.saturating_add(1))
        .read_to_end(&mut out)?;
    if out.len() as u64 > cap {
        return Err(Error::new(
            ErrorKind::InvalidData,
            format!("decompresses to more than {cap} bytes: refused"),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_and_fifos_are_refused_before_opening() {
        let e = read(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().contains("a device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = open(&fifo).unwrap_err();
        assert!(e.to_string().contains("a FIFO"), "{e}");
        let f = dir.path().join("f");
        std::fs::write(&f, b"x").unwrap();
        assert_eq!(read(&f).unwrap(), b"x");
    }

    #[test]
    fn decompression_stops_at_the_cap() {
        let big = zstd::encode_all(&vec![0u8; 1 << 20][..], 3).unwrap();
        assert_eq!(zstd_capped(&big, 1 << 20).unwrap().len(), 1 << 20);
        let e = zstd_capped(&big, 1000).unwrap_err();
        assert!(e.to_string().contains("more than 1000 bytes"), "{e}");
    }
}
