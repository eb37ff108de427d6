//! `ffstream run` on the Cornell box, end to end: compute, solve, render, and the
//! picture read back. The acceptance checks of a picture a person would recognise: red
//! left wall, green right wall, the light brightest, colour bleeding onto the tall
//! block, no black holes inside the box.

use glam::DVec3;

use ffstream::render::{Camera, Image};

use crate::common::{ok, path_str};

fn mean_rgb(img: &Image, cx: f64, cy: f64, r: i64) -> [f64; 3] {
    let mut s = [0.0; 3];
    let mut count = 0.0;
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, y) = (cx as i64 + dx, cy as i64 + dy);
            assert!(
                x >= 0 && y >= 0 && x < img.width as i64 && y < img.height as i64,
                "sample outside the image"
            );
            let p = img.pixel(x as u32, y as u32);
            for c in 0..3 {
                s[c] += p[c] as f64;
            }
            count += 1.0;
        }
    }
    s.map(|v| v / count)
}

#[test]
fn cornell_box_run_renders_a_recognisable_picture() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cornell");
    ok(&[
        "run",
        "builtin:cornell",
        "--patches",
        "800",
        "--out-dir",
        path_str(&out),
        "--quiet",
    ]);
    for f in [
        "form_factors.ffz",
        "radiosity.csv",
        "lit.ply",
        "lit.vtu",
        "image.png",
        "wireframe.png",
    ] {
        assert!(out.join(f).is_file(), "run must write {f}");
    }
    let img = Image::read_png(&out.join("image.png")).unwrap();
    let cam = Camera::cornell();
    let at = |p: DVec3| {
        cam.project(p, img.width, img.height)
            .expect("point in front of the camera")
    };

    // Left of the picture: the red wall (x = 550); right: the green wall (x = 0).
    let (lx, ly) = at(DVec3::new(551.0, 300.0, 300.0));
    let (rx, ry) = at(DVec3::new(1.0, 300.0, 300.0));
    assert!(
        lx < img.width as f64 / 3.0 && rx > 2.0 * img.width as f64 / 3.0,
        "red wall left, green wall right"
    );
    let red = mean_rgb(&img, lx, ly, 4);
    let green = mean_rgb(&img, rx, ry, 4);
    assert!(
        red[0] > 1.5 * red[1] && red[0] > 1.5 * red[2],
        "left wall must be red-dominant: {red:?}"
    );
    assert!(
        green[1] > 1.2 * green[0] && green[1] > 1.5 * green[2],
        "right wall must be green-dominant: {green:?}"
    );

    // The light is the brightest thing in the picture.
    let (gx, gy) = at(DVec3::new(278.0, 548.8, 279.5));
    let light = mean_rgb(&img, gx, gy, 2);
    let lum = |p: [u8; 3]| p.iter().map(|&c| c as u32).sum::<u32>();
    let brightest = (0..img.height)
        .flat_map(|y| (0..img.width).map(move |x| (x, y)))
        .map(|(x, y)| lum(img.pixel(x, y)))
        .max()
        .unwrap();
    assert!(
        light.iter().sum::<f64>() >= brightest as f64 - 1.0,
        "light {light:?} must be the brightest ({brightest})"
    );

    // Colour bleeding: the tall block's face toward the red wall is redder (R/G) than
    // its face toward the camera.
    // Midpoints of two faces of the tall block (published corners (423, 247), (472, 406)
    // and (423, 247), (265, 296)), at mid height.
    let (sx, sy) = at(DVec3::new(447.5, 150.0, 326.5)); // faces +x (the red wall) and -z
    let (fx, fy) = at(DVec3::new(344.0, 150.0, 271.5)); // faces -z (the camera)
    let side = mean_rgb(&img, sx, sy, 2);
    let front = mean_rgb(&img, fx, fy, 2);
    eprintln!("bleeding: side {side:?} front {front:?}; red {red:?} green {green:?}");
    assert!(
        side[0] / side[1] > front[0] / front[1],
        "red bleeding onto the tall block: side {side:?}, front {front:?}"
    );

    // No black holes or NaN-black pixels inside the box opening.
    let (x0, y0) = at(DVec3::new(540.0, 540.0, 0.0));
    let (x1, y1) = at(DVec3::new(10.0, 10.0, 0.0));
    let mut black = 0;
    for y in y0.max(0.0) as u32 + 2..(y1 as u32).min(img.height) - 2 {
        for x in x0.max(0.0) as u32 + 2..(x1 as u32).min(img.width) - 2 {
            if img.pixel(x, y).iter().all(|&c| c < 3) {
                black += 1;
            }
        }
    }
    assert_eq!(black, 0, "black pixels inside the box");
}
