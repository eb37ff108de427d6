//! `.ffz` write benchmark: write throughput of the writer against `dd` to the same
//! disk, the I/O-master path (workers encode, the master only appends), peak memory,
//! and the byte-shuffle / zstd-level study quoted in `formats/ffz-v1.md` §5.5.
//!
//!     cargo bench --no-default-features --bench ffz_write            # ~64 MB raw, quick
//!     cargo bench --no-default-features --bench ffz_write -- --full  # ~2.1 GB raw dense
//!     options: --dir DIR (default: the system temp dir), --keep (keep the files)
//!
//! The matrix is synthetic but shaped like a real one: the point-to-point form-factor
//! kernel cosθ_i cosθ_j A_j / (π r²) between patches of a g×g grid on each inner face of
//! a unit cube (n = 6 g²; no occlusion inside a convex room). The perfect grid makes
//! rows exact translations of each other, a best case for LZ matching that real meshes
//! do not offer, so the throughput runs use centroids jittered in their plane (an
//! irregular mesh) with ±10 % multiplicative noise (a Monte Carlo estimator with few
//! samples); the study also shows the smooth and the grid cases.

use ffstream::formfactor::sampling::SplitMix64;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use ffstream::ffz::{
    encode_chunk, encode_chunk_with, ChunkEncoding, FfzWriter, FileMeta, Layout, WriterOptions,
};
use ffstream::patch::{Patch, PatchSet};
use ffstream::rows::{Row, RowValues};
use glam::DVec3;

/// g×g patches on each of the 6 inner faces of the unit cube, normals pointing inward.
fn cube_room(g: u32) -> PatchSet {
    let mut patches = Vec::new();
    let h = 1.0 / g as f64;
    for face in 0..6u32 {
        let axis = (face / 2) as usize;
        let hi = face % 2 == 1;
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut normal = DVec3::ZERO;
        normal[axis] = if hi { -1.0 } else { 1.0 };
        for a in 0..g {
            for b in 0..g {
                let mut c = [DVec3::ZERO; 4];
                for (k, (da, db)) in [(0, 0), (1, 0), (1, 1), (0, 1)].iter().enumerate() {
                    c[k][axis] = if hi { 1.0 } else { 0.0 };
                    c[k][u] = (a + da) as f64 * h;
                    c[k][v] = (b + db) as f64 * h;
                }
                patches.push(Patch {
                    corners: c,
                    n_corners: 4,
                    normal,
                    area: h * h,
                    group: face,
                    face,
                    rho: [0.5; 3],
                    emission: [0.0; 3],
                });
            }
        }
    }
    PatchSet {
        patches,
        groups: (0..6).map(|f| format!("wall{f}")).collect(),
    }
}

/// Row i of the point kernel (optionally with multiplicative noise).
fn kernel_row(ps: &PatchSet, cent: &[DVec3], i: usize, noise: bool) -> Vec<f32> {
    let pi = &ps.patches[i];
    let mut rng = SplitMix64::new(i as u64 + 1);
    (0..cent.len())
        .map(|j| {
            let pj = &ps.patches[j];
            if pj.face == pi.face {
                return 0.0;
            }
            let d = cent[j] - cent[i];
            let r2 = d.length_squared();
            let ci = pi.normal.dot(d) / r2.sqrt();
            let cj = -pj.normal.dot(d) / r2.sqrt();
            if ci <= 0.0 || cj <= 0.0 {
                return 0.0;
            }
            let mut f = ci * cj * pj.area / (std::f64::consts::PI * r2);
            if noise {
                f *= 0.9 + 0.2 * rng.next_f64();
            }
            f as f32
        })
        .collect()
}

/// Top-k of a dense row: the k largest, columns ascending, dropped mass recorded.
fn top_k(i: u32, v: &[f32], k: usize) -> Row {
    let mut idx: Vec<u32> = (0..v.len() as u32)
        .filter(|&j| v[j as usize] > 0.0)
        .collect();
    idx.sort_unstable_by(|&a, &b| v[b as usize].total_cmp(&v[a as usize]));
    let dropped: f64 = idx.iter().skip(k).map(|&j| v[j as usize] as f64).sum();
    idx.truncate(k);
    idx.sort_unstable();
    Row {
        index: i,
        values: RowValues::Sparse {
            vals: idx.iter().map(|&j| v[j as usize]).collect(),
            cols: idx,
        },
        dropped: dropped as f32,
        links: Vec::new(),
        link_error: None,
    }
}

