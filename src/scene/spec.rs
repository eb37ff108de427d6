//! Naming a scene on the command line: a file path (its format from the extension, or
//! from a `FORMAT:` prefix such as `stl:mesh.dat`), or a built-in scene as
//! `builtin:NAME[:PARAM]` (the form [`Scene::source`] records), or `NAME[:PARAM]`
//! when no file of that name exists.

use std::path::Path;

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

/// Open the scene `spec` names: `builtin:room:200`, `cornell`, `plates:0.5`, a path to
/// a mesh file (OBJ, STL, PLY, glTF by extension) or `FORMAT:PATH` (`stl:mesh.dat`).
/// An existing file always wins over a built-in of the same name.
///
/// # Errors
/// As [`load_file`] and [`builtin`](fn@builtin); a parameter that is not a number is a
/// [`SceneError::BadParam`].
pub fn open_scene(spec: &str) -> Result<Scene, SceneError> {
    let explicit = spec.strip_prefix("builtin:");
    if explicit.is_none() && Path::new(spec).exists() {
        let path = Path::new(spec);
        return load_file(path, SceneFormat::of_path(path));
    }
    if let Some((name, path)) = spec.split_once(':') {
        if let Some(format) = SceneFormat::from_name(name) {
            return load_file(Path::new(path), format);
        }
    }
    let body = explicit.unwrap_or(spec);
    let (name, param) = match body.split_once(':') {
        Some((n, p)) => (n, Some(p)),
        None => (body, None),
    };
    if explicit.is_none() && !builtin_names().contains(&name) {
        // Neither a file nor a built-in: report the missing file.
        return load_obj(Path::new(spec));
    }
    let param = match param {
        None => None,
        Some(p) => Some(p.parse::<f64>().map_err(|_| SceneError::BadParam {
            name: name.to_owned(),
            reason: format!("parameter `{p}` is not a number"),
        })?),
    };
    builtin(name, param)
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
}
