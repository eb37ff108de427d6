//! Sparse rows that link to clusters of patches (`--links`, spec §4.3, §5.7): the light
//! they give against dense rows on the same mesh, against the pool they replace, and
//! the file's guarantees (checked by `verify`, bitwise the same for any thread or rank
//! count, refused by shooting).

use std::collections::BTreeMap;
use std::path::Path;

use crate::common::{mpirun, need_mpi, ok, output_of_within, path_str};

/// Per group: area-weighted mean radiosity (R, G, B) from a `solve -o` CSV.
fn group_radiosity(csv: &Path) -> BTreeMap<String, [f64; 3]> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (g, a, r) = (col("group"), col("area"), col("B_r"));
    let mut sums: BTreeMap<String, (f64, [f64; 3])> = BTreeMap::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let area: f64 = f[a].parse().unwrap();
        let s = sums.entry(f[g].to_string()).or_insert((0.0, [0.0; 3]));
        s.0 += area;
        for c in 0..3 {
            s.1[c] += area * f[r + c].parse::<f64>().unwrap();
        }
    }
    sums.into_iter()
        .map(|(k, (area, b))| (k, b.map(|x| x / area)))
        .collect()
}

/// The largest relative difference of any group's radiosity in any channel, and that
/// group.
fn worst(
    reference: &BTreeMap<String, [f64; 3]>,
    other: &BTreeMap<String, [f64; 3]>,
) -> (f64, String) {
    let mut out = (0.0, String::new());
    for (k, want) in reference {
        let got = other[k];
        for c in 0..3 {
            let e = (got[c] / want[c] - 1.0).abs();
            if e > out.0 {
                out = (e, k.clone());
            }
        }
    }
    out
}

/// Every row of `linked` with links carries a link error (spec §5.7), and none is
/// below the true relative error of what its row gathers, measured with the dense rows
/// of `dense` (same mesh) and their solve's radiosity (`tests/python/link_error.py`).
fn link_errors_hold(dense: &Path, linked: &Path) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = std::process::Command::new("python3")
        .arg(root.join("tests/python/link_error.py"))
        .arg(root.join("formats"))
        .args([dense, linked, &dense.with_extension("csv")])
        .output()
        .expect("python3");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    eprintln!("link errors of {}: {text}", linked.display());
    assert!(out.status.success(), "{text}");
}

fn compute(dir: &Path, name: &str, extra: &[&str]) -> std::path::PathBuf {
    compute_scene(dir, "builtin:room", name, extra)
}

fn compute_scene(dir: &Path, scene: &str, name: &str, extra: &[&str]) -> std::path::PathBuf {
    let out = dir.join(format!("{name}.ffz"));
    let mut args = vec!["compute", scene, "--patches", "1500", "-q", "-o"];
    args.push(path_str(&out));
    args.extend_from_slice(extra);
    ok(&args);
    out
}

fn solve(file: &Path) -> BTreeMap<String, [f64; 3]> {
    let csv = file.with_extension("csv");
    ok(&["solve", path_str(file), "-q", "-o", path_str(&csv)]);
    group_radiosity(&csv)
}

