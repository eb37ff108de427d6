//! Daylight inside a scene: what each patch and each sensor receives directly from the
//! sky patches, the ground and the sun, with visibility through the scene's geometry,
//! and the sensors' view of the patches (for the inter-reflected light).
//!
//! Openings are holes in the mesh: a ray that leaves the scene's bounding box without
//! hitting a triangle sees the sky (upwards) or the ground (downwards; the dome's ground
//! patch). Every triangle is opaque from both sides, except glazing
//! ([`super::glazing`]): a ray through glass carries the glass's transmittance.
//!
//! Integration rules (deterministic, no random numbers):
//! - over a patch: each of its triangles is cut into four by its edge midpoints and the
//!   four centroids carry a quarter of the triangle's area each (`level 1`), or the
//!   triangle's centroid carries it all (`level 0`);
//! - over a sky patch: the dome's equal-solid-angle cells, one ray per cell (the ground
//!   by the same cells mirrored below the horizon);
//! - sensor to patch: the exact point-to-polygon form factor of the part of the patch in
//!   front of the sensor (Lambert's formula), times the patch's visible fraction seen from
//!   the sensor, estimated with the patch's integration points weighted by the
//!   point-to-point kernel cos θ cos θ' / r².

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::DVec3;

use super::dome::SkyDome;
use super::glazing::{inside, Glazing};
use super::input::InputError;
use crate::formfactor::clip::Polygon;
use crate::formfactor::shadow::point_polygon;
use crate::geometry::occluders::Occluders;
use crate::patch::{Patch, PatchSet};

/// A point where illuminance is wanted, with the normal of the surface it lies on.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    pub name: String,
    pub point: DVec3,
    /// Unit normal.
    pub normal: DVec3,
}

/// The header a sensors file starts with.
pub const SENSORS_HEADER: &str = "name,x,y,z,nx,ny,nz";

/// Read sensors from a CSV file with header `name,x,y,z,nx,ny,nz` (the normal need not be
/// unit length; it is normalised). Blank lines and lines starting with `#` are skipped.
///
/// # Errors
/// The file cannot be read; the header is not the expected one; a line has the wrong
/// number of fields, a non-number, a non-finite coordinate, a zero normal, or a name
/// used before (each naming the file and line).
pub fn read_sensors(path: &Path) -> Result<Vec<Sensor>, InputError> {
    let bytes = crate::input::read(path).map_err(|e| InputError::io(path, e))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        InputError::file(path, format!("not UTF-8 text (byte {at})"))
    })?;
    let at = |line: usize, what: String| InputError::at(path, line, what);
    let mut records = crate::table::records(&text);
    match records.next() {
        Some(Ok(h)) if h.fields.join(",") == SENSORS_HEADER => {}
        Some(Ok(h)) => {
            return Err(at(
                h.line,
                format!(
                    "header `{}`: expected `{SENSORS_HEADER}`",
                    h.fields.join(",")
                ),
            ))
        }
        Some(Err((line, e))) => return Err(at(line, e)),
        None => {
            return Err(at(
                1,
                format!("empty: expected the header `{SENSORS_HEADER}`"),
            ))
        }
    }
    let mut out: Vec<Sensor> = Vec::new();
    for r in records {
        let crate::table::Record { line: k, fields: f } = r.map_err(|(l, e)| at(l, e))?;
        if f.len() != 7 {
            return Err(at(
                k,
                format!("{} fields, expected 7 ({SENSORS_HEADER})", f.len()),
            ));
        }
        let mut v = [0.0; 6];
        for (c, x) in v.iter_mut().enumerate() {
            let name = SENSORS_HEADER.split(',').nth(c + 1).unwrap_or("?");
            *x = f[c + 1]
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| at(k, format!("{name} `{}` is not a finite number", f[c + 1])))?;
        }
        let normal = DVec3::new(v[3], v[4], v[5]);
        if normal.length_squared() == 0.0 {
            return Err(at(k, "the normal is zero".into()));
        }
        if f[0].is_empty() {
            return Err(at(k, "empty name".into()));
        }
        if out.iter().any(|s| s.name == f[0]) {
            return Err(at(k, format!("sensor name `{}` used twice", f[0])));
        }
        out.push(Sensor {
            name: f[0].clone(),
            point: DVec3::new(v[0], v[1], v[2]),
            normal: normal.normalize(),
        });
    }
    if out.is_empty() {
        return Err(at(1, "no sensors".into()));
    }
    Ok(out)
}

