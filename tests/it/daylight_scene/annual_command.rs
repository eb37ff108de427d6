//! The `annual` command on the room with a window: with glazing under a clear sky, its
//! hourly table and metrics against the library's own year (`library_year`), and on the
//! office with a floor grid.

use super::*;

/// What the library gives for `dir/room.obj`, `dir/sensors.csv` and the form factors in
/// `out/form_factors.ffz` over the weather `w`, with `glazing`, as `annual` runs it.
fn library_year(
    dir: &std::path::Path,
    out: &std::path::Path,
    glazing: &[(String, f64)],
    w: &weather::Weather,
) -> annual::AnnualResult {
    let reader = ffstream::ffz::FfzReader::open(out.join("form_factors.ffz")).unwrap();
    let mut patches = ffstream::solve::RowSource::patches(&reader).clone();
    let scene = ffstream::scene::open_scene(dir.join("room.obj").to_str().unwrap()).unwrap();
    let glass = Glazing::new(&scene, glazing).unwrap();
    glass.darken(&mut patches);
    let occluders = OccluderMesh::prepare(glass.opaque_triangles(&scene), false, false).build();
    let mut light = SceneLight::new(&patches, &occluders, scene.bounds(), 2);
    light.glazing = glass;
    let sensors = ffstream::daylight::scene::read_sensors(&dir.join("sensors.csv")).unwrap();
    annual::sensors_over_year(
        &light,
        w,
        2005,
        0.2,
        &sensors,
        &reader,
        &SolveConfig::default(),
        &mut |_| {},
    )
    .unwrap()
}