/// The pool shares every row's dropped mass out by one global rule, so in the 16-box
/// room the ceiling and walls come out tens of percent too bright (issue: up to +122 %
/// at 10k patches). Links put that mass on the clusters the row sees, and their slopes
/// where in each cluster. Measured at 1,512 patches: pool worst surface 62–84 %; links
/// without slopes 3–6 % (c23c811 + links), 2.1 % (87d3b76), with slopes 0.4 %
/// (6c9adeb), with links sampled by one-ray points 0.5 % (1.0 % when links of up to
/// 4 patches are sampled too, not evaluated in full; 0.5 % with 4t points shared by
/// weight). The bound below, the issue's
/// 1 %, fails without slopes.
#[test]
fn links_put_the_rooms_light_where_dense_rows_put_it_and_the_pool_does_not() {
    let dir = tempfile::tempdir().unwrap();
    let dense_file = compute(dir.path(), "dense", &[]);
    let dense = solve(&dense_file);
    let pool = solve(&compute(
        dir.path(),
        "pool",
        &["--top-k", "64", "--links", "off"],
    ));
    let links_file = compute(dir.path(), "links", &["--top-k", "64", "--links", "256"]);
    let links = solve(&links_file);
    link_errors_hold(&dense_file, &links_file);
    let (e_pool, g_pool) = worst(&dense, &pool);
    let (e_links, g_links) = worst(&dense, &links);
    eprintln!("worst surface: pool {e_pool:.3} ({g_pool}), links {e_links:.3} ({g_links})");
    assert!(
        e_pool > 0.3,
        "the pool was expected to misplace light here: {e_pool} ({g_pool})"
    );
    assert!(
        e_links < 0.01,
        "links: worst surface {e_links} ({g_links}) against dense rows"
    );
    assert!(e_links * 5.0 < e_pool, "links {e_links} vs pool {e_pool}");
}

/// An OBJ of axis-aligned rectangles, each facing one way (normal along +axis or
/// −axis), in groups; materials `grey` (ρ 0.6) and `lit` (emits, ρ 0).
struct Boxes {
    obj: String,
    verts: usize,
}

impl Boxes {
    fn new() -> Self {
        Boxes {
            obj: "mtllib m.mtl\n".into(),
            verts: 0,
        }
    }

