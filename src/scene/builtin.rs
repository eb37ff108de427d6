//! Built-in scenes, written as Rust tables so tests and benchmarks need no files.
//!
//! | name | what | param |
//! |---|---|---|
//! | `cornell` | the Cornell box of `tests/data/scenes/cornell_box.obj` (docs/known-answers.md §7), mm | none |
//! | `cube` | closed cube `[0,s]³`, faces inward, groups `x0 x1 y0 y1 z0 z1`, ρ = 0.5, `y1` emits 1 | side s (1) |
//! | `plates` | unit squares facing each other, `bottom` (emits 1) and `top` | distance (1) |
//! | `perpendicular` | unit square `bottom` and 1 × h rectangle `side` sharing an edge at 90° | h (1) |
//! | `obstructed` | `plates` at distance 1 with a two-sided 0.5 × 0.5 `blocker` midway | none |
//! | `room` | closed room, ceiling light, many boxes (see [`super::room`]) | boxes (16) |
//! | `city` | city blocks open to the sky, one building each, the ground emits 1 (see [`super::city`]) | blocks per side (4) |
//! | `office` | 4 × 6 × 3 m room with a south window opening, z up, no light source, for `annual` (see [`super::office`]) | window width, m (2; at most 3.8) |
//!
//! The small scenes have analytic form factors (docs/known-answers.md §2, §3), e.g. between the two
//! `plates` at distance 1: 0.19982; `perpendicular` with h = 1: 0.20004.

use glam::DVec3;

use super::builder::Builder;
use super::{city, office, room, Scene, SceneError};

/// Names accepted by [`builtin`].
pub fn builtin_names() -> &'static [&'static str] {
    &[
        "cornell",
        "cube",
        "plates",
        "perpendicular",
        "obstructed",
        "room",
        "city",
        "office",
    ]
}

/// A built-in scene by name, with an optional size parameter (see the module table).
///
/// # Errors
/// [`SceneError::UnknownBuiltin`] for an unknown name, [`SceneError::BadParam`] for a
/// parameter out of range or given to a scene that takes none.
pub fn builtin(name: &str, param: Option<f64>) -> Result<Scene, SceneError> {
    let positive = |default: f64| -> Result<f64, SceneError> {
        let p = param.unwrap_or(default);
        if p > 0.0 && p.is_finite() {
            Ok(p)
        } else {
            Err(SceneError::BadParam {
                name: name.to_owned(),
                reason: format!("parameter must be a positive number, got {p}"),
            })
        }
    };
    let none = || -> Result<(), SceneError> {
        match param {
            None => Ok(()),
            Some(p) => Err(SceneError::BadParam {
                name: name.to_owned(),
                reason: format!("takes no parameter, got {p}"),
            }),
        }
    };
    match name {
        "cornell" => none().map(|_| cornell()),
        "cube" => positive(1.0).map(cube),
        "plates" => positive(1.0).map(plates),
        "perpendicular" => positive(1.0).map(|h| builtin_perpendicular(1.0, h)),
        "obstructed" => none().map(|_| obstructed()),
        "room" => {
            let p = param.unwrap_or(room::DEFAULT_BOXES as f64);
            if !(p >= 0.0 && p.fract() == 0.0 && p <= 1e6) {
                return Err(SceneError::BadParam {
                    name: name.to_owned(),
                    reason: format!("number of boxes must be a whole number in 0..=1e6, got {p}"),
                });
            }
            Ok(room::builtin_room(p as usize))
        }
        "city" => {
            let p = param.unwrap_or(city::DEFAULT_BLOCKS as f64);
            if !(p >= 1.0 && p.fract() == 0.0 && p <= 1000.0) {
                return Err(SceneError::BadParam {
                    name: name.to_owned(),
                    reason: format!("blocks per side must be a whole number in 1..=1000, got {p}"),
                });
            }
            Ok(city::builtin_city(p as usize))
        }
        "office" => {
            let p = param.unwrap_or(office::DEFAULT_WINDOW);
            if !(p > 0.0 && p <= office::SIZE[0] - 0.2) {
                return Err(SceneError::BadParam {
                    name: name.to_owned(),
                    reason: format!("window width must be in (0, 3.8] m, got {p}"),
                });
            }
            Ok(office::builtin_office(p))
        }
        _ => Err(SceneError::UnknownBuiltin {
            name: name.to_owned(),
            known: builtin_names().join(", "),
        }),
    }
}

