//! [`Builder`]: how the built-in scenes are put together, face by face.

use std::collections::HashMap;

use glam::DVec3;

use super::{Face, Material, Scene};

/// Builds a scene face by face, creating groups in order of first use (as loading the
/// written OBJ back does, so [`super::write_obj`] round-trips).
pub(super) struct Builder {
    scene: Scene,
    group_ids: HashMap<String, u32>,
}

impl Builder {
    pub(super) fn new(name: &str) -> Self {
        Builder {
            scene: Scene {
                source: format!("builtin:{name}"),
                ..Scene::default()
            },
            group_ids: HashMap::new(),
        }
    }

    /// Add a material; returns its index.
    pub(super) fn material(&mut self, name: &str, rho: [f32; 3], emission: [f32; 3]) -> u32 {
        self.scene.materials.push(Material {
            name: name.to_owned(),
            rho,
            emission,
        });
        (self.scene.materials.len() - 1) as u32
    }

    /// Add a face (3 or 4 corners, counter-clockwise seen from the front).
    pub(super) fn face(&mut self, group: &str, material: u32, corners: &[DVec3]) {
        let g = match self.group_ids.get(group) {
            Some(&g) => g,
            None => {
                let g = self.scene.groups.len() as u32;
                self.scene.groups.push(group.to_owned());
                self.group_ids.insert(group.to_owned(), g);
                g
            }
        };
        self.scene.faces.push(Face {
            corners: corners.to_vec(),
            group: g,
            material,
            line: 0,
        });
    }

    /// Add the parallelogram `o, o+u, o+u+v, o+v`, whose front normal is `u × v`.
    pub(super) fn quad(&mut self, group: &str, material: u32, o: DVec3, u: DVec3, v: DVec3) {
        self.face(group, material, &[o, o + u, o + u + v, o + v]);
    }

    pub(super) fn finish(self) -> Scene {
        debug_assert_eq!(self.scene.validate(), Ok(()));
        self.scene
    }
}