    /// The rectangle at coordinate `at` along `axis`, spanning `lo..hi` in the next
    /// two axes (cyclic), facing +axis (`sign` > 0) or −axis.
    fn rect(&mut self, group: &str, axis: usize, at: f64, lo: [f64; 2], hi: [f64; 2], sign: f64) {
        let mtl = if group == "light" { "lit" } else { "grey" };
        self.obj += &format!("g {group}\nusemtl {mtl}\n");
        let mut corners = [
            [lo[0], lo[1]],
            [hi[0], lo[1]],
            [hi[0], hi[1]],
            [lo[0], hi[1]],
        ];
        if sign < 0.0 {
            corners.reverse();
        }
        for [u, v] in corners {
            let mut p = [0.0; 3];
            p[axis] = at;
            p[(axis + 1) % 3] = u;
            p[(axis + 2) % 3] = v;
            self.obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        let k = self.verts;
        self.obj += &format!("f {} {} {} {}\n", k + 1, k + 2, k + 3, k + 4);
        self.verts += 4;
    }

    /// The inside of the box [x0, x1] × [0, w] × [0, h] (z up), without its wall at
    /// x = x1 when `open_east`, walls named `{name}_floor` and so on.
    fn room(&mut self, name: &str, x: [f64; 2], w: f64, h: f64, open: [bool; 2]) {
        self.rect(
            &format!("{name}_floor"),
            2,
            0.0,
            [x[0], 0.0],
            [x[1], w],
            1.0,
        );
        self.rect(
            &format!("{name}_ceiling"),
            2,
            h,
            [x[0], 0.0],
            [x[1], w],
            -1.0,
        );
        // y = 0 and y = w: spanning z, x.
        self.rect(
            &format!("{name}_south"),
            1,
            0.0,
            [0.0, x[0]],
            [h, x[1]],
            1.0,
        );
        self.rect(&format!("{name}_north"), 1, w, [0.0, x[0]], [h, x[1]], -1.0);
        // x = x0 and x = x1: spanning y, z.
        if !open[0] {
            self.rect(&format!("{name}_west"), 0, x[0], [0.0, 0.0], [w, h], 1.0);
        }
        if !open[1] {
            self.rect(&format!("{name}_east"), 0, x[1], [0.0, 0.0], [w, h], -1.0);
        }
    }

    fn write(&self, dir: &Path, name: &str) -> std::path::PathBuf {
        std::fs::write(
            dir.join("m.mtl"),
            "newmtl grey\nKd 0.6 0.6 0.6\nnewmtl lit\nKd 0 0 0\nKe 10 10 10\n",
        )
        .unwrap();
        let path = dir.join(format!("{name}.obj"));
        std::fs::write(&path, &self.obj).unwrap();
        path
    }
}

/// Two 2 × 2 × 2 rooms side by side, joined by a door (0.6 wide, 1.4 high) in the wall
/// between them, a light in the middle of the first one's ceiling.
fn two_rooms(dir: &Path) -> std::path::PathBuf {
    let mut b = Boxes::new();
    b.room("a", [0.0, 2.0], 2.0, 2.0, [false, true]);
    b.room("b", [2.0, 4.0], 2.0, 2.0, [true, false]);
    // The wall between, both sides, around the door y ∈ [0.7, 1.3], z ∈ [0, 1.4].
    for (side, sign) in [("a_east", -1.0), ("b_west", 1.0)] {
        b.rect(side, 0, 2.0, [0.0, 0.0], [0.7, 2.0], sign);
        b.rect(side, 0, 2.0, [1.3, 0.0], [2.0, 2.0], sign);
        b.rect(side, 0, 2.0, [0.7, 1.4], [1.3, 2.0], sign);
    }
    b.rect("light", 2, 1.99, [0.8, 0.8], [1.2, 1.2], -1.0);
    b.write(dir, "two_rooms")
}

/// A corridor 10 long, 1 wide and 1 high, lit at one end.
fn corridor(dir: &Path) -> std::path::PathBuf {
    let mut b = Boxes::new();
    // In five stretches, so that each is a group of its own.
    for k in 0..5 {
        let x = [2.0 * k as f64, 2.0 * (k + 1) as f64];
        b.room(&format!("s{k}"), x, 1.0, 1.0, [k > 0, k < 4]);
    }
    b.rect("light", 2, 0.99, [0.3, 0.3], [0.7, 0.7], -1.0);
    b.write(dir, "corridor")
}

/// Scenes where what a patch sees depends on where it is (two rooms joined by a door,
/// a long corridor lit at one end): the pool, one global rule for every row's dropped
/// mass, carries the lit room's light into the dark one and down the corridor; links
/// keep it where dense rows put it. Measured at about 1,500 patches, top-k 32 (eb098f3
/// with this test): two rooms, pool worst surface +767 % (the dark room's wall by the
/// door; the lit room −50 %), links 0.5 %; corridor, pool 115× the dense radiosity at
/// the far end's ceiling, links 1.1 %. With links sampled by one-ray points (spec
/// §5.7's writer, docs/numerics.md §8): two rooms 1.9 %, corridor 0.6 % with at least
/// 4 points a link; 0.3 % and 0.9 % with 4t points shared by weight, at least 2.
#[test]
fn links_keep_light_in_the_lit_room_and_near_the_lit_end_where_the_pool_spreads_it() {
    let dir = tempfile::tempdir().unwrap();
    for (scene, name) in [
        (two_rooms(dir.path()), "rooms"),
        (corridor(dir.path()), "corridor"),
    ] {
        let scene = path_str(&scene);
        let dense_file = compute_scene(dir.path(), scene, &format!("{name}_dense"), &[]);
        let dense = solve(&dense_file);
        let pool = solve(&compute_scene(
            dir.path(),
            scene,
            &format!("{name}_pool"),
            &["--top-k", "32", "--links", "off"],
        ));
        let links_file = compute_scene(
            dir.path(),
            scene,
            &format!("{name}_links"),
            &["--top-k", "32"],
        );
        let links = solve(&links_file);
        link_errors_hold(&dense_file, &links_file);
        let (e_pool, g_pool) = worst(&dense, &pool);
        let (e_links, g_links) = worst(&dense, &links);
        eprintln!(
            "{name}: worst surface: pool {e_pool:.3} ({g_pool}), links {e_links:.3} ({g_links})"
        );
        for (g, b) in &dense {
            eprintln!(
                "  {g}: dense {:.4e} pool {:.4e} links {:.4e}",
                b[0], pool[g][0], links[g][0]
            );
        }
        assert!(
            e_pool > 1.0,
            "{name}: the pool was expected to misplace light: {e_pool} ({g_pool})"
        );
        assert!(
            e_links < 0.02,
            "{name}: links: worst surface {e_links} ({g_links}) against dense rows"
        );
    }
}

/// A linked file passes `verify` (links inside [0, n), dropped = Σ links, cluster order
/// a permutation), and its rows are bitwise the same for one or two threads and under
/// `mpirun -n 3`; shooting refuses it rather than solve the transposed model.
#[test]
fn linked_rows_verify_and_are_the_same_for_any_thread_or_rank_count() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["--top-k", "16", "--links", "64"];
    let two = compute(
        dir.path(),
        "two",
        &[&args[..], &["--threads", "2"]].concat(),
    );
    let one = compute(
        dir.path(),
        "one",
        &[&args[..], &["--threads", "1"]].concat(),
    );
    ok(&["verify", path_str(&two)]);
    let same = crate::common::ffstream(&["verify", path_str(&one), "--against", path_str(&two)]);
    let text =
        String::from_utf8_lossy(&same.stdout).into_owned() + &String::from_utf8_lossy(&same.stderr);
    assert!(same.status.success(), "{text}");
    // Links included: the solves read them, so equal rows give equal radiosity files.
    let csv = |f: &Path| {
        let c = f.with_extension("csv");
        // Jacobi: each row gathers on its own, so the file order does not matter.
        ok(&[
            "solve",
            path_str(f),
            "--solver",
            "jacobi",
            "-q",
            "-o",
            path_str(&c),
        ]);
        std::fs::read(c).unwrap()
    };
    assert!(
        csv(&one) == csv(&two),
        "one and two threads solve differently"
    );
    let shot = crate::common::ffstream(&[
        "solve",
        path_str(&two),
        "--solver",
        "shooting",
        "-q",
        "-o",
        path_str(&dir.path().join("s.csv")),
    ]);
    let msg = String::from_utf8_lossy(&shot.stderr).into_owned();
    assert!(
        !shot.status.success() && msg.contains("gauss-seidel"),
        "{msg}"
    );
    if need_mpi() {
        let mpi = dir.path().join("mpi.ffz");
        let mut all = vec!["compute", "builtin:room", "--patches", "1500", "-q", "-o"];
        all.push(path_str(&mpi));
        all.extend_from_slice(&args);
        let mut cmd = mpirun(3, &all);
        let out = output_of_within(cmd.spawn().unwrap(), "mpirun -n 3 compute --links");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        ok(&["verify", path_str(&mpi), "--against", path_str(&two)]);
        assert!(csv(&mpi) == csv(&two), "mpirun -n 3 solves differently");
    }
}

