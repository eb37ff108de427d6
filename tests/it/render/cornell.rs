//! A synthetic Cornell box (the published geometry, mm, with a made-up irradiance that
//! peaks under the light) rendered and read back from its PNG, wireframe and flat; and
//! `Camera::frame` looking into the open box, inside a closed room and at an object
//! from outside.

use ffstream::render::Image;

use super::*;

const G_FLOOR: u32 = 0;
const G_CEILING: u32 = 1;
const G_BACK: u32 = 2;
const G_RIGHT: u32 = 3; // green, x = 0
const G_LEFT: u32 = 4; // red, x ≈ 550
const G_SHORT: u32 = 5;
const G_TALL: u32 = 6;
const G_LIGHT: u32 = 7;

const KD_WHITE: [f32; 3] = [0.725, 0.71, 0.68];
const KD_RED: [f32; 3] = [0.63, 0.065, 0.05];
const KD_GREEN: [f32; 3] = [0.14, 0.45, 0.091];
const KE_LIGHT: [f32; 3] = [53.407_074, 37.699_112, 12.566_371];
const LIGHT_CENTRE: DVec3 = DVec3::new(278.0, 548.8, 279.5);

/// The Cornell box of `tests/data/scenes/cornell_box.obj` (mm), walls cut into `n × n` patches,
/// the ceiling into a 3 × 3 arrangement of cells around the light, blocks 2 × 2.
fn cornell(n: usize) -> PatchSet {
    let mut ps = Vec::new();
    let y = 548.8;
    ps.extend(grid(
        [
            v(552.8, 0., 0.),
            v(0., 0., 0.),
            v(0., 0., 559.2),
            v(549.6, 0., 559.2),
        ],
        n,
        n,
        G_FLOOR,
        KD_WHITE,
        BLACK,
    ));
    ps.extend(grid(
        [
            v(549.6, 0., 559.2),
            v(0., 0., 559.2),
            v(0., y, 559.2),
            v(556., y, 559.2),
        ],
        n,
        n,
        G_BACK,
        KD_WHITE,
        BLACK,
    ));
    ps.extend(grid(
        [
            v(0., 0., 559.2),
            v(0., 0., 0.),
            v(0., y, 0.),
            v(0., y, 559.2),
        ],
        n,
        n,
        G_RIGHT,
        KD_GREEN,
        BLACK,
    ));
    ps.extend(grid(
        [
            v(552.8, 0., 0.),
            v(549.6, 0., 559.2),
            v(556., y, 559.2),
            v(556., y, 0.),
        ],
        n,
        n,
        G_LEFT,
        KD_RED,
        BLACK,
    ));
    // Ceiling cells (x0..x1) × (z0..z1), corners (x1,z0) (x1,z1) (x0,z1) (x0,z0) face
    // down; the middle cell is the light.
    let xs = [0.0, 213.0, 343.0, 556.0];
    let zs = [0.0, 227.0, 332.0, 559.2];
    for a in 0..3 {
        for b in 0..3 {
            let (x0, x1, z0, z1) = (xs[a], xs[a + 1], zs[b], zs[b + 1]);
            let c = [v(x1, y, z0), v(x1, y, z1), v(x0, y, z1), v(x0, y, z0)];
            if a == 1 && b == 1 {
                ps.extend(grid(c, 2, 2, G_LIGHT, [0.78; 3], KE_LIGHT));
            } else {
                ps.extend(grid(c, 3, 3, G_CEILING, KD_WHITE, BLACK));
            }
        }
    }
    ps.extend(blocks());
    PatchSet {
        patches: ps,
        groups: [
            "floor",
            "ceiling",
            "back_wall",
            "right_wall",
            "left_wall",
            "short_block",
            "tall_block",
            "light",
        ]
        .map(String::from)
        .to_vec(),
    }
}

