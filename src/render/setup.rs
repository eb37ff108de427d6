//! Triangle setup: patches in world space → triangles on the sample grid.
//!
//! For each patch: corners to camera space, Sutherland–Hodgman clipping of the whole
//! (convex) patch polygon against the near plane `z_c = near` (so nothing behind the
//! eye is ever projected), projection, then a triangle fan. Each vertex carries
//! `w = 1/z_c` and `colour · w`: both are affine in screen space, so interpolating them
//! with screen-space barycentrics and dividing gives perspective-correct colour, and
//! `w` itself is the depth the z-buffer compares (larger = nearer; no far plane needed).
//!
//! Wireframe lines are not drawn as separate line primitives with a depth bias. Each
//! visible sample instead knows its distance to the boundary of the patch it belongs to
//! (for a convex polygon and a point inside it, the minimum distance to the lines
//! through its edges), and samples closer than half the line width take the line
//! colour. Hidden edges are thus hidden exactly, with no bias to tune and no
//! z-fighting; a line shared by two visible patches gets half its width from each.
//! Edges created by near-plane clipping are not outlined. When the near plane cuts a
//! quad, its fan is taken over the clipped polygon, so the shading diagonal can differ
//! from the unclipped fan's inside the cut patch (a shading-only difference).

use glam::DVec3;

use super::camera::View;
use super::shading::CornerColours;
use crate::patch::PatchSet;

/// Near plane distance as a fraction of the scene's bounding box diagonal.
const NEAR_FRACTION: f64 = 1e-5;

/// Linear colour of wireframe lines (dark grey, before exposure: not scaled).
pub(crate) const WIRE_COLOUR: [f64; 3] = [0.01, 0.01, 0.01];

/// Settings for [`setup`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct SetupParams {
    /// Multiplies every colour.
    pub(crate) exposure: f64,
    /// Multiplies the colour of patches seen from their back side.
    pub(crate) back_face_scale: f64,
    /// Record patch boundaries for wireframe lines.
    pub(crate) wireframe: bool,
    /// Half the line width, in sample units.
    pub(crate) wire_half_width: f64,
}

/// One screen triangle with everything the rasterizer interpolates.
#[derive(Clone, Debug)]
pub(crate) struct Triangle {
    /// Vertex positions on the sample grid.
    pub(crate) v: [[f64; 2]; 3],
    /// Orientation (+1 or −1) that makes inside samples give non-negative edge values.
    pub(crate) sign: f64,
    /// 1 / |twice the signed area|.
    pub(crate) inv_area: f64,
    /// `1/z_c` per vertex.
    pub(crate) w: [f64; 3],
    /// Colour (exposure and back-face scale applied) times `w`, per vertex.
    pub(crate) cw: [[f64; 3]; 3],
    /// `[min x, min y, max x, max y]` of the vertices.
    pub(crate) bbox: [f64; 4],
    /// Index into [`ScreenScene::wires`], when wireframe is on.
    pub(crate) wire: Option<u32>,
}

/// The outline of one clipped patch polygon: lines `a x + b y + c = 0` with
/// `a² + b² = 1`, so `|a x + b y + c|` is the distance in sample units.
#[derive(Clone, Debug, Default)]
pub(crate) struct WirePolygon {
    pub(crate) lines: [[f64; 3]; 5],
    pub(crate) n: usize,
}

impl WirePolygon {
    /// Distance from `(x, y)` to the nearest outlined edge line (infinity when none).
    #[inline]
    pub(crate) fn distance(&self, x: f64, y: f64) -> f64 {
        self.lines[..self.n]
            .iter()
            .map(|l| (l[0] * x + l[1] * y + l[2]).abs())
            .fold(f64::INFINITY, f64::min)
    }
}

/// Everything the rasterizer needs.
#[derive(Clone, Debug, Default)]
pub(crate) struct ScreenScene {
    pub(crate) triangles: Vec<Triangle>,
    pub(crate) wires: Vec<WirePolygon>,
    pub(crate) wire_half_width: f64,
}

/// A polygon vertex during clipping: camera-space position, colour, and whether the
/// edge from this vertex to the next one lies on the patch boundary.
#[derive(Clone, Copy, Debug)]
struct ClipVertex {
    p: DVec3,
    colour: [f64; 3],
    boundary: bool,
}

