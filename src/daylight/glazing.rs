//! Glazing: groups of faces that let daylight through, scaled by a visible
//! transmittance τ, instead of blocking it (`ffstream annual --glazing GROUP:TAU`;
//! docs/daylight.md, "Glazing").
//!
//! A ray of the daylight calculation (sky, ground, sun, sensor to patch) that no opaque
//! face blocks carries the product of the τ of every glazing face it crosses. Glazing
//! faces stay patches of the form-factor matrix with reflectance 0 in the daylight solve:
//! light from inside that reaches the glass leaves. The form factors themselves are
//! those of the scene with the glass opaque, so light reflected by modelled surfaces
//! *outside* reaches the room through openings only, not through glazing (the ground
//! outside is the sky dome's ground patch, which does pass).
//!
//! Each pane is tested against each ray (plane crossing, then point in polygon): the
//! cost grows with the number of glazing faces, a few hundred at most in practice.

use glam::DVec3;

use crate::patch::PatchSet;
use crate::scene::Scene;

/// One glazing face: its plane, its outline in a frame of that plane, its bounds.
#[derive(Clone, Debug)]
struct Pane {
    face: u32,
    normal: DVec3,
    origin: DVec3,
    u: DVec3,
    v: DVec3,
    outline: Vec<(f64, f64)>,
    lo: DVec3,
    hi: DVec3,
    tau: f64,
}

/// The scene's glazing (empty: every face opaque).
#[derive(Clone, Debug, Default)]
pub struct Glazing {
    panes: Vec<Pane>,
    /// Per scene face: whether it is glazing.
    is_glass: Vec<bool>,
}

impl Glazing {
    /// The faces of each group named in `groups` become glazing of transmittance τ.
    ///
    /// # Errors
    /// A group the scene does not have (the message lists its groups), a group named
    /// twice, or τ outside (0, 1].
    pub fn new(scene: &Scene, groups: &[(String, f64)]) -> Result<Self, String> {
        let mut g = Glazing {
            panes: Vec::new(),
            is_glass: vec![false; scene.faces.len()],
        };
        for (k, (name, tau)) in groups.iter().enumerate() {
            if !(*tau > 0.0 && *tau <= 1.0) {
                return Err(format!(
                    "group {name}: transmittance {tau} must lie in (0, 1]"
                ));
            }
            if groups[..k].iter().any(|(n, _)| n == name) {
                return Err(format!("group {name} given twice"));
            }
            let Some(id) = scene.groups.iter().position(|n| n == name) else {
                return Err(format!(
                    "group {name} is not in the scene (groups: {})",
                    scene.groups.join(", ")
                ));
            };
            for (f, face) in scene.faces.iter().enumerate() {
                if face.group as usize != id {
                    continue;
                }
                let normal = face.normal();
                let origin = face.corners[0];
                let u = (face.corners[1] - origin).normalize();
                let v = normal.cross(u);
                let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
                for &c in &face.corners {
                    lo = lo.min(c);
                    hi = hi.max(c);
                }
                g.is_glass[f] = true;
                g.panes.push(Pane {
                    face: f as u32,
                    normal,
                    origin,
                    u,
                    v,
                    outline: face
                        .corners
                        .iter()
                        .map(|&c| ((c - origin).dot(u), (c - origin).dot(v)))
                        .collect(),
                    lo,
                    hi,
                    tau: *tau,
                });
            }
        }
        Ok(g)
    }

    /// Whether there is no glazing.
    pub fn is_empty(&self) -> bool {
        self.panes.is_empty()
    }

    /// Number of glazing faces.
    pub fn faces(&self) -> usize {
        self.panes.len()
    }

    /// Whether scene face `face` is glazing.
    pub fn is_glass(&self, face: u32) -> bool {
        self.is_glass.get(face as usize).copied().unwrap_or(false)
    }

    /// The scene's triangles that block light: all but the glazing's (for the
    /// daylight occluders), with their face numbers.
    pub fn opaque_triangles(&self, scene: &Scene) -> Vec<(u32, [DVec3; 3])> {
        scene
            .triangles()
            .filter(|(f, _)| !self.is_glass(*f))
            .collect()
    }

    /// Give the glazing patches of `patches` reflectance 0 (module docs).
    pub fn darken(&self, patches: &mut PatchSet) {
        for p in &mut patches.patches {
            if self.is_glass(p.face) {
                p.rho = [0.0; 3];
            }
        }
    }