fn vm_hwm_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|x| x.parse().ok()))
        })
        .unwrap_or(0)
}

fn mb(bytes: u64, t: Duration) -> f64 {
    bytes as f64 / 1e6 / t.as_secs_f64()
}

/// `dd` of `mbytes` MB of zeros with fdatasync: the disk's sequential write rate.
fn dd_rate(dir: &Path, mbytes: u64) -> Option<f64> {
    let target = dir.join("ffz_bench_dd.tmp");
    let t = Instant::now();
    let st = std::process::Command::new("dd")
        .arg("if=/dev/zero")
        .arg(format!("of={}", target.display()))
        .args([
            "bs=1M",
            &format!("count={mbytes}"),
            "conv=fdatasync",
            "status=none",
        ])
        .status()
        .ok()?;
    let el = t.elapsed();
    let _ = std::fs::remove_file(&target);
    st.success().then(|| mb(mbytes << 20, el))
}

/// Centroids moved in their plane by up to ±h/4 (deterministic): an irregular mesh, so
/// rows are not exact translations of each other as on a perfect grid.
fn jittered(ps: &PatchSet, g: u32) -> Vec<DVec3> {
    let h = 1.0 / g as f64;
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    ps.patches
        .iter()
        .map(|p| {
            let mut d = DVec3::new(next(), next(), next()) * (h / 2.0);
            d -= p.normal * p.normal.dot(d);
            p.centroid() + d
        })
        .collect()
}