/// Cornell box vertices, as in `tests/data/scenes/cornell_box.obj` (1-based in the face table).
#[rustfmt::skip]
const CORNELL_VERTICES: [[f64; 3]; 32] = [
    [552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2],
    [556.0, 548.8, 0.0], [556.0, 548.8, 227.0], [0.0, 548.8, 227.0], [0.0, 548.8, 0.0],
    [556.0, 548.8, 332.0], [556.0, 548.8, 559.2], [0.0, 548.8, 559.2], [0.0, 548.8, 332.0],
    [213.0, 548.8, 227.0], [213.0, 548.8, 332.0], [343.0, 548.8, 332.0], [343.0, 548.8, 227.0],
    [130.0, 165.0, 65.0], [82.0, 165.0, 225.0], [240.0, 165.0, 272.0], [290.0, 165.0, 114.0],
    [290.0, 0.0, 114.0], [240.0, 0.0, 272.0], [130.0, 0.0, 65.0], [82.0, 0.0, 225.0],
    [423.0, 330.0, 247.0], [265.0, 330.0, 296.0], [314.0, 330.0, 456.0], [472.0, 330.0, 406.0],
    [423.0, 0.0, 247.0], [472.0, 0.0, 406.0], [314.0, 0.0, 456.0], [265.0, 0.0, 296.0],
];

/// Cornell box faces: (group, material, 1-based vertex indices; 0 = no 4th corner).
#[rustfmt::skip]
const CORNELL_FACES: [(&str, usize, [usize; 4]); 19] = [
    ("floor", 0, [1, 2, 3, 4]),
    ("ceiling", 0, [5, 6, 7, 8]),
    ("ceiling", 0, [9, 10, 11, 12]),
    ("ceiling", 0, [13, 14, 12, 7]),
    ("ceiling", 0, [6, 9, 15, 16]),
    ("back_wall", 0, [4, 3, 11, 10]),
    ("right_wall", 2, [3, 2, 8, 11]),
    ("left_wall", 1, [1, 4, 10, 0]),
    ("left_wall", 1, [1, 10, 5, 0]),
    ("short_block", 0, [17, 18, 19, 20]),
    ("short_block", 0, [21, 20, 19, 22]),
    ("short_block", 0, [23, 17, 20, 21]),
    ("short_block", 0, [24, 18, 17, 23]),
    ("short_block", 0, [22, 19, 18, 24]),
    ("tall_block", 0, [25, 26, 27, 28]),
    ("tall_block", 0, [29, 25, 28, 30]),
    ("tall_block", 0, [30, 28, 27, 31]),
    ("tall_block", 0, [31, 27, 26, 32]),
    ("tall_block", 0, [32, 26, 25, 29]),
];

/// The Cornell box: geometry and materials of `tests/data/scenes/cornell_box.obj` + `.mtl`
/// (units mm; `Ke` is exitance = π × radiance (17, 12, 4)).
fn cornell() -> Scene {
    let mut b = Builder::new("cornell");
    let mats = [
        b.material("white", [0.725, 0.71, 0.68], [0.0; 3]),
        b.material("red", [0.63, 0.065, 0.05], [0.0; 3]),
        b.material("green", [0.14, 0.45, 0.091], [0.0; 3]),
        b.material(
            "light",
            [0.78, 0.78, 0.78],
            // As written in the MTL file (f64), stored as f32 like every loaded value.
            [
                53.407_075_1_f64 as f32,
                37.699_111_8_f64 as f32,
                12.566_370_6_f64 as f32,
            ],
        ),
    ];
    let vertex = |i: usize| DVec3::from_array(CORNELL_VERTICES[i - 1]);
    for (group, m, idx) in CORNELL_FACES {
        let corners: Vec<DVec3> = idx.iter().filter(|&&i| i > 0).map(|&i| vertex(i)).collect();
        b.face(group, mats[m], &corners);
    }
    b.face(
        "light",
        mats[3],
        &[vertex(16), vertex(15), vertex(14), vertex(13)],
    );
    b.finish()
}

/// Closed cube [0, s]³ with inward faces, one group per face.
fn cube(s: f64) -> Scene {
    let mut b = Builder::new("cube");
    let white = b.material("white", [0.5; 3], [0.0; 3]);
    let light = b.material("light", [0.5; 3], [1.0; 3]);
    let (x, y, z) = (DVec3::X * s, DVec3::Y * s, DVec3::Z * s);
    let o = DVec3::ZERO;
    // Each normal u × v points into the cube.
    b.quad("x0", white, o, y, z);
    b.quad("x1", white, x, z, y);
    b.quad("y0", white, o, z, x);
    b.quad("y1", light, y, x, z);
    b.quad("z0", white, o, x, y);
    b.quad("z1", white, z, y, x);
    b.finish()
}