/// The short and the tall block of the Cornell box, each face cut 2 × 2.
fn blocks() -> Vec<Patch> {
    let mut ps = Vec::new();
    let short = [
        v(130., 165., 65.),
        v(82., 165., 225.),
        v(240., 165., 272.),
        v(290., 165., 114.),
        v(290., 0., 114.),
        v(240., 0., 272.),
        v(130., 0., 65.),
        v(82., 0., 225.),
    ];
    let tall = [
        v(423., 330., 247.),
        v(265., 330., 296.),
        v(314., 330., 456.),
        v(472., 330., 406.),
        v(423., 0., 247.),
        v(472., 0., 406.),
        v(314., 0., 456.),
        v(265., 0., 296.),
    ];
    // OBJ faces, with vertex numbers relative to each block's first vertex.
    let short_faces = [
        [0, 1, 2, 3],
        [4, 3, 2, 5],
        [6, 0, 3, 4],
        [7, 1, 0, 6],
        [5, 2, 1, 7],
    ];
    let tall_faces = [
        [0, 1, 2, 3],
        [4, 0, 3, 5],
        [5, 3, 2, 6],
        [6, 2, 1, 7],
        [7, 1, 0, 4],
    ];
    for f in short_faces {
        ps.extend(grid(f.map(|k| short[k]), 2, 2, G_SHORT, KD_WHITE, BLACK));
    }
    for f in tall_faces {
        ps.extend(grid(f.map(|k| tall[k]), 2, 2, G_TALL, KD_WHITE, BLACK));
    }
    ps
}

/// `B = E + ρ·H(p)` with a made-up irradiance that is brightest under the light.
fn synthetic_radiosity(s: &PatchSet) -> Vec<[f32; 3]> {
    s.patches
        .iter()
        .map(|p| {
            let d2 = (p.centroid() - LIGHT_CENTRE).length_squared();
            let h = 6.0 + 30.0 * (-d2 / (350.0f64 * 350.0)).exp();
            [0, 1, 2].map(|c| p.emission[c] + p.rho[c] * h as f32)
        })
        .collect()
}

/// Writes `img` under `$FFSTREAM_KEEP_RENDER` when set, to look at by eye.
fn keep(img: &Image, name: &str) {
    if let Some(d) = std::env::var_os("FFSTREAM_KEEP_RENDER") {
        img.write_png(&std::path::PathBuf::from(d).join(name))
            .unwrap();
    }
}

/// Sums of the red and green codes over a pixel rectangle.
fn red_green(img: &Image, xs: std::ops::Range<u32>, ys: std::ops::Range<u32>) -> (u64, u64) {
    let (mut r, mut g) = (0, 0);
    for y in ys {
        for x in xs.clone() {
            let p = img.pixel(x, y);
            r += u64::from(p[0]);
            g += u64::from(p[1]);
        }
    }
    (r, g)
}