/// The Python reader (`formats/ffz.py`) reads a linked file as the Rust reader does:
/// the same cluster order and, row by row, the same links and slopes to the bit; its
/// expansion of the links (spec 5.7) keeps every row's true sum, and the radiosity
/// solved from it directly (scipy) is `solve`'s, which gathers through prefix sums
/// instead: the two readings of the slope rule agree.
#[test]
fn the_python_reader_gives_the_links_and_cluster_order_of_the_rust_reader() {
    let dir = tempfile::tempdir().unwrap();
    let file = compute(dir.path(), "py", &["--top-k", "16", "--links", "64"]);
    let csv = file.with_extension("csv");
    ok(&["solve", path_str(&file), "-q", "-o", path_str(&csv)]);
    let rust = ffstream::ffz::FfzReader::open(&file).unwrap();
    let order = rust.meta().clusters.clone().expect("a cluster order");
    let mut want = format!(
        "order {}\n",
        order
            .iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    );
    let mut linked = 0;
    for i in 0..order.len() as u32 {
        let row = rust.row(i).unwrap().unwrap();
        linked += usize::from(!row.links.is_empty());
        for l in &row.links {
            want += &format!(
                "{i} {} {} {:08x} {:08x} {:08x} {:08x}\n",
                l.start,
                l.len,
                l.value.to_bits(),
                l.slope[0].to_bits(),
                l.slope[1].to_bits(),
                l.slope[2].to_bits()
            );
        }
    }
    assert!(linked > order.len() / 2, "only {linked} rows have links");
    let script = r#"
import sys, numpy as np
sys.path.insert(0, sys.argv[1])
import ffz
r = ffz.open(sys.argv[2])
out = ["order " + " ".join(str(int(x)) for x in r.cluster_order)]
for i in range(r.n):
    s, ln, v, q = r.links(i)
    q = q.view("<u4")
    out += [f"{i} {int(a)} {int(b)} {int(c):08x} " + " ".join(f"{int(x):08x}" for x in qs) for a, b, c, qs in zip(s, ln, v.view("<u4"), q)]
f = r.read()
full = f.matrix.astype(np.float64) + r.link_matrix()
err = np.abs(np.asarray(full.sum(axis=1)).ravel() - f.true_row_sums()).max()
assert err < 1e-5, err
b = np.random.default_rng(1).random((r.n, 3))
ex, op = r.link_matrix() @ b, r.link_operator() @ b
# Prefix sums over the whole cluster order cancel: a few digits of f64 go.
assert np.abs(op - ex).max() <= 1e-9 * np.abs(ex).max(), np.abs(op - ex).max()
t = np.genfromtxt(sys.argv[3], delimiter=",", names=True, dtype=None, encoding=None)
assert np.array_equal(t["patch"], np.arange(r.n))
import scipy.sparse, scipy.sparse.linalg
for ch in "rgb":
    a = scipy.sparse.identity(r.n, format="csc") - scipy.sparse.diags(t["rho_" + ch]) @ full
    b = scipy.sparse.linalg.spsolve(a.tocsc(), t["E_" + ch].astype(np.float64))
    rel = np.abs(b - t["B_" + ch]).max() / np.abs(b).max()
    assert rel < 1e-5, f"{ch}: solve differs from the expansion's by {rel:e}"
print("\n".join(out))
"#;
    let out = std::process::Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("formats"))
        .arg(&file)
        .arg(&csv)
        .output()
        .expect("python3");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout), want);
}

