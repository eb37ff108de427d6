//! Shadow-ray throughput of [`Occluders::occluded`] against Embree, on the same rays.
//!
//! Scenes: the built-in cluttered room with enough boxes for about 10k and 100k
//! triangles. Rays: incoherent shadow segments from a random point of a random
//! triangle to a random point of another random triangle (SplitMix64, fixed seed),
//! both ends offset by [`RAY_EPSILON`] along the segment, no face ignored — the same
//! query for both tracers. ffstream's rays run on one thread through the public API
//! (world coordinates in, normalization inside); the same segments, normalized as
//! the `Occluders` do it, go to `target/embree-shadow` (bench/embree/shadow.c,
//! `rtcOccluded1`, one thread), which is run from here when it exists.
//!
//! Run: `bench/embree/build.sh && cargo bench --no-default-features --bench perf_rays
//! [-- BOXES...] [--rays N]`. Prints one line per scene and tracer and the ratio.

use std::io::Write;
use std::process::Command;
use std::time::Instant;

use ffstream::formfactor::sampling::SplitMix64;
use ffstream::geometry::bvh::{Occluders, RAY_EPSILON};
use glam::DVec3;

fn point_on(t: &[DVec3; 3], rng: &mut SplitMix64) -> DVec3 {
    let (u, v) = (rng.next_f64(), rng.next_f64());
    let s = u.sqrt();
    t[0] * (1.0 - s) + t[1] * (s * (1.0 - v)) + t[2] * (s * v)
}

fn main() {
    let mut boxes: Vec<usize> = Vec::new();
    let mut rays = 1_000_000usize;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--bench" => {}
            "--rays" => rays = it.next().and_then(|v| v.parse().ok()).unwrap_or(rays),
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
    let embree = std::path::Path::new("target/embree-shadow");
    for b in boxes {
        let scene = ffstream::scene::open_scene(&format!("builtin:room:{b}")).expect("scene");
        let tris: Vec<(u32, [DVec3; 3])> = scene.triangles().collect();
        let t0 = Instant::now();
        let occ = Occluders::new(tris.clone());
        let build = t0.elapsed().as_secs_f64();
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
        let mut best = f64::INFINITY;
        let mut blocked = 0usize;
        for _ in 0..3 {
            let t0 = Instant::now();
            blocked = segs
                .iter()
                .filter(|(a, b)| occ.occluded(*a, *b, (u32::MAX, u32::MAX)))
                .count();
            best = best.min(t0.elapsed().as_secs_f64());
        }
        let ours = rays as f64 / best;
        println!(
            "room:{b} triangles {} build {build:.3} s | ffstream rays {rays} occluded {blocked} seconds {best:.4} rays_per_s {ours:.4e}",
            occ.len()
        );
        if !embree.exists() {
            println!("  (target/embree-shadow missing: run bench/embree/build.sh)");
            continue;
        }
        // The normalized frame of the Occluders: centre of the box, unit diagonal.
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for (_, t) in &tris {
            for p in t {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        let c = 0.5 * (lo + hi);
        let inv = 1.0 / (hi - lo).length();
        let path = std::env::temp_dir().join(format!("ffstream-rays-{b}.bin"));
        let mut buf: Vec<u8> = Vec::new();
        buf.extend((tris.len() as u64).to_le_bytes());
        for (_, t) in &tris {
            for p in t {
                for x in ((*p - c) * inv).to_array() {
                    buf.extend((x as f32).to_le_bytes());
                }
            }
        }
        buf.extend((segs.len() as u64).to_le_bytes());
        for (a, b2) in &segs {
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
        let out = Command::new(embree)
            .arg(&path)
            .arg("3")
            .output()
            .expect("embree-shadow");
        let text = String::from_utf8_lossy(&out.stdout);
        let theirs: f64 = text
            .split_whitespace()
            .skip_while(|w| *w != "rays_per_s")
            .nth(1)
            .and_then(|v| v.parse().ok())
            .unwrap_or(f64::NAN);
        println!(
            "room:{b} | {} | ratio ffstream/embree {:.3}",
            text.trim(),
            ours / theirs
        );
        let _ = std::fs::remove_file(&path);
    }
}
