//! `ffstream annual`: illuminance at sensor points for every hour of a weather year
//! (docs/daylight.md). Computes the form factors (or reuses a file), then the daylight.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use ffstream::brief_number;
use ffstream::daylight::{
    annual, clearsky,
    glazing::Glazing,
    heatmap,
    report::{self, Metrics, Occupied},
    scene::{grid_sensors, group_plane, read_sensors, scene_frame, SceneLight, Sensor},
    weather, Site,
};
use ffstream::ffz::size::human_bytes;
use ffstream::ffz::FfzReader;
use ffstream::geometry::merge::OccluderMesh;
use ffstream::solve::{RowSource, SolveConfig};

use super::choices::RowsArg;
use super::compute::{execute, stopped, stopped_by_signal, ComputeOptions, Outcome};
use super::SceneInput;

#[derive(Args, Debug)]
pub(crate) struct AnnualArgs {
    #[command(flatten)]
    pub input: SceneInput,
    /// Weather file: EnergyPlus EPW or NREL TMY3 CSV (a name ending in .zst is
    /// decompressed). Its hours, in local standard time, drive the sun and the sky.
    /// Without it, every hour of --year is clear (Ineichen–Perez clear sky at
    /// --linke-turbidity) at --location.
    #[arg(long, value_name = "FILE")]
    pub weather: Option<PathBuf>,
    /// Linke turbidity of the clear sky used without --weather: about 2 for clean
    /// mountain air, 3 for a clean lowland sky, 4–7 for hazy or polluted air.
    /// A finite number ≥ 1.
    #[arg(long, default_value_t = clearsky::DEFAULT_LINKE, value_name = "TL", conflicts_with = "weather", value_parser = linke)]
    pub linke_turbidity: f64,
    /// Faces of group GROUP are glazing of visible transmittance TAU (0 < TAU ≤ 1):
    /// daylight passes them scaled by TAU instead of being blocked, and light from
    /// inside that reaches them leaves (reflectance 0). Repeat for several groups.
    #[arg(long, value_name = "GROUP:TAU", value_parser = glazing)]
    pub glazing: Vec<(String, f64)>,
    /// Sensors: a CSV file with header `name,x,y,z,nx,ny,nz` (scene units; the normal is
    /// the direction the sensor faces, e.g. 0,0,1 for a desk).
    #[arg(
        long,
        value_name = "FILE.csv",
        required_unless_present = "grid",
        conflicts_with = "grid"
    )]
    pub sensors: Option<PathBuf>,
    /// Sensors on a grid over the faces of a group instead: pitch SPACING (scene units),
    /// lifted OFFSET along the faces' normal (default 0.8: a work plane over a floor),
    /// facing along it, named GROUP_0, GROUP_1, ...
    #[arg(long, value_name = "GROUP:SPACING[:OFFSET]", value_parser = grid)]
    pub grid: Option<Grid>,
    /// The site as LAT,LON,TZ[,ELEV]: degrees north, degrees east, hours from UTC of the
    /// local standard time, metres. Default: the weather file's; required without one.
    /// South latitudes and west longitudes are negative: `--location -33.9,18.4,2`.
    #[arg(long, value_name = "LAT,LON,TZ[,ELEV]", allow_hyphen_values = true, value_parser = location)]
    pub location: Option<Site>,
    /// Output directory (default: out/SCENE_NAME-annual). It receives form_factors.ffz
    /// (unless --ffz), illuminance.csv, metrics.csv and heatmap_SENSOR.png per sensor.
    #[arg(long, short = 'o', value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Use this form-factor file of the same scene instead of computing one.
    #[arg(long, value_name = "FILE.ffz")]
    pub ffz: Option<PathBuf>,
    /// The year the sun is computed for. Weather files of typical years mix months of
    /// different years; any non-leap year gives the same geometry to 0.1°.
    /// −2000 to 6000, the range of the solar position algorithm (NREL's SPA).
    #[arg(long, default_value_t = 2005, value_name = "YEAR", allow_hyphen_values = true,
          value_parser = clap::value_parser!(i32).range(-2000..=6000))]
    pub year: i32,
    /// Reflectance of the ground outside (below the horizon, seen through openings).
    #[arg(long, default_value_t = 0.2, value_name = "RHO", value_parser = super::choices::number::open_unit)]
    pub ground_reflectance: f64,
    /// Occupied hours for the metrics, START-END in local standard time: an hour of the
    /// weather file counts when it lies within (default 8-18: the hours ending 9 … 18).
    #[arg(long, default_value = "8-18", value_name = "START-END", value_parser = occupied)]
    pub occupied: Occupied,
    /// Illuminance (lux) that daylight autonomy counts as enough (default 300: DA300).
    #[arg(long, default_value_t = 300.0, value_name = "LUX", value_parser = super::choices::number::positive)]
    pub da_threshold: f64,
    /// The scene's up axis: z (x east, y north, z up) or y (x east, y up, −z north, as
    /// glTF and many OBJ exporters write).
    #[arg(long, value_enum, default_value_t = UpAxis::Z, value_name = "AXIS")]
    pub up: UpAxis,
    /// Turn the building: the scene's north axis points this many degrees clockwise from
    /// true north (90: the scene's north points east).
    #[arg(long, default_value_t = 0.0, value_name = "DEG", allow_hyphen_values = true, value_parser = super::choices::number::finite)]
    pub rotate: f64,
    #[command(flatten)]
    pub compute: ComputeOptions,
}

