//! The scene layer's error type. Every variant that comes from a file names the file
//! and, where one exists, the 1-based line (OBJ or MTL) that caused it.

use std::path::{Path, PathBuf};

/// Longest text from a file an error quotes, in characters.
const ECHO_CHARS: usize = 200;

/// Text from a file as an error quotes it: control characters escaped (a carriage
/// return would send the terminal's cursor back over the message) and cut after
/// [`ECHO_CHARS`] characters, saying how long it was. A file whose lines end in CR
/// alone is one line to the loader, and its errors used to echo the whole file.
pub(crate) fn echo(text: &str) -> String {
    let mut out = String::new();
    for (shown, c) in text.chars().enumerate() {
        if shown == ECHO_CHARS {
            out.push_str(&format!("... ({} characters in all)", text.chars().count()));
            return out;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// Why a scene could not be loaded, built or written.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The OBJ or MTL file could not be read.
    #[error("{}: cannot read: {cause}", path.display())]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// A statement the loader needs could not be parsed.
    #[error("{}:{line}: malformed `{}` statement: {}", path.display(), echo(keyword), echo(reason))]
    Malformed {
        path: PathBuf,
        line: u32,
        keyword: String,
        reason: String,
    },
    /// A face refers to a vertex (or texture coordinate / normal) that does not exist.
    #[error("{}:{line}: {what} index {index} out of range ({count} defined before this line)", path.display())]
    IndexOutOfRange {
        path: PathBuf,
        line: u32,
        what: &'static str,
        index: i64,
        count: usize,
    },
    /// A vertex coordinate is NaN, infinite, or so large (|x| > 1e150) that lengths and
    /// areas would overflow.
    #[error(
        "{}:{line}: vertex coordinate `{}` is not finite or too large (|x| ≤ 1e150 keeps lengths and areas finite)",
        path.display(),
        echo(value)
    )]
    NonFinite {
        path: PathBuf,
        line: u32,
        value: String,
    },
    /// An `mtllib` names a file that does not exist or cannot be read.
    #[error("{}:{line}: material library {} cannot be read: {reason}", path.display(), echo(&mtl.to_string_lossy()))]
    MissingMtl {
        path: PathBuf,
        line: u32,
        mtl: PathBuf,
        reason: String,
    },
    /// A `usemtl` names a material no material library defines.
    #[error("{}:{line}: material `{}` is not defined by a material library loaded before this line", path.display(), echo(name))]
    MissingMaterial {
        path: PathBuf,
        line: u32,
        name: String,
    },
    /// A face comes before any `usemtl`: it has no reflectance.
    #[error("{}:{line}: face has no material (no `usemtl` before it)", path.display())]
    NoMaterial { path: PathBuf, line: u32 },
    /// A `Kd` channel outside [0, 1) (docs/numerics.md §3); `path` is the MTL file.
    #[error("{}:{line}: material `{material}`: Kd {value} is outside [0, 1)", path.display())]
    Reflectance {
        path: PathBuf,
        line: u32,
        material: String,
        value: f64,
    },
    /// A `Ke` channel negative or not finite; `path` is the MTL file.
    #[error("{}:{line}: material `{material}`: Ke {value} must be finite and >= 0", path.display())]
    Emission {
        path: PathBuf,
        line: u32,
        material: String,
        value: f64,
    },
    /// An element of an STL, PLY or glTF file (a facet, face, vertex, accessor or
    /// buffer, named with its 1-based number) is not usable, or the file's structure is
    /// broken (truncated, wrong counts): `element` says where.
    #[error("{}: {element}: {reason}", path.display())]
    Element {
        path: PathBuf,
        element: String,
        reason: String,
    },
    /// No usable face at all.
    /// `dropped` says how many degenerate faces were dropped and the first one's line
    /// (empty when none were), so a file of only bad faces still points at a line.
    #[error("{}: the scene has no faces{dropped}", path.display())]
    Empty { path: PathBuf, dropped: String },
    /// `tobj` refused the file for a reason the loader's own checks did not catch.
    #[error("{}: OBJ/MTL parser: {message}", path.display())]
    Parser { path: PathBuf, message: String },
    /// `builtin` was asked for a scene it does not know.
    #[error("unknown built-in scene `{name}` (known: {known})")]
    UnknownBuiltin { name: String, known: String },
    /// A built-in scene's parameter is out of range.
    #[error("built-in scene `{name}`: {reason}")]
    BadParam { name: String, reason: String },
    /// Writing an OBJ or MTL file failed.
    #[error("{}: cannot write: {cause}", path.display())]
    Write {
        path: PathBuf,
        cause: std::io::Error,
    },
}

impl SceneError {
    /// The file the error is about, if any.
    pub fn path(&self) -> Option<&Path> {
        use SceneError::*;
        match self {
            Read { path, .. }
            | Malformed { path, .. }
            | IndexOutOfRange { path, .. }
            | NonFinite { path, .. }
            | MissingMtl { path, .. }
            | MissingMaterial { path, .. }
            | NoMaterial { path, .. }
            | Reflectance { path, .. }
            | Emission { path, .. }
            | Empty { path, .. }
            | Parser { path, .. }
            | Element { path, .. }
            | Write { path, .. } => Some(path),
            UnknownBuiltin { .. } | BadParam { .. } => None,
        }
    }

    /// The 1-based line in [`SceneError::path`] the error is about, if any.
    pub fn line(&self) -> Option<u32> {
        use SceneError::*;
        match self {
            Malformed { line, .. }
            | IndexOutOfRange { line, .. }
            | NonFinite { line, .. }
            | MissingMtl { line, .. }
            | MissingMaterial { line, .. }
            | NoMaterial { line, .. }
            | Reflectance { line, .. }
            | Emission { line, .. } => Some(*line),
            _ => None,
        }
    }
}
