//! Outputs that would destroy an input or each other: every command names its input
//! and output files to [`check`] before it opens anything for writing, and a clash is
//! a usage error (exit 2) naming both options.
//!
//! Files are compared by identity, not spelling: an existing file by device and inode
//! (so `F.ffz`, `./F.ffz`, `dir/../F.ffz`, a hard link and a symbolic link are one
//! file), a file still to be created by its canonical parent directory and its name.
//! Devices and pipes (`/dev/null`, `/dev/stdout`) are left out: writing one replaces
//! nothing, and several outputs to `/dev/null` are a normal way to discard them.
//!
//! Before this check `export F.ffz --matrix F.ffz` truncated the file it was reading
//! through a memory map (bus error, F.ffz left at 0 bytes), and `solve F.ffz -o F.ffz`
//! or `--matrix X --sparse X` replaced or interleaved files and exited 0 (issue 48).

use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use super::Usage;

/// What makes two paths the same file.
#[derive(Debug, PartialEq, Eq)]
enum Identity {
    /// An existing file or directory.
    Inode(u64, u64),
    /// A file still to be created: its directory, canonical, and its name.
    Path(PathBuf),
}

/// The identity of `path`; `None` for a device or a pipe, and for a path whose
/// directory does not exist (creating it fails with its own error).
fn identity(path: &Path) -> Option<Identity> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() || m.is_dir() => Some(Identity::Inode(m.dev(), m.ino())),
        Ok(_) => None,
        Err(_) => {
            let name = path.file_name()?;
            let parent = match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p,
                _ => Path::new("."),
            };
            Some(Identity::Path(parent.canonicalize().ok()?.join(name)))
        }
    }
}

/// A file a command reads or writes, and the option (or argument) that names it.
pub(super) type Named<'a> = (&'a str, &'a Path);

/// Refuse when an output is an input or another output.
///
/// # Errors
/// [`Usage`] naming both options and the path.
pub(super) fn check(inputs: &[Named<'_>], outputs: &[Named<'_>]) -> anyhow::Result<()> {
    let ins: Vec<_> = inputs.iter().map(|&(o, p)| (o, p, identity(p))).collect();
    let mut seen: Vec<(&str, &Path, Identity)> = Vec::with_capacity(outputs.len());
    for &(option, path) in outputs {
        let Some(id) = identity(path) else { continue };
        if let Some((what, p, _)) = ins.iter().find(|(_, _, i)| i.as_ref() == Some(&id)) {
            return Err(Usage(format!(
                "{option} {} is the input {what} {}: refusing to overwrite it",
                path.display(),
                p.display()
            ))
            .into());
        }
        if let Some((what, p, _)) = seen.iter().find(|(_, _, i)| *i == id) {
            return Err(Usage(format!(
                "{option} {} and {what} {} are the same file: give each output its own",
                path.display(),
                p.display()
            ))
            .into());
        }
        seen.push((option, path, id));
    }
    Ok(())
}

/// The file a scene spec names (`PATH`, `FORMAT:PATH`), if any: built-in scenes have
/// none.
pub(super) fn scene_file(spec: &str) -> Option<&Path> {
    if spec.starts_with("builtin:") {
        return None;
    }
    if Path::new(spec).exists() {
        return Some(Path::new(spec));
    }
    match spec.split_once(':') {
        Some((format, path)) if ffstream::scene::SceneFormat::from_name(format).is_some() => {
            Some(Path::new(path))
        }
        // A built-in's name, or a missing file: nothing an output could destroy.
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_file_under_two_spellings_is_one_file() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("F.ffz");
        std::fs::write(&f, b"x").unwrap();
        let other = dir.path().join("sub/../F.ffz");
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let e = check(&[("FILE", &f)], &[("--matrix", &other)]).unwrap_err();
        assert!(e.to_string().contains("--matrix"), "{e}");
        // Two outputs still to be created, spelt differently.
        let a = dir.path().join("new.txt");
        let b = dir.path().join("sub/../new.txt");
        assert!(check(&[], &[("--matrix", &a), ("--sparse", &b)]).is_err());
        // Devices are left out.
        let null = Path::new("/dev/null");
        assert!(check(&[("FILE", &f)], &[("--matrix", null), ("--sparse", null)]).is_ok());
        assert!(check(&[("FILE", &f)], &[("--matrix", &a)]).is_ok());
    }
}