/// The scene's up axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum UpAxis {
    Z,
    Y,
}

impl From<UpAxis> for ffstream::daylight::scene::UpAxis {
    fn from(a: UpAxis) -> Self {
        match a {
            UpAxis::Z => Self::Z,
            UpAxis::Y => Self::Y,
        }
    }
}

/// A sensor grid: group, pitch, offset along the normal.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Grid {
    pub group: String,
    pub spacing: f64,
    pub offset: f64,
}

fn grid(s: &str) -> Result<Grid, String> {
    let bad = || format!("`{s}`: expected GROUP:SPACING[:OFFSET], SPACING > 0");
    let num = |x: &str| x.trim().parse::<f64>().ok().filter(|v| v.is_finite());
    let parts: Vec<&str> = s.split(':').collect();
    let (group, spacing, offset) = match parts[..] {
        [g, sp] => (g, num(sp), Some(0.8)),
        [g, sp, off] => (g, num(sp), num(off)),
        _ => return Err(bad()),
    };
    match (spacing, offset) {
        (Some(spacing), Some(offset)) if spacing > 0.0 && !group.is_empty() => Ok(Grid {
            group: group.to_string(),
            spacing,
            offset,
        }),
        _ => Err(bad()),
    }
}

/// `--linke-turbidity`: a finite number ≥ 1 (1 is a dry, clean atmosphere), checked
/// when the command line is read (it was refused only when the clear year was made).
fn linke(s: &str) -> Result<f64, String> {
    match super::choices::number::finite(s)? {
        x if x >= 1.0 => Ok(x),
        x => Err(format!(
            "Linke turbidity {x}: expected a number ≥ 1 (1 is a dry, clean atmosphere)"
        )),
    }
}

fn glazing(s: &str) -> Result<(String, f64), String> {
    let bad = || format!("`{s}`: expected GROUP:TAU with 0 < TAU ≤ 1");
    let (g, t) = s.rsplit_once(':').ok_or_else(bad)?;
    let tau: f64 = t.trim().parse().map_err(|_| bad())?;
    if g.is_empty() || !(tau > 0.0 && tau <= 1.0) {
        return Err(bad());
    }
    Ok((g.to_string(), tau))
}

fn occupied(s: &str) -> Result<Occupied, String> {
    let bad = || format!("`{s}`: expected START-END in whole hours, 0 ≤ START < END ≤ 24");
    let (a, b) = s.split_once('-').ok_or_else(bad)?;
    let (start, end) = (
        a.trim().parse::<u32>().map_err(|_| bad())?,
        b.trim().parse::<u32>().map_err(|_| bad())?,
    );
    if start >= end || end > 24 {
        return Err(bad());
    }
    Ok(Occupied { start, end })
}

fn location(s: &str) -> Result<Site, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected LAT,LON,TZ[,ELEV] as numbers"))?;
    let site = match v[..] {
        [lat, lon, tz] => Site::new(lat, lon, tz, 0.0),
        [lat, lon, tz, elev] => Site::new(lat, lon, tz, elev),
        _ => return Err(format!("`{s}`: expected 3 or 4 numbers LAT,LON,TZ[,ELEV]")),
    };
    site.check().map_err(|e| e.to_string())?;
    Ok(site)
}