/// `ffstream annual` without a weather file (a clear year at `--location`) on the room
/// with a glazed window (`--glazing`): its table is the library's clear year through the
/// same glazing and form-factor file; and the options' errors.
#[test]
fn annual_command_with_glazing_under_a_clear_sky() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("room.obj"), room_obj_glazed()).unwrap();
    std::fs::write(d.join("room.mtl"), MTL).unwrap();
    std::fs::write(
        d.join("sensors.csv"),
        "name,x,y,z,nx,ny,nz\nfront,2,1.5,0.8,0,0,1\nback,2,4,0.8,0,0,1\n",
    )
    .unwrap();
    let out = d.join("out");
    let p = |x: &std::path::Path| x.to_str().unwrap().to_string();
    let args = |extra: &[&str]| {
        let mut a = vec![
            "annual".to_string(),
            p(&d.join("room.obj")),
            "--sensors".into(),
            p(&d.join("sensors.csv")),
            "-o".into(),
            p(&out),
            "--patches".into(),
            "300".into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let call = |extra: &[&str]| {
        let a = args(extra);
        crate::common::ffstream(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let run = call(&["--location", "36.1,-79.9,-5,270", "--glazing", "glass:0.6"]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("clear sky (Linke turbidity 3)"), "{stderr}");
    assert!(
        stderr.contains("glazing: 1 faces (glass τ 0.6)"),
        "{stderr}"
    );
    let table = std::fs::read_to_string(out.join("illuminance.csv")).unwrap();
    let rows: Vec<Vec<f64>> = table
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 8760);

    // The library: the clear year, the glass left out of the occluders and dark.
    let site = ffstream::daylight::Site::new(36.1, -79.9, -5.0, 270.0);
    let w = ffstream::daylight::clearsky::clear_year(&site, 2005, 3.0).unwrap();
    let result = library_year(d, &out, &[("glass".into(), 0.6)], &w);
    let mut bright = 0;
    for (k, s) in result.series.iter().enumerate() {
        for (t, row) in rows.iter().enumerate() {
            assert!(
                (row[3 + k] - s.total[t]).abs() <= 0.05 + 1e-9 * s.total[t],
                "{row:?} vs {}",
                s.total[t]
            );
            bright += usize::from(s.total[t] > 1000.0);
        }
    }
    assert!(bright > 1000, "{bright} bright sensor-hours");

    // Bad options name themselves and cost no form factors.
    for (extra, says) in [
        (&["--glazing", "glass:0.6"][..], "--location"),
        (
            &["--location", "36,-80,-5", "--glazing", "nope:0.5"][..],
            "nope is not in the scene",
        ),
        (
            &["--location", "36,-80,-5", "--glazing", "glass:1.5"][..],
            "0 < TAU",
        ),
        (
            &["--location", "36,-80,-5", "--linke-turbidity", "0.5"][..],
            "Linke turbidity 0.5",
        ),
    ] {
        let run = call(extra);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(
            !run.status.success() && stderr.contains(says),
            "{extra:?}: {stderr}"
        );
    }
}

/// `metrics.csv` in `out` against the hourly table `rows` (month, day, hour, then one
/// column per sensor): occupied hours 8–18 are those ending 9 … 18.
fn assert_metrics_match_the_table(out: &std::path::Path, rows: &[Vec<f64>]) {
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let mut ml = metrics.lines();
    assert!(ml
        .next()
        .unwrap()
        .starts_with("sensor,occupied_hours,da300_percent,"));
    for (k, line) in ml.enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let occ: Vec<f64> = rows
            .iter()
            .filter(|r| r[2] >= 9.0 && r[2] <= 18.0)
            .map(|r| r[3 + k])
            .collect();
        assert_eq!(f[1].parse::<usize>().unwrap(), occ.len());
        assert_eq!(occ.len(), 3650);
        let share = |p: &dyn Fn(f64) -> bool| {
            100.0 * occ.iter().filter(|&&e| p(e)).count() as f64 / occ.len() as f64
        };
        // The table rounds to 0.1 lx: hours within 0.05 lx of a threshold may count
        // either way, at most a few.
        let close = |x: f64| (f64::from(f[2].parse::<f32>().unwrap()) - x).abs() <= 0.1;
        assert!(
            close(share(&|e| e >= 300.0)),
            "DA300 {} vs {}",
            f[2],
            share(&|e| e >= 300.0)
        );
        let udi = share(&|e| (100.0..=2000.0).contains(&e));
        assert!(
            (f[4].parse::<f64>().unwrap() - udi).abs() <= 0.1,
            "UDI {} vs {udi}",
            f[4]
        );
    }
}

/// `ffstream annual` end to end on the room with a window: the tables it writes are the
/// library's numbers for the same form-factor file, hour by hour, and its metrics are
/// what the hourly table gives when counted here.
#[test]
fn annual_command_writes_the_hourly_table_and_the_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("room.obj"), room_obj(false)).unwrap();
    std::fs::write(d.join("room.mtl"), MTL).unwrap();
    std::fs::write(
        d.join("sensors.csv"),
        "name,x,y,z,nx,ny,nz\nfront,2,1.5,0.8,0,0,1\nback,2,4,0.8,0,0,1\nwall,0.01,2.5,1.5,1,0,0\n",
    )
    .unwrap();
    let weather = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/weather/723170TYA.CSV.zst");
    let out = d.join("out");
    let p = |x: &std::path::Path| x.to_str().unwrap().to_string();
    let run = crate::common::ffstream(&[
        "annual",
        &p(&d.join("room.obj")),
        "--weather",
        &p(&weather),
        "--sensors",
        &p(&d.join("sensors.csv")),
        "-o",
        &p(&out),
        "--patches",
        "400",
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("DA300"), "{stdout}");
    let table = std::fs::read_to_string(out.join("illuminance.csv")).unwrap();
    let mut lines = table.lines();
    assert_eq!(lines.next(), Some("month,day,hour,front,back,wall"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 8760);

    // The library on the same file.
    let result = library_year(d, &out, &[], &greensboro());
    let hours = &result.hours;
    for (k, s) in result.series.iter().enumerate() {
        for (t, row) in rows.iter().enumerate() {
            assert_eq!(
                (row[0] as u32, row[1] as u32, row[2] as u32),
                (hours[t].month, hours[t].day, hours[t].hour)
            );
            assert!(
                (row[3 + k] - s.total[t]).abs() <= 0.05 + 1e-9 * s.total[t],
                "{row:?} vs {}",
                s.total[t]
            );
        }
    }

    // Metrics counted from the table: occupied hours 8–18 are those ending 9 … 18.
    assert_metrics_match_the_table(&out, &rows);

    // One heat map per sensor: each hour's cell has the colour of its value on the
    // map's scale (values from the table, rounded to 0.1 lx: one level of colour).
    for (k, name) in ["front", "back", "wall"].iter().enumerate() {
        let img =
            ffstream::render::Image::read_png(&out.join(format!("heatmap_{name}.png"))).unwrap();
        let values: Vec<f64> = rows.iter().map(|r| r[3 + k]).collect();
        let top = ffstream::daylight::heatmap::scale_top(&values);
        for t in (0..8760).step_by(97) {
            let (x, y) = ffstream::daylight::heatmap::cell(t, rows[t][2] as u32);
            let want = ffstream::daylight::heatmap::colour(values[t] / top);
            let got = img.pixel(x, y);
            assert!(
                (0..3).all(|c| (i16::from(got[c]) - i16::from(want[c])).abs() <= 1),
                "{name} hour {t}: pixel {got:?}, value {} of {top} is {want:?}",
                values[t]
            );
        }
    }
    assert!(stdout.contains("heat map:"), "{stdout}");

    // Bad inputs: one error line naming the file and line, nothing computed.
    std::fs::write(
        d.join("bad.csv"),
        "name,x,y,z,nx,ny,nz\nfront,2,1.5,zero,0,0,1\n",
    )
    .unwrap();
    let o = crate::common::ffstream(&[
        "annual",
        &p(&d.join("room.obj")),
        "--weather",
        &p(&weather),
        "--sensors",
        &p(&d.join("bad.csv")),
        "-o",
        &p(&d.join("out2")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("bad.csv: line 2: z `zero` is not a finite number"),
        "{err}"
    );
    assert!(
        !d.join("out2").exists(),
        "nothing is written for a bad sensors file"
    );
}

/// `annual builtin:office --grid floor:1`: a sensor per square metre of the floor, 0.8 m
/// up; daylight autonomy falls from the window row to the back row (the light comes in
/// through the south window only).
#[test]
fn annual_on_the_office_with_a_floor_grid() {
    let dir = tempfile::tempdir().unwrap();
    let weather = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/weather/723170TYA.CSV.zst");
    let out = dir.path().join("office");
    let run = crate::common::ffstream(&[
        "annual",
        "builtin:office",
        "--weather",
        weather.to_str().unwrap(),
        "--grid",
        "floor:1",
        "-o",
        out.to_str().unwrap(),
        "--patches",
        "300",
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    // 4 × 6 points; the lattice runs along the floor's first edge (x) fastest in y.
    let da: Vec<(String, f64)> = metrics
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].to_string(), f[2].parse().unwrap())
        })
        .collect();
    assert_eq!(da.len(), 24);
    let sensors = ffstream::daylight::scene::grid_sensors(
        &ffstream::scene::builtin("office", None).unwrap(),
        "floor",
        1.0,
        0.8,
    )
    .unwrap();
    let row_mean = |y: f64| {
        let v: Vec<f64> = sensors
            .iter()
            .zip(&da)
            .filter(|(s, _)| (s.point.y - y).abs() < 1e-9)
            .map(|(_, d)| d.1)
            .collect();
        assert_eq!(v.len(), 4);
        v.iter().sum::<f64>() / 4.0
    };
    let rows: Vec<f64> = (0..6).map(|k| row_mean(0.5 + k as f64)).collect();
    for k in 1..6 {
        assert!(
            rows[k] <= rows[k - 1] + 1e-9,
            "DA300 by row from the window: {rows:?}"
        );
    }
    assert!(rows[0] > rows[5] + 10.0, "{rows:?}");
    // The DA map: each sensor's cell in its value's colour, the window's row at the
    // bottom (b = y up on the floor).
    let img = ffstream::render::Image::read_png(&out.join("da_map.png")).unwrap();
    let at: Vec<(f64, f64)> = sensors.iter().map(|s| (s.point.x, s.point.y)).collect();
    for (p, (_, d)) in at.iter().zip(&da) {
        let (x, y) = ffstream::daylight::heatmap::grid_map_pixel(&at, 1.0, *p);
        let want = ffstream::daylight::heatmap::colour(d / 100.0);
        let got = img.pixel(x, y);
        assert!(
            (0..3).all(|c| (i16::from(got[c]) - i16::from(want[c])).abs() <= 1),
            "sensor at {p:?}: pixel {got:?}, DA {d} is {want:?}"
        );
    }
    let (_, y_front) = ffstream::daylight::heatmap::grid_map_pixel(&at, 1.0, (0.5, 0.5));
    let (_, y_back) = ffstream::daylight::heatmap::grid_map_pixel(&at, 1.0, (0.5, 5.5));
    assert!(y_front > y_back);
}
