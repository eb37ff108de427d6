//! Row-engine benchmark on a real scene: wall time, rays and pair counters of a
//! sample of rows (extrapolated to the whole matrix), and the form-factor error of
//! each mode against the `reference` preset on a few random rows.
//!
//! Run (release build of the library, no MPI needed):
//!
//! ```text
//! cargo bench --no-default-features --bench perf_rows -- SCENE PATCHES [options]
//!   --modes symmetric,default,topk256,occluders   modes to time (default: default)
//!                   (modes: see `config_of`; `fasttopk64` is `--preset fast --top-k 64`)
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
use ffstream::formfactor::{Counters, FormFactorConfig, RowEngine, Scratch, TopKSearch, TopKTail};
use ffstream::geometry::merge::OccluderMesh;
use ffstream::geometry::occluders::Occluders;
use ffstream::geometry::subdivide::{default_max_edge, subdivide};
use ffstream::patch::PatchSet;
use ffstream::rows::Row;

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
/// search with the preset's sampled tail), `topkKe` (exhaustive search, exact tail:
/// every pair evaluated), `topkKs` (exhaustive search with the tail sampled from 32
/// pairs), `fast`, `fasttopkK` (exactly `--preset fast --top-k K`, as bench/run.py's
/// top-k scaling series runs it), `fasttopkKx` (the same with `--top-k-search
/// exhaustive`), `occluders` (the scene's faces as foreign occluders,
/// i.e. `--occluders` with the scene's own OBJ), `fineocc` (occluders = the patches'
/// own triangles, as if the OBJ were tessellated as finely as the patches), `qtolTOL`
/// (the accurate preset with `--quad-tol TOL`), `minffEPS` (`--min-ff EPS`),
/// `symmetricMODE` (MODE in half rows),
/// `exact`,
/// `exactTOL` or `exactTOLrN` (the accurate preset with `--visibility exact`,
/// `--shadow-tol TOL`, `--samples N` for the pairs left to rays), `raysN` (the accurate
/// preset with `--samples N`).
fn config_of(mode: &str) -> FormFactorConfig {
    let base = FormFactorConfig::accurate();
    match mode {
        m if m.starts_with("fasttopk") => {
            // The CLI applies --top-k on top of the preset and keeps its tail setting.
            let k = m["fasttopk".len()..]
                .trim_end_matches('x')
                .parse()
                .unwrap_or(64);
            let mut c = FormFactorConfig::fast().with_top_k(Some(k));
            if m.ends_with('x') {
                c.top_k_search = TopKSearch::Exhaustive;
            }
            c
        }
        m if m.starts_with("topk") => {
            let k = m[4..].trim_end_matches(['s', 'e']).parse().unwrap_or(256);
            let mut c = base.with_top_k(Some(k));
            if m.ends_with('s') || m.ends_with('e') {
                c.top_k_search = TopKSearch::Exhaustive;
                c.top_k_tail = match m.ends_with('s') {
                    true => TopKTail::Sampled(32),
                    false => TopKTail::Exact,
                };
            }
            c
        }
        "fast" => FormFactorConfig::fast(),
        m if m.starts_with("symmetric") && m.len() > "symmetric".len() => {
            config_of(&m["symmetric".len()..])
        }
        m if m.starts_with("minff") => {
            // `minffEPS`: the accurate preset with `--min-ff EPS` (tree search).
            base.with_min_ff(m["minff".len()..].parse().ok())
        }
        m if m.starts_with("qtol") => {
            // `qtolTOL`: the accurate preset with `--quad-tol TOL`.
            let mut c = base;
            c.quad_tol = m["qtol".len()..].parse().unwrap_or(c.quad_tol);
            c
        }
        m if m.starts_with("exact") => {
            // `exact`, `exactTOL` or `exactTOLrN`: the accurate preset with
            // --visibility exact (--shadow-tol TOL), N rays for the pairs left to rays.
            let (tol, rays) = m["exact".len()..]
                .split_once('r')
                .map_or((&m["exact".len()..], None), |(t, r)| (t, Some(r)));
            let mut c = match rays.and_then(|r| r.parse().ok()) {
                Some(n) => base.with_samples(n),
                None => base,
            };
            c.visibility = ffstream::formfactor::Visibility::Exact;
            if let Ok(t) = tol.parse() {
                c.shadow_tol = t;
            }
            c
        }
        m if m.starts_with("rays") => {
            // `raysN`: the accurate preset with N rays per pair (all cast).
            base.with_samples(m["rays".len()..].parse().unwrap_or(16))
        }
        _ => base,
    }
}