/// Most lattice points [`grid_sensors`] tries: a million sensors would need about
/// 400 GB over a year (0.4 MB each: 9600 sensors of `builtin:office` peaked at 4.1 GB).
pub const MAX_GRID_POINTS: usize = 1_000_000;

/// A point in a face's plane.
type Flat = (f64, f64);

/// Face `f` in its own plane (first corner at the origin, first edge along the first
/// axis), the lattice of pitch `spacing` over its bounding rectangle (points along
/// each axis, as f64 so that no count overflows) and the rectangle's low corner.
fn lattice(f: &crate::scene::Face, spacing: f64) -> (Vec<Flat>, (f64, f64), Flat) {
    let n = f.normal();
    let o = f.corners[0];
    let u = (f.corners[1] - o).normalize();
    let v = n.cross(u);
    let flat: Vec<Flat> = f
        .corners
        .iter()
        .map(|&c| ((c - o).dot(u), (c - o).dot(v)))
        .collect();
    let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
    for &(a, b) in &flat {
        lo = (lo.0.min(a), lo.1.min(b));
        hi = (hi.0.max(a), hi.1.max(b));
    }
    let counts = (
        ((hi.0 - lo.0) / spacing).floor() + 1.0,
        ((hi.1 - lo.1) / spacing).floor() + 1.0,
    );
    (flat, counts, lo)
}

/// Sensors on a grid over the faces of group `group` of `scene`: on each face, the
/// points of a square lattice of pitch `spacing` (aligned with the face's first edge,
/// starting half a pitch in from the corner of the face's bounding rectangle) that lie
/// inside the face, lifted `offset` along the face's normal and facing along it. Named
/// `GROUP_k`, k from 0 in face order.
///
/// # Errors
/// No group of that name (the message lists the groups), a spacing that is not a
/// positive finite number, more than [`MAX_GRID_POINTS`] lattice points to try, or no
/// point on the group.
pub fn grid_sensors(
    scene: &crate::scene::Scene,
    group: &str,
    spacing: f64,
    offset: f64,
) -> Result<Vec<Sensor>, String> {
    if !(spacing.is_finite() && spacing > 0.0 && offset.is_finite()) {
        return Err(format!(
            "grid spacing {spacing} and offset {offset} must be finite, the spacing > 0"
        ));
    }
    let Some(g) = scene.groups.iter().position(|n| n == group) else {
        return Err(format!(
            "no group `{group}` in the scene (groups: {})",
            scene.groups.join(", ")
        ));
    };
    // Counted before any is made: `floor:1e-4` made billions of points and aborted
    // allocating 4.8 GB (issue 48).
    let tries: f64 = scene
        .faces
        .iter()
        .filter(|f| f.group as usize == g)
        .map(|f| {
            let (na, nb) = lattice(f, spacing).1;
            na * nb
        })
        .sum();
    if tries > MAX_GRID_POINTS as f64 {
        return Err(format!(
            "spacing {spacing} gives about {tries:.3e} grid points on group `{group}`, more than \
             the {MAX_GRID_POINTS} supported (each sensor costs about 0.4 MB over a year): use a \
             larger spacing"
        ));
    }
    let mut out = Vec::new();
    for f in scene.faces.iter().filter(|f| f.group as usize == g) {
        let n = f.normal();
        let o = f.corners[0];
        let u = (f.corners[1] - o).normalize();
        let v = n.cross(u);
        let (flat, (na, nb), lo) = lattice(f, spacing);
        let (na, nb) = (na as usize, nb as usize);
        for i in 0..na {
            for j in 0..nb {
                let (a, b) = (
                    lo.0 + (i as f64 + 0.5) * spacing,
                    lo.1 + (j as f64 + 0.5) * spacing,
                );
                if inside(&flat, a, b) {
                    out.push(Sensor {
                        name: format!("{group}_{}", out.len()),
                        point: o + u * a + v * b + n * offset,
                        normal: n,
                    });
                }
            }
        }
    }
    if out.is_empty() {
        return Err(format!(
            "no grid point falls on group `{group}` at spacing {}",
            crate::brief_number(spacing)
        ));
    }
    Ok(out)
}

