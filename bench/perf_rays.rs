//! Shadow-ray throughput of [`Occluders`] against Embree, on the same rays.
//!
//! Scenes: the built-in cluttered room with enough boxes for about 10k and 100k
//! triangles. Two workloads, the same segments for both tracers:
//!
//! - incoherent: from a random point of a random triangle to a random point of another
//!   random triangle (SplitMix64, fixed seed), both ends offset by [`RAY_EPSILON`]
//!   along the segment, no face ignored; ffstream one ray at a time
//!   ([`Occluders::occluded`]), Embree `rtcOccluded1`;
//! - pairs: 16 rays between random points of two triangles that face each other, as
//!   the `contour` kernel casts them; ffstream as packets of [`PACKET`]
//!   ([`Occluders::occluded_packet`]), one ray at a time through the hierarchy, and
//!   through the pair's candidate list (`collect_between`, as for scenes of few
//!   occluders, timed with the rays) one ray at a time and as packets
//!   ([`Occluders::occluded_packet_by`]); Embree one ray at a time (`rtcOccluded1`)
//!   and as packets of 16 (`rtcOccluded16`).
//!
//! Each scene's line `tree:` gives the shape of ffstream's hierarchy
//! ([`ffstream::geometry::occluders::TreeStats`]): compare Embree's with
//! `EMBREE_VERBOSE=1 target/embree-shadow RAYFILE 1 1` on a file kept by `--keep-rays`.
//!
//! ffstream's rays run on one thread through the public API (world coordinates in,
//! normalization inside); the same segments, normalized as the `Occluders` do it, go to
//! `target/embree-shadow` (bench/embree/shadow.c, one thread), which is run from here
//! when it exists. Each rate is the best of `--reps` timings.
//!
//! Run: `bench/embree/build.sh && cargo bench --no-default-features --bench perf_rays
//! [-- BOXES...] [--rays N] [--reps R] [--only incoherent|pairs|packets]
//! [--keep-rays]`. Prints one line per scene, workload and tracer, and the ratios;
//! `--keep-rays` keeps the ray files written for Embree and prints their paths.

use std::io::Write;
use std::process::Command;
use std::time::Instant;

use ffstream::formfactor::sampling::SplitMix64;
use ffstream::geometry::occluders::{Between, Occluders, PACKET, RAY_EPSILON};
use glam::DVec3;

fn point_on(t: &[DVec3; 3], rng: &mut SplitMix64) -> DVec3 {
    let (u, v) = (rng.next_f64(), rng.next_f64());
    let s = u.sqrt();
    t[0] * (1.0 - s) + t[1] * (s * (1.0 - v)) + t[2] * (s * v)
}