fn main() {
    let a = parse_args();
    let setup_start = Instant::now();
    let scene = ffstream::scene::open_scene(&a.scene).expect("scene");
    let max_edge = default_max_edge(&scene, a.patches);
    let patches: Arc<PatchSet> = Arc::new(subdivide(&scene, max_edge));
    let n = patches.len();
    // The scene's triangles as `ffstream compute` uses them by default (coplanar ones
    // merged: --no-merge-occluders not given).
    let mesh = OccluderMesh::prepare(scene.triangles().collect(), false, true);
    let (given, merged_note) = (mesh.given, mesh.header_note());
    let fine = Arc::new(mesh.build());
    // The engine of the first mode, built here so that the set-up time covers the same
    // steps as `ffstream compute`'s "set-up (load, subdivide, Bvh, engine)" line.
    let first_engine = RowEngine::new(
        &patches,
        Arc::clone(&fine),
        config_of(a.modes.first().map_or("default", String::as_str)),
    );
    let setup = setup_start.elapsed().as_secs_f64();
    drop(first_engine);
    println!(
        "scene {} patches {n} occluder triangles {} threads {}",
        a.scene,
        fine.len(),
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
    let mut rng = SplitMix64::new(12345);
    let mut ref_idx: Vec<u32> = (0..a.ref_rows)
        .map(|_| (rng.next_f64() * n as f64) as u32)
        .collect();
    if a.ref_partial > 0 {
        let first = a.modes.first().map_or("default", String::as_str);
        let e = RowEngine::new(&patches, Arc::clone(&fine), config_of(first));
        let all: Vec<u32> = (0..n as u32).collect();
        let (rows, _, wall) = run_rows(&e, &all, a.threads, full_row);
        let partial: Vec<u32> = rows
            .iter()
            .filter(|r| (1e-4..=1.0 - 1e-4).contains(&r.true_sum()))
            .map(|r| r.index)
            .collect();
        let take = a.ref_partial.min(partial.len());
        println!(
            "partly hidden rows ({first}, all {n} rows in {wall:.1} s): {} (total in [1e-4, 1 - 1e-4]); {take} of them, evenly spread, join the reference rows",
            partial.len()
        );
        ref_idx.extend((0..take).map(|k| partial[k * partial.len() / take]));
    }
    ref_idx.sort_unstable();
    ref_idx.dedup();
    let reference = if ref_idx.is_empty() {
        Vec::new()
    } else {
        let cfg = a
            .ref_mode
            .as_deref()
            .map_or_else(FormFactorConfig::reference, config_of);
        let e = RowEngine::new(&patches, Arc::clone(&fine), cfg);
        let (rows, _, wall) = run_rows(&e, &ref_idx, a.threads, full_row);
        println!("reference: {} rows in {wall:.1} s", rows.len());
        rows.iter().map(|r| r.to_dense(n)).collect::<Vec<_>>()
    };
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
        let occ = if mode == "occluders" {
            let coarse = match a.occluders.as_deref() {
                Some(path) => ffstream::scene::open_scene(path).expect("coarse scene"),
                None => scene.clone(),
            };
            Arc::new(Occluders::new_foreign(coarse.triangles().collect()))
        } else if mode == "fineocc" {
            let tris = patches
                .patches
                .iter()
                .flat_map(|p| {
                    let c = p.corners();
                    (1..c.len() - 1).map(move |k| (p.face, [c[0], c[k], c[k + 1]]))
                })
                .collect();
            Arc::new(Occluders::new(tris))
        } else {
            Arc::clone(&fine)
        };
        let occ_tris = occ.len();
        let e = RowEngine::new(&patches, occ, config_of(mode));
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
        let (mut max_abs, mut sum_err, mut mean_abs) = (0.0f64, 0.0f64, 0.0f64);
        let (mut sum_err_mean, mut sum_err_signed) = (0.0f64, 0.0f64);
        let mut worst: Vec<(f64, String)> = Vec::new();
        if !reference.is_empty() {
            let (rows, _, _) = run_rows(&e, &ref_idx, a.threads, checked_fn);
            for (r, want) in rows.iter().zip(&reference) {
                let ws: f64 = want.iter().map(|&x| x as f64).sum();
                let d = r.true_sum() - ws;
                worst.push((
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
                    max_abs = max_abs.max(d);
                    s += d;
                }
                mean_abs += s / n as f64;
                let ws: f64 = want.iter().map(|&x| x as f64).sum();
                sum_err = sum_err.max((r.true_sum() - ws).abs());
                sum_err_mean += (r.true_sum() - ws).abs();
                sum_err_signed += r.true_sum() - ws;
            }
            mean_abs /= reference.len() as f64;
            sum_err_mean /= reference.len() as f64;
            sum_err_signed /= reference.len() as f64;
        }
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
            max_abs,
            sum_err,
            mean_abs
        );
        if !reference.is_empty() {
            println!(
                "  row sums (stored + dropped) against the reference rows: mean |error| {sum_err_mean:.2e}, mean error {sum_err_signed:.2e}, max |error| {sum_err:.2e} over {} rows",
                reference.len()
            );
            worst.sort_by(|a, b| b.0.total_cmp(&a.0));
            for (_, line) in worst.iter().take(5) {
                println!("    {line}");
            }
        }
        println!(
            "  nonzero entries per timed row: {:.1} (all rows: {:.3e})",
            stored as f64 / timed.len() as f64,
            stored as f64 * scale
        );
        println!(
            "  occluder triangles {occ_tris}; rays skipped by the top-k bound: {} of {} pairs needing rays; counters (timed rows): {c:?}",
            c.pairs_topk_tail_skipped,
            c.pairs_evaluated - c.pairs_unoccludable
        );
        // The engine's parameters as `ffstream compute` writes them into the file header
        // (bench/run.py checks that a sampled mode matches the run it stands in for).
        let described = match mode.as_str() {
            "occluders" | "fineocc" => e.describe(),
            _ => RowEngine::description(&config_of(mode), given, false) + &merged_note,
        };
        println!("  engine: {described}");
    }
}
