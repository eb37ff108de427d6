//! Naming a scene on the command line: a file path (its format from the extension, or
//! from a `FORMAT:` prefix such as `stl:mesh.dat`), or a built-in scene as
//! `builtin:NAME[:PARAM]` (the form [`Scene::source`] records), or `NAME[:PARAM]`
//! when no file of that name exists.

use std::path::{Path, PathBuf};

use super::{builtin, builtin_names, load_obj, Scene, SceneError};

/// The mesh file formats a scene can be read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// Wavefront OBJ with MTL materials ([`load_obj`]).
    Obj,
    /// STL, ASCII or binary.
    Stl,
    /// PLY, ASCII or binary.
    Ply,
    /// glTF 2.0, `.gltf` + buffers or `.glb`.
    Gltf,
}

impl SceneFormat {
    /// Names accepted in a `FORMAT:` prefix and by `--format` (`glb` is `gltf`).
    pub const NAMES: [&'static str; 5] = ["obj", "stl", "ply", "gltf", "glb"];

    /// The format of a name in [`SceneFormat::NAMES`] (any case).
    pub fn from_name(name: &str) -> Option<SceneFormat> {
        match name.to_ascii_lowercase().as_str() {
            "obj" => Some(SceneFormat::Obj),
            "stl" => Some(SceneFormat::Stl),
            "ply" => Some(SceneFormat::Ply),
            "gltf" | "glb" => Some(SceneFormat::Gltf),
            _ => None,
        }
    }

    /// The format of a file by its extension; OBJ for any other extension (files
    /// without one have always been read as OBJ).
    pub fn of_path(path: &Path) -> SceneFormat {
        path.extension()
            .and_then(|e| e.to_str())
            .and_then(SceneFormat::from_name)
            .unwrap_or(SceneFormat::Obj)
    }
}

/// Load the mesh file `path` in `format`.
///
/// # Errors
/// The loader's [`SceneError`], naming the file and the line or element.
pub fn load_file(path: &Path, format: SceneFormat) -> Result<Scene, SceneError> {
    match format {
        SceneFormat::Obj => load_obj(path),
        SceneFormat::Stl => super::stl::load_stl(path),
        SceneFormat::Ply => super::ply::load_ply(path),
        SceneFormat::Gltf => super::gltf::load_gltf(path),
    }
}

/// A scene as named (`builtin:room:200`, `cornell`, `plates:0.5`, a path to a mesh
/// file, or `FORMAT:PATH` such as `stl:mesh.dat`) and what the name stands for. The
/// name is kept as given: the file header records it (`scene_path`), and a resume or
/// `solve` opens it again.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSpec {
    text: String,
    source: SceneSource,
}

/// What a [`SceneSpec`] stands for.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    /// A mesh file read in `format` (a name that is neither an existing file nor a
    /// built-in scene is taken for a missing OBJ file, which opening then reports).
    File { path: PathBuf, format: SceneFormat },
    /// A built-in scene ([`builtin`](fn@builtin)) and its parameter.
    Builtin { name: String, param: Option<f64> },
}

impl SceneSpec {
    /// What `text` names. An existing file always wins over a built-in of the same
    /// name; `builtin:` says a built-in whatever files exist.
    ///
    /// # Errors
    /// [`SceneError::BadParam`] for a built-in's parameter that is not a number.
    pub fn parse(text: &str) -> Result<SceneSpec, SceneError> {
        let named = |source| {
            Ok(SceneSpec {
                text: text.to_owned(),
                source,
            })
        };
        let explicit = text.strip_prefix("builtin:");
        if explicit.is_none() && Path::new(text).exists() {
            let path = PathBuf::from(text);
            let format = SceneFormat::of_path(&path);
            return named(SceneSource::File { path, format });
        }
        if let Some((name, path)) = text.split_once(':') {
            if let Some(format) = SceneFormat::from_name(name) {
                let path = PathBuf::from(path);
                return named(SceneSource::File { path, format });
            }
        }
        let body = explicit.unwrap_or(text);
        let (name, param) = match body.split_once(':') {
            Some((n, p)) => (n, Some(p)),
            None => (body, None),
        };
        if explicit.is_none() && !builtin_names().contains(&name) {
            // Neither a file nor a built-in: opening reports the missing file.
            let path = PathBuf::from(text);
            return named(SceneSource::File {
                path,
                format: SceneFormat::Obj,
            });
        }
        let param = match param {
            None => None,
            Some(p) => Some(p.parse::<f64>().map_err(|_| SceneError::BadParam {
                name: name.to_owned(),
                reason: format!("parameter `{p}` is not a number"),
            })?),
        };
        let name = name.to_owned();
        named(SceneSource::Builtin { name, param })
    }