/// Two unit squares in y = 0 (`bottom`, facing +y, emitting) and y = d (`top`, facing
/// −y).
fn plates(d: f64) -> Scene {
    let mut b = Builder::new("plates");
    let light = b.material("light", [0.0; 3], [1.0; 3]);
    let white = b.material("white", [0.5; 3], [0.0; 3]);
    b.quad("bottom", light, DVec3::ZERO, DVec3::Z, DVec3::X);
    b.quad("top", white, DVec3::Y * d, DVec3::X, DVec3::Z);
    b.finish()
}

/// Two rectangles sharing the edge x ∈ [0, 1] on the x axis at 90°: `bottom` in
/// y = 0 (z ∈ [0, w], facing +y, emitting) and `side` in z = 0 (y ∈ [0, h], facing +z).
pub fn builtin_perpendicular(w: f64, h: f64) -> Scene {
    let mut b = Builder::new("perpendicular");
    let light = b.material("light", [0.0; 3], [1.0; 3]);
    let white = b.material("white", [0.5; 3], [0.0; 3]);
    b.quad("bottom", light, DVec3::ZERO, DVec3::Z * w, DVec3::X);
    b.quad("side", white, DVec3::ZERO, DVec3::X, DVec3::Y * h);
    b.finish()
}

/// `plates` at distance 1 with a 0.5 × 0.5 blocker at y = 0.5 centred over them, made
/// of two opposite-facing quads so it is opaque and visible from both sides.
fn obstructed() -> Scene {
    let mut b = Builder::new("obstructed");
    let light = b.material("light", [0.0; 3], [1.0; 3]);
    let white = b.material("white", [0.5; 3], [0.0; 3]);
    b.quad("bottom", light, DVec3::ZERO, DVec3::Z, DVec3::X);
    b.quad("top", white, DVec3::Y, DVec3::X, DVec3::Z);
    let o = DVec3::new(0.25, 0.5, 0.25);
    let (u, v) = (DVec3::X * 0.5, DVec3::Z * 0.5);
    b.quad("blocker", white, o, u, v); // faces −y, towards `bottom`
    b.quad("blocker", white, o, v, u); // faces +y, towards `top`
    b.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_is_valid_and_inward() {
        for name in builtin_names() {
            let s = builtin(name, None).unwrap();
            assert_eq!(s.validate(), Ok(()), "{name}");
            // Every built-in carries its own light but the office, lit by daylight.
            assert_eq!(s.has_emitter(), *name != "office", "{name}");
            assert_eq!(s.source, format!("builtin:{name}"));
        }
    }

    #[test]
    fn cube_faces_point_inward_and_cover_six() {
        let s = builtin("cube", Some(2.0)).unwrap();
        assert_eq!(s.groups, ["x0", "x1", "y0", "y1", "z0", "z1"]);
        let centre = DVec3::splat(1.0);
        for f in &s.faces {
            let c = f.corners.iter().copied().sum::<DVec3>() / 4.0;
            assert!(f.normal().dot(centre - c) > 0.99, "{f:?}");
            assert!((f.area() - 4.0).abs() < 1e-12);
        }
        assert!((s.total_area() - 24.0).abs() < 1e-12);
    }

    #[test]
    fn plates_face_each_other() {
        let s = builtin("plates", Some(0.5)).unwrap();
        assert_eq!(s.groups, ["bottom", "top"]);
        assert_eq!(s.faces[0].normal(), DVec3::Y);
        assert_eq!(s.faces[1].normal(), -DVec3::Y);
        assert_eq!(s.bounds(), (DVec3::ZERO, DVec3::new(1.0, 0.5, 1.0)));
    }

    #[test]
    fn perpendicular_and_obstructed_orientation() {
        let s = builtin_perpendicular(2.0, 3.0);
        assert_eq!(s.faces[0].normal(), DVec3::Y);
        assert_eq!(s.faces[1].normal(), DVec3::Z);
        assert!((s.faces[0].area() - 2.0).abs() < 1e-15);
        assert!((s.faces[1].area() - 3.0).abs() < 1e-15);
        let o = builtin("obstructed", None).unwrap();
        let n: Vec<DVec3> = o.faces.iter().map(|f| f.normal()).collect();
        assert_eq!(n, [DVec3::Y, -DVec3::Y, -DVec3::Y, DVec3::Y]);
    }

    #[test]
    fn bad_names_and_params() {
        assert!(matches!(
            builtin("nope", None),
            Err(SceneError::UnknownBuiltin { .. })
        ));
        for (n, p) in [
            ("cube", -1.0),
            ("plates", 0.0),
            ("plates", f64::NAN),
            ("room", 2.5),
        ] {
            assert!(
                matches!(builtin(n, Some(p)), Err(SceneError::BadParam { .. })),
                "{n} {p}"
            );
        }
        assert!(matches!(
            builtin("cornell", Some(1.0)),
            Err(SceneError::BadParam { .. })
        ));
    }
}
