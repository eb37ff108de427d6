//! Stress, bad or unusual input to `ffstream annual` (issue 48): a southern site on the
//! command line, weather files that are not a plain year, sensor sets too large for
//! memory or whose names clash, and the exit codes of usage mistakes.

use crate::common::{ffstream, path_str};
use crate::stress_cli::assert_no_panic;

/// `--location -33.9,18.4,2` (Cape Town) was read by clap as the option `-3`
/// ("unexpected argument '-3'"): a negative latitude must reach the site check. The
/// run stops later, at the missing grid group, which proves the location was read;
/// `-95,...` is refused by the site check itself, naming the latitude.
#[test]
fn a_southern_latitude_is_a_value_not_an_option() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let base = [
        "annual",
        "builtin:office",
        "--grid",
        "no_such_group:1",
        "-o",
        path_str(&out),
        "--location",
    ];
    let mut a = base.to_vec();
    a.push("-33.9,18.4,2");
    let o = ffstream(&a);
    assert_no_panic(&o, "--location -33.9,18.4,2");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!stderr.contains("unexpected argument"), "{stderr}");
    assert!(stderr.contains("no_such_group"), "{stderr}");
    let mut a = base.to_vec();
    a.push("-95,18.4,2");
    let o = ffstream(&a);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("latitude"), "{stderr}");
}

/// The shipped TMY3 year (Greensboro) as text.
fn greensboro_text() -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/weather/723170TYA.CSV.zst");
    let bytes = zstd::decode_all(std::fs::read(p).unwrap().as_slice()).unwrap();
    String::from_utf8(bytes).unwrap()
}

/// The shipped year with February 29 added after February 28 (a copy of it): 8784
/// hours, a whole leap year. Returns the text and the line of the first February 29.
fn leap_year_text() -> (String, usize) {
    let text = greensboro_text();
    let mut out = Vec::new();
    let mut first = 0;
    let lines: Vec<&str> = text.lines().collect();
    for l in &lines {
        out.push(l.to_string());
        if l.starts_with("02/28/") && l.split(',').nth(1) == Some("24:00") {
            first = out.len() + 1;
            for d in lines.iter().filter(|x| x.starts_with("02/28/")) {
                out.push(d.replacen("02/28/", "02/29/", 1));
            }
        }
    }
    assert!(first > 0);
    (out.join("\n") + "\n", first)
}

/// A weather file with February 29 under the default `--year 2005` stopped, after the
/// form factors were computed, on a debug dump (`time LocalTime { year: 2005, ... }:
/// not a valid date and time`). It is now refused before any work, naming the file and
/// the line and suggesting a leap year; with `--year 2004` the same file runs.
#[test]
fn february_29_in_a_common_year_names_the_line_and_suggests_a_leap_year() {
    let dir = tempfile::tempdir().unwrap();
    let (text, line) = leap_year_text();
    let w = dir.path().join("leap.csv");
    std::fs::write(&w, text).unwrap();
    let out = dir.path().join("out");
    let args = [
        "annual",
        "builtin:office",
        "--weather",
        path_str(&w),
        "--grid",
        "floor:1",
        "--patches",
        "100",
        "-o",
        path_str(&out),
        "--quiet",
    ];
    let o = ffstream(&args);
    crate::stress_cli::assert_one_error(
        &o,
        "February 29 in 2005",
        &[
            "leap.csv",
            &format!("line {line}"),
            "February 29",
            "--year",
            "2004",
        ],
    );
    assert!(
        !out.join("form_factors.ffz").exists(),
        "the form factors were computed before the check"
    );
    let mut a = args.to_vec();
    a.extend(["--year", "2004"]);
    let o = ffstream(&a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `--grid floor:1e-4` on the office (24 m² of floor) made 2.4e9 grid points and
/// aborted allocating 9.7 GB; `floor:0.01` (240 000 sensors, about 100 GB over a
/// year at 0.4 MB each) would run for hours into the memory limit. Both are refused
/// at once, before the form factors: the first by the grid's point limit (1e6), the
/// second by the memory check when the machine has less than 100 GB available.
#[test]
fn a_sensor_grid_too_fine_for_memory_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let run = |grid: &str| {
        let start = std::time::Instant::now();
        let o = ffstream(&[
            "annual",
            "builtin:office",
            "--location",
            "36,-80,-5",
            "--grid",
            grid,
            "--patches",
            "100",
            "-o",
            path_str(&out),
            "--quiet",
        ]);
        assert!(
            start.elapsed().as_secs() < 20,
            "{grid}: not refused up front"
        );
        assert!(!out.join("form_factors.ffz").exists());
        o
    };
    let o = run("floor:1e-4");
    crate::stress_cli::assert_one_error(&o, "floor:1e-4", &["--grid", "spacing", "1000000"]);
    // 240 000 sensors need about 103 GB: refused wherever less is available (a
    // machine with more would start the run, which this test does not wait for).
    let available_kb: u64 = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            let line = m
                .lines()
                .find(|l| l.starts_with("MemAvailable:"))?
                .to_string();
            line.split_whitespace().nth(1)?.parse().ok()
        })
        .unwrap_or(u64::MAX);
    if available_kb < 100_000_000 {
        let o = run("floor:0.01");
        crate::stress_cli::assert_one_error(
            &o,
            "floor:0.01",
            &["240000 sensors", "memory", "available"],
        );
    }
}

