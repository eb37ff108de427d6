//! Software renderer: known answers for projection, depth, shading, exposure and the
//! sRGB output, and a synthetic Cornell box read back from its PNG.
//!
//! Scenes are built here (the radiosity solver is not needed): quads with known
//! radiosity, and a Cornell box with the published geometry (mm) whose radiosity is
//! `B = E + ρ·H(p)` for a made-up irradiance `H` that peaks under the light.
//!
//! This file holds the helpers and the known answers on small scenes of quads;
//! `cornell`: the synthetic Cornell box, and the camera that frames a scene.

use ffstream::patch::{Patch, PatchSet};
use ffstream::render::{render, Camera, RenderError, RenderOptions};
use glam::DVec3;

mod cornell;

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// A planar quad patch, corners counter-clockwise seen from the front.
fn quad(c: [DVec3; 4], group: u32, rho: [f32; 3], emission: [f32; 3]) -> Patch {
    let normal = (c[1] - c[0]).cross(c[2] - c[0]).normalize();
    let area = 0.5 * (c[2] - c[0]).cross(c[3] - c[1]).length();
    Patch {
        corners: c,
        n_corners: 4,
        normal,
        area,
        group,
        face: group,
        rho,
        emission,
    }
}

/// Quad `c` cut into `nu × nv` patches by bilinear interpolation (u along c0→c1, v
/// along c0→c3); orientation is kept.
fn grid(c: [DVec3; 4], nu: usize, nv: usize, group: u32, rho: [f32; 3], e: [f32; 3]) -> Vec<Patch> {
    let at = |u: f64, w: f64| {
        c[0] * ((1.0 - u) * (1.0 - w))
            + c[1] * (u * (1.0 - w))
            + c[2] * (u * w)
            + c[3] * ((1.0 - u) * w)
    };
    let mut out = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let (u0, u1) = (i as f64 / nu as f64, (i + 1) as f64 / nu as f64);
            let (w0, w1) = (j as f64 / nv as f64, (j + 1) as f64 / nv as f64);
            out.push(quad(
                [at(u0, w0), at(u1, w0), at(u1, w1), at(u0, w1)],
                group,
                rho,
                e,
            ));
        }
    }
    out
}

/// Camera at the origin looking along +z, +y up, 90° vertical field of view: a point
/// (x, y, z) lands at pixel (w/2 − (h/2)·x/z, h/2 − (h/2)·y/z).
fn axis_camera() -> Camera {
    Camera {
        eye: DVec3::ZERO,
        target: DVec3::Z,
        up: DVec3::Y,
        fov_y_deg: 90.0,
    }
}

fn opts(width: u32, height: u32, spp: u32) -> RenderOptions {
    RenderOptions {
        width,
        height,
        samples_per_pixel: spp,
        exposure: Some(1.0),
        ..RenderOptions::default()
    }
}

fn set(patches: Vec<Patch>, groups: usize) -> PatchSet {
    PatchSet {
        patches,
        groups: (0..groups).map(|g| format!("g{g}")).collect(),
    }
}

// sRGB codes of linear values (1.055·x^(1/2.4) − 0.055, times 255, rounded).
const SRGB_0_5: u8 = 188; // 0.5 → 0.735357 → 187.52
const SRGB_0_8: u8 = 231; // 0.8 → 0.906332 → 231.11
const SRGB_0_15: u8 = 108; // 0.15 → 0.423583 → 108.01

/// sRGB code (unrounded) of a linear value, IEC 61966-2-1.
fn srgb_code(x: f64) -> f64 {
    let e = if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    e * 255.0
}

/// Linear value of an 8-bit sRGB pixel (inverse of IEC 61966-2-1).
fn linear(p: [u8; 3]) -> [f64; 3] {
    p.map(|c| {
        let e = f64::from(c) / 255.0;
        if e <= 0.04045 {
            e / 12.92
        } else {
            ((e + 0.055) / 1.055).powf(2.4)
        }
    })
}

const WHITE: [f32; 3] = [0.5; 3];
const BLACK: [f32; 3] = [0.0; 3];

