//! Naming a scene on the command line: a file path, or a built-in scene as
//! `builtin:NAME[:PARAM]` (the form [`Scene::source`] records), or `NAME[:PARAM]`
//! when no file of that name exists.

use std::path::Path;

use super::{builtin, builtin_names, load_obj, Scene, SceneError};

/// Open the scene `spec` names: `builtin:room:200`, `cornell`, `plates:0.5` or a path
/// to an OBJ file. An existing file always wins over a built-in of the same name.
///
/// # Errors
/// As [`load_obj`] and [`builtin`](fn@builtin); a parameter that is not a number is a
/// [`SceneError::BadParam`].
pub fn open_scene(spec: &str) -> Result<Scene, SceneError> {
    let explicit = spec.strip_prefix("builtin:");
    if explicit.is_none() && Path::new(spec).exists() {
        return load_obj(Path::new(spec));
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