fn main() {
    let mut boxes: Vec<usize> = Vec::new();
    let mut rays = 1_000_000usize;
    let mut reps = 3usize;
    let mut only: Option<String> = None;
    let mut keep_rays = false;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--bench" => {}
            "--rays" => rays = it.next().and_then(|v| v.parse().ok()).unwrap_or(rays),
            "--reps" => reps = it.next().and_then(|v| v.parse().ok()).unwrap_or(reps),
            "--only" => only = it.next(),
            "--keep-rays" => keep_rays = true,
            _ => {
                if let Ok(b) = a.parse() {
                    boxes.push(b)
                }
            }
        }
    }
    if boxes.is_empty() {
        boxes = vec![900, 9000];
    }
    let embree = &Embree {
        exe: std::path::Path::new("target/embree-shadow"),
        keep_rays,
    };
    for b in boxes {
        let scene = ffstream::scene::open_scene(&format!("builtin:room:{b}")).expect("scene");
        let tris: Vec<(u32, [DVec3; 3])> = scene.triangles().collect();
        let t0 = Instant::now();
        let occ = Occluders::new(tris.clone());
        let build = t0.elapsed().as_secs_f64();
        if let Some(st) = occ.stats() {
            println!(
                "room:{b} tree: depth {} nodes {} leaves {} blocks {} node SAH {:.3} block SAH {:.3}",
                st.depth, st.nodes, st.leaves, st.blocks, st.node_sah, st.block_sah
            );
        }
        let mut rng = SplitMix64::new(7);
        let segs: Vec<(DVec3, DVec3)> = (0..rays)
            .map(|_| {
                let i = (rng.next_f64() * tris.len() as f64) as usize % tris.len();
                let j = (rng.next_f64() * tris.len() as f64) as usize % tris.len();
                (
                    point_on(&tris[i].1, &mut rng),
                    point_on(&tris[j].1, &mut rng),
                )
            })
            .collect();
        let time_it = |f: &dyn Fn() -> usize| {
            let mut best = f64::INFINITY;
            let mut blocked = 0usize;
            for _ in 0..reps {
                let t0 = Instant::now();
                blocked = f();
                best = best.min(t0.elapsed().as_secs_f64());
            }
            (best, blocked)
        };
        let wants = |part: &str| only.as_deref().is_none_or(|o| o == part);
        if wants("incoherent") {
            let (best, blocked) = time_it(&|| {
                segs.iter()
                    .filter(|(a, b)| occ.occluded(*a, *b, (u32::MAX, u32::MAX)))
                    .count()
            });
            let ours = rays as f64 / best;
            println!(
            "room:{b} triangles {} build {build:.3} s | incoherent | ffstream rays {rays} occluded {blocked} seconds {best:.4} rays_per_s {ours:.4e}",
            occ.len()
        );
            report_embree(
                embree,
                &tris,
                &segs,
                b,
                "incoherent",
                &[1],
                &[("through the Bvh", ours)],
            );
        }
        if !(wants("pairs") || wants("packets")) {
            continue;
        }

        // The rays of the form-factor workload: 16 per pair of triangles that face
        // each other, from random points of one to random points of the other. ffstream
        // collects the pair's candidate occluders once (`collect_between`, as the
        // `contour` kernel does) and tests its rays against them; Embree casts the same
        // segments one by one.
        let mut pairs: Vec<(usize, usize, DVec3, DVec3)> = Vec::new();
        while pairs.len() * PAIR_RAYS < rays {
            let i = (rng.next_f64() * tris.len() as f64) as usize % tris.len();
            let j = (rng.next_f64() * tris.len() as f64) as usize % tris.len();
            let (ti, tj) = (&tris[i].1, &tris[j].1);
            let (ci, cj) = ((ti[0] + ti[1] + ti[2]) / 3.0, (tj[0] + tj[1] + tj[2]) / 3.0);
            let normal = |t: &[DVec3; 3], toward: DVec3, c: DVec3| {
                let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                if n.dot(toward - c) >= 0.0 {
                    n
                } else {
                    -n
                }
            };
            let (ni, nj) = (normal(ti, cj, ci), normal(tj, ci, cj));
            let front = |t: &[DVec3; 3], n: DVec3, o: DVec3| t.iter().all(|p| n.dot(*p - o) > 1e-9);
            if i != j && tris[i].0 != tris[j].0 && front(tj, ni, ti[0]) && front(ti, nj, tj[0]) {
                pairs.push((i, j, ni, nj));
            }
        }
        let pair_segs: Vec<(DVec3, DVec3)> = pairs
            .iter()
            .flat_map(|&(i, j, _, _)| {
                (0..PAIR_RAYS)
                    .map(|_| {
                        (
                            point_on(&tris[i].1, &mut rng),
                            point_on(&tris[j].1, &mut rng),
                        )
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let n_pair_rays = pair_segs.len();
        // The pair's rays in packets (`occluded_packet`, as the `contour` kernel casts
        // them when it walks the hierarchy); Embree gets them one by one and in packets
        // of 16 (rtcOccluded16).
        let (best_packets, blocked_packets) = time_it(&|| {
            let mut blocked = 0;
            for (p, &(i, j, _, _)) in pairs.iter().enumerate() {
                let faces = (tris[i].0, tris[j].0);
                for packet in pair_segs[p * PAIR_RAYS..(p + 1) * PAIR_RAYS].chunks(PACKET) {
                    blocked += occ.occluded_packet(packet, faces, None).count_ones() as usize;
                }
            }
            blocked
        });
        let rate_packets = n_pair_rays as f64 / best_packets;
        println!(
            "room:{b} | pairs of {PAIR_RAYS} | ffstream packets of {PACKET}: occluded {blocked_packets} rays_per_s {rate_packets:.4e}"
        );
        let mut ours = vec![("packets", rate_packets)];
        if wants("pairs") {
            let (best_bvh, blocked_bvh) = time_it(&|| {
                pair_segs
                    .iter()
                    .enumerate()
                    .filter(|(k, (a, b))| {
                        let (i, j, _, _) = pairs[k / PAIR_RAYS];
                        occ.occluded(*a, *b, (tris[i].0, tris[j].0))
                    })
                    .count()
            });
            // Through the pair's candidate list (`collect_between`, timed with the
            // rays), one ray at a time or as packets; pairs whose query gives up walk
            // the hierarchy the same way.
            let by_list = |packets: bool| {
                let mut ids = Vec::new();
                let mut blocked = 0;
                for (p, &(i, j, ni, nj)) in pairs.iter().enumerate() {
                    let faces = (tris[i].0, tris[j].0);
                    let listed = occ.collect_between(
                        &Between::new(&tris[i].1, ni, &tris[j].1, nj, faces),
                        &mut ids,
                    );
                    let mut first = 0;
                    let segs = &pair_segs[p * PAIR_RAYS..(p + 1) * PAIR_RAYS];
                    if packets {
                        for packet in segs.chunks(PACKET) {
                            let hits = if listed {
                                occ.occluded_packet_by(packet, &ids, None, &mut first)
                            } else {
                                occ.occluded_packet(packet, faces, None)
                            };
                            blocked += hits.count_ones() as usize;
                        }
                        continue;
                    }
                    for (a, b) in segs {
                        let hit = if listed {
                            occ.occluded_by(*a, *b, &ids, None, &mut first)
                        } else {
                            occ.occluded(*a, *b, faces)
                        };
                        blocked += hit as usize;
                    }
                }
                blocked
            };
            let (best_pairs, blocked_pairs) = time_it(&|| by_list(false));
            let (best_list_packets, blocked_list_packets) = time_it(&|| by_list(true));
            let rate_bvh = n_pair_rays as f64 / best_bvh;
            let rate_pairs = n_pair_rays as f64 / best_pairs;
            let rate_list_packets = n_pair_rays as f64 / best_list_packets;
            println!(
                "room:{b} | pairs of {PAIR_RAYS} | ffstream per ray through the Bvh: occluded {blocked_bvh} rays_per_s {rate_bvh:.4e} | per pair (candidate list): occluded {blocked_pairs} rays_per_s {rate_pairs:.4e} | candidate list, packets: occluded {blocked_list_packets} rays_per_s {rate_list_packets:.4e}"
            );
            ours.push(("one ray at a time", rate_bvh));
            ours.push(("candidate list", rate_pairs));
            ours.push(("candidate list, packets", rate_list_packets));
        }
        report_embree(embree, &tris, &pair_segs, b, "pairs", &[1, 16], &ours);
    }
}

/// Rays per pair in the pair workload (the `accurate` preset's 16).
const PAIR_RAYS: usize = 16;

/// The Embree yardstick (bench/embree/shadow.c) and whether the ray files written for
/// it are kept (`--keep-rays`: their paths are printed, e.g. to run the yardstick under
/// valgrind on the same rays).
struct Embree<'a> {
    exe: &'a std::path::Path,
    keep_rays: bool,
}

/// Run the Embree yardstick on `segs` (if built) and print its rate and the ratio of
/// each of our rates `ours` (label, rays/s) to it.
fn report_embree(
    embree: &Embree<'_>,
    tris: &[(u32, [DVec3; 3])],
    segs: &[(DVec3, DVec3)],
    b: usize,
    what: &str,
    embree_packets: &[usize],
    ours: &[(&str, f64)],
) {
    if !embree.exe.exists() {
        println!("  (target/embree-shadow missing: run bench/embree/build.sh)");
        return;
    }
    // The normalized frame of the Occluders: centre of the box, unit diagonal.
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (_, t) in tris {
        for p in t {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    let c = 0.5 * (lo + hi);
    let inv = 1.0 / (hi - lo).length();
    let path = std::env::temp_dir().join(format!("ffstream-rays-{b}-{what}.bin"));
    let mut buf: Vec<u8> = Vec::new();
    buf.extend((tris.len() as u64).to_le_bytes());
    for (_, t) in tris {
        for p in t {
            for x in ((*p - c) * inv).to_array() {
                buf.extend((x as f32).to_le_bytes());
            }
        }
    }
    buf.extend((segs.len() as u64).to_le_bytes());
    for (a, b2) in segs {
        let (a, b2) = ((*a - c) * inv, (*b2 - c) * inv);
        let d = b2 - a;
        let len = d.length();
        let dir = d / len;
        let rec = [
            a.x,
            a.y,
            a.z,
            dir.x,
            dir.y,
            dir.z,
            RAY_EPSILON,
            (len - RAY_EPSILON).max(0.0),
        ];
        for x in rec {
            buf.extend((x as f32).to_le_bytes());
        }
    }
    std::fs::File::create(&path)
        .and_then(|mut f| f.write_all(&buf))
        .expect("ray file");
    for &packet in embree_packets {
        let out = Command::new(embree.exe)
            .arg(&path)
            .arg("3")
            .arg(packet.to_string())
            .output()
            .expect("embree-shadow");
        let text = String::from_utf8_lossy(&out.stdout);
        let theirs: f64 = text
            .split_whitespace()
            .skip_while(|w| *w != "rays_per_s")
            .nth(1)
            .and_then(|v| v.parse().ok())
            .unwrap_or(f64::NAN);
        let ratios: Vec<String> = ours
            .iter()
            .map(|(label, rate)| format!("ratio ffstream/embree {:.3} ({label})", rate / theirs))
            .collect();
        println!(
            "room:{b} | {what} | {} | {}",
            text.trim(),
            ratios.join(", ")
        );
    }
    if embree.keep_rays {
        println!("room:{b} | {what} | ray file kept: {}", path.display());
    } else {
        let _ = std::fs::remove_file(&path);
    }
}
