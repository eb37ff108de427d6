//! Row-engine benchmark on a real scene: wall time, rays and pair counters of a
//! sample of rows (extrapolated to the whole matrix), and the form-factor error of
//! each mode against the `reference` preset on a few random rows.
//!
//! Run (release build of the library, no MPI needed):
//!
//! ```text
//! cargo bench --no-default-features --bench perf_rows -- SCENE PATCHES [options]
//!   --modes symmetric,default,topk256,occluders   modes to time (default: default)
//!                   (modes: see `config_of`; `fasttopk64` is `--preset fast --top-k 64`,
//!                   `topk64p` `--top-k 64 --links off`)
//!   --rows R        rows timed per mode, spread evenly over the matrix (default: all)
//!   --threads T     threads (default: 2)
//!   --ref-rows M    random rows compared against the reference preset (default: 0)
//!   --ref-mode MODE the reference rows from this mode instead (see `config_of`)
//!   --ref-partial P up to P more reference rows among the partly hidden ones: rows of
//!                   the first mode (every row computed once) whose total (stored +
//!                   dropped) is neither within 1e-4 of 0 nor of 1 (in a closed scene,
//!                   patches partly under a box: where row totals are hardest)
//!   --occluders F   coarse OBJ for the `occluders` mode
//! ```
//!
//! Output: the set-up time (load, subdivide, Bvh, engine: what `ffstream compute` reports
//! as set-up), the number of timed rows, then one line per mode: wall and CPU seconds
//! extrapolated to all rows (measured × n / timed rows), rays for
//! all rows, % of evaluated pairs on the far-field path and needing no rays, top-k
//! tail pairs whose rays the bound skipped (timed rows), and the errors against the
//! reference rows (largest entry, largest row sum, mean per entry).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use ffstream::formfactor::sampling::SplitMix64;
use ffstream::formfactor::{
    Counters, Preset, RowEngine, Scratch, TopKSearch, TopKTail, Visibility,
};
use ffstream::geometry::occluders::Occluders;
use ffstream::job::{
    build_job, EngineParams, FormSettings, HalfRows, JobSettings, PatchBudget, RowMode,
};
use ffstream::patch::PatchSet;
use ffstream::rows::Row;
use ffstream::scene::SceneSpec;
use ffstream::service::{ComputeJob, Role};

struct Args {
    scene: String,
    patches: usize,
    modes: Vec<String>,
    rows: Option<usize>,
    threads: usize,
    ref_rows: usize,
    ref_mode: Option<String>,
    ref_partial: usize,
    occluders: Option<String>,
}

fn parse_args() -> Args {
    let mut a = Args {
        scene: "builtin:room".into(),
        patches: 2000,
        modes: vec!["default".into()],
        rows: None,
        threads: 2,
        ref_rows: 0,
        ref_mode: None,
        ref_partial: 0,
        occluders: None,
    };
    let mut pos = 0;
    let mut it = std::env::args().skip(1);
    while let Some(s) = it.next() {
        let mut val = || it.next().unwrap_or_default();
        match s.as_str() {
            "--bench" => {}
            "--modes" => a.modes = val().split(',').map(str::to_string).collect(),
            "--rows" => a.rows = val().parse().ok(),
            "--threads" => a.threads = val().parse().unwrap_or(2),
            "--ref-rows" => a.ref_rows = val().parse().unwrap_or(0),
            "--ref-mode" => a.ref_mode = Some(val()),
            "--ref-partial" => a.ref_partial = val().parse().unwrap_or(0),
            "--occluders" => a.occluders = Some(val()),
            _ => {
                match pos {
                    0 => a.scene = s,
                    1 => a.patches = s.parse().unwrap_or(2000),
                    _ => {}
                }
                pos += 1;
            }
        }
    }
    a
}

/// CPU seconds (user + system) of this process so far, from /proc/self/stat (Linux;
/// 0 elsewhere). Under a loaded machine this is steadier than wall time.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesized command name; utime and stime are the 14th and
    // 15th fields of the line, in clock ticks (100 per second on Linux).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    if f.len() < 13 {
        return 0.0;
    }
    (f[11] + f[12]) / 100.0
}

