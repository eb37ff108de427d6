//! Writing a scene as OBJ + MTL (`ffstream scene NAME -o FILE.obj`).
//!
//! Numbers are written in Rust's shortest round-trip form, so [`super::load_obj`] on
//! the output gives back the same coordinates and materials bit for bit. Faces keep
//! their order; a `g` line is written whenever the group changes and a `usemtl` line
//! whenever the material changes, so groups come back in order of first appearance
//! (which is how every constructor numbers them). Shared vertices are written once.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use super::{Scene, SceneError};

/// Write `scene` to `obj` and its materials to the `.mtl` file beside it (same stem).
///
/// # Errors
/// [`SceneError::Write`] naming the file that could not be written.
pub fn write_obj(scene: &Scene, obj: &Path) -> Result<(), SceneError> {
    let mtl = obj.with_extension("mtl");
    let mtl_name = mtl
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene.mtl".into());

    let mut m = String::new();
    let _ = writeln!(m, "# written by ffstream from {}", scene.source);
    let _ = writeln!(m, "# Kd = diffuse reflectance, Ke = emitted exitance");
    for mat in &scene.materials {
        let [r, g, b] = mat.rho;
        let [er, eg, eb] = mat.emission;
        let _ = writeln!(
            m,
            "\nnewmtl {}\nKd {r} {g} {b}\nKe {er} {eg} {eb}",
            mat.name
        );
    }

    let mut o = String::new();
    let _ = writeln!(o, "# written by ffstream from {}", scene.source);
    let _ = writeln!(o, "# faces are one-sided, counter-clockwise = front");
    let _ = writeln!(o, "mtllib {mtl_name}");
    let mut ids: HashMap<[u64; 3], usize> = HashMap::new();
    let mut refs: Vec<Vec<usize>> = Vec::with_capacity(scene.faces.len());
    for f in &scene.faces {
        let mut r = Vec::with_capacity(f.corners.len());
        for c in &f.corners {
            let key = [c.x.to_bits(), c.y.to_bits(), c.z.to_bits()];
            let next = ids.len() + 1;
            let id = *ids.entry(key).or_insert_with(|| {
                let _ = writeln!(o, "v {} {} {}", c.x, c.y, c.z);
                next
            });
            r.push(id);
        }
        refs.push(r);
    }
    let (mut group, mut material) = (None, None);
    for (f, r) in scene.faces.iter().zip(&refs) {
        if group != Some(f.group) {
            let _ = writeln!(o, "g {}", scene.groups[f.group as usize]);
            group = Some(f.group);
            material = None; // a new group starts a new tobj model: repeat usemtl
        }
        if material != Some(f.material) {
            let _ = writeln!(o, "usemtl {}", scene.materials[f.material as usize].name);
            material = Some(f.material);
        }
        o.push('f');
        for id in r {
            let _ = write!(o, " {id}");
        }
        o.push('\n');
    }

    for (path, text) in [(&mtl, m), (&obj.to_path_buf(), o)] {
        std::fs::write(path, text).map_err(|cause| SceneError::Write {
            path: path.clone(),
            cause,
        })?;
    }
    Ok(())
}