/// The plane of group `group` when all its faces lie in one plane: an origin and two
/// unit axes in it (the first face's first edge, and normal × that), for maps of a grid.
/// `None` for a group that is not planar or does not exist.
pub fn group_plane(scene: &crate::scene::Scene, group: &str) -> Option<(DVec3, DVec3, DVec3)> {
    let g = scene.groups.iter().position(|n| n == group)?;
    let mut faces = scene.faces.iter().filter(|f| f.group as usize == g);
    let first = faces.next()?;
    let n = first.normal();
    let o = first.corners[0];
    let (lo, hi) = scene.bounds();
    let tol = 1e-9 * (hi - lo).length().max(f64::MIN_POSITIVE);
    let planar = faces.all(|f| {
        f.normal().dot(n) > 1.0 - 1e-9 && f.corners.iter().all(|&c| (c - o).dot(n).abs() <= tol)
    });
    if !planar {
        return None;
    }
    let u = (first.corners[1] - o).normalize();
    Some((o, u, n.cross(u)))
}

/// Integration points of a patch: `(point, area weight)`, weights summing to the area.
/// Each triangle of the patch is cut `level` times into four by its edge midpoints and
/// the centroids of the 4^level pieces carry their areas.
pub fn patch_points(p: &Patch, level: u8) -> Vec<(DVec3, f64)> {
    fn split(t: [DVec3; 3], area: f64, level: u8, out: &mut Vec<(DVec3, f64)>) {
        if level == 0 {
            out.push(((t[0] + t[1] + t[2]) / 3.0, area));
            return;
        }
        let [a, b, d] = t;
        let (ab, bd, da) = ((a + b) * 0.5, (b + d) * 0.5, (d + a) * 0.5);
        for q in [[a, ab, da], [ab, b, bd], [da, bd, d], [ab, bd, da]] {
            split(q, area / 4.0, level - 1, out);
        }
    }
    let c = p.corners();
    let mut out = Vec::new();
    for k in 1..c.len() - 1 {
        let t = [c[0], c[k], c[k + 1]];
        let area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        split(t, area, level, &mut out);
    }
    out
}

/// Integration level of the sun on a patch whose first points are partly lit (the sun
/// patch's edge crosses it): 4^5 = 1024 points per triangle.
pub const SUN_EDGE_LEVEL: u8 = 5;

/// The scene's geometry as daylight sees it.
pub struct SceneLight<'a> {
    pub patches: &'a PatchSet,
    pub occluders: &'a Occluders,
    /// Length of a ray that surely leaves the scene.
    reach: f64,
    /// Integration level over patches: 4^level points per triangle (module docs).
    pub level: u8,
    /// Threads (≥ 1).
    pub threads: usize,
    /// Rotation from east–north–up to the scene's axes (identity: x east, y north, z
    /// up). Sky and sun directions are given in east–north–up.
    pub frame: glam::DMat3,
    /// Faces that pass light scaled by their transmittance; their triangles must not be
    /// in `occluders` (empty: none).
    pub glazing: Glazing,
}

/// Which of the scene's axes points up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpAxis {
    /// x east, y north, z up.
    #[default]
    Z,
    /// x east, y up, −z north (the glTF and OpenGL habit).
    Y,
}

/// The rotation taking east–north–up directions into a scene whose up axis is `up`, with
/// the scene's north axis pointing `rotate` degrees clockwise from true north seen from
/// above (90: the scene's north axis points east, so a wall facing the scene's south
/// faces west).
pub fn scene_frame(up: UpAxis, rotate: f64) -> glam::DMat3 {
    // True azimuth θ along the scene's north axis: a turn by +θ about up takes it there.
    let turn = glam::DMat3::from_rotation_z(rotate.to_radians());
    let axes = match up {
        UpAxis::Y => glam::DMat3::from_cols(DVec3::X, -DVec3::Z, DVec3::Y),
        UpAxis::Z => glam::DMat3::IDENTITY,
    };
    axes * turn
}

/// Map `f` over `0..n` on `threads` threads, results in index order.
pub(crate) fn par_map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let mut parts: Vec<Vec<(usize, T)>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads.max(1))
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= n {
                            break mine;
                        }
                        mine.push((i, f(i)));
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a daylight thread panicked"))
            .collect()
    });
    let mut slots: Vec<Option<T>> = (0..n).map(|_| None).collect();
    for part in parts.drain(..) {
        for (i, v) in part {
            slots[i] = Some(v);
        }
    }
    slots
        .into_iter()
        .map(|v| v.expect("every index mapped"))
        .collect()
}

