//! What every mesh loader shares once its format is parsed: polygons to faces (repaired
//! by [`super::polygon::repair`]), groups in order of first use, materials by group
//! name from a materials file, coordinate checks, and the closing checks and warnings
//! (no face left, no emitter, duplicate faces), each naming the file and the element
//! (`line` for OBJ, `facet` for STL, `face` for PLY, `triangle` for glTF).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::polygon::{repair, Repair};
use super::{Face, Material, Scene, SceneError};

/// Largest vertex coordinate magnitude accepted: beyond it squares overflow, so edge
/// lengths and areas of the faces would be infinite.
pub(super) const MAX_COORDINATE: f64 = 1e150;

/// Reflectance of faces whose group has no material anywhere (docs/scenes.md
/// §5): a mid grey that neither emits nor absorbs everything.
const FALLBACK_KD: f32 = 0.5;

/// Name of the materials file entry used for groups it does not name.
pub(super) const DEFAULT_MATERIAL: &str = "default";

/// Count and first element (line, facet, ...) of one kind of repair.
#[derive(Default)]
pub(super) struct Count {
    pub(super) n: usize,
    pub(super) first: u32,
}

impl Count {
    pub(super) fn note(&mut self, at: u32) {
        if self.n == 0 {
            self.first = at;
        }
        self.n += 1;
    }
}

/// The repairs made while loading, one [`Count`] per kind.
#[derive(Default)]
pub(super) struct Tally {
    pub(super) degenerate: Count,
    pub(super) nonplanar: Count,
    pub(super) nonconvex: Count,
    /// OBJ line elements (`l`), which are not surfaces.
    pub(super) lines: Count,
}

impl Tally {
    pub(super) fn note(&mut self, what: Repair, at: u32) {
        match what {
            Repair::Degenerate => self.degenerate.note(at),
            Repair::NonPlanar => self.nonplanar.note(at),
            Repair::NonConvex => self.nonconvex.note(at),
            Repair::None | Repair::Triangulated => {}
        }
    }

    /// One warning line per kind of repair made, naming the first `unit` concerned.
    fn warn(&self, out: &mut Vec<String>, p: &str, unit: &str) {
        let items = [
            (
                &self.degenerate,
                "dropped",
                "degenerate face(s) (zero area or collinear corners)",
            ),
            (
                &self.nonplanar,
                "split",
                "non-planar polygon(s) into triangles",
            ),
            (
                &self.nonconvex,
                "split",
                "non-convex quad(s) into triangles",
            ),
            (&self.lines, "ignored", "line element(s) (`l`)"),
        ];
        for (c, verb, what) in items {
            if c.n > 0 {
                out.push(format!(
                    "{p}: {verb} {} {what}, first at {unit} {}",
                    c.n, c.first
                ));
            }
        }
    }
}

/// The checks every loader ends with: the repairs of `tally` as warnings, an error when
/// no face is left, warnings for a scene without emitter and for duplicate faces.
/// `unit` names what [`Face::line`] counts in this format.
///
/// # Errors
/// [`SceneError::Empty`] when `scene` has no faces.
pub(super) fn finish(
    path: &Path,
    mut scene: Scene,
    tally: &Tally,
    unit: &'static str,
) -> Result<Scene, SceneError> {
    let p = path.display().to_string();
    scene.element = unit;
    scene.dropped = tally.degenerate.n;
    tally.warn(&mut scene.warnings, &p, unit);
    if scene.faces.is_empty() {
        let d = &tally.degenerate;
        let dropped = if d.n == 0 {
            String::new()
        } else {
            format!(
                " (dropped {} degenerate face(s): zero area, collinear corners or an area \
                 too large for f64; first at {unit} {})",
                d.n, d.first
            )
        };
        return Err(SceneError::Empty {
            path: path.to_owned(),
            dropped,
        });
    }
    if !scene.has_emitter() {
        scene.warnings.push(format!("{p}: {}", super::NO_EMITTER));
    }
    let dups = super::duplicates::coincident_duplicates(&scene.faces);
    if let Some(w) =
        super::duplicates::duplicates_warning(&p, &scene.faces, &scene.groups, &dups, unit)
    {
        scene.warnings.push(w);
    }
    debug_assert_eq!(scene.validate(), Ok(()));
    Ok(scene)
}