#[test]
fn near_quad_hides_far_quad_in_either_order() {
    // Far green quad at z = 20 spanning ±10 (pixels 16..48 of 64), near red quad at
    // z = 10 spanning ±2 (pixels 26..38).
    let far = quad(
        [
            v(10., -10., 20.),
            v(-10., -10., 20.),
            v(-10., 10., 20.),
            v(10., 10., 20.),
        ],
        0,
        WHITE,
        BLACK,
    );
    let near = quad(
        [
            v(2., -2., 10.),
            v(-2., -2., 10.),
            v(-2., 2., 10.),
            v(2., 2., 10.),
        ],
        1,
        WHITE,
        BLACK,
    );
    assert!(
        far.normal.z < 0.0 && near.normal.z < 0.0,
        "both face the camera"
    );
    let rad_far = [0.0, 0.5, 0.0];
    let rad_near = [0.5, 0.0, 0.0];
    for swap in [false, true] {
        let (ps, rad) = if swap {
            (vec![near.clone(), far.clone()], vec![rad_near, rad_far])
        } else {
            (vec![far.clone(), near.clone()], vec![rad_far, rad_near])
        };
        let img = render(&set(ps, 2), &rad, &axis_camera(), &opts(64, 64, 4)).unwrap();
        assert_eq!(
            img.pixel(32, 32),
            [SRGB_0_5, 0, 0],
            "near quad in front (swap {swap})"
        );
        assert_eq!(img.pixel(20, 32), [0, SRGB_0_5, 0], "far quad around it");
        assert_eq!(img.pixel(5, 32), [0, 0, 0], "background");
    }
}

#[test]
fn back_faces_are_drawn_scaled_and_occlude() {
    // Quad at z = 10 wound so its front faces +z, away from the camera.
    let back = quad(
        [
            v(-5., -5., 10.),
            v(5., -5., 10.),
            v(5., 5., 10.),
            v(-5., 5., 10.),
        ],
        0,
        WHITE,
        BLACK,
    );
    assert!(back.normal.z > 0.0);
    let far = quad(
        [
            v(20., -20., 20.),
            v(-20., -20., 20.),
            v(-20., 20., 20.),
            v(20., 20., 20.),
        ],
        1,
        WHITE,
        BLACK,
    );
    let scene = set(vec![far, back], 2);
    let rad = [[0.0, 0.5, 0.0], [0.5; 3]];
    let mut o = opts(64, 64, 1);
    o.back_face_scale = 1.0;
    let img = render(&scene, &rad, &axis_camera(), &o).unwrap();
    assert_eq!(img.pixel(32, 32), [SRGB_0_5; 3]);
    o.back_face_scale = 0.3; // 0.5 · 0.3 = 0.15 linear
    let img = render(&scene, &rad, &axis_camera(), &o).unwrap();
    assert_eq!(img.pixel(32, 32), [SRGB_0_15; 3]);
    assert_eq!(
        img.pixel(12, 32),
        [0, SRGB_0_5, 0],
        "far quad outside the back face"
    );
}

#[test]
fn uniform_scene_auto_exposure_gives_expected_grey() {
    // Every patch has radiosity 0.37 (luminance 0.37): the 99th percentile maps to
    // 0.8 linear, sRGB code 231, everywhere the scene covers.
    let wall = grid(
        [
            v(30., -30., 10.),
            v(-30., -30., 10.),
            v(-30., 30., 10.),
            v(30., 30., 10.),
        ],
        7,
        5,
        0,
        WHITE,
        BLACK,
    );
    let rad = vec![[0.37f32; 3]; wall.len()];
    let mut o = opts(48, 32, 4);
    o.exposure = None;
    let img = render(&set(wall, 1), &rad, &axis_camera(), &o).unwrap();
    assert!(
        img.rgb.iter().all(|&b| b == SRGB_0_8),
        "{:?}",
        &img.rgb[..12]
    );
}

#[test]
fn auto_exposure_ignores_the_light() {
    // A dim wall (0.1) and a small bright emitter (100): the wall, not the light,
    // sets the exposure, so the wall comes out at 0.8 linear and the light saturates.
    let mut ps = grid(
        [
            v(30., -30., 10.),
            v(-30., -30., 10.),
            v(-30., 30., 10.),
            v(30., 30., 10.),
        ],
        4,
        4,
        0,
        WHITE,
        BLACK,
    );
    ps.push(quad(
        [
            v(1., -1., 9.),
            v(-1., -1., 9.),
            v(-1., 1., 9.),
            v(1., 1., 9.),
        ],
        1,
        WHITE,
        [100.0; 3],
    ));
    let mut rad = vec![[0.1f32; 3]; ps.len()];
    *rad.last_mut().unwrap() = [100.0; 3];
    let scene = set(ps, 2);
    let exposure = ffstream::render::auto_exposure(&scene, &rad);
    assert!((exposure - 8.0).abs() < 1e-5, "{exposure}");
    let mut o = opts(32, 32, 1);
    o.exposure = None;
    let img = render(&scene, &rad, &axis_camera(), &o).unwrap();
    assert_eq!(img.pixel(16, 16), [255; 3]);
    assert_eq!(img.pixel(4, 16), [SRGB_0_8; 3]);
}