/// A weather file of a few kB that decompresses to 200 MB (a `.epw.zst` of spaces):
/// it was decompressed whole, however large. Refused past 64 MiB, naming the file.
#[test]
fn a_compressed_weather_file_is_decompressed_only_up_to_a_cap() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let w = dir.path().join("bomb.epw.zst");
    let mut e = zstd::stream::Encoder::new(std::fs::File::create(&w).unwrap(), 3).unwrap();
    e.write_all(b"LOCATION,").unwrap();
    let spaces = vec![b' '; 1 << 20];
    for _ in 0..200 {
        e.write_all(&spaces).unwrap();
    }
    e.finish().unwrap();
    assert!(std::fs::metadata(&w).unwrap().len() < 100_000);
    let out = dir.path().join("out");
    let o = ffstream(&[
        "annual",
        "builtin:office",
        "--weather",
        path_str(&w),
        "--grid",
        "floor:1",
        "-o",
        path_str(&out),
    ]);
    crate::stress_cli::assert_one_error(&o, "bomb", &["bomb.epw.zst", "more than 67108864 bytes"]);
}

/// A weather file of one hour was taken as the year (its metrics, shares of the
/// year's hours, then meant nothing), and one with an hour missing likewise. `annual`
/// needs every hour of a year (8760, or 8784 with February 29): the error names the
/// count and the first missing hour, before any work.
#[test]
fn weather_that_is_not_a_whole_year_is_refused_naming_the_first_missing_hour() {
    let dir = tempfile::tempdir().unwrap();
    let text = greensboro_text();
    let lines: Vec<&str> = text.lines().collect();
    // Header lines 1-2; line 3 is 01/01 hour 1, so line 3 + 24·31 + 10 is 02/01 hour 11.
    let gap = 2 + 24 * 31 + 10;
    assert!(lines[gap].starts_with("02/01/") && lines[gap].contains(",11:00,"));
    let one_hour = lines[..3].join("\n") + "\n";
    let mut holed = lines.clone();
    holed.remove(gap);
    let holed = holed.join("\n") + "\n";
    for (name, text, want) in [
        (
            "hour.csv",
            one_hour,
            "1 hours, not a whole year (8760): the first missing is month 1, day 1, hour 2",
        ),
        (
            "holed.csv",
            holed,
            "8759 hours, not a whole year (8760): the first missing is month 2, day 1, hour 11",
        ),
    ] {
        let w = dir.path().join(name);
        std::fs::write(&w, text).unwrap();
        let out = dir.path().join("out");
        let o = ffstream(&[
            "annual",
            "builtin:office",
            "--weather",
            path_str(&w),
            "--grid",
            "floor:1",
            "-o",
            path_str(&out),
        ]);
        crate::stress_cli::assert_one_error(&o, name, &[name, want]);
        assert!(!out.join("form_factors.ffz").exists());
    }
}

/// Sensors `a/b` and `a_b` both wrote `heatmap_a_b.png`, the second over the first.
/// The clash is refused before any work, naming both sensors.
#[test]
fn sensors_whose_heat_maps_would_share_a_file_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sensors.csv");
    std::fs::write(
        &csv,
        "name,x,y,z,nx,ny,nz\na/b,1,1,0.8,0,0,1\na_b,2,1,0.8,0,0,1\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let o = ffstream(&[
        "annual",
        "builtin:office",
        "--location",
        "36,-80,-5",
        "--sensors",
        path_str(&csv),
        "-o",
        path_str(&out),
    ]);
    crate::stress_cli::assert_one_error(&o, "a/b and a_b", &["`a/b`", "`a_b`", "heatmap_a_b.png"]);
    assert!(!out.join("form_factors.ffz").exists());
}

/// Usage mistakes of `annual` and `render` found after clap's parse exited 1: no
/// `--weather` and no `--location`, `--linke-turbidity 0`, `render --exposure 1e300`
/// (infinite as the 32-bit float it is used as), a `--year` outside the solar
/// position algorithm's range. Each is a usage error, exit 2, naming the option.
#[test]
fn annual_and_render_usage_mistakes_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let annual = |extra: &[&str]| {
        let mut a = vec![
            "annual",
            "builtin:office",
            "--grid",
            "floor:1",
            "-o",
            path_str(&out),
        ];
        a.extend_from_slice(extra);
        ffstream(&a)
    };
    let cases = [
        (annual(&[]), "--location"),
        (
            annual(&["--location", "36,-80,-5", "--linke-turbidity", "0"]),
            "--linke-turbidity",
        ),
        (
            annual(&["--location", "36,-80,-5", "--year", "99999"]),
            "--year",
        ),
        (
            ffstream(&[
                "render",
                "x.ffz",
                "--radiosity",
                "r.csv",
                "-o",
                "i.png",
                "--exposure",
                "1e300",
            ]),
            "--exposure",
        ),
    ];
    for (o, option) in cases {
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{option}: {stderr}");
        assert!(stderr.contains(option), "{option}: {stderr}");
    }
    assert!(!out.join("form_factors.ffz").exists());
}