/// Per sensor: the mean illuminance over occupied hours from `annual`'s metrics.csv.
fn mean_lux(dir: &Path) -> BTreeMap<String, f64> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = head.iter().position(|h| *h == "mean_occupied_lux").unwrap();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].to_string(), f[col].parse().unwrap())
        })
        .collect()
}

/// `annual`'s inter-reflection (the adjoint solve, `solve/adjoint.rs`) reads a linked
/// file through its links: on the office lit by a year of clear skies, with top-16 rows
/// and links, every sensor's mean illuminance is within 0.5 % of what dense rows give
/// on the same mesh, where the pool puts some sensor more than 5 % off. Measured at 800
/// patches and a 1 m grid (24 sensors): links +0.04 % at worst, the pool +14.5 %; at
/// 3,000 patches, top-32 and a 0.5 m grid, links −0.14 % and the pool +17 %.
#[test]
fn annual_reads_linked_rows_through_their_links_and_matches_dense_rows() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec![
            "annual",
            "builtin:office",
            "--location",
            "52.0,4.4,1",
            "--grid",
            "floor:1.0",
            "--patches",
            "800",
            "-q",
            "-o",
            path_str(&out),
        ];
        args.extend_from_slice(extra);
        ok(&args);
        mean_lux(&out)
    };
    let dense = run("dense", &[]);
    let spread = |other: &BTreeMap<String, f64>| {
        dense
            .iter()
            .map(|(k, d)| ((other[k] / d - 1.0).abs(), k.clone()))
            .fold((0.0, String::new()), |a, b| if b.0 > a.0 { b } else { a })
    };
    assert!(dense.len() >= 20, "{} sensors", dense.len());
    let (links, at) = spread(&run("links", &["--top-k", "16"]));
    assert!(links <= 0.005, "links: {at} is {:.2} % off", 100.0 * links);
    let (pool, at) = spread(&run("pool", &["--top-k", "16", "--links", "off"]));
    assert!(pool > 0.05, "pool: {at} only {:.2} % off", 100.0 * pool);
}