/// Builds screen triangles for all patches. `colours[i][k]` is the linear colour of
/// corner `k` of patch `i`; `view` is sized to the sample grid.
pub(crate) fn setup(
    patches: &PatchSet,
    colours: &CornerColours,
    view: &View,
    params: &SetupParams,
) -> ScreenScene {
    debug_assert_eq!(patches.len(), colours.len());
    let near = near_distance(patches);
    let mut scene = ScreenScene {
        wire_half_width: params.wire_half_width,
        ..ScreenScene::default()
    };
    let mut poly: Vec<ClipVertex> = Vec::with_capacity(4);
    let mut clipped: Vec<ClipVertex> = Vec::with_capacity(5);
    for (patch, corner_colours) in patches.patches.iter().zip(colours) {
        let corners = patch.corners();
        let back = patch.normal.dot(view.eye - corners[0]) < 0.0;
        let scale = params.exposure * if back { params.back_face_scale } else { 1.0 };
        poly.clear();
        for (c, col) in corners.iter().zip(corner_colours) {
            poly.push(ClipVertex {
                p: view.to_camera(*c),
                colour: col.map(|x| f64::from(x) * scale),
                boundary: true,
            });
        }
        clip_near(&poly, near, &mut clipped);
        if clipped.len() < 3 {
            continue;
        }
        let screen: Vec<[f64; 2]> = clipped
            .iter()
            .map(|v| {
                let (x, y) = view.to_screen(v.p);
                [x, y]
            })
            .collect();
        if screen
            .iter()
            .any(|s| !(s[0].is_finite() && s[1].is_finite()))
        {
            continue;
        }
        let wire = if params.wireframe {
            scene.wires.push(outline(&clipped, &screen));
            Some((scene.wires.len() - 1) as u32)
        } else {
            None
        };
        for k in 1..clipped.len() - 1 {
            let idx = [0, k, k + 1];
            if let Some(t) = triangle(idx.map(|i| (&clipped[i], screen[i])), wire) {
                scene.triangles.push(t);
            }
        }
    }
    scene
}

/// Near plane: a small fixed fraction of the scene size (positive even for an empty or
/// degenerate scene).
fn near_distance(patches: &PatchSet) -> f64 {
    let diag = patches.diagonal();
    if diag > 0.0 {
        diag * NEAR_FRACTION
    } else {
        1e-9
    }
}

/// Sutherland–Hodgman against `z ≥ near`, keeping track of which output edges lie on
/// the input polygon's boundary (edges along the clip plane do not).
fn clip_near(input: &[ClipVertex], near: f64, out: &mut Vec<ClipVertex>) {
    out.clear();
    let n = input.len();
    for i in 0..n {
        let a = input[i];
        let b = input[(i + 1) % n];
        let (a_in, b_in) = (a.p.z >= near, b.p.z >= near);
        match (a_in, b_in) {
            (true, true) => out.push(a),
            (true, false) => {
                out.push(a);
                out.push(ClipVertex {
                    boundary: false,
                    ..intersect(&a, &b, near)
                });
            }
            (false, true) => out.push(ClipVertex {
                boundary: a.boundary,
                ..intersect(&a, &b, near)
            }),
            (false, false) => {}
        }
    }
}

/// Point of segment `a`–`b` on the plane `z = near`, colour interpolated linearly in
/// camera space. The parameter is computed from a canonical endpoint order so that two
/// patches sharing the edge (traversing it in opposite directions) get bit-identical
/// points and leave no crack.
fn intersect(a: &ClipVertex, b: &ClipVertex, near: f64) -> ClipVertex {
    let (a, b) = if a.p.to_array() <= b.p.to_array() {
        (a, b)
    } else {
        (b, a)
    };
    let t = (near - a.p.z) / (b.p.z - a.p.z);
    let mut colour = [0.0; 3];
    for (c, (x, y)) in colour.iter_mut().zip(a.colour.iter().zip(b.colour)) {
        *c = x + (y - x) * t;
    }
    let mut p = a.p + (b.p - a.p) * t;
    p.z = near;
    ClipVertex {
        p,
        colour,
        boundary: true,
    }
}