    /// The share of light that passes along the segment `a` → `b` through the glazing:
    /// the product of τ over the panes the segment crosses (strictly: a segment that
    /// starts or ends in a pane's plane does not cross it), the faces `ignore` (those the
    /// segment's ends lie on) left out.
    pub fn transmittance(&self, a: DVec3, b: DVec3, ignore: (u32, u32)) -> f64 {
        let (lo, hi) = (a.min(b), a.max(b));
        let mut t = 1.0;
        for p in &self.panes {
            if p.face == ignore.0
                || p.face == ignore.1
                || hi.cmplt(p.lo).any()
                || lo.cmpgt(p.hi).any()
            {
                continue;
            }
            let (da, db) = ((a - p.origin).dot(p.normal), (b - p.origin).dot(p.normal));
            if !((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
                continue;
            }
            let x = a + (b - a) * (da / (da - db)) - p.origin;
            if inside(&p.outline, x.dot(p.u), x.dot(p.v)) {
                t *= p.tau;
            }
        }
        t
    }
}

/// Even-odd test of the point (a, b) against a polygon in its plane (`daylight::scene`
/// also places its sensors with it).
pub(crate) fn inside(poly: &[(f64, f64)], a: f64, b: f64) -> bool {
    let mut inside = false;
    for k in 0..poly.len() {
        let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
        if (p.1 > b) != (q.1 > b) && a < p.0 + (b - p.1) / (q.1 - p.1) * (q.0 - p.0) {
            inside = !inside;
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_through_panes_carry_their_transmittances() {
        // The office's window hole, glazed with two panes one behind the other.
        let mut s = crate::scene::builtin("office", None).unwrap();
        let pane = |y: f64| {
            vec![
                DVec3::new(1.0, y, 0.9),
                DVec3::new(3.0, y, 0.9),
                DVec3::new(3.0, y, 2.1),
                DVec3::new(1.0, y, 2.1),
            ]
        };
        for (name, y) in [("outer", -0.1), ("inner", 0.0)] {
            s.groups.push(name.into());
            s.faces.push(crate::scene::Face {
                corners: pane(y),
                group: s.groups.len() as u32 - 1,
                material: 0,
                line: 0,
            });
        }
        let g = Glazing::new(&s, &[("outer".into(), 0.5), ("inner".into(), 0.8)]).unwrap();
        assert_eq!(g.faces(), 2);
        let inside = DVec3::new(2.0, 3.0, 1.0);
        let (outer, inner) = (s.faces.len() as u32 - 2, s.faces.len() as u32 - 1);
        // Out through both panes; through the wall beside them (no glass); stopping
        // between them; from a point in the inner pane's plane; ignoring a pane.
        let t = |a: DVec3, b: DVec3, ignore: u32| g.transmittance(a, b, (ignore, u32::MAX));
        assert!((t(inside, DVec3::new(2.0, -5.0, 1.8), u32::MAX) - 0.4).abs() < 1e-15);
        assert_eq!(t(inside, DVec3::new(8.0, -5.0, 1.5), u32::MAX), 1.0);
        assert!((t(inside, DVec3::new(2.0, -0.05, 1.0), u32::MAX) - 0.8).abs() < 1e-15);
        assert!(
            (t(
                DVec3::new(2.0, 0.0, 1.5),
                DVec3::new(2.0, -1.0, 1.5),
                u32::MAX
            ) - 0.5)
                .abs()
                < 1e-15
        );
        assert!((t(inside, DVec3::new(2.0, -5.0, 1.8), inner) - 0.5).abs() < 1e-15);
        assert!((t(inside, DVec3::new(2.0, -5.0, 1.8), outer) - 0.8).abs() < 1e-15);
        assert!(g.is_glass(inner) && !g.is_glass(0));

        let err = |groups: &[(String, f64)]| Glazing::new(&s, groups).unwrap_err();
        assert!(err(&[("nope".into(), 0.5)]).contains("groups: floor"));
        assert!(err(&[("inner".into(), 0.0)]).contains("(0, 1]"));
        assert!(err(&[("inner".into(), 1.5)]).contains("(0, 1]"));
        assert!(err(&[("inner".into(), 0.5), ("inner".into(), 0.6)]).contains("twice"));
    }
}
