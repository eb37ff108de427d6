//! Daylight in a room with a window (a hole in the south wall), from the library: the
//! sensors' adjoint route against forward solves, darkness without openings, linearity,
//! the energy balance through the window and the sun patch on the floor.
//!
//! This file holds the room, its sensors and weather, and the tests through the
//! library; `annual_command`: the `annual` command on the same rooms (and on the office),
//! checked against the library's year.

use std::sync::Arc;

use ffstream::daylight::{
    annual::{self, Domes, HourSky, PatchLight},
    glazing::Glazing,
    scene::{scene_frame, SceneLight, Sensor, UpAxis},
    weather,
};
use ffstream::formfactor::{FormFactorConfig, RowEngine, Scratch};
use ffstream::geometry::{merge::OccluderMesh, occluders::Occluders, subdivide::subdivide};
use ffstream::patch::PatchSet;
use ffstream::solve::{self, MemoryRows, SolveConfig};
use glam::DVec3;

mod annual_command;

/// Room 4 m (x, east) × 5 m (y, north) × 3 m (z, up), faces facing in; a window
/// x ∈ [1, 3], z ∈ [1, 2] in the south wall (y = 0) unless `closed`.
fn room_obj(closed: bool) -> String {
    room_obj_mapped(closed, |p| p)
}