/// Unit-normal lines through the polygon's boundary edges.
fn outline(poly: &[ClipVertex], screen: &[[f64; 2]]) -> WirePolygon {
    let mut w = WirePolygon::default();
    let n = poly.len();
    for i in 0..n {
        if !poly[i].boundary || w.n == w.lines.len() {
            continue;
        }
        let (a, b) = (screen[i], screen[(i + 1) % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        if len == 0.0 {
            continue;
        }
        let (nx, ny) = (-dy / len, dx / len);
        w.lines[w.n] = [nx, ny, -(nx * a[0] + ny * a[1])];
        w.n += 1;
    }
    w
}

/// Twice the signed area of `(a, b, p)`, computed from a canonical endpoint order so
/// that the two triangles sharing edge `a`–`b` get exactly opposite values at any
/// sample: a sample on a shared edge is inside at least one of them (no cracks).
#[inline]
pub(crate) fn edge_function(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> f64 {
    if a <= b {
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
    } else {
        -((a[0] - b[0]) * (p[1] - b[1]) - (a[1] - b[1]) * (p[0] - b[0]))
    }
}

fn triangle(v: [(&ClipVertex, [f64; 2]); 3], wire: Option<u32>) -> Option<Triangle> {
    let s = v.map(|(_, s)| s);
    let area2 = edge_function(s[1], s[2], s[0]);
    if !(area2.abs() > 0.0 && area2.is_finite()) {
        return None; // edge-on or degenerate: covers no area
    }
    let w = v.map(|(c, _)| 1.0 / c.p.z);
    let mut cw = [[0.0; 3]; 3];
    for k in 0..3 {
        cw[k] = v[k].0.colour.map(|c| c * w[k]);
    }
    let xs = s.map(|p| p[0]);
    let ys = s.map(|p| p[1]);
    Some(Triangle {
        v: s,
        sign: area2.signum(),
        inv_area: 1.0 / area2.abs(),
        w,
        cw,
        bbox: [
            xs.into_iter().fold(f64::INFINITY, f64::min),
            ys.into_iter().fold(f64::INFINITY, f64::min),
            xs.into_iter().fold(f64::NEG_INFINITY, f64::max),
            ys.into_iter().fold(f64::NEG_INFINITY, f64::max),
        ],
        wire,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cv(x: f64, y: f64, z: f64) -> ClipVertex {
        ClipVertex {
            p: DVec3::new(x, y, z),
            colour: [z; 3],
            boundary: true,
        }
    }

    #[test]
    fn clipping_keeps_the_front_part_and_marks_the_cut() {
        // Square in the x-z plane from z = -1 to z = 1, clipped at z = 0.5.
        let sq = [
            cv(0., 0., -1.),
            cv(1., 0., -1.),
            cv(1., 0., 1.),
            cv(0., 0., 1.),
        ];
        let mut out = Vec::new();
        clip_near(&sq, 0.5, &mut out);
        assert_eq!(out.len(), 4);
        assert!(out.iter().all(|v| v.p.z >= 0.5));
        // Colour (= z here) interpolates to 0.5 on the cut.
        let cut: Vec<_> = out.iter().filter(|v| v.p.z == 0.5).collect();
        assert_eq!(cut.len(), 2);
        assert!(cut.iter().all(|v| (v.colour[0] - 0.5).abs() < 1e-12));
        // Exactly one edge runs along the clip plane and is not a boundary.
        assert_eq!(out.iter().filter(|v| !v.boundary).count(), 1);

        // A triangle with one corner cut off becomes a quad.
        let tri = [cv(0., 0., 1.), cv(1., 0., 1.), cv(0.5, 0., -1.)];
        clip_near(&tri, 0.5, &mut out);
        assert_eq!(out.len(), 4);
        // Fully behind: nothing.
        let behind = [cv(0., 0., -1.), cv(1., 0., -1.), cv(0., 1., -2.)];
        clip_near(&behind, 0.5, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn edge_function_is_antisymmetric_bitwise() {
        let (a, b) = ([0.1, 0.7], [3.3, -2.9]);
        for p in [[0.3, 0.3], [1.7, -1.1], [100.5, 7.25]] {
            assert_eq!(edge_function(a, b, p), -edge_function(b, a, p));
        }
    }

    #[test]
    fn wire_distance_is_distance_to_nearest_edge() {
        let poly = [
            cv(0., 0., 1.),
            cv(4., 0., 1.),
            cv(4., 2., 1.),
            cv(0., 2., 1.),
        ];
        let screen = poly.map(|v| [v.p.x, v.p.y]);
        let w = outline(&poly, &screen);
        assert_eq!(w.n, 4);
        assert!((w.distance(1.0, 0.5) - 0.5).abs() < 1e-12);
        assert!((w.distance(2.0, 1.0) - 1.0).abs() < 1e-12);
        assert!((w.distance(3.75, 1.0) - 0.25).abs() < 1e-12);
    }
}