fn study(ps: &PatchSet, grid: &[DVec3], jit: &[DVec3]) {
    let n = ps.len() as u32;
    let rows_per = ((4 << 20) / (4 * n as usize)).max(1).min(n as usize);
    println!(
        "\n## Shuffle / level study: one chunk of {rows_per} rows of n = {n} (~4 MiB raw dense)\n"
    );
    println!(
        "| data | layout | zstd level | shuffle | raw bytes | compressed | ratio | encode MB/s |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (data, cent, noise) in [
        ("grid, smooth", grid, false),
        ("jittered, smooth", jit, false),
        ("jittered, noisy ±10 %", jit, true),
    ] {
        let dense: Vec<Row> = (0..rows_per as u32)
            .map(|i| Row::dense(i * 7 % n, kernel_row(ps, cent, (i * 7 % n) as usize, noise)))
            .collect();
        let k = (n / 10).max(1);
        let sparse: Vec<Row> = dense
            .iter()
            .map(|r| match &r.values {
                RowValues::Dense(v) => top_k(r.index, v, k as usize),
                _ => unreachable!(),
            })
            .collect();
        for (name, rows, layout) in [
            ("dense", &dense, Layout::Dense),
            ("top-k n/10", &sparse, Layout::TopK { k }),
        ] {
            for level in [1, 3] {
                for shuffle in [false, true] {
                    let t = Instant::now();
                    let c = encode_chunk_with(
                        rows,
                        layout,
                        n,
                        ChunkEncoding {
                            zstd_level: level,
                            shuffle,
                        },
                    )
                    .unwrap();
                    let el = t.elapsed();
                    println!(
                        "| {data} | {name} | {level} | {} | {} | {} | {:.3} | {:.0} |",
                        if shuffle { "on" } else { "off" },
                        c.raw_len,
                        c.bytes.len(),
                        c.raw_len as f64 / c.bytes.len() as f64,
                        mb(c.raw_len, el)
                    );
                }
            }
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let full = args.iter().any(|a| a == "--full");
    let keep = args.iter().any(|a| a == "--keep");
    let dir: PathBuf = args
        .iter()
        .position(|a| a == "--dir")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir);
    let g = if full { 62 } else { 26 };
    let ps = cube_room(g);
    let n = ps.len() as u32;
    let grid: Vec<DVec3> = ps.patches.iter().map(|p| p.centroid()).collect();
    let cent = jittered(&ps, g);
    let raw_total = n as u64 * n as u64 * 4;
    println!("# ffz write benchmark");
    println!(
        "command: {}\nn = {n} (cube room, g = {g}), dense raw matrix {:.1} MB, dir {}",
        args.join(" "),
        raw_total as f64 / 1e6,
        dir.display()
    );

    study(&ps, &grid, &cent);

    let meta = FileMeta {
        layout: Layout::Dense,
        method: "point".into(),
        params: "bench".into(),
        scene_hash: ps.content_hash(),
        created: "bench/ffz_write.rs".into(),
        patches: ps.clone(),
        clusters: None,
    };
    let opts = WriterOptions::default();

    // 1. push_row: the writer compresses on the calling thread.
    let path = dir.join("ffz_bench_push.ffz");
    let mut w = FfzWriter::create(&path, &meta, opts).unwrap();
    let mut t_write = Duration::ZERO;
    let t_all = Instant::now();
    for i in 0..n {
        let row = Row::dense(i, kernel_row(&ps, &cent, i as usize, true));
        let t = Instant::now();
        w.push_row(row).unwrap();
        t_write += t.elapsed();
    }
    let t = Instant::now();
    let st = w.finish().unwrap();
    t_write += t.elapsed();
    let wall_push = t_all.elapsed();
    let hwm_push = vm_hwm_kib();

    // 2. The I/O-master path: a worker thread generates and encodes chunks, the main
    //    thread only appends (timed alone), as rank 0 does.
    let path2 = dir.join("ffz_bench_append.ffz");
    let mut w2 = FfzWriter::create(&path2, &meta, opts).unwrap();
    let rows_per_chunk = (opts.chunk_bytes / (4 * n as usize)).max(1) as u32;
    let (tx, rx) = std::sync::mpsc::sync_channel(4);
    let mut t_append = Duration::ZERO;
    let t_all = Instant::now();
    std::thread::scope(|s| {
        s.spawn(|| {
            let mut i = 0;
            while i < n {
                let end = (i + rows_per_chunk).min(n);
                let rows: Vec<Row> = (i..end)
                    .map(|r| Row::dense(r, kernel_row(&ps, &cent, r as usize, true)))
                    .collect();
                tx.send(encode_chunk(&rows, Layout::Dense, n, opts.zstd_level).unwrap())
                    .unwrap();
                i = end;
            }
            drop(tx);
        });
        for c in rx {
            let t = Instant::now();
            w2.append_chunk(c).unwrap();
            t_append += t.elapsed();
        }
    });
    let t = Instant::now();
    let st2 = w2.finish().unwrap();
    t_append += t.elapsed();
    let wall_append = t_all.elapsed();

    let dd_mb = (st.bytes_on_disk >> 20).max(16);
    let dd = dd_rate(&dir, dd_mb);
    println!(
        "\n## Write throughput (zstd level {}, chunk {} KiB, fsync at finish)\n",
        opts.zstd_level,
        opts.chunk_bytes >> 10
    );
    println!(
        "| path | raw MB | on disk MB | ratio | time in writer s | raw MB/s | disk MB/s | wall s |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (name, s, t, wall) in [
        (
            "push_row (compress + append on one thread)",
            st,
            t_write,
            wall_push,
        ),
        (
            "append_chunk only (I/O master; 1 worker encodes)",
            st2,
            t_append,
            wall_append,
        ),
    ] {
        println!(
            "| {name} | {:.1} | {:.1} | {:.3} | {:.2} | {:.0} | {:.0} | {:.2} |",
            s.raw_bytes as f64 / 1e6,
            s.bytes_on_disk as f64 / 1e6,
            s.raw_bytes as f64 / s.bytes_on_disk as f64,
            t.as_secs_f64(),
            mb(s.raw_bytes, t),
            mb(s.bytes_on_disk, t),
            wall.as_secs_f64()
        );
    }
    match dd {
        Some(r) => println!(
            "| dd if=/dev/zero bs=1M count={dd_mb} conv=fdatasync | | {dd_mb} | | | | {r:.0} | |"
        ),
        None => println!("(dd not available)"),
    }
    println!(
        "\npeak RSS (VmHWM) after the push_row run: {:.1} MB; at the end: {:.1} MB (dense matrix would be {:.1} MB)",
        hwm_push as f64 / 1024.0,
        vm_hwm_kib() as f64 / 1024.0,
        raw_total as f64 / 1e6
    );
    let _ = std::io::stdout().flush();
    if !keep {
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_file(&path2);
    }
}