pub(super) fn run(mut a: AnnualArgs) -> anyhow::Result<ExitCode> {
    a.input.daylight = true;
    let dir = a.out_dir.clone().unwrap_or_else(|| {
        let mut d = super::default_run_dir(&a.input.scene).into_os_string();
        d.push("-annual");
        PathBuf::from(d)
    });
    // Inputs first: a bad weather or sensors file costs no form factors.
    let w = year_of(&a)?;
    let scene = super::compute::load_scene(&a.input.scene)?;
    // Computing the form factors prints the scene's warnings; a reused file does not.
    super::compute::scene_warnings(&a.input, &scene, a.ffz.is_some())?;
    let glass = Glazing::new(&scene, &a.glazing).map_err(|e| anyhow::anyhow!("--glazing: {e}"))?;
    let sensors = match (&a.sensors, &a.grid) {
        (Some(path), _) => read_sensors(path)?,
        (None, Some(g)) => grid_sensors(&scene, &g.group, g.spacing, g.offset)
            .map_err(|e| anyhow::anyhow!("--grid {}: {e}", g.group))?,
        (None, None) => anyhow::bail!("give --sensors FILE.csv or --grid GROUP:SPACING"),
    };
    sensors_fit(sensors.len())?;
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    check_files(&a, &dir, &sensors)?;
    let ffz = match form_factors(&mut a, &dir)? {
        ControlFlow::Continue(f) => f,
        ControlFlow::Break(code) => return Ok(code),
    };
    let reader = FfzReader::open(&ffz).with_context(|| format!("{}", ffz.display()))?;
    let mut patches = RowSource::patches(&reader).clone();
    super::solve::materials_from_scene(&patches, &scene, &a.input.scene)?;
    glass.darken(&mut patches);
    let threads = ffstream::job::threads_or_all(a.compute.threads);
    let start = Instant::now();
    let step = |what: &str| {
        eprintln!(
            "ffstream: annual: {what} ({:.1} s)",
            start.elapsed().as_secs_f64()
        )
    };
    // Glazing does not block: its triangles are left out of the occluders.
    let occluders = OccluderMesh::prepare(glass.opaque_triangles(&scene), false, false).build();
    let mut light = SceneLight::new(&patches, &occluders, scene.bounds(), threads);
    light.frame = scene_frame(a.up.into(), a.rotate);
    step(&format!(
        "site {:.4} N {:.4} E, UTC{:+}, weather {}",
        w.site.latitude,
        w.site.longitude,
        w.site.time_zone,
        a.weather
            .as_ref()
            .map_or(w.name.clone(), |p| p.display().to_string())
    ));
    if !glass.is_empty() {
        let groups: Vec<String> = a
            .glazing
            .iter()
            .map(|(g, t)| format!("{g} τ {}", brief_number(*t)))
            .collect();
        step(&format!(
            "glazing: {} faces ({})",
            glass.faces(),
            groups.join(", ")
        ));
    }
    light.glazing = glass;
    let result = annual::sensors_over_year(
        &light,
        &w,
        a.year,
        a.ground_reflectance,
        &sensors,
        &reader,
        &SolveConfig::default(),
        &mut |line| step(&line),
    )?;
    let (hours, series) = (result.hours, result.series);
    let names: Vec<&str> = sensors.iter().map(|s| s.name.as_str()).collect();
    let csv = dir.join("illuminance.csv");
    report::write_illuminance(&csv, &hours, &names, &series)
        .with_context(|| format!("cannot write {}", csv.display()))?;
    let table: Vec<Metrics> = series
        .iter()
        .map(|s| report::metrics(&s.total, &hours, a.occupied, a.da_threshold))
        .collect();
    let mcsv = dir.join("metrics.csv");
    report::write_metrics(&mcsv, &names, &table, a.da_threshold)
        .with_context(|| format!("cannot write {}", mcsv.display()))?;
    let when: Vec<(u32, u32)> = hours.iter().map(|h| (h.month, h.hour)).collect();
    let mut pictures = Vec::new();
    for (s, v) in sensors.iter().zip(&series) {
        let path = dir.join(heatmap_name(&s.name));
        let title = format!(
            "{}: illuminance, {:.2} N {:.2} E UTC{:+}, {}",
            s.name, w.site.latitude, w.site.longitude, w.site.time_zone, w.name
        );
        heatmap::write(&path, &title, &v.total, &when)
            .with_context(|| format!("cannot write {}", path.display()))?;
        pictures.push(path);
    }
    if let Some(g) = &a.grid {
        da_map(&a, g, &dir, &scene, &sensors, &table, &w.name)?;
    }
    step(&format!(
        "wrote the tables and heat maps; peak RSS {:.0} MB",
        ffstream::service::rss::peak_rss_bytes() as f64 / 1e6
    ));
    print_table(&a, &sensors, &table);
    print_files(&[&csv, &mcsv], &pictures, &dir);
    Ok(ExitCode::SUCCESS)
}