/// Rows `which` computed on `threads` threads; returns (rows by position, counters,
/// wall seconds).
fn run_rows(
    engine: &RowEngine,
    which: &[u32],
    threads: usize,
    row_of: RowFn,
) -> (Vec<Row>, Counters, f64) {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<Row>>> = Mutex::new(vec![None; which.len()]);
    let total = Mutex::new(Counters::default());
    let t0 = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                let mut scratch = Scratch::new();
                let mut local = Vec::new();
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    if k >= which.len() {
                        break;
                    }
                    local.push((k, row_of(engine, which[k], &mut scratch)));
                }
                let mut o = out.lock().unwrap();
                for (k, r) in local {
                    o[k] = Some(r);
                }
                total.lock().unwrap().add(&scratch.take_counters());
            });
        }
    });
    let wall = t0.elapsed().as_secs_f64();
    let rows = out.into_inner().unwrap().into_iter().flatten().collect();
    (rows, total.into_inner().unwrap(), wall)
}

/// How a mode computes the row it is timed (or checked) on.
type RowFn = fn(&RowEngine, u32, &mut Scratch) -> Row;

fn full_row(e: &RowEngine, i: u32, s: &mut Scratch) -> Row {
    e.compute_row(i, s)
}

/// `--symmetric`, timed: the half row of row i in a run of all rows (the pairs j > i:
/// what a worker computes for row i). Its entries are returned as a sparse row (only
/// the counters and the time matter).
fn half_row_all(e: &RowEngine, i: u32, s: &mut Scratch) -> Row {
    let in_run = vec![true; e.n()];
    let (mut own, mut mirrored) = (Vec::new(), Vec::new());
    e.half_row(i, &in_run, s, &mut own, &mut mirrored);
    sparse(i, &own)
}

/// `--symmetric`, checked: row i exactly as a half-row run stores it. With row i alone
/// in the run, `half_row` owns every pair of row i and evaluates each as a half-row run
/// does (pair {a < b} from a's side, mirrored by reciprocity), so its own entries are
/// the stored row.
fn half_row_as_stored(e: &RowEngine, i: u32, s: &mut Scratch) -> Row {
    let mut in_run = vec![false; e.n()];
    in_run[i as usize] = true;
    let (mut own, mut mirrored) = (Vec::new(), Vec::new());
    e.half_row(i, &in_run, s, &mut own, &mut mirrored);
    sparse(i, &own)
}

fn sparse(i: u32, entries: &[(u32, f64)]) -> Row {
    Row {
        index: i,
        values: ffstream::rows::RowValues::Sparse {
            cols: entries.iter().map(|e| e.0).collect(),
            vals: entries.iter().map(|e| e.1 as f32).collect(),
        },
        dropped: 0.0,
        links: Vec::new(),
        link_error: None,
    }
}