#[test]
fn wireframe_darkens_visible_edges_only() {
    // 2 × 2 grid at z = 10 spanning ±5 on a 101-pixel image: its middle edges land on
    // pixel centres (x, y = 50.5), the outer ones on x, y = 25.25 and 75.75.
    let wall = grid(
        [
            v(5., -5., 10.),
            v(-5., -5., 10.),
            v(-5., 5., 10.),
            v(5., 5., 10.),
        ],
        2,
        2,
        0,
        WHITE,
        BLACK,
    );
    let rad = vec![[0.5f32; 3]; 4];
    let scene = set(wall, 1);
    let mut o = opts(101, 101, 9);
    let plain = render(&scene, &rad, &axis_camera(), &o).unwrap();
    o.wireframe = true;
    let wired = render(&scene, &rad, &axis_camera(), &o).unwrap();
    // On the middle vertical edge: every sample is within half a pixel of it, so the
    // pixel is the line colour (0.01 linear → code 25).
    assert_eq!(plain.pixel(50, 35), [SRGB_0_5; 3]);
    assert_eq!(wired.pixel(50, 35), [25; 3]);
    assert_eq!(wired.pixel(35, 50), [25; 3], "middle horizontal edge");
    // Patch interiors are untouched.
    assert_eq!(wired.pixel(38, 38), [SRGB_0_5; 3]);
    assert_eq!(wired.pixel(62, 62), [SRGB_0_5; 3]);
    // The outer edges are darker than the interior too.
    assert!(wired.pixel(25, 40)[0] < plain.pixel(25, 40)[0]);

    // A nearer quad covering the middle hides the wall's edges behind it (no line
    // shows through), while its own border is drawn.
    let mut ps = scene.patches.clone();
    ps.push(quad(
        [
            v(1., -1., 8.),
            v(-1., -1., 8.),
            v(-1., 1., 8.),
            v(1., 1., 8.),
        ],
        1,
        WHITE,
        BLACK,
    ));
    let mut rad2 = rad.clone();
    rad2.push([0.5; 3]);
    let covered = render(&set(ps, 2), &rad2, &axis_camera(), &o).unwrap();
    // The near quad spans pixels 50.5 ± 50.5/8 = 44.19..56.81; its centre column is
    // where the wall's edge would be.
    assert_eq!(covered.pixel(50, 48), [SRGB_0_5; 3]);
    assert!(
        covered.pixel(44, 50)[0] < SRGB_0_5,
        "near quad's own left edge at x = 44.19"
    );
}

#[test]
fn gouraud_interpolation_is_perspective_correct() {
    // Floor y = −1 from z = 1 to z = 9 in two strips with radiosity 0 and 1: the
    // welded vertex values are 0, 0.5, 1 at z = 1, 5, 9, i.e. B(z) = (z − 1)/8 on the
    // whole floor. Camera at the origin, 90° field of view, 64 × 64, one sample per
    // pixel at its centre: row r (below the middle) sees the floor at
    // z = 32 / (r + 0.5 − 32).
    let near = quad(
        [
            v(10., -1., 1.),
            v(-10., -1., 1.),
            v(-10., -1., 5.),
            v(10., -1., 5.),
        ],
        0,
        WHITE,
        BLACK,
    );
    let far = quad(
        [
            v(10., -1., 5.),
            v(-10., -1., 5.),
            v(-10., -1., 9.),
            v(10., -1., 9.),
        ],
        0,
        WHITE,
        BLACK,
    );
    assert!(near.normal.y > 0.0);
    let img = render(
        &set(vec![near, far], 1),
        &[[0.0; 3], [1.0; 3]],
        &axis_camera(),
        &opts(64, 64, 1),
    )
    .unwrap();
    let mut checked = 0;
    for r in 36..64 {
        let z = 32.0 / (r as f64 + 0.5 - 32.0);
        let expected = srgb_code((z - 1.0) / 8.0);
        let got = f64::from(img.pixel(32, r)[0]);
        assert!(
            (got - expected).abs() <= 0.51,
            "row {r}: z {z:.3}, got {got}, expected {expected:.2}"
        );
        checked += 1;
    }
    assert_eq!(checked, 28);
    // The vertex value 0.5 sits at z = 5, i.e. at row 32 + 32/5 − 0.5 = 37.9: rows 37
    // and 38 straddle it. A screen-space (affine) interpolation would put the half-way
    // value half-way between the rows of z = 1 (63.5) and z = 9 (35.1), near row 49.
    let (a, b) = (img.pixel(32, 37)[0], img.pixel(32, 38)[0]);
    assert!(a > SRGB_0_5 && b < SRGB_0_5, "{a} {b}");
}