/// The hours of the year: the weather file's (checked against `--year`, the site
/// from `--location` when given), or a clear year at `--location`.
fn year_of(a: &AnnualArgs) -> anyhow::Result<weather::Weather> {
    Ok(match (&a.weather, &a.location) {
        (Some(path), site) => {
            let mut w = weather::read(path)?;
            w.check_year(path, a.year)?;
            if let Some(site) = site {
                w.site = site.clone();
            }
            w
        }
        (None, Some(site)) => clearsky::clear_year(site, a.year, a.linke_turbidity)?,
        (None, None) => {
            return Err(super::Usage(
                "give --weather FILE, or --location LAT,LON,TZ[,ELEV] for a year of clear skies"
                    .into(),
            )
            .into())
        }
    })
}

/// The form-factor file: `--ffz`, or one computed into `dir`. `Break` with the exit
/// code when this process is an MPI worker or a signal stopped the computation.
fn form_factors(
    a: &mut AnnualArgs,
    dir: &std::path::Path,
) -> anyhow::Result<ControlFlow<ExitCode, PathBuf>> {
    if let Some(f) = &a.ffz {
        return Ok(ControlFlow::Continue(f.clone()));
    }
    let f = dir.join("form_factors.ffz");
    a.compute.force |= !a.compute.resume;
    a.compute.rows.get_or_insert(RowsArg::Needed);
    match execute(&a.input, f.clone(), &a.compute) {
        Ok(Outcome::Master(r)) => eprintln!("{}", r.summary()),
        Ok(Outcome::Worker) => return Ok(ControlFlow::Break(ExitCode::SUCCESS)),
        // SIGTERM or SIGINT stopped the form factors: 143 or 130, as `compute` and
        // `run` exit (it was 1).
        Err(e) => return stopped_by_signal(e).map(ControlFlow::Break),
    }
    // A signal that came as the last rows were written: stop before the year.
    if let Some(signal) = ffstream::service::interrupt::interrupted() {
        return Ok(ControlFlow::Break(stopped(signal)));
    }
    Ok(ControlFlow::Continue(f))
}

/// The daylight autonomy of a `--grid` as a map over its group's plane (`da_map.png`
/// in `dir`), or a note when the group is not planar.
fn da_map(
    a: &AnnualArgs,
    g: &Grid,
    dir: &std::path::Path,
    scene: &ffstream::scene::Scene,
    sensors: &[Sensor],
    table: &[Metrics],
    weather: &str,
) -> anyhow::Result<()> {
    let da_map = dir.join("da_map.png");
    match group_plane(scene, &g.group) {
        Some((o, u, v)) => {
            let at: Vec<(f64, f64)> = sensors
                .iter()
                .map(|s| ((s.point - o).dot(u), (s.point - o).dot(v)))
                .collect();
            let da: Vec<f64> = table.iter().map(|m| m.da).collect();
            let title = format!(
                "DA{} over {}: share of hours {}-{} h with >= {} lux, {}",
                brief_number(a.da_threshold),
                g.group,
                a.occupied.start,
                a.occupied.end,
                brief_number(a.da_threshold),
                weather
            );
            heatmap::write_grid_map(&da_map, &title, &at, &da, g.spacing, 100.0, "%")
                .with_context(|| format!("cannot write {}", da_map.display()))?;
            println!("daylight autonomy map: {}", da_map.display());
        }
        None => eprintln!(
            "ffstream: annual: group {} is not planar: no DA map (the metrics table has \
             every sensor)",
            g.group
        ),
    }
    Ok(())
}