/// A parser's error message on one line (some span several, which would break the
/// one-line error every bad input gets).
pub(super) fn one_line(message: impl std::fmt::Display) -> String {
    message
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// A coordinate as the loaders accept it: finite and at most [`MAX_COORDINATE`].
///
/// # Errors
/// [`SceneError::Element`] naming `path`, `unit` and `at`.
pub(super) fn check_point(
    path: &Path,
    unit: &str,
    at: u32,
    p: [f64; 3],
) -> Result<DVec3, SceneError> {
    match p.iter().find(|x| !(x.is_finite() && x.abs() <= MAX_COORDINATE)) {
        None => Ok(DVec3::from_array(p)),
        Some(x) => Err(SceneError::Element {
            path: path.to_owned(),
            element: format!("{unit} {at}"),
            reason: format!(
                "vertex coordinate {x} is not finite or too large (|x| ≤ 1e150 keeps lengths and areas finite)"
            ),
        }),
    }
}

/// The materials file of a mesh format that has none of its own (STL, PLY) or whose
/// materials it overrides (glTF): `NAME.mtl` beside `NAME.stl`, an MTL file whose
/// `newmtl` names are group names, `newmtl default` for the groups it does not name.
pub(super) fn materials_file(mesh: &Path) -> PathBuf {
    mesh.with_extension("mtl")
}

/// Builds a scene from the polygons of a mesh format: groups by name in order of first
/// use, a material per group, repairs counted in a [`Tally`].
pub(super) struct Assembler<'p> {
    path: &'p Path,
    unit: &'static str,
    scene: Scene,
    tally: Tally,
    groups: HashMap<String, u32>,
    /// Materials of the materials file by name.
    named: HashMap<String, u32>,
    /// Index in `scene.materials` of the fallback grey, once used.
    fallback: Option<u32>,
    /// Groups that got the fallback grey (for one warning).
    unmatched: Vec<String>,
}

impl<'p> Assembler<'p> {
    /// An assembler for the mesh at `path`, whose elements are called `unit`; reads the
    /// materials file beside it when there is one.
    ///
    /// # Errors
    /// As [`super::mtl::read_mtl`] for a materials file that exists but is not valid.
    pub(super) fn new(path: &'p Path, unit: &'static str) -> Result<Self, SceneError> {
        let mut scene = Scene {
            source: path.display().to_string(),
            ..Scene::default()
        };
        let mtl = materials_file(path);
        if mtl.is_file() {
            scene.materials = super::mtl::read_mtl(&mtl, &mut scene.warnings)?;
        }
        let named = scene
            .materials
            .iter()
            .enumerate()
            .map(|(k, m)| (m.name.clone(), k as u32))
            .collect();
        Ok(Assembler {
            path,
            unit,
            scene,
            tally: Tally::default(),
            groups: HashMap::new(),
            named,
            fallback: None,
            unmatched: Vec::new(),
        })
    }

    /// Add a warning (a line naming the file).
    pub(super) fn warn(&mut self, w: String) {
        self.scene.warnings.push(w);
    }

    /// Add a material the mesh file itself defines (glTF); returns its index.
    pub(super) fn own_material(&mut self, m: Material) -> u32 {
        self.scene.materials.push(m);
        (self.scene.materials.len() - 1) as u32
    }

    /// The material of group `group`: the materials file's entry of that name, else
    /// `own` (the mesh file's), else the file's `default`, else the fallback grey.
    pub(super) fn material_for(&mut self, group: &str, own: Option<u32>) -> u32 {
        if let Some(&m) = self.named.get(group) {
            return m;
        }
        if let Some(m) = own {
            return m;
        }
        if let Some(&m) = self.named.get(DEFAULT_MATERIAL) {
            return m;
        }
        if !self.unmatched.iter().any(|g| g == group) {
            self.unmatched.push(group.to_owned());
        }
        *self.fallback.get_or_insert_with(|| {
            self.scene.materials.push(Material {
                name: "ffstream_fallback".into(),
                rho: [FALLBACK_KD; 3],
                emission: [0.0; 3],
            });
            (self.scene.materials.len() - 1) as u32
        })
    }

    /// Add the polygon `corners` (element `at`, 1-based) to group `group` with
    /// material `material`, repaired as OBJ faces are.
    pub(super) fn polygon(&mut self, group: &str, material: u32, at: u32, corners: &[DVec3]) {
        let (parts, what) = repair(corners);
        self.tally.note(what, at);
        if parts.is_empty() {
            return;
        }
        let next = self.groups.len() as u32;
        let g = *self.groups.entry(group.to_owned()).or_insert_with(|| {
            self.scene.groups.push(group.to_owned());
            next
        });
        for corners in parts {
            self.scene.faces.push(Face {
                corners,
                group: g,
                material,
                line: at,
            });
        }
    }

    /// The scene, after [`finish`]'s checks; warns once about groups that got the
    /// fallback grey.
    ///
    /// # Errors
    /// As [`finish`].
    pub(super) fn finish(mut self) -> Result<Scene, SceneError> {
        if !self.unmatched.is_empty() {
            let shown = self.unmatched.len().min(5);
            let more = match self.unmatched.len() - shown {
                0 => String::new(),
                m => format!(" and {m} more"),
            };
            self.scene.warnings.push(format!(
                "{}: no material for group(s) {}{more} (no `newmtl NAME` or `newmtl {DEFAULT_MATERIAL}` in {}): reflectance {FALLBACK_KD}, no emission",
                self.path.display(),
                self.unmatched[..shown].join(", "),
                materials_file(self.path).display(),
            ));
        }
        finish(self.path, self.scene, &self.tally, self.unit)
    }
}