impl<'a> SceneLight<'a> {
    /// `extent`: the scene's bounding box (a ray of 4 diagonals leaves it).
    pub fn new(
        patches: &'a PatchSet,
        occluders: &'a Occluders,
        extent: (DVec3, DVec3),
        threads: usize,
    ) -> Self {
        let reach = 4.0 * (extent.1 - extent.0).length().max(1e-9);
        SceneLight {
            patches,
            occluders,
            reach,
            level: 1,
            threads: threads.max(1),
            frame: glam::DMat3::IDENTITY,
            glazing: Glazing::default(),
        }
    }

    /// The share of light that reaches `b` from `a` (or `a` from `b`): 0 when an opaque
    /// face blocks the segment, else the glazing's transmittance along it (faces
    /// `ignore` of each end left out).
    fn passes(&self, a: DVec3, b: DVec3, ignore: (u32, u32)) -> f64 {
        if self.occluders.occluded(a, b, ignore) {
            return 0.0;
        }
        if self.glazing.is_empty() {
            return 1.0;
        }
        self.glazing.transmittance(a, b, ignore)
    }

    /// The share of the light arriving at `x` from direction `d` (from outside the
    /// scene) that is not blocked (face `face` ignored).
    fn escapes(&self, x: DVec3, d: DVec3, face: u32) -> f64 {
        self.passes(x, x + d * self.reach, (face, face))
    }

    /// Coefficients of one point with normal `n` (face `face` ignored): per sky patch and
    /// the ground, Σ over visible cells of max(0, n·d) dω.
    fn point_coefficients(&self, dome: &SkyDome, x: DVec3, n: DVec3, face: u32) -> Vec<f64> {
        let mut c = vec![0.0; dome.len() + 1];
        let cells = dome.cells();
        for (k, p) in dome.patches().iter().enumerate() {
            for (d_enu, w) in p.cells(cells) {
                let d = self.frame * d_enu;
                let up = n.dot(d);
                if up > 0.0 {
                    c[k] += up * w * self.escapes(x, d, face);
                }
                let down = self.frame * DVec3::new(d_enu.x, d_enu.y, -d_enu.z);
                let dn = n.dot(down);
                if dn > 0.0 {
                    c[dome.len()] += dn * w * self.escapes(x, down, face);
                }
            }
        }
        c
    }

    /// Per patch, its area-mean sky coefficients (sr) for every sky patch of `dome` and
    /// the ground: the patch's first-arrival illuminance from the sky is
    /// Σ_p coefficient × luminance. Row-major `n × (dome.len() + 1)`.
    pub fn patch_sky(&self, dome: &SkyDome) -> Vec<f32> {
        let width = dome.len() + 1;
        let rows = par_map(self.patches.len(), self.threads, |i| {
            let p = &self.patches.patches[i];
            let mut acc = vec![0.0; width];
            for (x, w) in patch_points(p, self.level) {
                let c = self.point_coefficients(dome, x, p.normal, p.face);
                for (a, c) in acc.iter_mut().zip(c) {
                    *a += w * c;
                }
            }
            acc.iter()
                .map(|a| (a / p.area) as f32)
                .collect::<Vec<f32>>()
        });
        rows.concat()
    }

    /// Per patch, the area-mean of max(0, n·s) over its sunlit points for the sun in
    /// direction `s`: first-arrival illuminance from the sun = this × direct normal
    /// illuminance.
    pub fn patch_sun(&self, s: DVec3) -> Vec<f32> {
        let s = self.frame * s;
        par_map(self.patches.len(), self.threads, |i| {
            let p = &self.patches.patches[i];
            let cos = p.normal.dot(s);
            if cos <= 0.0 {
                return 0.0;
            }
            // Light let through at each point, and the least and most of it (a sun-patch
            // edge, or a pane's, lies between points that differ).
            let lit_at = |level: u8| -> (f64, f64, f64) {
                let (mut lit, mut least, mut most) = (0.0, f64::INFINITY, 0.0_f64);
                for (x, w) in patch_points(p, level) {
                    let t = self.escapes(x, s, p.face);
                    lit += w * t;
                    least = least.min(t);
                    most = most.max(t);
                }
                (lit, least, most)
            };
            let (mut lit, mut least, mut most) = lit_at(self.level);
            // A sun-patch edge that crosses the patch between its integration points
            // separates two of its corners (taken 1 % inside, off the neighbours' edges).
            let centre = p.centroid();
            for &c in p.corners() {
                let t = self.escapes(centre + (c - centre) * 0.99, s, p.face);
                least = least.min(t);
                most = most.max(t);
            }
            if least < most {
                lit = lit_at(SUN_EDGE_LEVEL.max(self.level)).0;
            }
            (cos * lit / p.area) as f32
        })
    }