#[test]
fn near_plane_clips_geometry_behind_the_eye() {
    // A floor y = −1 that extends from z = −10 (behind the eye) to z = 10. Rows
    // r ≥ 36 of a 64-row image see it at z = 32/(r + 0.5 − 32) ≤ 7.1 (and |x| ≤ z):
    // covered. Rows above the horizon (r < 32) see nothing.
    for (nu, nv) in [(1, 1), (3, 4)] {
        let floor = grid(
            [
                v(10., -1., -10.),
                v(-10., -1., -10.),
                v(-10., -1., 10.),
                v(10., -1., 10.),
            ],
            nu,
            nv,
            0,
            WHITE,
            BLACK,
        );
        let rad = vec![[0.5f32; 3]; floor.len()];
        let img = render(&set(floor, 1), &rad, &axis_camera(), &opts(64, 64, 4)).unwrap();
        for y in 0..64 {
            for x in 0..64 {
                let p = img.pixel(x, y);
                if y < 32 {
                    assert_eq!(p, [0; 3], "({x}, {y}) above the horizon ({nu}x{nv})");
                } else if y >= 36 {
                    assert_eq!(p, [SRGB_0_5; 3], "({x}, {y}) on the floor ({nu}x{nv})");
                }
            }
        }
    }
}

#[test]
fn flat_shading_shows_each_patch_value() {
    // Two side by side patches with different values: Gouraud blends at the shared
    // edge, flat does not.
    let wall = grid(
        [
            v(5., -5., 10.),
            v(-5., -5., 10.),
            v(-5., 5., 10.),
            v(5., 5., 10.),
        ],
        2,
        1,
        0,
        WHITE,
        BLACK,
    );
    // Patch 0 spans x ∈ [0, 5] (image left half, pixels 25..50), patch 1 x ∈ [−5, 0].
    let rad = [[0.5f32; 3], [0.15; 3]];
    let scene = set(wall, 1);
    let mut o = opts(100, 100, 1);
    o.flat = true;
    let flat = render(&scene, &rad, &axis_camera(), &o).unwrap();
    assert_eq!(flat.pixel(48, 50), [SRGB_0_5; 3]);
    assert_eq!(flat.pixel(51, 50), [SRGB_0_15; 3]);
    o.flat = false;
    let smooth = render(&scene, &rad, &axis_camera(), &o).unwrap();
    // Gouraud: the shared edge (x = 0) gets (0.5 + 0.15)/2 = 0.325, the outer edges keep
    // their patch's value, linear in between. Pixel column c sees x = (50 − c − 0.5)/5.
    for c in (26..75).step_by(4) {
        let x = (50.0 - c as f64 - 0.5) / 5.0;
        // 0.5 at x = 5, 0.325 at x = 0, 0.15 at x = −5: one line.
        let expected = 0.325 + 0.175 * x / 5.0;
        let got = f64::from(smooth.pixel(c, 50)[0]);
        assert!(
            (got - srgb_code(expected)).abs() <= 0.51,
            "column {c}: {got} vs {:.2}",
            srgb_code(expected)
        );
    }
}

#[test]
fn invalid_input_is_an_error() {
    let wall = grid(
        [
            v(5., -5., 10.),
            v(-5., -5., 10.),
            v(-5., 5., 10.),
            v(5., 5., 10.),
        ],
        2,
        1,
        0,
        WHITE,
        BLACK,
    );
    let scene = set(wall, 1);
    let cam = axis_camera();
    let o = opts(8, 8, 1);
    assert!(matches!(
        render(&scene, &[[0.0; 3]], &cam, &o),
        Err(RenderError::RadiosityLength {
            expected: 2,
            got: 1
        })
    ));
    assert!(matches!(
        render(&scene, &[[0.0; 3], [0.0, f32::NAN, 0.0]], &cam, &o),
        Err(RenderError::NonFiniteRadiosity { patch: 1, .. })
    ));
    let rad = [[0.0; 3]; 2];
    for bad in [
        RenderOptions {
            samples_per_pixel: 8,
            ..o.clone()
        },
        RenderOptions {
            width: 0,
            ..o.clone()
        },
        RenderOptions {
            exposure: Some(-1.0),
            ..o.clone()
        },
    ] {
        assert!(matches!(
            render(&scene, &rad, &cam, &bad),
            Err(RenderError::InvalidOptions(_))
        ));
    }
    let blind = Camera {
        target: cam.eye,
        ..cam
    };
    assert!(matches!(
        render(&scene, &rad, &blind, &o),
        Err(RenderError::InvalidCamera { .. })
    ));
}