/// Every pixel inside the projected front opening of the box (shrunk by 2 pixels)
/// shows some surface, and the opening covers most of the frame.
fn assert_no_holes(img: &Image, cam: &Camera) {
    let (w, h) = (img.width, img.height);
    let opening = [
        v(552.8, 0., 0.),
        v(0., 0., 0.),
        v(0., 548.8, 0.),
        v(556., 548.8, 0.),
    ]
    .map(|p| cam.project(p, w, h).unwrap());
    // Orientation of the projected quad, so that the edge distances below are positive
    // inside whichever way it winds on screen.
    let orient = (0..4)
        .map(|k| {
            let (a, b) = (opening[k], opening[(k + 1) % 4]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum::<f64>()
        .signum();
    let mut inside = 0;
    for y in 0..h {
        for x in 0..w {
            let p = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            let margin = (0..4)
                .map(|k| {
                    let (a, b) = (opening[k], opening[(k + 1) % 4]);
                    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                    orient * (dx * (p.1 - a.1) - dy * (p.0 - a.0)) / dx.hypot(dy)
                })
                .fold(f64::INFINITY, f64::min);
            if margin > 2.0 {
                inside += 1;
                assert_ne!(
                    img.pixel(x, y),
                    [0; 3],
                    "black pixel ({x}, {y}) inside the box"
                );
            }
        }
    }
    // The opening covers most of the frame (~97 % of the width at z = 0).
    assert!(
        inside > (w * h) as usize * 8 / 10,
        "only {inside} pixels inside the opening"
    );
}

#[test]
fn cornell_box_render_reads_back_as_a_cornell_box() {
    let scene = cornell(8);
    let rad = synthetic_radiosity(&scene);
    let cam = Camera::cornell();
    let o = RenderOptions::default(); // 512 × 512, 3 × 3 samples, automatic exposure
    let (w, h) = (o.width, o.height);
    let t = std::time::Instant::now();
    let img = render(&scene, &rad, &cam, &o).unwrap();
    eprintln!(
        "cornell {} patches, {w}x{h}, 9 spp: {:?}",
        scene.len(),
        t.elapsed()
    );

    // Through the PNG file and back.
    let dir = tempfile::tempdir().unwrap();
    let path = match std::env::var_os("FFSTREAM_KEEP_RENDER") {
        Some(d) => std::path::PathBuf::from(d).join("cornell_synthetic.png"),
        None => dir.path().join("cornell.png"),
    };
    img.write_png(&path).unwrap();
    let img = Image::read_png(&path).unwrap();
    assert_eq!((img.width, img.height), (w, h));

    // Red wall on the left, green wall on the right (middle band of rows).
    let band = h * 3 / 10..h * 7 / 10;
    let (r, g) = red_green(&img, 0..w / 3, band.clone());
    assert!(r as f64 > 1.3 * g as f64, "left third: red {r} green {g}");
    let (r, g) = red_green(&img, 2 * w / 3..w, band.clone());
    assert!(g as f64 > 1.3 * r as f64, "right third: red {r} green {g}");
    // The walls themselves, 5 % in from the image edges: with B = ρ·H, their linear
    // colours have the ratios of the walls' Kd (red 0.63 : 0.065 : 0.05, green
    // 0.14 : 0.45 : 0.091), up to 8-bit rounding.
    let left = linear(img.pixel(w / 20, h / 2));
    let right = linear(img.pixel(w - w / 20, h / 2));
    let ratio = |a: f64, b: f64, expected: f64| (a / b / expected - 1.0).abs() < 0.1;
    assert!(
        ratio(left[0], left[1], 0.63 / 0.065),
        "left wall pixel {left:?}"
    );
    assert!(
        ratio(left[0], left[2], 0.63 / 0.05),
        "left wall pixel {left:?}"
    );
    assert!(
        ratio(right[1], right[0], 0.45 / 0.14),
        "right wall pixel {right:?}"
    );
    assert!(
        ratio(right[1], right[2], 0.45 / 0.091),
        "right wall pixel {right:?}"
    );

    // The light is the brightest thing in the picture (saturated white).
    let (lx, ly) = cam.project(LIGHT_CENTRE, w, h).unwrap();
    let light = img.pixel(lx as u32, ly as u32);
    assert_eq!(light, [255; 3], "light at ({lx:.1}, {ly:.1})");
    let brightest = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| img.pixel(x, y).iter().map(|&c| u32::from(c)).sum::<u32>())
        .max()
        .unwrap();
    assert_eq!(brightest, 765);

    // No holes: every pixel inside the projected front opening of the box (shrunk by
    // 2 pixels) shows some surface.
    assert_no_holes(&img, &cam);

    // Deterministic: same bytes for any thread count and on a second run.
    for threads in [1, 2, 3] {
        let again = render(
            &scene,
            &rad,
            &cam,
            &RenderOptions {
                threads,
                ..o.clone()
            },
        )
        .unwrap();
        assert!(
            again.rgb == img.rgb,
            "render with {threads} threads differs"
        );
    }
}

#[test]
fn cornell_box_wireframe_and_flat() {
    let scene = cornell(6);
    let rad = synthetic_radiosity(&scene);
    let cam = Camera::cornell();
    let o = RenderOptions {
        width: 256,
        height: 256,
        ..RenderOptions::default()
    };
    let smooth = render(&scene, &rad, &cam, &o).unwrap();
    let wired = render(
        &scene,
        &rad,
        &cam,
        &RenderOptions {
            wireframe: true,
            ..o.clone()
        },
    )
    .unwrap();
    let flat = render(
        &scene,
        &rad,
        &cam,
        &RenderOptions {
            flat: true,
            ..o.clone()
        },
    )
    .unwrap();
    let dark = |img: &Image| {
        img.rgb
            .chunks(3)
            .filter(|p| p.iter().all(|&c| c <= 30))
            .count()
    };
    // Lines add many dark pixels; the smooth image has only the background ones.
    assert!(
        dark(&wired) > dark(&smooth) + 2000,
        "{} vs {}",
        dark(&wired),
        dark(&smooth)
    );
    assert_ne!(flat.rgb, smooth.rgb);
    keep(&wired, "cornell_wire.png");
    keep(&flat, "cornell_flat.png");
}

#[test]
fn frame_looks_into_the_open_cornell_box() {
    let scene = cornell(4);
    let cam = Camera::frame(&scene);
    // The box is open towards −z: the camera stands there, looking in.
    assert!(cam.eye.z < 0.0, "{cam}");
    let (w, h) = (200, 200);
    for k in 0..8 {
        let corner = v(
            if k & 1 == 0 { 0.0 } else { 556.0 },
            if k & 2 == 0 { 0.0 } else { 548.8 },
            if k & 4 == 0 { 0.0 } else { 559.2 },
        );
        let (x, y) = cam.project(corner, w, h).unwrap();
        assert!(
            (0.0..=f64::from(w)).contains(&x) && (0.0..=f64::from(h)).contains(&y),
            "{corner} at ({x}, {y})"
        );
    }
    let rad = synthetic_radiosity(&scene);
    let img = render(
        &scene,
        &rad,
        &cam,
        &RenderOptions {
            width: w,
            height: h,
            ..RenderOptions::default()
        },
    )
    .unwrap();
    keep(&img, "cornell_framed.png");
    let (r, g) = red_green(&img, 0..w / 3, 60..140);
    assert!(r > g, "left third red {r} green {g}");
    let (r, g) = red_green(&img, 2 * w / 3..w, 60..140);
    assert!(g > r, "right third red {r} green {g}");
}

/// Unit cube faces, normals inward (`inward`) or outward.
fn cube(inward: bool) -> PatchSet {
    let c = |x: f64, y: f64, z: f64| v(x, y, z);
    // Outward-facing quads (CCW seen from outside).
    let mut faces = vec![
        [c(0., 0., 0.), c(0., 1., 0.), c(1., 1., 0.), c(1., 0., 0.)], // z = 0, −z
        [c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)], // z = 1, +z
        [c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)], // y = 0, −y
        [c(0., 1., 0.), c(0., 1., 1.), c(1., 1., 1.), c(1., 1., 0.)], // y = 1, +y
        [c(0., 0., 0.), c(0., 0., 1.), c(0., 1., 1.), c(0., 1., 0.)], // x = 0, −x
        [c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)], // x = 1, +x
    ];
    if inward {
        for f in &mut faces {
            f.reverse();
        }
    }
    let mut ps = Vec::new();
    for (g, f) in faces.into_iter().enumerate() {
        ps.extend(grid(f, 3, 3, g as u32, WHITE, BLACK));
    }
    set(ps, 6)
}