    /// The name as given.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// What the name stands for.
    pub fn source(&self) -> &SceneSource {
        &self.source
    }

    /// Load the scene.
    ///
    /// # Errors
    /// As [`load_file`] and [`builtin`](fn@builtin).
    pub fn open(&self) -> Result<Scene, SceneError> {
        match &self.source {
            SceneSource::File { path, format } => load_file(path, *format),
            SceneSource::Builtin { name, param } => builtin(name, *param),
        }
    }
}

impl std::fmt::Display for SceneSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

/// Open the scene `spec` names ([`SceneSpec::parse`], then [`SceneSpec::open`]).
///
/// # Errors
/// As [`load_file`] and [`builtin`](fn@builtin); a parameter that is not a number is a
/// [`SceneError::BadParam`].
pub fn open_scene(spec: &str) -> Result<Scene, SceneError> {
    SceneSpec::parse(spec)?.open()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs() {
        assert_eq!(
            open_scene("builtin:cornell").unwrap(),
            builtin("cornell", None).unwrap()
        );
        assert_eq!(
            open_scene("plates:0.5").unwrap(),
            builtin("plates", Some(0.5)).unwrap()
        );
        assert_eq!(open_scene("builtin:room:3").unwrap().source, "builtin:room");
        assert!(matches!(
            open_scene("room:x"),
            Err(SceneError::BadParam { .. })
        ));
        assert!(matches!(
            open_scene("builtin:nope"),
            Err(SceneError::UnknownBuiltin { .. })
        ));
        assert!(matches!(
            open_scene("no/such/file.obj"),
            Err(SceneError::Read { .. })
        ));
    }

    /// A name says what it stands for: a built-in with or without its parameter, an
    /// existing file by its extension, `FORMAT:PATH`, and a name that is neither a file
    /// nor a built-in (a missing OBJ, which opening reports); the name is kept as given.
    #[test]
    fn a_scene_name_is_typed_and_kept_as_given() {
        let builtin = |name: &str, param| SceneSource::Builtin {
            name: name.into(),
            param,
        };
        let cases = [
            ("builtin:room:64", builtin("room", Some(64.0))),
            ("builtin:cornell", builtin("cornell", None)),
            ("plates:0.5", builtin("plates", Some(0.5))),
            (
                "stl:mesh.dat",
                SceneSource::File {
                    path: "mesh.dat".into(),
                    format: SceneFormat::Stl,
                },
            ),
            (
                "no_such_file.stl",
                SceneSource::File {
                    path: "no_such_file.stl".into(),
                    format: SceneFormat::Obj,
                },
            ),
        ];
        for (text, want) in cases {
            let spec = SceneSpec::parse(text).unwrap();
            assert_eq!(spec.source(), &want, "{text}");
            assert_eq!(spec.as_str(), text);
            assert_eq!(spec.to_string(), text);
        }
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("cornell.ply");
        std::fs::write(&file, "").unwrap();
        let text = file.to_str().unwrap();
        assert_eq!(
            SceneSpec::parse(text).unwrap().source(),
            &SceneSource::File {
                path: file.clone(),
                format: SceneFormat::Ply
            }
        );
        assert!(matches!(
            SceneSpec::parse("builtin:room:many"),
            Err(SceneError::BadParam { .. })
        ));
        assert_eq!(
            SceneSpec::parse("builtin:cube").unwrap().open().unwrap(),
            builtin_scene("cube")
        );
    }

    fn builtin_scene(name: &str) -> Scene {
        builtin(name, None).unwrap()
    }
}