/// The files written: the two tables, and the heat maps (by name up to 8 of them).
fn print_files(tables: &[&std::path::Path; 2], pictures: &[PathBuf], dir: &std::path::Path) {
    println!(
        "illuminance: {}\nmetrics: {}",
        tables[0].display(),
        tables[1].display()
    );
    if pictures.len() <= 8 {
        for p in pictures {
            println!("heat map: {}", p.display());
        }
    } else {
        println!(
            "heat maps: {} files {}/heatmap_*.png",
            pictures.len(),
            dir.display()
        );
    }
}

/// The metrics table on stdout, one line per sensor.
fn print_table(a: &AnnualArgs, sensors: &[Sensor], table: &[Metrics]) {
    println!(
        "{:<16} {:>8} {:>7} {:>9} {:>9} {:>10} {:>10}",
        "sensor",
        format!("DA{}", brief_number(a.da_threshold)),
        "UDI<100",
        "UDI100-2k",
        "UDI>2k",
        "mean lx",
        "max lx"
    );
    for (s, m) in sensors.iter().zip(table) {
        println!(
            "{:<16} {:>7.1}% {:>6.1}% {:>8.1}% {:>8.1}% {:>10.0} {:>10.0}",
            s.name, m.da, m.udi[0], m.udi[1], m.udi[2], m.mean, m.max
        );
    }
}

/// Memory a sensor takes over a year of hours, measured: the 9600 sensors of
/// `--grid floor:0.05` on `builtin:office` (100 patches) peaked at 4.07 GB, 424 kB each.
const SENSOR_BYTES: u64 = 430_000;

/// Refuse, before the form factors, a sensor set this machine has not the memory for
/// (as `compute` refuses a patch count before subdividing).
fn sensors_fit(sensors: usize) -> anyhow::Result<()> {
    let need = (sensors as u64).saturating_mul(SENSOR_BYTES);
    match ffstream::job::plan::mem_available() {
        Some(available) if need > available => anyhow::bail!(
            "{sensors} sensors need about {} of memory over a year (about {} each) and this \
             machine has {} available: use fewer sensors (a larger --grid spacing)",
            human_bytes(need),
            human_bytes(SENSOR_BYTES),
            human_bytes(available)
        ),
        _ => Ok(()),
    }
}

/// Refuse outputs that are inputs or each other ([`super::outputs`]): among them the
/// heat maps of two sensors whose names become one file name (`a/b` and `a_b`).
fn check_files(a: &AnnualArgs, dir: &std::path::Path, sensors: &[Sensor]) -> anyhow::Result<()> {
    // Named first, as the sensors' own problem (their names, not the command line).
    let mut maps: std::collections::HashMap<String, &str> = std::collections::HashMap::new();
    for s in sensors {
        if let Some(other) = maps.insert(heatmap_name(&s.name), &s.name) {
            anyhow::bail!(
                "sensors `{other}` and `{}` would both write {}: a heat map's name keeps \
                 letters, digits, - and _ of the sensor's name; rename one of them",
                s.name,
                heatmap_name(&s.name)
            );
        }
    }
    let mut inputs = super::compute::compute_inputs(&a.input, &a.compute);
    for (option, path) in [
        ("--weather", &a.weather),
        ("--sensors", &a.sensors),
        ("--ffz", &a.ffz),
    ] {
        if let Some(p) = path {
            inputs.push((option, p.as_path()));
        }
    }
    let mut outputs: Vec<(String, PathBuf)> = Vec::new();
    if a.ffz.is_none() {
        outputs.push(("form_factors.ffz".into(), dir.join("form_factors.ffz")));
    }
    outputs.push(("illuminance.csv".into(), dir.join("illuminance.csv")));
    outputs.push(("metrics.csv".into(), dir.join("metrics.csv")));
    if a.grid.is_some() {
        outputs.push(("da_map.png".into(), dir.join("da_map.png")));
    }
    for s in sensors {
        outputs.push((
            format!("the heat map of sensor `{}`", s.name),
            dir.join(heatmap_name(&s.name)),
        ));
    }
    let named: Vec<_> = outputs
        .iter()
        .map(|(o, p)| (o.as_str(), p.as_path()))
        .collect();
    super::outputs::check(&inputs, &named)
}

/// The heat map file of sensor `name`.
fn heatmap_name(name: &str) -> String {
    format!("heatmap_{}.png", file_safe(name))
}

/// A sensor name as part of a file name: letters, digits, `-` and `_` kept, the rest `_`.
fn file_safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}