/// [`room_obj`] with every vertex moved by `map` (a rotation, to test scene frames).
fn room_obj_mapped(closed: bool, map: fn([f64; 3]) -> [f64; 3]) -> String {
    let mut v: Vec<[f64; 3]> = Vec::new();
    let mut f: Vec<(String, Vec<usize>)> = Vec::new();
    let mut quad = |g: &str, p: [[f64; 3]; 4]| {
        let base = v.len();
        v.extend(p);
        f.push((g.to_string(), (base + 1..=base + 4).collect()));
    };
    // Corners listed counter-clockwise seen from inside the room.
    let walls: [(&str, [[f64; 3]; 4]); 5] = [
        (
            "floor",
            [[0., 0., 0.], [4., 0., 0.], [4., 5., 0.], [0., 5., 0.]],
        ),
        (
            "ceiling",
            [[0., 0., 3.], [0., 5., 3.], [4., 5., 3.], [4., 0., 3.]],
        ),
        (
            "north",
            [[0., 5., 0.], [4., 5., 0.], [4., 5., 3.], [0., 5., 3.]],
        ),
        (
            "west",
            [[0., 0., 0.], [0., 5., 0.], [0., 5., 3.], [0., 0., 3.]],
        ),
        (
            "east",
            [[4., 0., 0.], [4., 0., 3.], [4., 5., 3.], [4., 5., 0.]],
        ),
    ];
    for (g, p) in walls {
        quad(g, p);
    }
    // South wall (y = 0), seen from inside (looking −y): counter-clockwise is x
    // decreasing along the bottom.
    let south = |x0: f64, x1: f64, z0: f64, z1: f64| {
        [[x1, 0., z0], [x0, 0., z0], [x0, 0., z1], [x1, 0., z1]]
    };
    if closed {
        quad("south", south(0., 4., 0., 3.));
    } else {
        quad("south", south(0., 4., 0., 1.));
        quad("south", south(0., 4., 2., 3.));
        quad("south", south(0., 1., 1., 2.));
        quad("south", south(3., 4., 1., 2.));
    }
    let mut s = String::from("mtllib room.mtl\n");
    for p in v.iter().map(|&p| map(p)) {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for (g, idx) in &f {
        s += &format!(
            "g {g}\nusemtl {g}\nf {}\n",
            idx.iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    s
}

/// [`room_obj`] with the window glazed: a pane (group `glass`, facing in) fills it.
fn room_obj_glazed() -> String {
    // room_obj(false) writes 9 quads: 36 vertices before the pane's.
    room_obj(false) + "v 3 0 1\nv 1 0 1\nv 1 0 2\nv 3 0 2\ng glass\nusemtl glass\nf 37 38 39 40\n"
}

const MTL: &str =
    "newmtl glass\nKd 0.1 0.1 0.1\nnewmtl floor\nKd 0.2 0.2 0.2\nnewmtl ceiling\nKd 0.7 0.7 0.7\n\
                   newmtl north\nKd 0.5 0.5 0.5\nnewmtl west\nKd 0.5 0.4 0.3\n\
                   newmtl east\nKd 0.5 0.5 0.5\nnewmtl south\nKd 0.5 0.5 0.5\n";

struct Room {
    _dir: tempfile::TempDir,
    scene: ffstream::scene::Scene,
    patches: PatchSet,
    occluders: Occluders,
    extent: (DVec3, DVec3),
    rows: MemoryRows,
}

fn room(closed: bool, max_edge: f64) -> Room {
    room_from(room_obj(closed), max_edge)
}

fn room_from(obj: String, max_edge: f64) -> Room {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("room.obj"), obj).unwrap();
    std::fs::write(dir.path().join("room.mtl"), MTL).unwrap();
    let scene = ffstream::scene::open_scene(dir.path().join("room.obj").to_str().unwrap()).unwrap();
    let patches = subdivide(&scene, max_edge);
    let tris: Vec<_> = scene.triangles().collect();
    let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
    for (_, t) in &tris {
        for p in t {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    let occluders = OccluderMesh::prepare(tris.clone(), false, false).build();
    let engine = RowEngine::new(
        &patches,
        Arc::new(OccluderMesh::prepare(tris, false, false).build()),
        FormFactorConfig::accurate(),
    );
    let mut s = Scratch::new();
    let rows = (0..patches.len() as u32)
        .map(|i| engine.compute_row(i, &mut s))
        .collect();
    let rows = MemoryRows::new(patches.clone(), rows).unwrap();
    Room {
        _dir: dir,
        scene,
        patches,
        occluders,
        extent: (lo, hi),
        rows,
    }
}

fn greensboro() -> weather::Weather {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/weather/723170TYA.CSV.zst");
    weather::read(&p).unwrap()
}

fn sensors() -> Vec<Sensor> {
    [
        ("desk_front", [2.0, 1.5, 0.8]),
        ("desk_back", [2.0, 4.0, 0.8]),
        ("corner", [0.5, 4.5, 0.8]),
    ]
    .into_iter()
    .map(|(n, p)| Sensor {
        name: n.into(),
        point: DVec3::from(p),
        normal: DVec3::Z,
    })
    .collect()
}

fn tight() -> SolveConfig {
    SolveConfig {
        tolerance: 1e-10,
        ..SolveConfig::default()
    }
}

/// The forward solve of hour `t`: B = ρ∘E⁰ + ρ F B per channel, and E⁰.
fn forward(r: &Room, pl: &PatchLight, hours: &[HourSky], t: usize) -> (Vec<f64>, solve::Solution) {
    let rho = solve::scene_reflectance(&r.patches);
    let e0 = annual::first_arrival(pl, hours, t, &Domes::default(), 0.2);
    let emission: Vec<[f32; 3]> = e0
        .iter()
        .zip(&rho)
        .map(|(e, r)| r.map(|x| (f64::from(x) * e) as f32))
        .collect();
    let sol = solve::solve(&r.rows, &[emission], &rho, &tight()).unwrap();
    (e0, sol)
}

/// Hours used by the per-hour checks: a bright sunny noon, an overcast noon, a low sun.
fn some_hours(hours: &[HourSky]) -> Vec<usize> {
    let best = (0..hours.len())
        .max_by(|&a, &b| {
            hours[a]
                .direct_normal()
                .total_cmp(&hours[b].direct_normal())
        })
        .unwrap();
    let overcast = (0..hours.len())
        .find(|&t| hours[t].sky.is_some() && hours[t].direct_normal() == 0.0 && hours[t].hour == 13)
        .unwrap();
    let low = (0..hours.len())
        .find(|&t| {
            hours[t].direct_normal() > 1000.0 && hours[t].sun.z < 0.2 && hours[t].sun.z > 0.05
        })
        .unwrap();
    vec![best, overcast, low]
}

#[test]
fn sensors_adjoint_route_equals_forward_solves_per_hour() {
    let r = room(false, 0.5);
    let light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
    let domes = Domes::default();
    let w = greensboro();
    let hours = annual::hour_skies(&w, 2005).unwrap();
    let pl = PatchLight::new(&light, &domes, &hours);
    let sensors = sensors();
    let models = annual::sensor_models(&light, &domes, &pl, &sensors, &r.rows, &tight()).unwrap();
    let series = annual::series(&models, &light, &hours, &pl.bin_of_hour, &domes, 0.2);
    let g: Vec<Vec<f32>> = sensors
        .iter()
        .map(|s| light.sensor_form_factors(s))
        .collect();
    for t in some_hours(&hours) {
        let (_, sol) = forward(&r, &pl, &hours, t);
        for (k, s) in series.iter().enumerate() {
            let forward: f64 = g[k]
                .iter()
                .zip(&sol.b[0])
                .map(|(&gj, b)| {
                    f64::from(gj) * (0..3).map(|c| annual::PHOTOPIC[c] * b[c]).sum::<f64>()
                })
                .sum();
            let adjoint = s.reflected[t];
            assert!(
                (forward - adjoint).abs() <= 1e-5 * forward.abs() + 1e-9,
                "hour {t} sensor {k}: forward {forward} lx, adjoint {adjoint} lx"
            );
            assert!(
                forward > 1.0,
                "hour {t}: inter-reflected light {forward} lx"
            );
        }
    }
}

/// A pane of transmittance τ in the window: every sensor gets exactly τ times what it
/// gets through the open window, in each part and hour. Sky, ground and sun reach the
/// room only through the window, and light from inside that reaches the pane leaves as it
/// leaves through the hole (the glass reflects nothing), so the glazed room is the open
/// room with all its daylight scaled by τ.
#[test]
fn glazing_scales_the_open_windows_light_by_its_transmittance() {
    let tau = 0.6;
    let open = room(false, 0.75);
    let glazed = room_from(room_obj_glazed(), 0.75);
    assert!(glazed.patches.len() > open.patches.len());
    let glass = Glazing::new(&glazed.scene, &[("glass".into(), tau)]).unwrap();
    assert_eq!(glass.faces(), 1);
    let occluders =
        OccluderMesh::prepare(glass.opaque_triangles(&glazed.scene), false, false).build();
    let mut patches = glazed.patches.clone();
    glass.darken(&mut patches);
    let mut w = greensboro();
    // Three days: a clear one in June, one in December, a cloudy one in March.
    w.hours
        .retain(|h| matches!((h.month, h.day), (6, 21) | (12, 21) | (3, 10)));
    assert_eq!(w.hours.len(), 72);
    let run = |light: &SceneLight<'_>, rows: &MemoryRows| {
        annual::sensors_over_year(
            light,
            &w,
            2005,
            0.2,
            &sensors(),
            rows,
            &tight(),
            &mut |_| {},
        )
        .unwrap()
        .series
    };
    let without = run(
        &SceneLight::new(&open.patches, &open.occluders, open.extent, 2),
        &open.rows,
    );
    let mut light = SceneLight::new(&patches, &occluders, glazed.extent, 2);
    light.glazing = glass;
    let with = run(&light, &glazed.rows);
    let mut lit = 0;
    for (a, b) in without.iter().zip(&with) {
        let parts = |s: &annual::Series| {
            [
                s.total.clone(),
                s.direct_sky.clone(),
                s.direct_sun.clone(),
                s.reflected.clone(),
            ]
        };
        for (pa, pb) in parts(a).iter().zip(parts(b)) {
            for (t, (x, y)) in pa.iter().zip(&pb).enumerate() {
                assert!(
                    (y - tau * x).abs() <= 1e-6 * x + 1e-9,
                    "hour {t}: glazed {y} lx, open {x} lx × {tau}"
                );
                lit += usize::from(*x > 1.0);
            }
        }
    }
    assert!(lit > 100, "{lit} lit values");
}

/// Without an opening no daylight gets in: every sensor reads exactly 0 in every hour.
#[test]
fn a_closed_room_is_dark_all_year() {
    let r = room(true, 0.75);
    let light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
    let domes = Domes::default();
    let hours = annual::hour_skies(&greensboro(), 2005).unwrap();
    let pl = PatchLight::new(&light, &domes, &hours);
    assert!(pl.sky.iter().all(|&c| c == 0.0), "a patch sees the sky");
    assert!(
        pl.sun.iter().flatten().all(|&c| c == 0.0),
        "a patch sees the sun"
    );
    let models = annual::sensor_models(&light, &domes, &pl, &sensors(), &r.rows, &tight()).unwrap();
    let all = annual::series(&models, &light, &hours, &pl.bin_of_hour, &domes, 0.2);
    for (m, s) in models.iter().zip(&all) {
        assert!(
            s.total.iter().all(|&e| e == 0.0),
            "{}: light in a closed room",
            m.sensor.name
        );
    }
}

/// Twice the sky's luminance and twice the sun give twice every sensor's illuminance in
/// every hour (the pipeline is linear in its light; the Perez model itself is not
/// homogeneous in the weather's irradiance, since Δ and the efficacies depend on its
/// level, so the doubling is applied to the sky vectors and the sun).
#[test]
fn doubling_the_light_doubles_every_result() {
    let r = room(false, 0.75);
    let light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
    let domes = Domes::default();
    let hours = annual::hour_skies(&greensboro(), 2005).unwrap();
    let double: Vec<HourSky> = hours
        .iter()
        .map(|h| {
            let mut h = h.clone();
            if let Some(s) = &mut h.sky {
                s.diffuse_horizontal *= 2.0;
                s.direct_normal *= 2.0;
            }
            h
        })
        .collect();
    let pl = PatchLight::new(&light, &domes, &hours);
    let models = annual::sensor_models(&light, &domes, &pl, &sensors(), &r.rows, &tight()).unwrap();
    let mut lit = 0;
    let once = annual::series(&models, &light, &hours, &pl.bin_of_hour, &domes, 0.2);
    let twice = annual::series(&models, &light, &double, &pl.bin_of_hour, &domes, 0.2);
    for (a, b) in once.iter().zip(&twice) {
        for (x, y) in a.total.iter().zip(&b.total) {
            assert!((y - 2.0 * x).abs() <= 1e-12 * x.abs(), "{x} → {y}");
            lit += usize::from(*x > 0.0);
        }
    }
    assert!(lit > 3 * 4000, "{lit} lit sensor-hours");
}

/// Issue 22's acceptance: the light that comes in through the opening is absorbed by the
/// patches or leaves through the opening again, hour by hour, within 1e-4 (forward solve
/// per hour; the room's rows are exact, so they are reciprocal). And the light that
/// comes in, Σ A_i E⁰_i from the patches' own views of sky, ground and sun, is what the
/// window's outside plane receives times its area.
#[test]
fn light_through_the_window_is_absorbed_or_leaves_again() {
    let r = room(false, 0.5);
    let light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
    let domes = Domes::default();
    let hours = annual::hour_skies(&greensboro(), 2005).unwrap();
    let pl = PatchLight::new(&light, &domes, &hours);
    let rho = solve::scene_reflectance(&r.patches);
    let outward = domes.fine.coefficients(-DVec3::Y);
    let window_area = 2.0;
    for t in some_hours(&hours) {
        let h = &hours[t];
        let (e0, sol) = forward(&r, &pl, &hours, t);
        let phi_in: f64 = r
            .patches
            .patches
            .iter()
            .zip(&e0)
            .map(|(p, e)| p.area * e)
            .sum();
        let (mut absorbed, mut out) = ([0.0f64; 3], [0.0f64; 3]);
        for (i, p) in r.patches.patches.iter().enumerate() {
            let row_sum: f64 = r.rows.rows()[i]
                .to_dense(r.patches.len())
                .iter()
                .map(|&f| f64::from(f))
                .sum();
            for (c, (a, o)) in absorbed.iter_mut().zip(&mut out).enumerate() {
                let arriving = e0[i] + sol.h[0][i][c];
                *a += p.area * (1.0 - f64::from(rho[i][c])) * arriving;
                *o += p.area * sol.b[0][i][c] * (1.0 - row_sum);
            }
        }
        for c in 0..3 {
            let gap = (phi_in - absorbed[c] - out[c]).abs() / phi_in;
            eprintln!(
                "hour {t} channel {c}: in {phi_in:.2} lm, absorbed {:.2}, out {:.2}, gap {gap:.1e}",
                absorbed[c], out[c]
            );
            assert!(gap <= 1e-4, "hour {t} channel {c}: gap {gap:.2e}");
        }
        let fine = h.sky.as_ref().map(|s| domes.fine.sky_vector(s, 0.2));
        let sky = fine.as_ref().map_or(0.0, |v| {
            outward.iter().zip(&v.luminance).map(|(c, l)| c * l).sum()
        });
        let window = window_area * (sky + h.direct_normal() * (-h.sun.y).max(0.0));
        // The sky's part: what the patches' views of sky and ground let in against the
        // window's view, within 1 % (coarse dome cells against the fine dome).
        let sun_in: f64 = match pl.bin_of_hour[t] {
            Some(b) => {
                h.direct_normal()
                    * r.patches
                        .patches
                        .iter()
                        .zip(&pl.sun[b])
                        .map(|(p, &z)| p.area * f64::from(z))
                        .sum::<f64>()
            }
            None => 0.0,
        };
        let sky_in = phi_in - sun_in;
        eprintln!(
            "hour {t}: in {phi_in:.1} lm (sky {sky_in:.1}, sun {sun_in:.1} in its bin's direction); \
             the window's outside plane: sky {:.1}, sun {:.1}",
            window_area * sky,
            window - window_area * sky
        );
        assert!((sky_in / (window_area * sky) - 1.0).abs() <= 0.01);
    }
}

/// Issue 22's acceptance: at solar noon on the March equinox the sun patch on the floor
/// lies where the window's outline projects along the sun's direction, within a patch.
#[test]
fn the_equinox_noon_sun_patch_is_the_windows_projection() {
    let r = room(false, 0.25);
    let light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
    let w = greensboro();
    // Local standard time of solar noon: search the day's minute of smallest zenith.
    let site = &w.site;
    let at = |m: u32| {
        ffstream::daylight::SunPosition::at(
            site,
            ffstream::daylight::LocalTime {
                year: 2005,
                month: 3,
                day: 20,
                hour: m / 60,
                minute: m % 60,
                second: 0.0,
            },
        )
        .unwrap()
    };
    let noon = (600..840)
        .min_by(|&a, &b| at(a).zenith.total_cmp(&at(b).zenith))
        .unwrap();
    let sun = at(noon).enu();
    let z = sun.z.acos();
    // The window's bottom and top edges land at y = z_edge · tan(zenith) (x unchanged,
    // up to the sun's small east-west component).
    let (y0, y1) = (1.0 * z.tan(), 2.0 * z.tan());
    let dx = -sun.x / sun.z; // x shift per metre of drop
    let lit = light.patch_sun(sun);
    let (mut wrong, mut floor) = (0, 0);
    for (p, &l) in r.patches.patches.iter().zip(&lit) {
        if p.normal.z < 0.9 {
            continue;
        }
        floor += 1;
        let c = p.centroid();
        let fraction = l as f64 / sun.z;
        // Inside the projection by more than half a patch: lit; outside by as much: dark.
        let margin = 0.25;
        let xs = |h: f64| (1.0 + dx * h, 3.0 + dx * h);
        let (xa, xb) = xs(1.5);
        let inside =
            c.y > y0 + margin && c.y < y1 - margin && c.x > xa + margin && c.x < xb - margin;
        let outside =
            c.y < y0 - margin || c.y > y1 + margin || c.x < xa - margin || c.x > xb + margin;
        if (inside && fraction < 0.999) || (outside && fraction > 0.0) {
            wrong += 1;
            eprintln!("floor patch at {c}: lit fraction {fraction}");
        }
    }
    assert!(floor > 100);
    assert_eq!(
        wrong,
        0,
        "sun {sun}, zenith {:.2}°, expected y in [{y0:.3}, {y1:.3}]",
        z.to_degrees()
    );
}

/// Sunlight through the window lands on the patches: for several sun directions the
/// patches' sunlit cosines, summed with their areas, equal the window's area times its
/// cosine to the sun within 1 % (sampling of the sun patch's edges, docs/daylight.md),
/// and a ray from a patch point reaches the sun exactly when it passes through the
/// window rectangle (no leak between the wall's quads, none blocked wrongly).
#[test]
fn sunlight_through_the_window_lands_on_the_patches() {
    let r = room(false, 0.5);
    let light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
    for (alt, az) in [(40f64, 180f64), (30.0, 150.0), (60.0, 200.0), (15.0, 120.0)] {
        let s = ffstream::daylight::dome::direction(alt.to_radians(), az.to_radians());
        let z = light.patch_sun(s);
        let total: f64 = r
            .patches
            .patches
            .iter()
            .zip(&z)
            .map(|(p, &z)| p.area * f64::from(z))
            .sum();
        let window = 2.0 * (-s.y);
        eprintln!(
            "sun at altitude {alt}°, azimuth {az}°: Σ A Z {total:.4} m², window {window:.4} m²"
        );
        assert!((total / window - 1.0).abs() <= 0.01, "{total} vs {window}");
        let mut mismatches = 0;
        for p in &r.patches.patches {
            if p.normal.dot(s) <= 0.0 {
                continue;
            }
            for (x, _) in ffstream::daylight::scene::patch_points(p, 2) {
                let free = !r.occluders.occluded(x, x + s * 100.0, (p.face, p.face));
                let c = x + s * (-x.y / s.y);
                let through = c.x > 1.0 && c.x < 3.0 && c.z > 1.0 && c.z < 2.0;
                mismatches += usize::from(free != through);
            }
        }
        assert_eq!(mismatches, 0);
    }
}

/// The same room given y-up (glTF habit: x east, y up, −z north) and read with the 'y'
/// frame, or turned 90° about the vertical (its window facing west) and read with
/// `rotate` 90, receives the same light as the z-up room: scene frames only relabel
/// axes.
#[test]
fn scene_frames_relabel_axes_and_turn_the_building() {
    let w = greensboro();
    let run = |r: &Room, frame: glam::DMat3, map: fn([f64; 3]) -> [f64; 3]| {
        let mut light = SceneLight::new(&r.patches, &r.occluders, r.extent, 2);
        light.frame = frame;
        let sensors: Vec<Sensor> = sensors()
            .into_iter()
            .map(|s| Sensor {
                point: DVec3::from(map(s.point.into())),
                normal: DVec3::from(map(s.normal.into())),
                ..s
            })
            .collect();
        annual::sensors_over_year(
            &light,
            &w,
            2005,
            0.2,
            &sensors,
            &r.rows,
            &tight(),
            &mut |_| {},
        )
        .unwrap()
        .series
    };
    let base = run(&room(false, 0.75), glam::DMat3::IDENTITY, |p| p);
    let y_up: fn([f64; 3]) -> [f64; 3] = |p| [p[0], p[2], -p[1]];
    // Turned so the scene's north axis (+y) points east: scene = Rz(+90°) · east-north-up,
    // i.e. (x, y) → (−y, x).
    let turned: fn([f64; 3]) -> [f64; 3] = |p| [-p[1], p[0], p[2]];
    for (name, r, frame, map) in [
        (
            "y up",
            room_from(room_obj_mapped(false, y_up), 0.75),
            scene_frame(UpAxis::Y, 0.0),
            y_up,
        ),
        (
            "turned",
            room_from(room_obj_mapped(false, turned), 0.75),
            scene_frame(UpAxis::Z, 90.0),
            turned,
        ),
    ] {
        let other = run(&r, frame, map);
        for (a, b) in base.iter().zip(&other) {
            let peak = a.total.iter().copied().fold(0.0, f64::max);
            for (x, y) in a.total.iter().zip(&b.total) {
                assert!((x - y).abs() <= 1e-6 * peak, "{name}: {x} vs {y} lx");
            }
        }
    }
}