/// Modes: `symmetric` (accurate preset, half rows: `--symmetric on`), `default` (accurate
/// preset, full rows), `topkK` (accurate + top-k K: what `--top-k K` does, the tree
/// search with the preset's sampled tail and its links), `topkKp` (the same with
/// `--links off`: the pool), `topkKe` (exhaustive search, exact tail:
/// every pair evaluated), `topkKs` (exhaustive search with the tail sampled from 32
/// pairs), `fast`, `fasttopkK` (exactly `--preset fast --top-k K`, as bench/run.py's
/// top-k scaling series runs it), `fasttopkKx` (the same with `--top-k-search
/// exhaustive`), `occluders` (the scene's faces, or `--occluders F`, as foreign
/// occluders, as given), `fineocc` (occluders = the patches' own triangles, as if the
/// OBJ were tessellated as finely as the patches), `qtolTOL` (the accurate preset with
/// `--quad-tol TOL`), `minffEPS` (`--min-ff EPS`), `symmetricMODE` (MODE in half rows),
/// `exact`, `exactTOL` or `exactTOLrN` (the accurate preset with `--visibility exact`,
/// `--shadow-tol TOL`, `--samples N` for the pairs left to rays), `raysN` (the accurate
/// preset with `--samples N`). Each is the library's settings of those options, so that
/// a mode computes what the command line computes.
fn form_of(mode: &str) -> FormSettings {
    let base = FormSettings::default();
    let after = |prefix: &str| mode[prefix.len()..].to_string();
    match mode {
        m if m.starts_with("fasttopk") => FormSettings {
            preset: Preset::Fast,
            rows: RowMode::TopK(
                after("fasttopk")
                    .trim_end_matches('x')
                    .parse()
                    .unwrap_or(64),
            ),
            top_k_search: m.ends_with('x').then_some(TopKSearch::Exhaustive),
            ..base
        },
        m if m.starts_with("topk") && m.ends_with('p') => FormSettings {
            links: Some(None),
            ..form_of(&m[..m.len() - 1])
        },
        m if m.starts_with("topk") => {
            let exhaustive = m.ends_with('s') || m.ends_with('e');
            FormSettings {
                rows: RowMode::TopK(
                    after("topk")
                        .trim_end_matches(['s', 'e'])
                        .parse()
                        .unwrap_or(256),
                ),
                top_k_search: exhaustive.then_some(TopKSearch::Exhaustive),
                top_k_tail: match (exhaustive, m.ends_with('s')) {
                    (false, _) => None,
                    (true, true) => Some(TopKTail::Sampled(32)),
                    (true, false) => Some(TopKTail::Exact),
                },
                ..base
            }
        }
        "fast" => FormSettings {
            preset: Preset::Fast,
            ..base
        },
        m if m.starts_with("symmetric") && m.len() > "symmetric".len() => {
            form_of(&after("symmetric"))
        }
        m if m.starts_with("minff") => FormSettings {
            rows: RowMode::of(None, after("minff").parse().ok()),
            ..base
        },
        m if m.starts_with("qtol") => FormSettings {
            quad_tol: after("qtol").parse().ok(),
            ..base
        },
        m if m.starts_with("exact") => {
            // `exact`, `exactTOL` or `exactTOLrN`.
            let rest = after("exact");
            let (tol, rays) = rest
                .split_once('r')
                .map_or((rest.as_str(), None), |(t, r)| (t, Some(r)));
            FormSettings {
                visibility: Some(Visibility::Exact),
                shadow_tol: tol.parse().ok(),
                samples: rays.and_then(|r| r.parse().ok()),
                ..base
            }
        }
        m if m.starts_with("rays") => FormSettings {
            samples: Some(after("rays").parse().unwrap_or(16)),
            ..base
        },
        _ => base,
    }
}

/// The job of `mode` as `ffstream compute` builds it (output nowhere, full rows: the
/// half rows of the `symmetric` modes are the benchmark's own, `half_row_all`).
fn job_of(a: &Args, form: FormSettings) -> ComputeJob {
    let scene = SceneSpec::parse(&a.scene).expect("a scene name");
    let mut s = JobSettings::new(scene, "/dev/null");
    s.budget = PatchBudget::Target(a.patches);
    s.form = form;
    s.half_rows = HalfRows::Off;
    s.threads = Some(a.threads);
    s.progress = false;
    build_job(&s, Role::Alone, &|_| {}).expect("the job of a mode")
}

/// The engine of `mode` and the run parameters a file header would carry for it.
fn engine_of(a: &Args, mode: &str, patches: &PatchSet) -> (Arc<RowEngine>, String) {
    let foreign = |occ: Occluders| {
        let e = RowEngine::new(
            patches,
            Arc::new(occ),
            form_of("default").config(HalfRows::Off).unwrap(),
        );
        let params = EngineParams::of_engine(&e).to_string();
        (Arc::new(e), params)
    };
    match mode {
        "occluders" => {
            let coarse = ffstream::scene::open_scene(a.occluders.as_deref().unwrap_or(&a.scene))
                .expect("coarse scene");
            foreign(Occluders::new_foreign(coarse.triangles().collect()))
        }
        "fineocc" => foreign(Occluders::new(
            patches
                .patches
                .iter()
                .flat_map(|p| {
                    let c = p.corners();
                    (1..c.len() - 1).map(move |k| (p.face, [c[0], c[k], c[k + 1]]))
                })
                .collect(),
        )),
        _ => {
            let job = job_of(a, form_of(mode));
            (
                Arc::clone(job.engine.as_ref().expect("an engine")),
                job.meta.params,
            )
        }
    }
}