#[test]
fn frame_goes_inside_a_closed_room_and_outside_an_object() {
    for inward in [true, false] {
        let scene = cube(inward);
        for p in &scene.patches {
            let out = (p.centroid() - v(0.5, 0.5, 0.5)).dot(p.normal) > 0.0;
            assert_eq!(out, !inward);
        }
        let cam = Camera::frame(&scene);
        let inside = (0.0..1.0).contains(&cam.eye.x)
            && (0.0..1.0).contains(&cam.eye.y)
            && (0.0..1.0).contains(&cam.eye.z);
        assert_eq!(inside, inward, "{cam}");
        // Only front faces shown (back sides black): the centre of the picture must
        // still see a surface.
        let rad = vec![[0.5f32; 3]; scene.len()];
        let o = RenderOptions {
            width: 64,
            height: 64,
            back_face_scale: 0.0,
            ..opts(64, 64, 1)
        };
        let img = render(
            &scene,
            &rad,
            &cam,
            &RenderOptions {
                wireframe: true,
                ..o.clone()
            },
        )
        .unwrap();
        keep(
            &img,
            if inward {
                "cube_inside.png"
            } else {
                "cube_outside.png"
            },
        );
        let img = render(&scene, &rad, &cam, &o).unwrap();
        assert_eq!(img.pixel(32, 32), [SRGB_0_5; 3], "inward {inward}");
        if inward {
            assert!(
                img.rgb.iter().all(|&b| b == SRGB_0_5),
                "a closed room fills the frame"
            );
        }
    }
}