    /// A sensor's sky coefficients on `dome` (and the ground, last), with visibility.
    pub fn sensor_sky(&self, s: &Sensor, dome: &SkyDome) -> Vec<f64> {
        self.point_coefficients(dome, s.point, s.normal, u32::MAX)
    }

    /// The cosine between a sensor's normal and the sun in direction `d` (east, north,
    /// up) when the sun is in front of the sensor, times the share of its light that
    /// reaches the sensor (0 when blocked, the glazing's transmittance through glass).
    pub fn sensor_sun(&self, s: &Sensor, d: DVec3) -> f64 {
        let d = self.frame * d;
        let cos = s.normal.dot(d);
        if cos > 0.0 {
            cos * self.escapes(s.point, d, u32::MAX)
        } else {
            0.0
        }
    }

    /// The sensor's form factors to every patch: F(sensor → patch j) with visibility
    /// (module docs). A patch facing away from the sensor gets 0.
    pub fn sensor_form_factors(&self, s: &Sensor) -> Vec<f32> {
        par_map(self.patches.len(), self.threads, |j| {
            let p = &self.patches.patches[j];
            // The patch must face the sensor, and lie (partly) in front of it.
            if p.normal.dot(s.point - p.corners[0]) <= 0.0 {
                return 0.0;
            }
            let poly = Polygon::new(p.corners());
            let offset = s.normal.dot(s.point);
            let front = poly.clip_front(s.normal, offset, 0.0);
            if front.verts().len() < 3 {
                return 0.0;
            }
            let f0 = point_polygon(s.point, s.normal, front.verts());
            if f0 <= 0.0 {
                return 0.0;
            }
            let (mut seen, mut all) = (0.0, 0.0);
            for (y, w) in patch_points(p, self.level) {
                let r = y - s.point;
                let d2 = r.length_squared();
                let k = w * s.normal.dot(r).max(0.0) * p.normal.dot(-r).max(0.0) / (d2 * d2);
                if k > 0.0 {
                    all += k;
                    seen += k * self.passes(s.point, y, (u32::MAX, p.face));
                }
            }
            if all > 0.0 {
                (f0 * seen / all) as f32
            } else {
                // Every integration point lies behind the sensor's plane while a sliver
                // of the patch is in front: ask the sliver's centre.
                let c = front.vertex_mean();
                (f0 * self.passes(s.point, c, (u32::MAX, p.face))) as f32
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_covers_the_office_floor_at_its_pitch() {
        let s = crate::scene::builtin("office", None).unwrap();
        let g = grid_sensors(&s, "floor", 0.5, 0.8).unwrap();
        // 4 m × 6 m at 0.5 m: 8 × 12 points, 0.8 m up, facing up.
        assert_eq!(g.len(), 96);
        for p in &g {
            assert!((p.point.z - 0.8).abs() < 1e-12 && p.normal == DVec3::Z);
            assert!(p.point.x > 0.0 && p.point.x < 4.0 && p.point.y > 0.0 && p.point.y < 6.0);
        }
        // The south wall's points avoid the window hole.
        let w = grid_sensors(&s, "wall_south", 0.3, 0.0).unwrap();
        assert!(w
            .iter()
            .all(|p| !(p.point.x > 1.0 && p.point.x < 3.0 && p.point.z > 0.9 && p.point.z < 2.1)));
        assert!(grid_sensors(&s, "nope", 0.5, 0.8)
            .unwrap_err()
            .contains("groups: floor"));
        assert!(grid_sensors(&s, "floor", 0.0, 0.8).is_err());
    }
}