/// The rows the modes are checked against: `--ref-rows` random ones and up to
/// `--ref-partial` partly hidden ones, computed with `--ref-mode` (default: the
/// reference preset); their indices and dense values.
fn reference_rows(a: &Args, first: &RowEngine, n: usize) -> (Vec<u32>, Vec<Vec<f32>>) {
    let mut rng = SplitMix64::new(12345);
    let mut ref_idx: Vec<u32> = (0..a.ref_rows)
        .map(|_| (rng.next_f64() * n as f64) as u32)
        .collect();
    if a.ref_partial > 0 {
        let all: Vec<u32> = (0..n as u32).collect();
        let (rows, _, wall) = run_rows(first, &all, a.threads, full_row);
        let partial: Vec<u32> = rows
            .iter()
            .filter(|r| (1e-4..=1.0 - 1e-4).contains(&r.true_sum()))
            .map(|r| r.index)
            .collect();
        let take = a.ref_partial.min(partial.len());
        println!(
            "partly hidden rows ({}, all {n} rows in {wall:.1} s): {} (total in [1e-4, 1 - 1e-4]); {take} of them, evenly spread, join the reference rows",
            a.modes.first().map_or("default", String::as_str),
            partial.len()
        );
        ref_idx.extend((0..take).map(|k| partial[k * partial.len() / take]));
    }
    ref_idx.sort_unstable();
    ref_idx.dedup();
    if ref_idx.is_empty() {
        return (ref_idx, Vec::new());
    }
    let form = match a.ref_mode.as_deref() {
        Some(m) => form_of(m),
        None => FormSettings {
            preset: Preset::Reference,
            ..FormSettings::default()
        },
    };
    let job = job_of(a, form);
    let (rows, _, wall) = run_rows(job.engine.as_ref().unwrap(), &ref_idx, a.threads, full_row);
    println!("reference: {} rows in {wall:.1} s", rows.len());
    let dense = rows.iter().map(|r| r.to_dense(n)).collect();
    (ref_idx, dense)
}

/// The errors of `rows` against the reference rows `reference`, printed as they go.
#[derive(Default)]
struct Errors {
    max_abs: f64,
    sum_err: f64,
    mean_abs: f64,
    sum_err_mean: f64,
    sum_err_signed: f64,
    worst: Vec<(f64, String)>,
}

impl Errors {
    fn of(rows: &[Row], reference: &[Vec<f32>], n: usize) -> Self {
        let mut e = Errors::default();
        for (r, want) in rows.iter().zip(reference) {
            let ws: f64 = want.iter().map(|&x| x as f64).sum();
            let d = r.true_sum() - ws;
            e.worst.push((
                d.abs(),
                format!(
                    "row {} total {:.6} reference {ws:.6} (stored {:.6}, dropped {:.6}): {d:+.2e}",
                    r.index,
                    r.true_sum(),
                    r.true_sum() - r.dropped as f64,
                    r.dropped
                ),
            ));
            let got = r.to_dense(n);
            let mut s = 0.0;
            for (g, w) in got.iter().zip(want) {
                let d = (*g as f64 - *w as f64).abs();
                e.max_abs = e.max_abs.max(d);
                s += d;
            }
            e.mean_abs += s / n as f64;
            e.sum_err = e.sum_err.max(d.abs());
            e.sum_err_mean += d.abs();
            e.sum_err_signed += d;
        }
        let m = reference.len().max(1) as f64;
        e.mean_abs /= m;
        e.sum_err_mean /= m;
        e.sum_err_signed /= m;
        e.worst.sort_by(|a, b| b.0.total_cmp(&a.0));
        e
    }
}

fn main() {
    let a = parse_args();
    // The first mode's job, built as `ffstream compute` builds it, so that the set-up
    // time covers the same steps as its "set-up (load, subdivide, Bvh, engine)" line.
    let setup_start = Instant::now();
    let first = job_of(
        &a,
        form_of(a.modes.first().map_or("default", String::as_str)),
    );
    let setup = setup_start.elapsed().as_secs_f64();
    let patches = Arc::clone(&first.patches);
    let n = patches.len();
    let first_engine = Arc::clone(first.engine.as_ref().expect("an engine"));
    println!(
        "scene {} patches {n} occluder triangles {} threads {}",
        a.scene,
        EngineParams::of_engine(&first_engine).occluder_triangles,
        a.threads
    );
    let timed: Vec<u32> = match a.rows {
        Some(r) if r < n => (0..r).map(|k| (k * n / r) as u32).collect(),
        _ => (0..n as u32).collect(),
    };
    println!(
        "set-up (load, subdivide, Bvh, engine) {setup:.3} s; timed rows {} of {n} (evenly spread)",
        timed.len()
    );
    let (ref_idx, reference) = reference_rows(&a, &first_engine, n);
    drop((first, first_engine));
    println!(
        "{:<10} {:>9} {:>9} {:>12} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "mode",
        "wall_s",
        "cpu_s",
        "rays",
        "far%",
        "unoccl%",
        "tailskip",
        "max_abs",
        "rowsum_err",
        "mean_abs"
    );
    for mode in &a.modes {
        let (wall0, cpu0) = (Instant::now(), cpu_seconds());
        let (e, params) = engine_of(&a, mode, &patches);
        let engine_setup = (wall0.elapsed().as_secs_f64(), cpu_seconds() - cpu0);
        let cpu0 = cpu_seconds();
        let (timed_fn, checked_fn): (RowFn, RowFn) = if mode.starts_with("symmetric") {
            (half_row_all, half_row_as_stored)
        } else {
            (full_row, full_row)
        };
        let (timed_rows, c, wall) = run_rows(&e, &timed, a.threads, timed_fn);
        let cpu = cpu_seconds() - cpu0;
        let mut stored = 0usize;
        for r in &timed_rows {
            r.for_each_nonzero(|_, _| stored += 1);
        }
        let scale = n as f64 / timed.len() as f64;
        let err = match reference.is_empty() {
            true => Errors::default(),
            false => Errors::of(
                &run_rows(&e, &ref_idx, a.threads, checked_fn).0,
                &reference,
                n,
            ),
        };
        let evaluated = c.pairs_evaluated.max(1) as f64;
        println!(
            "{:<10} {:>9.2} {:>9.2} {:>12.3e} {:>9.1}% {:>9.1}% {:>10} {:>10.2e} {:>10.2e} {:>10.2e}",
            mode,
            wall * scale,
            cpu * scale,
            c.rays_cast as f64 * scale,
            100.0 * c.pairs_far_field as f64 / evaluated,
            100.0 * c.pairs_unoccludable as f64 / evaluated,
            c.pairs_topk_tail_skipped,
            err.max_abs,
            err.sum_err,
            err.mean_abs
        );
        if !reference.is_empty() {
            println!(
                "  row sums (stored + dropped) against the reference rows: mean |error| {:.2e}, mean error {:.2e}, max |error| {:.2e} over {} rows",
                err.sum_err_mean, err.sum_err_signed, err.sum_err,
                reference.len()
            );
            for (_, line) in err.worst.iter().take(5) {
                println!("    {line}");
            }
        }
        println!(
            "  set-up (load, subdivide, Bvh, engine; with links the first-bounce pass) \
             {:.2} s wall, {:.2} CPU-s; with it, all rows {:.1} CPU-s",
            engine_setup.0,
            engine_setup.1,
            engine_setup.1 + cpu * scale
        );
        println!(
            "  nonzero entries per timed row: {:.1} (all rows: {:.3e})",
            stored as f64 / timed.len() as f64,
            stored as f64 * scale
        );
        println!(
            "  occluder triangles {}; rays skipped by the top-k bound: {} of {} pairs needing rays; counters (timed rows): {c:?}",
            EngineParams::of_engine(&e).occluder_triangles,
            c.pairs_topk_tail_skipped,
            c.pairs_evaluated - c.pairs_unoccludable
        );
        // The run parameters as `ffstream compute` writes them into the file header
        // (built by the same library code, so they cannot drift from it).
        println!("  params: {params}");
    }
}
