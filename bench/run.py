#!/usr/bin/env python3
"""ffstream benchmark harness: regenerates bench/RESULTS.md and bench/plots/*.png.

    python3 bench/run.py            full run (< 30 min on a 2-core machine), writes
                                    bench/RESULTS.md, bench/plots/ and bench/out/ (scratch)
    python3 bench/run.py --quick    every section on tiny sizes (< 3 min), writes into
                                    bench/out-quick/ only; exits non-zero when a run fails
                                    or an accuracy check that must hold is violated

Sections (docs/numerics.md §10, docs/known-answers.md):
  1. time vs error: analytic cases (Howell C-11, C-14), the obstructed plates against a
     self-computed reference, the Cornell box radiosity against its most refined solution
  2. scaling: embedded threads and MPI ranks, time vs n on the `room` builtin (dense
     1k-8k full runs; top-k 64 full at 8k and 12k, and 8k-100k extrapolated from sampled
     rows with bench/perf_rows.rs, built here through `cargo bench --no-run`)
  3. I/O: master idle fraction, throughput, compression, streaming vs --gather memory,
     solver memory vs file size
  4. peers: pyviewfactor (when installable)
  5. kernel modes (issue 6): the cluttered room at ~8.5k and ~20k patches, wall/CPU time
     and rays of half rows (--symmetric, the default), full rows, top-k and --occluders,
     extrapolated from sampled rows (bench/perf_rows.rs), each mode's error against
     exact-visibility rows; and the real `compute` at ~8.5k patches, half and
     full rows

Needs numpy, scipy, zstandard (the .ffz reader of formats/); matplotlib for the plots
(without it the tables are still written and a message says so). Timing figures are wall
clock as printed by `ffstream compute` ("wall ... s") unless a table says otherwise.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
import traceback

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "formats"))
sys.path.insert(0, HERE)

import analytic  # noqa: E402
import ffz  # noqa: E402

GNU_TIME = "/usr/bin/time" if os.access("/usr/bin/time", os.X_OK) else None
RSS_TAG = "FFBENCH_MAXRSS_KIB="
CPU_TAG = "FFBENCH_CPU_SECONDS="
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}


class CheckFailed(Exception):
    pass


# --------------------------------------------------------------------------- running


class Runner:
    """Runs ffstream commands, records each command line, wall time and peak RSS."""

    def __init__(self, binary: str, work: str):
        self.binary = binary
        self.work = work
        self.log = open(os.path.join(work, "commands.log"), "w")
        self.failures: list[str] = []
        self.checks: list[tuple[str, bool, str]] = []

    def show(self, args: list[str]) -> str:
        """The command as a user would type it (binary and work dir shortened)."""
        out = []
        for a in args:
            a = a.replace(self.binary, "ffstream").replace(self.work + "/", "")
            out.append(a)
        return " ".join(out)

    def run(self, args: list[str], mpi: int = 0, timeout: float = 1800, poll: bool = False,
            exe: str | None = None, shown_as: str | None = None) -> dict:
        """Run one command. poll=True (not with mpi): sample /proc/PID/status every 20 ms
        for the largest RssAnon (heap, anonymous maps) and RssFile (file-backed pages, e.g.
        the memory-mapped .ffz) the process reached. exe: another program than ffstream
        (e.g. the perf_rows bench binary), recorded as shown_as followed by args."""
        if args[:1] == ["compute"] and "--resume" not in args and "--force" not in args:
            # Benchmarks rewrite their scratch files: say so (compute refuses to
            # overwrite an existing file without --force).
            args = args + ["--force"]
        cmd = [exe or self.binary] + args
        env = dict(os.environ)
        env.setdefault("RUST_LOG", "warn")
        if mpi:
            cmd = ["mpirun", "-n", str(mpi), "--oversubscribe"] + cmd
            env.update(MPI_ENV)
        shown = self.show(cmd) if exe is None else " ".join([shown_as or exe] + args)
        # Peak RSS through GNU time: a child's own ru_maxrss (os.wait4) would include the
        # Python interpreter it was forked from.
        if GNU_TIME and not poll:
            cmd = [GNU_TIME, "-f", RSS_TAG + "%M " + CPU_TAG + "%U+%S"] + cmd
        out_path = os.path.join(self.work, "last.stdout")
        err_path = os.path.join(self.work, "last.stderr")
        t0 = time.perf_counter()
        with open(out_path, "w") as so, open(err_path, "w") as se:
            p = subprocess.Popen(cmd, stdout=so, stderr=se, env=env, cwd=self.work)
            peaks = {"RssAnon": 0, "RssFile": 0, "VmHWM": 0}
            while poll:
                try:
                    with open(f"/proc/{p.pid}/status") as st:
                        for line in st:
                            key = line.split(":", 1)[0]
                            if key in peaks:
                                peaks[key] = max(peaks[key], int(line.split()[1]))
                    # Stop at the zombie state (the process has exited; wait4 below reaps it).
                    with open(f"/proc/{p.pid}/stat") as st:
                        if st.read().rsplit(")", 1)[1].split()[0] == "Z":
                            break
                except (OSError, ValueError, IndexError):
                    break
                time.sleep(0.02)
            try:
                _, status, ru = os.wait4(p.pid, 0)
            except KeyboardInterrupt:
                p.kill()
                raise
            p.returncode = os.waitstatus_to_exitcode(status)
            del ru
        wall = time.perf_counter() - t0
        stdout = open(out_path).read()
        stderr = open(err_path).read()
        m = re.search(RSS_TAG + r"(\d+)", stderr)
        mc = re.search(CPU_TAG + r"([\d.]+)\+([\d.]+)", stderr)
        rec = {
            "cmd": shown,
            "rc": p.returncode,
            "process_wall": wall,
            # GNU time %M: maximum resident set size in KiB (of the process and the
            # descendants it waited for).
            "process_rss_mb": int(m.group(1)) * 1024 / 1e6 if m else peaks["VmHWM"] * 1024 / 1e6 if poll else float("nan"),
            "rss_anon_mb": peaks["RssAnon"] * 1024 / 1e6 if poll else float("nan"),
            "rss_file_mb": peaks["RssFile"] * 1024 / 1e6 if poll else float("nan"),
            # user + system CPU seconds of the process and its waited-for descendants
            # (for mpirun: every rank); unlike wall time, barely affected by other load.
            "cpu": float(mc.group(1)) + float(mc.group(2)) if mc else float("nan"),
            "stdout": stdout,
            "stderr": stderr,
        }
        rec.update(parse_summary(stderr))
        self.log.write(f"[{wall:8.2f} s rc={p.returncode}] {shown}\n")
        self.log.flush()
        print(f"  {wall:7.2f} s  {shown}", flush=True)
        if p.returncode != 0:
            msg = f"command failed (exit {p.returncode}): {shown}\n{stderr.strip()[-2000:]}"
            self.failures.append(msg)
            raise RuntimeError(msg)
        return rec

    def check(self, name: str, ok: bool, detail: str) -> None:
        self.checks.append((name, bool(ok), detail))
        print(f"  check {'ok  ' if ok else 'FAIL'} {name}: {detail}", flush=True)


SUMMARY_RES = {
    "faces_patches": re.compile(r"(\d+) faces -> (\d+) patches"),
    "setup": re.compile(r"set-up \(load, subdivide, Bvh, engine\) took ([\d.]+) s"),
    "wall": re.compile(
        r"wall ([\d.]+) s, ([\d.]+) rows/s; file ([\d.]+) MB on disk \(([\d.]+) MB raw, ratio ([\d.]+)\)"
    ),
    "master": re.compile(r"I/O master: idle ([\d.]+)% of wall time, peak RSS ([\d.]+) MB"),
    "worker": re.compile(
        r"worker rank (\d+): (\d+) rows, (\d+) threads, busy ([\d.]+) s \(([\d.]+)% of wall x threads\), peak RSS ([\d.]+) MB"
    ),
}


def parse_summary(stderr: str) -> dict:
    """Fields of the `ffstream compute` stderr summary (src/service/job.rs)."""
    r: dict = {}
    m = SUMMARY_RES["faces_patches"].search(stderr)
    if m:
        r["n"] = int(m.group(2))
    m = SUMMARY_RES["setup"].search(stderr)
    if m:
        r["setup"] = float(m.group(1))
    m = SUMMARY_RES["wall"].search(stderr)
    if m:
        r["wall"] = float(m.group(1))
        r["rows_per_s"] = float(m.group(2))
        r["disk_mb"] = float(m.group(3))
        r["raw_mb"] = float(m.group(4))
        r["ratio"] = float(m.group(5))
    m = SUMMARY_RES["master"].search(stderr)
    if m:
        r["idle"] = float(m.group(1)) / 100.0
        r["master_rss_mb"] = float(m.group(2))
    r["workers"] = [
        {"rank": int(w[0]), "rows": int(w[1]), "threads": int(w[2]), "busy": float(w[3]), "rss_mb": float(w[5])}
        for w in SUMMARY_RES["worker"].findall(stderr)
    ]
    return r


def group_matrix(f: "ffz.FfzFile") -> tuple[list[str], np.ndarray]:
    """F_IJ = sum_{i in I} (A_i / A_I) sum_{j in J} F_ij (docs/known-answers.md §1), from the matrix a
    solver would use (top-k rows scaled so no light is lost)."""
    m = f.no_light_lost() if f.layout == "topk" else f.matrix.astype(np.float64)
    g = f.patches["group"].astype(np.int64)
    a = f.patches["area"]
    ng = len(f.groups)
    onehot = np.zeros((f.n, ng))
    onehot[np.arange(f.n), g] = 1.0
    per_patch = m @ onehot  # n x G: sum over j in J
    area_g = onehot.T @ a
    fg = (onehot * a[:, None]).T @ per_patch / area_g[:, None]
    return list(f.groups), fg


def group_error(f, pairs: dict) -> float:
    names, fg = group_matrix(f)
    idx = {g: k for k, g in enumerate(names)}
    return max(abs(fg[idx[a], idx[b]] - v) for (a, b), v in pairs.items())


def group_value(f, a: str, b: str) -> float:
    names, fg = group_matrix(f)
    return float(fg[names.index(a), names.index(b)])


def fmt(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if isinstance(x, (int, np.integer)):
        return str(x)
    if x == 0:
        return "0"
    if abs(x) >= 1000 or abs(x) < 1e-2:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def table(header: list[str], rows: list[list]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        out.append("| " + " | ".join(c if isinstance(c, str) else fmt(c) for c in r) + " |")
    return "\n".join(out)


# --------------------------------------------------------------------------- section 1


def method_configs(quick: bool) -> list[tuple[str, str, list[str]]]:
    """(curve, label, ffstream options) for the time/error study."""
    c = [("point", "point", ["--method", "point"])]
    for s in [4, 16, 64, 256]:
        c.append(("mc", f"mc S={s}", ["--method", "mc", "--samples", str(s)]))
    for p in ["fast", "accurate", "reference"]:
        c.append(("contour preset", f"contour {p}", ["--preset", p]))
    for s in [4, 64]:
        c.append(("contour accurate, samples", f"contour accurate S={s}", ["--preset", "accurate", "--samples", str(s)]))
    c.append(("contour exact visibility", "contour accurate exact", ["--visibility", "exact"]))
    for k in [8, 32, 128]:
        c.append(("contour accurate, top-k", f"accurate top-k {k}", ["--preset", "accurate", "--top-k", str(k)]))
    return c


def section_time_error(r: Runner, quick: bool, res: dict) -> None:
    print("== 1. time vs error", flush=True)
    res["howell"] = analytic.self_check()
    r.check("Howell C-11/C-14 formulas reproduce the tables of docs/known-answers.md §2, §3", True,
            f"max deviation {max(x[3] for x in res['howell']):.1e}")
    cases = [
        ("cube", "builtin:cube", 96 if quick else 384, analytic.cube_pairs()),
        ("plates d=1", "builtin:plates:1", 32 if quick else 200, analytic.plates_pairs(1.0)),
        ("plates d=0.5", "builtin:plates:0.5", 32 if quick else 200, analytic.plates_pairs(0.5)),
        ("perpendicular h=1", "builtin:perpendicular:1", 32 if quick else 200, analytic.perpendicular_pairs(1.0)),
        ("perpendicular h=2", "builtin:perpendicular:2", 48 if quick else 300, analytic.perpendicular_pairs(2.0)),
    ]
    configs = method_configs(quick)
    rows = []
    for name, scene, npatch, pairs in cases:
        for curve, label, opts in configs:
            if "top-k" in label and name != "cube":
                continue  # top-k only changes anything where rows are long
            out = os.path.join(r.work, "s1.ffz")
            rec = r.run(["compute", scene, "--patches", str(npatch), "-q", "-o", out] + opts)
            f = ffz.read(out, verify=False)
            err = group_error(f, pairs)
            rowsum = float(np.max(np.abs(f.true_row_sums() - 1.0))) if name == "cube" else float("nan")
            rows.append({"case": name, "curve": curve, "label": label, "n": rec["n"], "wall": rec["wall"],
                         "err": err, "rowsum": rowsum, "cmd": rec["cmd"]})
            if label in ("contour accurate", "contour reference"):
                r.check(f"{label} on {name}: group factors within 1e-5 of Howell", err <= 1e-5, f"max abs error {err:.2e}")
            if name == "cube" and label in ("contour accurate", "contour reference"):
                r.check(f"{label} on closed cube: row sums 1 +- 1e-5", rowsum <= 1e-5, f"max |row sum - 1| {rowsum:.2e}")
            if name == "cube" and "top-k" in label:
                r.check(f"{label}: stored + dropped row sums 1 +- 1e-5", rowsum <= 1e-5, f"max |row sum - 1| {rowsum:.2e}")
    res["analytic"] = rows

    # (b) obstructed plates: the closed form of tests/data/occluded_refs.json (C-11 minus
    # the blocker's shadow, computed by tests/reference/occluded_ff.py), cross-checked
    # here against an independent mc estimate.
    with open(os.path.join(ROOT, "tests", "data", "occluded_refs.json")) as fh:
        ref = next(c for c in json.load(fh) if c["name"] == "obstructed")["closed_form_F_ij"]
    mc_n = 40 if quick else 200
    mc_s = 1024 if quick else 4096
    seeds = [0, 1, 2]
    mc_vals, mc_cmds = [], []
    for seed in seeds:
        out = os.path.join(r.work, "obs_mc.ffz")
        rec = r.run(["compute", "builtin:obstructed", "--patches", str(mc_n), "--method", "mc",
                     "--samples", str(mc_s), "--seed", str(seed), "-q", "-o", out])
        mc_vals.append(group_value(ffz.read(out, verify=False), "bottom", "top"))
        mc_cmds.append(rec["cmd"])
    mc = float(np.mean(mc_vals))
    mc_se = float(np.std(mc_vals, ddof=1) / math.sqrt(len(mc_vals)))
    diff = abs(ref - mc)
    tol = max(4 * mc_se, 1e-4 if not quick else 1e-3)
    r.check("obstructed: the closed form agrees with mc at high S", diff <= tol,
            f"closed form {ref:.10f}, mc {mc:.6f} +- {mc_se:.1e}, |diff| {diff:.1e} (tolerance {tol:.1e})")
    # The reference script's tolerance: errors below it are not resolved.
    unc = 1e-11
    res["obstructed_ref"] = {"ref": ref, "mc": mc, "mc_se": mc_se, "unc": unc, "mc_vals": mc_vals,
                             "mc_cmds": mc_cmds, "mc_n": mc_n, "mc_s": mc_s}
    obs_rows = []
    obs_n = 48 if quick else 200
    for curve, label, opts in configs:
        if "top-k" in label:
            continue
        out = os.path.join(r.work, "obs.ffz")
        rec = r.run(["compute", "builtin:obstructed", "--patches", str(obs_n), "-q", "-o", out] + opts)
        v = group_value(ffz.read(out, verify=False), "bottom", "top")
        obs_rows.append({"curve": curve, "label": label, "n": rec["n"], "wall": rec["wall"], "value": v,
                         "err": abs(v - ref), "cmd": rec["cmd"]})
        if label == "contour accurate exact":
            r.check("obstructed: exact visibility within 1e-6 of the closed form", abs(v - ref) <= 1e-6,
                    f"error {abs(v - ref):.1e}")
    res["obstructed"] = obs_rows
    # Error against patch size, rays (the default) and exact visibility.
    sizes = []
    for edge in ([0.2, 0.1] if quick else [0.2, 0.1, 0.05]):
        for curve, opts in [("rays (default)", []), ("exact visibility", ["--visibility", "exact"])]:
            out = os.path.join(r.work, "obs_size.ffz")
            rec = r.run(["compute", "builtin:obstructed", "--max-edge", str(edge), "-q", "-o", out] + opts)
            v = group_value(ffz.read(out, verify=False), "bottom", "top")
            sizes.append({"curve": curve, "edge": edge, "n": rec["n"], "wall": rec["wall"], "value": v,
                          "err": abs(v - ref), "cmd": rec["cmd"]})
    res["obstructed_sizes"] = sizes

    # (c) Cornell box radiosity: per-group area-averaged B against the most refined run.
    levels = [60, 120, 240] if quick else [250, 500, 1000]
    ref_level = 600 if quick else 3000
    cb_methods = [("point", "point", ["--method", "point"]),
                  ("mc S=16", "mc S=16", ["--method", "mc", "--samples", "16"]),
                  ("contour fast", "contour fast", ["--preset", "fast"]),
                  ("contour accurate", "contour accurate", ["--preset", "accurate"])]

    def cornell(npatch, opts):
        out = os.path.join(r.work, "cornell.ffz")
        csv = os.path.join(r.work, "cornell.csv")
        rec = r.run(["compute", "builtin:cornell", "--patches", str(npatch), "--rows", "needed", "-q", "-o", out] + opts)
        rs = r.run(["solve", out, "-o", csv])
        data = np.genfromtxt(csv, delimiter=",", names=True, dtype=None, encoding="utf-8")
        groups = sorted(set(data["group"]))
        b = {}
        for g in groups:
            sel = data["group"] == g
            a = data["area"][sel]
            b[g] = np.array([np.sum(a * data[c][sel]) / np.sum(a) for c in ("B_r", "B_g", "B_b")])
        if not all(np.all(np.isfinite(v)) and np.all(v >= 0) for v in b.values()):
            r.check("cornell radiosity finite and non-negative", False, rec["cmd"])
        return rec, rs, b

    ref_rec, ref_solve, bref = cornell(ref_level, ["--preset", "accurate"])
    cb_rows = []
    for label, _, opts in cb_methods:
        for lv in levels:
            rec, rs, b = cornell(lv, opts)
            errs = [np.max(np.abs(b[g] - bref[g]) / np.maximum(np.abs(bref[g]), 1e-30)) for g in bref if g != "light"]
            cb_rows.append({"curve": label, "level": lv, "n": rec["n"], "wall": rec["wall"],
                            "solve_wall": rs["process_wall"], "err": float(max(errs)), "cmd": rec["cmd"],
                            "b": b})
    res["cornell"] = {"rows": cb_rows, "ref_n": ref_rec["n"], "ref_cmd": ref_rec["cmd"], "ref_wall": ref_rec["wall"],
                      "bref": bref, "solve_cmd": ref_solve["cmd"]}
    acc = [x for x in cb_rows if x["curve"] == "contour accurate"]
    decreasing = all(acc[k + 1]["err"] < acc[k]["err"] for k in range(len(acc) - 1))
    r.check("cornell (contour accurate) per-group error decreases as patches are refined", decreasing or quick,
            " -> ".join(f"{x['n']}: {x['err']:.2e}" for x in acc) + (" (informational in quick mode)" if quick else ""))


# --------------------------------------------------------------------------- section 2


def section_scaling(r: Runner, quick: bool, res: dict) -> None:
    print("== 2. scaling", flush=True)
    sizes = [300, 600] if quick else [1000, 2000, 4000, 8000]
    configs = [("embedded --threads 1", 0, ["--threads", "1"], 1),
               ("embedded --threads 2", 0, ["--threads", "2"], 2),
               ("mpirun -n 2 (1 worker)", 2, ["--threads", "1"], 1),
               ("mpirun -n 3 (2 workers)", 3, ["--threads", "1"], 2),
               ("mpirun -n 4 (3 workers)", 4, ["--threads", "1"], 3)]
    rows = []
    for n in sizes:
        mats = {}
        for label, mpi, opts, p in configs:
            out = os.path.join(r.work, f"scale_{n}_{mpi}_{p}.ffz")
            rec = r.run(["compute", "builtin:room", "--patches", str(n), "--preset", "fast", "-q", "-o", out] + opts, mpi=mpi)
            rows.append({"config": label, "mpi": mpi, "p": p, "n": rec["n"], "wall": rec["wall"], "idle": rec.get("idle"),
                         "cpu": rec["cpu"], "load": os.getloadavg()[0],
                         "disk_mb": rec["disk_mb"], "raw_mb": rec["raw_mb"], "ratio": rec["ratio"],
                         "master_rss": rec.get("master_rss_mb"), "cmd": rec["cmd"]})
            if n == sizes[0]:
                mats[label] = ffz.read(out, verify=False).matrix
            if n == sizes[-1] and mpi == 0 and p == 2:
                dense_last = out  # kept for the top-k comparison below
            else:
                os.remove(out)
        if mats:
            base = mats[configs[0][0]]
            worst = max(float(abs(m - base).max()) if (m - base).nnz else 0.0 for m in mats.values())
            r.check(f"room n={sizes[0]}: identical rows for every thread and rank count", worst == 0.0,
                    f"max |difference| {worst:.1e} over {len(mats)} configurations")
    res["scaling"] = rows
    # Exponent of time vs n (embedded, 2 threads).
    pts = [(x["n"], x["wall"]) for x in rows if x["config"] == "embedded --threads 2"]
    slope = float(np.polyfit(np.log([p[0] for p in pts]), np.log([p[1] for p in pts]), 1)[0])
    res["scaling_exponent"] = slope
    pts = [(x["n"], x["cpu"]) for x in rows if x["config"] == "embedded --threads 1"]
    res["scaling_exponent_cpu"] = float(np.polyfit(np.log([p[0] for p in pts]), np.log([p[1] for p in pts]), 1)[0])
    # Top-k against dense at the same n: the kept entries plus the stored dropped mass
    # must restore the dense row sums (fast preset: the tail mass is estimated from 32
    # sampled pairs, unbiased, so the mean difference is small even if single rows are off).
    # Tolerance: 4 standard errors of the mean plus 2e-4 for the early-stop bias of the
    # dense rows (about 1e-4, measured in src/formfactor/visibility.rs).
    out = os.path.join(r.work, "topk_cmp.ffz")
    rec = r.run(["compute", "builtin:room", "--patches", str(sizes[-1]), "--preset", "fast", "--top-k", str(TOPK_K),
                 "--threads", "2", "-q", "-o", out])
    d_rs = ffz.read(dense_last, verify=False).true_row_sums()
    t_file = ffz.read(out, verify=False)
    t_rs = t_file.true_row_sums()
    diff = t_rs - d_rs
    res["topk_vs_dense"] = {"n": rec["n"], "mean_signed": float(np.mean(diff)), "mean_abs": float(np.mean(np.abs(diff))),
                            "max_abs": float(np.max(np.abs(diff))), "cmd": rec["cmd"], "wall": rec["wall"],
                            "dense_sum_mean": float(np.mean(d_rs))}
    r.check(f"room n={rec['n']} top-k 64 (sampled tail): stored + dropped restores the dense row sums on average",
            abs(float(np.mean(diff))) <= 4 * float(np.std(diff)) / math.sqrt(len(diff)) + 2e-4,
            f"mean signed difference {np.mean(diff):.1e}, mean |difference| {np.mean(np.abs(diff)):.1e}, "
            f"max {np.max(np.abs(diff)):.1e}")
    topk_full = [topk_full_point(rec, sizes[-1])]
    os.remove(out)
    os.remove(dense_last)
    # The same size by sampled rows, at once (about the same load as the full run).
    perf_rows = perf_rows_binary()
    rows_timed = TOPK_SAMPLED_ROWS_QUICK if quick else TOPK_SAMPLED_ROWS
    topk_sampled = [topk_sampled_point(r, perf_rows, sizes[-1], rows_timed)]
    # Top-k at the largest size run in full (also the top-k row of the I/O table).
    big = 2000 if quick else 12000
    out = os.path.join(r.work, "topk_big.ffz")
    rec = r.run(["compute", "builtin:room", "--patches", str(big), "--preset", "fast", "--top-k", str(TOPK_K),
                 "--threads", "2", "-q", "-o", out])
    res["scaling_topk"] = {"n": rec["n"], "wall": rec["wall"], "disk_mb": rec["disk_mb"], "raw_mb": rec["raw_mb"],
                           "ratio": rec["ratio"], "idle": rec.get("idle"), "master_rss": rec.get("master_rss_mb"),
                           "cmd": rec["cmd"], "k": TOPK_K}
    topk_full.append(topk_full_point(rec, big))
    os.remove(out)
    topk_sampled.append(topk_sampled_point(r, perf_rows, big, rows_timed))
    topk_series(r, quick, res, topk_full, topk_sampled, perf_rows)


TOPK_K = 64
# Top-k series beyond what a full run affords (issue 7: "1k to 100k patches, top-k for
# the largest"): a full `compute` at 100k patches takes ~40 min on 2 cores, so these
# sizes time an evenly spread sample of rows with bench/perf_rows.rs and extrapolate.
TOPK_SAMPLED_SIZES = [8000, 12000, 25000, 50000, 100000]
TOPK_SAMPLED_ROWS = 2000
TOPK_SAMPLED_SIZES_QUICK = [600, 2000, 4000]  # the first two: the quick full runs' sizes
TOPK_SAMPLED_ROWS_QUICK = 200

PERF_ROWS_RES = {
    "n": re.compile(r"^scene \S+ patches (\d+)", re.M),
    "setup": re.compile(r"^set-up \(load, subdivide, Bvh, engine\) ([\d.]+) s; timed rows (\d+) of (\d+)", re.M),
    "counters": re.compile(r"Counters \{ rows: (\d+), pairs_evaluated: (\d+), .*pairs_topk_tail_skipped: (\d+), "
                           r"pairs_unoccludable: (\d+), rays_cast: (\d+),"),
}


def topk_full_point(rec: dict, target: int) -> dict:
    """A top-k series point from a full `ffstream compute --patches target` run (every row
    computed)."""
    return {"kind": "full", "n": rec["n"], "target": target, "rows": rec["n"], "wall": rec["wall"], "cpu": rec["cpu"],
            "setup": rec.get("setup"), "process_wall": rec["process_wall"], "cmd": rec["cmd"],
            "load": os.getloadavg()[0]}


def perf_rows_binary() -> str:
    """Build bench/perf_rows.rs if needed (release profile, the crate's default features,
    as `make test` builds the benches) and return the path of its executable."""
    cargo = os.environ.get("CARGO", "cargo")
    cmd = [cargo, "bench", "--bench", "perf_rows", "--no-run", "--message-format=json"]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed (exit {p.returncode}):\n{p.stderr.strip()[-2000:]}")
    for line in p.stdout.splitlines():
        try:
            msg = json.loads(line)
        except ValueError:
            continue
        if msg.get("reason") == "compiler-artifact" and msg.get("target", {}).get("name") == "perf_rows" \
                and msg.get("executable"):
            return msg["executable"]
    raise RuntimeError(f"{' '.join(cmd)}: no perf_rows executable in cargo's output")


def topk_sampled_point(r: Runner, exe: str, n: int, rows_timed: int) -> dict:
    """A top-k series point from perf_rows: `rows_timed` evenly spread rows of the n-patch
    room, timed on 2 threads, extrapolated to all rows (perf_rows scales by n / rows)."""
    mode = f"fasttopk{TOPK_K}"
    rec = r.run(["builtin:room", str(n), "--modes", mode, "--rows", str(rows_timed), "--threads", "2"], exe=exe,
                shown_as="cargo bench --bench perf_rows --")
    out = rec["stdout"]
    setup = PERF_ROWS_RES["setup"].search(out)
    cnt = PERF_ROWS_RES["counters"].search(out)
    line = re.search(rf"^{mode}\s+([\d.]+)\s+([\d.]+)\s", out, re.M)
    if not (setup and cnt and line):
        raise RuntimeError(f"unexpected perf_rows output of `{rec['cmd']}`:\n{out[-2000:]}")
    timed, total = int(setup.group(2)), int(setup.group(3))
    per_row = 1.0 / int(cnt.group(1))
    return {"kind": "sampled", "n": total, "rows": timed, "wall": float(line.group(1)),
            "cpu": float(line.group(2)), "setup": float(setup.group(1)),
            "sample_wall": float(line.group(1)) * timed / total, "process_wall": rec["process_wall"],
            "pairs_per_row": int(cnt.group(2)) * per_row,
            "rays_pairs_per_row": (int(cnt.group(2)) - int(cnt.group(4)) - int(cnt.group(3))) * per_row,
            "rays_per_row": int(cnt.group(5)) * per_row, "cmd": rec["cmd"],
            "load": os.getloadavg()[0]}


def topk_series(r: Runner, quick: bool, res: dict, full: list[dict], sampled: list[dict], exe: str) -> None:
    """Top-k 64 (preset fast, 2 threads) time vs n: the full runs and the sampled points
    already taken (each right after the full run of its size, so that both see about the
    same load from other jobs), then the remaining sizes of TOPK_SAMPLED_SIZES; checks,
    extrapolation errors, fitted exponents."""
    mode = f"fasttopk{TOPK_K}"
    rows_timed = TOPK_SAMPLED_ROWS_QUICK if quick else TOPK_SAMPLED_ROWS
    done = {f["target"] for f in full}
    for n in TOPK_SAMPLED_SIZES_QUICK if quick else TOPK_SAMPLED_SIZES:
        if n not in done:
            sampled.append(topk_sampled_point(r, exe, n, rows_timed))
    sampled.sort(key=lambda x: x["n"])
    # The sampled mode computes what `compute --preset fast --top-k 64` does: perf_rows
    # builds its job through the library's settings, as the command line does.
    # Extrapolation against the full runs at the same n (CPU time: steadier than wall on a
    # shared machine; the full run's CPU also counts the I/O master and the file).
    by_n = {x["n"]: x for x in sampled}
    for f in full:
        s = by_n.get(f["n"])
        if s:
            s["wall_err"] = s["wall"] / f["wall"] - 1.0
            s["cpu_err"] = s["cpu"] / f["cpu"] - 1.0
    # Only a gross check (a wrong scale factor, a mode timing other work): the other jobs of
    # a shared 2-core machine move even CPU seconds by tens of percent (measured -35% to
    # +18% at 2k patches); the table reports the actual errors.
    errs = [x for x in sampled if "cpu_err" in x]
    r.check("sampled-row extrapolation of CPU time within a factor 3 of the full top-k runs", bool(errs) and
            all(1 / 3 <= 1 + x["cpu_err"] <= 3 for x in errs),
            ", ".join(f"n={x['n']}: CPU {x['cpu_err']:+.0%}, wall {x['wall_err']:+.0%}" for x in errs))

    def slope(pts: list[tuple[float, float]]) -> float:
        return float(np.polyfit(np.log([p[0] for p in pts]), np.log([p[1] for p in pts]), 1)[0])

    res["topk_series"] = {
        "k": TOPK_K, "mode": mode, "rows": rows_timed, "full": full, "sampled": sampled,
        "exponent_wall": slope([(x["n"], x["wall"]) for x in sampled]),
        "exponent_cpu": slope([(x["n"], x["cpu"]) for x in sampled]),
        "local_cpu": [(a["n"], b["n"], slope([(a["n"], a["cpu"]), (b["n"], b["cpu"])]))
                      for a, b in zip(sampled, sampled[1:])],
    }


# --------------------------------------------------------------------------- section 3


# --------------------------------------------------------------------------- section 5

# perf_rows modes of the issue-6 table and the flag each one stands for.
MODE_FLAGS = {
    "symmetric": "(default: half rows, `--symmetric auto`)",
    "default": "`--symmetric off` (full rows)",
    "topk256": "`--top-k 256` (tree search, tail sampled at 256 points)",
    "topk256s": "top-k 256, exhaustive search, tail sampled from 32 pairs",
    "occluders": "`--occluders room.obj` (the scene's faces as a foreign mesh)",
}


def section_modes(r: Runner, quick: bool, res: dict) -> None:
    print("== 5. kernel modes (issue 6)", flush=True)
    exe = perf_rows_binary()
    if quick:
        plan = [(1500, ["symmetric", "default", "topk256s", "occluders"], 30, 5)]
    else:
        plan = [(8500, ["symmetric", "default", "topk256", "topk256s", "occluders"], 150, 30),
                (20000, ["symmetric", "default", "topk256", "occluders"], 100, 20)]
    line_re = re.compile(r"^(\w+)\s+([\d.]+)\s+([\d.]+)\s+([\d.e+-]+)\s+([\d.]+)%\s+([\d.]+)%\s+(\d+)\s+"
                         r"([\d.e+-]+)\s+([\d.e+-]+)\s+([\d.e+-]+)\s*$", re.M)
    rows = []
    for n, modes, timed, ref in plan:
        # Reference rows: exact visibility to 1e-3 of F⁰ (largest entry error ~1e-6 on the
        # Cornell box, bench/PERF.md §14), 1024 rays for the pairs it leaves to rays; the
        # `reference` preset (1e-6) costs ~20 times more.
        rec = r.run(["builtin:room", str(n), "--modes", ",".join(modes), "--rows", str(timed),
                     "--ref-rows", str(ref), "--ref-mode", "exact1e-3r1024", "--threads", "2"], exe=exe,
                    shown_as="cargo bench --bench perf_rows --")
        got = {m.group(1): m for m in line_re.finditer(rec["stdout"])}
        nn = PERF_ROWS_RES["n"].search(rec["stdout"])
        if set(got) != set(modes) or not nn:
            raise RuntimeError(f"unexpected perf_rows output of `{rec['cmd']}`:\n{rec['stdout'][-2000:]}")
        for mode in modes:
            m = got[mode]
            rows.append({"n": int(nn.group(1)), "mode": mode, "wall": float(m.group(2)), "cpu": float(m.group(3)),
                         "rays": float(m.group(4)), "far": float(m.group(5)), "noray": float(m.group(6)),
                         "max_abs": float(m.group(8)), "rowsum": float(m.group(9)), "mean_abs": float(m.group(10)),
                         "timed": timed, "ref": ref, "cmd": rec["cmd"], "load": os.getloadavg()[0]})
        by = {x["mode"]: x for x in rows if x["n"] == int(nn.group(1))}
        half, full = by["symmetric"], by["default"]
        # Counts, not timings: every pair that faces the other is evaluated once instead
        # of twice, so half rows cast half the rays (up to the sampling of rows).
        ratio = half["rays"] / full["rays"]
        r.check(f"n={half['n']}: half rows cast half the rays of full rows", 0.4 < ratio < 0.6, f"ratio {ratio:.3f}")
        r.check(f"n={half['n']}: half rows are as accurate as full rows on average (mean |error| within 1.5x)",
                half["mean_abs"] <= 1.5 * full["mean_abs"] + 1e-12,
                f"{half['mean_abs']:.2e} vs {full['mean_abs']:.2e}")
    # The real service at the paper's largest size: half rows (default) and full rows.
    n_real = 1500 if quick else 8500
    real = []
    # The default three times (the machine may be shared: best and median are reported).
    for k, flag in enumerate([[]] * (1 if quick else 3) + [["--symmetric", "off"]]):
        rec = r.run(["compute", "builtin:room", "--patches", str(n_real), "-q", "-o", f"modes_{k}.ffz", "--force"]
                    + flag)
        real.append({"mode": "half rows (default)" if not flag else "full rows (`--symmetric off`)", "n": rec["n"],
                     "wall": rec["wall"], "cpu": rec["cpu"], "cmd": rec["cmd"], "load": os.getloadavg()[0]})
    res["modes"] = {"rows": rows, "real": real}


def section_io(r: Runner, quick: bool, res: dict) -> None:
    print("== 3. I/O and memory", flush=True)
    sizes = [600, 1200] if quick else [10000, 20000]
    boxes = 32 if quick else 64  # the cluttered room
    rows = []
    files = {}
    for n in sizes:
        for mode, extra in (("streaming", []), ("--gather", ["--gather"])):
            out = os.path.join(r.work, f"io_{n}_{mode.strip('-')}.ffz")
            rec = r.run(["compute", f"builtin:room:{boxes}", "--patches", str(n), "--method", "point", "--threads", "2",
                         "-q", "-o", out] + extra, poll=True)
            rows.append({"mode": mode, "anon": rec["rss_anon_mb"], "file": rec["rss_file_mb"], "n": rec["n"], "wall": rec["wall"], "process_wall": rec["process_wall"],
                         "process_rss": rec["process_rss_mb"], "master_rss": rec.get("master_rss_mb"),
                         "idle": rec.get("idle"), "disk_mb": rec["disk_mb"], "raw_mb": rec["raw_mb"],
                         "ratio": rec["ratio"], "cmd": rec["cmd"]})
            files[(n, mode)] = out
    # Gather and streaming must store the same rows.
    for n in sizes:
        a = ffz.read(files[(n, "streaming")], verify=False).matrix
        b = ffz.read(files[(n, "--gather")], verify=False).matrix
        d = abs(a - b)
        worst = float(d.max()) if d.nnz else 0.0
        r.check(f"room n={n}: --gather and streaming files hold the same rows", worst <= 1e-6, f"max |difference| {worst:.1e}")
        if n != sizes[-1]:
            os.remove(files[(n, "--gather")])
    st = [x for x in rows if x["mode"] == "streaming"]
    ga = [x for x in rows if x["mode"] == "--gather"]
    growth = st[1]["process_rss"] / st[0]["process_rss"]
    n_ratio2 = (st[1]["n"] / st[0]["n"]) ** 2
    r.check("streaming peak RSS grows far slower than n^2", growth < 0.5 * n_ratio2,
            f"{st[0]['process_rss']:.0f} MB -> {st[1]['process_rss']:.0f} MB (x{growth:.2f}) while n^2 grows x{n_ratio2:.1f}")
    res["io"] = rows
    # Solver memory vs file size (gauss-seidel reads rows sequentially, out of core).
    solve_rows = []
    for n, x in zip(sizes, st):
        path = files[(n, "streaming")]
        csv = os.path.join(r.work, "io_solve.csv")
        rec = r.run(["solve", path, "-o", csv, "--tolerance", "1e-4"], poll=True)
        solve_rows.append({"anon": rec["rss_anon_mb"], "file": rec["rss_file_mb"],"n": x["n"], "file_mb": os.path.getsize(path) / 1e6, "raw_mb": x["raw_mb"],
                           "rss": rec["process_rss_mb"], "wall": rec["process_wall"], "cmd": rec["cmd"]})
    res["io_solve"] = solve_rows
    for p in files.values():
        if os.path.exists(p):
            os.remove(p)


# --------------------------------------------------------------------------- section 4


def section_peers(r: Runner, quick: bool, res: dict) -> None:
    print("== 4. peers", flush=True)
    try:
        import pyvista as pv  # noqa: F401
        import pyviewfactor as pvf
    except Exception as e:  # not installable here: say so in RESULTS.md
        res["peers"] = {"error": f"pyviewfactor not importable ({type(e).__name__}: {e}); install with `pip install pyviewfactor`"}
        print("  " + res["peers"]["error"])
        return
    import pyvista as pv

    cases = [("cube", "builtin:cube", 96 if quick else 384, analytic.cube_pairs()),
             ("plates d=1", "builtin:plates:1", 32 if quick else 200, analytic.plates_pairs(1.0))]
    rows = []
    for name, scene, npatch, pairs in cases:
        out = os.path.join(r.work, "peer.ffz")
        rec = r.run(["compute", scene, "--patches", str(npatch), "--preset", "accurate", "--threads", "2", "-q", "-o", out])
        f = ffz.read(out, verify=False)
        err_ff = group_error(f, pairs)
        # Same patches for pyviewfactor: one polygon cell per patch.
        pts, faces = [], []
        for c in range(f.n):
            k = int(f.patches["n_corners"][c])
            base = len(pts)
            pts.extend(f.patches["corners"][c][:k].tolist())
            faces.extend([k] + list(range(base, base + k)))
        mesh = pv.PolyData(np.array(pts), np.array(faces))
        t0 = time.perf_counter()
        m = np.asarray(pvf.compute_viewfactor_matrix(mesh))
        t_first = time.perf_counter() - t0  # includes numba compilation
        t0 = time.perf_counter()
        m = np.asarray(pvf.compute_viewfactor_matrix(mesh))
        t_second = time.perf_counter() - t0
        # pyviewfactor's matrix convention: check which orientation gives row sums <= 1
        # (all patches have equal areas here, so F is symmetric either way).
        fp = _PseudoFfz(f, m)
        err_pvf = group_error(fp, pairs)
        rows.append({"case": name, "n": f.n, "ff_wall": rec["wall"], "ff_err": err_ff, "pvf_first": t_first,
                     "pvf_wall": t_second, "pvf_err": err_pvf, "cmd": rec["cmd"]})
    res["peers"] = {"rows": rows, "version": getattr(pvf, "__version__", "?")}


class _PseudoFfz:
    """Just enough of ffz.FfzFile for group_matrix(), around a dense matrix."""

    def __init__(self, f, m):
        import scipy.sparse

        self.n, self.patches, self.groups, self.layout = f.n, f.patches, f.groups, "dense"
        self.matrix = scipy.sparse.csr_matrix(m)


# --------------------------------------------------------------------------- output


def machine_info(binary: str) -> dict:
    cpu = "unknown"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "src", "Cargo.toml"], cwd=ROOT,
                               capture_output=True, text=True).stdout.strip()
        if dirty:
            commit += " (src modified)"
    except OSError:
        commit = "unknown"
    return {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "cores": os.cpu_count(), "cpu": cpu, "commit": commit, "host": platform.node(),
            "load_start": os.getloadavg()}


def make_plots(res: dict, plot_dir: str) -> list[str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        msg = "matplotlib is not installed (pip install matplotlib): tables written, plots skipped"
        print("  " + msg)
        return [msg]
    os.makedirs(plot_dir, exist_ok=True)
    stamp = f"{res['meta']['date']}, {res['meta']['cores']} cores {res['meta']['cpu']}, ffstream {res['meta']['commit'][:10]}"

    def short(x):
        lab = x.get("label", "")
        if "level" in x:
            return str(x["n"])
        for pre, rep in (("mc S=", "S="), ("contour accurate S=", "S="), ("accurate top-k ", "k="), ("contour ", "")):
            if lab.startswith(pre):
                return rep + lab[len(pre):]
        return ""

    def curves(ax, rows, key_x, key_y, key_curve):
        # Points joined in parameter order (samples, preset, k, refinement), not time order.
        for curve in dict.fromkeys(x[key_curve] for x in rows):
            pts = [(x[key_x], max(x[key_y], 1e-10), short(x)) for x in rows if x[key_curve] == curve]
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=curve)
            for px, py, t in pts:
                ax.annotate(t, (px, py), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)

    fig, axes = plt.subplots(1, 3, figsize=(17, 5.2))
    # (a) the closed unit cube (the analytic case with the most pairs; table has the rest).
    cube = [x for x in res["analytic"] if x["case"] == "cube"]
    curves(axes[0], cube, "wall", "err", "curve")
    axes[0].axhline(1e-5, color="k", ls=":", lw=1)
    axes[0].set_title(f"(a) unit cube, n = {cube[0]['n']}, vs Howell C-11/C-14 (dotted: 1e-5)")
    axes[0].set_xlabel("compute wall time [s]")
    axes[0].set_ylabel("max |F_IJ - Howell| over group pairs")
    curves(axes[1], res["obstructed"], "wall", "err", "curve")
    axes[1].axhline(max(res["obstructed_ref"]["unc"], 1e-9), color="k", ls=":", lw=1)
    axes[1].set_title("(b) obstructed plates, |F - reference| (dotted: ref. uncertainty)")
    axes[1].set_xlabel("compute wall time [s]")
    axes[1].set_ylabel("|F_bottom,top - reference|")
    curves(axes[2], res["cornell"]["rows"], "wall", "err", "curve")
    axes[2].set_title(f"(c) Cornell box vs {res['cornell']['ref_n']} patches (points: refinement levels)")
    axes[2].set_xlabel("compute wall time [s]")
    axes[2].set_ylabel("max rel. error of per-group mean B")
    for ax in axes:
        ax.legend(fontsize=7)
    fig.suptitle("ffstream time vs error  —  " + stamp, fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(plot_dir, "pareto.png"), dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for curve in dict.fromkeys(x["curve"] for x in res["obstructed_sizes"]):
        pts = [x for x in res["obstructed_sizes"] if x["curve"] == curve]
        ax.plot([x["edge"] for x in pts], [max(x["err"], 1e-12) for x in pts], "o-", label=curve)
    ax.axhline(1e-6, color="k", ls=":", lw=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_xlabel("patch edge (--max-edge)")
    ax.set_ylabel("|F_bottom,top - closed form|")
    ax.set_title("obstructed plates: error against patch size (dotted: 1e-6)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(plot_dir, "obstructed_sizes.png"), dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for cfg in dict.fromkeys(x["config"] for x in res["scaling"]):
        pts = sorted((x["n"], x["wall"]) for x in res["scaling"] if x["config"] == cfg)
        axes[0].plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=cfg)
    ts = res["topk_series"]
    pts = sorted((x["n"], x["wall"]) for x in ts["full"])
    axes[0].plot([p[0] for p in pts], [p[1] for p in pts], "k*-", ms=10,
                 label=f"top-k {ts['k']}, 2 threads, full run")
    pts = sorted((x["n"], x["wall"]) for x in ts["sampled"])
    axes[0].plot([p[0] for p in pts], [p[1] for p in pts], "s--", color="0.35", mfc="none", ms=7,
                 label=f"top-k {ts['k']}, 2 threads, extrapolated from {ts['rows']} sampled rows (hollow)")
    axes[0].set_xscale("log")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("patches n")
    axes[0].set_ylabel("compute wall time [s]")
    axes[0].set_title(f"room, preset fast (2-core machine); fitted wall ~ n^{res['scaling_exponent']:.2f} dense, "
                      f"n^{ts['exponent_wall']:.2f} top-k", fontsize=9)
    axes[0].grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    io = res["io"]
    for mode in ("streaming", "--gather"):
        pts = sorted((x["n"], x["process_rss"]) for x in io if x["mode"] == mode)
        axes[1].plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=f"compute {mode}: process peak RSS")
    pts = sorted((x["raw_mb"], x["rss"]) for x in res["io_solve"])
    axes[1].set_xscale("log")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("patches n")
    axes[1].set_ylabel("peak RSS [MB]")
    axes[1].set_title("memory: streaming vs --gather (cluttered room, point)")
    axes[1].grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=7)
    fig.suptitle("ffstream scaling and memory  —  " + stamp, fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(plot_dir, "scaling.png"), dpi=110)
    plt.close(fig)
    return []


def topk_series_text(res: dict) -> str:
    """RESULTS.md subsection: top-k time vs n up to 100k patches, exponents, why ~n²."""
    ts = res["topk_series"]
    k, rows_timed = ts["k"], ts["rows"]
    full, sampled = ts["full"], ts["sampled"]
    big = sampled[-1]
    L = [f"### Time vs n up to {big['n'] // 1000}k patches: top-k {k}\n"]
    L.append(f"`builtin:room`, preset fast, `--top-k {k}`, 2 compute threads. A full `ffstream compute` at "
             f"{big['n']} patches would take about {big['wall']:.0f} s ({big['wall'] / 60:.0f} min) here (extrapolated, "
             "below) while the whole "
             f"benchmark must finish in 30 min, so only the smaller sizes are run in full and every size is also "
             f"**extrapolated** the same way: `bench/perf_rows.rs` (mode `{ts['mode']}`, which "
             f"builds the job of `--preset fast --top-k {k}` through the library, as `compute` does) "
             f"times {rows_timed} rows spread evenly over the matrix (row k·n/{rows_timed}) on 2 threads and scales "
             f"the measured time by n / {rows_timed}. It runs the same row engine as `compute` but not the service "
             "around it (I/O master, compression, writing: small for top-k files, see section 3). The sizes that "
             "were also run in full show the extrapolation error (last columns; CPU = user + system seconds, "
             "the full run's including its I/O master and writer). Set-up = loading the scene, subdividing it, "
             "building the Bvh and the engine, as both tools report it; it is not in the wall column. F⁰ "
             "evaluations per row = candidates j facing patch i whose unoccluded form factor was computed; "
             "pairs with rays = those that cast visibility rays (the candidates visited before the bound stops "
             "plus the sampled tail). CPU per F⁰ evaluation = CPU / (n · F⁰ evaluations per row), everything "
             "included (rays, sorting).\n")
    rows = []
    for x in sorted(full + sampled, key=lambda x: (x["n"], x["kind"] == "sampled")):
        ext = x["kind"] == "sampled"
        rows.append([x["n"],
                     f"extrapolated from {x['rows']} of {x['n']} rows" if ext else "no: full run, all rows",
                     x["wall"], x["cpu"], x.get("sample_wall", float("nan")) if ext else x["wall"],
                     x["setup"], x.get("pairs_per_row", float("nan")), x.get("rays_pairs_per_row", float("nan")),
                     x["cpu"] / (x["n"] * x["pairs_per_row"]) * 1e6 if ext else float("nan"),
                     f"{x['wall_err']:+.1%}" if "wall_err" in x else "",
                     f"{x['cpu_err']:+.1%}" if "cpu_err" in x else "", x["load"], f"`{x['cmd']}`"])
    L.append(table(["n", "extrapolated?", "wall [s]", "CPU [s]", "measured wall [s]", "set-up [s]",
                    "F⁰ evaluations / row", "pairs with rays / row", "CPU per F⁰ evaluation [µs]", "wall vs full run", "CPU vs full run",
                    "load avg", "command"], rows) + "\n")
    def kilo(n: int) -> str:
        return f"{n / 1000:.3g}k" if n >= 1000 else str(n)

    local = ", ".join(f"{kilo(a)}→{kilo(b)}: n^{e:.2f}" for a, b, e in ts["local_cpu"])
    first = sampled[0]
    per_eval = [x["cpu"] / (x["n"] * x["pairs_per_row"]) * 1e6 for x in sampled]
    rays_growth = big["rays_pairs_per_row"] / first["rays_pairs_per_row"]
    if rays_growth > 1.5:
        rays_text = (f"The pairs with rays per row grow too ({first['rays_pairs_per_row']:.0f} at n = {first['n']}, "
                     f"{big['rays_pairs_per_row']:.0f} at n = {big['n']}, while n grew ×{big['n'] / first['n']:.1f}), "
                     "though they stay a fraction of the F⁰ evaluations: as patches shrink, more candidates have an "
                     "F⁰ close to the k-th kept value, so more of them get their visibility before the bound stops.")
    else:
        rays_text = (f"The pairs with rays per row do not grow with n ({first['rays_pairs_per_row']:.0f} at "
                     f"n = {first['n']}, {big['rays_pairs_per_row']:.0f} at n = {big['n']}): the bound does limit "
                     "the ray tracing to about k + tail pairs per row.")
    L.append(f"Fitted exponent, top-k {k}, least squares on log-log over the {len(sampled)} extrapolated points "
             f"({sampled[0]['n']}–{big['n']} patches): **wall ∝ n^{ts['exponent_wall']:.2f}, CPU ∝ "
             f"n^{ts['exponent_cpu']:.2f}**; between consecutive sizes (CPU) {local}. Dense, same preset "
             f"(table above, full runs, {min(x['n'] for x in res['scaling'])}–{max(x['n'] for x in res['scaling'])} "
             f"patches): wall ∝ n^{res['scaling_exponent']:.2f} (2 threads), CPU ∝ n^{res['scaling_exponent_cpu']:.2f} "
             "(1 thread).\n")
    L.append(f"**How top-k grows**: `--top-k` runs the tree search by default (`--top-k-search tree`, "
             "src/formfactor/engine/topk_tree.rs): a hierarchy over the patches bounds the unoccluded form factor "
             "of whole nodes, so a row evaluates only the columns of the nodes whose bound can still enter its top "
             "k, not every facing column; the kept entries are bitwise those of evaluating every column "
             "(`--top-k-search exhaustive`, which grew as n², bench/PERF.md §16). F⁰ evaluations per row: "
             f"{first['pairs_per_row']:.0f} at n = {first['n']}, {big['pairs_per_row']:.0f} at n = {big['n']} "
             f"(×{big['pairs_per_row'] / first['pairs_per_row']:.1f} while n grew ×{big['n'] / first['n']:.1f}; "
             "they include the sampled tail's walks). The measured CPU per F⁰ evaluation, everything included, is "
             f"between {min(per_eval):.2f} and {max(per_eval):.2f} µs. " + rays_text + " What remains above linear "
             "is these pairs with rays and the evaluations near each row's patch; visibility decided for whole "
             "nodes is the next step (issue 19 item 6).\n")
    return "\n".join(L)


def write_results(res: dict, path: str, plot_note: list[str], command: str) -> None:
    m = res["meta"]
    L = []
    L.append("# ffstream benchmark results\n")
    L.append(f"Produced by `{command}` (bench/run.py) on {m['date']}; machine: {m['cores']} cores, "
             f"CPU `{m['cpu']}`; ffstream commit `{m['commit']}`. Load average at start "
             f"{m['load_start'][0]:.2f}, at end {m['load_end'][0]:.2f} (the machine is shared: timings are "
             f"noisy, compare ratios within this run). Total wall time of this run: {m['total_wall'] / 60:.1f} min.\n")
    L.append("Every `ffstream` command below was run from the scratch directory `bench/out/`; `wall` is the "
             "compute wall time printed by `ffstream compute` (service start to file closed, scene loading "
             "excluded). All commands of the run, with process wall times, are listed in "
             "`bench/out/commands.log` (not committed).\n")
    for note in plot_note:
        L.append(f"**Note:** {note}\n")
    L.append("Plots: [plots/pareto.png](plots/pareto.png), [plots/scaling.png](plots/scaling.png).\n")
    L.append("![time vs error](plots/pareto.png)\n")

    # ---- 1a
    L.append("## 1. Time vs error\n")
    L.append("### 1a. Analytic cases (Howell C-11, C-14)\n")
    L.append("Group-to-group factors F_IJ = Σ_i (A_i/A_I) Σ_j F_ij computed from each file with "
             "`formats/ffz.py` (top-k files: kept entries scaled so no light is lost, as the solver does), "
             "against Howell C-11 (parallel) and C-14 (perpendicular) evaluated in `bench/analytic.py`. "
             "Before use the formulas were checked against every tabulated value of docs/known-answers.md §2, §3 "
             f"(largest deviation {max(x[3] for x in res['howell']):.1e}, within the tables' printed digits). "
             "Error = largest |F_IJ − analytic| over the group pairs of the case (cube: all 30 ordered pairs). "
             "Row-sum column: closed cube only, max |Σ_j F_ij + dropped_i − 1|.\n")
    rows = [[x["case"], x["label"], x["n"], x["wall"], x["err"], x["rowsum"], f"`{x['cmd']}`"] for x in res["analytic"]]
    L.append(table(["case", "method", "n", "wall [s]", "max abs error", "row-sum error", "command"], rows) + "\n")
    # ---- 1b
    o = res["obstructed_ref"]
    L.append("### 1b. Obstructed plates (`builtin:obstructed`)\n")
    L.append(f"Reference F_bottom→top = **{o['ref']:.10f}**: the unit plates' Howell C-11 value minus the "
             f"point-to-rectangle integral of the blocker's shadow, in closed form, which the independent "
             f"discontinuity-meshing quadrature of `tests/reference/occluded_ff.py` reproduces to 2e-17 "
             f"(`tests/data/occluded_refs.json`, docs/known-answers.md §8). Cross-check: `mc` with "
             f"{o['mc_s']} samples per pair, seeds 0, 1, 2, at {o['mc_n']} target patches: "
             f"{o['mc']:.6f} ± {o['mc_se']:.1e} (difference {abs(o['ref'] - o['mc']):.1e}).\n")
    L.append("Cross-check commands: " + "; ".join(f"`{c}`" for c in o["mc_cmds"]) + "\n")
    rows = [[x["label"], x["n"], x["wall"], f"{x['value']:.6f}", x["err"], f"`{x['cmd']}`"] for x in res["obstructed"]]
    L.append(table(["method", "n", "wall [s]", "F_bottom→top", "abs error", "command"], rows) + "\n")
    L.append("Error against patch size, the default (16 rays per pair) and `--visibility exact` "
             "([plots/obstructed_sizes.png](plots/obstructed_sizes.png)):\n")
    rows = [[x["edge"], x["curve"], x["n"], x["wall"], f"{x['value']:.10f}", x["err"], f"`{x['cmd']}`"]
            for x in res["obstructed_sizes"]]
    L.append(table(["max edge", "visibility", "n", "wall [s]", "F_bottom→top", "abs error", "command"], rows) + "\n")
    # ---- 1c
    c = res["cornell"]
    L.append("### 1c. Cornell box radiosity, refinement levels\n")
    L.append(f"Per-group area-averaged B (r, g, b) from `ffstream solve` (Gauss–Seidel, tolerance 1e-6) against "
             f"the most refined solution: {c['ref_n']} patches, contour accurate (`{c['ref_cmd']}` then "
             f"`{c['solve_cmd']}`, compute wall {c['ref_wall']:.1f} s). Error = largest relative difference over "
             "groups (light excluded) and channels; it mixes discretisation and form-factor error. "
             "Wall = compute only (`--rows needed`, as `ffstream run` does); the solve column is the process "
             "wall time of `ffstream solve`.\n")
    rows = [[x["curve"], x["n"], x["wall"], x["solve_wall"], x["err"], f"`{x['cmd']}`"] for x in c["rows"]]
    L.append(table(["method", "n", "compute wall [s]", "solve wall [s]", "max rel. error", "command"], rows) + "\n")
    groups = sorted(c["bref"])
    L.append(f"Reference per-group B at {c['ref_n']} patches:\n")
    L.append(table(["group", "B_r", "B_g", "B_b"], [[g] + [float(v) for v in c["bref"][g]] for g in groups]) + "\n")
    # ---- recommendation
    L.append("### Recommended default\n")
    L.append(recommendation(res) + "\n")

    # ---- 2
    L.append("## 2. Scaling\n")
    L.append(f"**This machine has {m['cores']} cores**: beyond 2 compute threads there is no hardware to scale "
             "onto, so `mpirun -n 4` (3 workers) measures oversubscription, not speed-up. MPI runs use "
             "`mpirun -n P --oversubscribe` with OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1, one "
             "compute thread per worker rank (`--threads 1`) so compute threads = workers; rank 0 is the I/O "
             "master and computes nothing. Scene: `builtin:room` (16 boxes), preset fast. Efficiency = "
             "T(1 thread) / (p · T(p)), p = compute threads. The machine is shared (see the 1-minute load "
             "average column, taken after each run): when it exceeds 2, wall times say more about the other "
             "jobs than about ffstream. The CPU columns (user + system seconds of all processes of the run, "
             "GNU time) measure the work done, which load changes much less (though not nothing: other jobs "
             "sharing the 2 virtual cores and their caches have moved it by tens of percent here): "
             "CPU / CPU(1 thread) close to 1 "
             "means no parallel overhead (no duplicated work, no busy waiting), whatever the wall time.\n")
    rows = []
    t1 = {x["n"]: x["wall"] for x in res["scaling"] if x["config"] == "embedded --threads 1"}
    c1 = {x["n"]: x["cpu"] for x in res["scaling"] if x["config"] == "embedded --threads 1"}
    for x in res["scaling"]:
        eff = t1[x["n"]] / (x["p"] * x["wall"])
        rows.append([x["config"], x["n"], x["wall"], eff, x["cpu"], x["cpu"] / c1[x["n"]], x["load"], x["idle"],
                     x["master_rss"], f"`{x['cmd']}`"])
    L.append(table(["configuration", "n", "wall [s]", "efficiency", "CPU [s]", "CPU / CPU(1 thread)", "load avg",
                    "rank 0 idle", "rank 0 peak RSS [MB]", "command"], rows) + "\n")
    t = res["scaling_topk"]
    L.append(f"Fitted exponent of wall time vs n (embedded, 2 threads, least squares on log-log): "
             f"**time ∝ n^{res['scaling_exponent']:.2f}**; from the CPU time of the 1-thread runs (less sensitive to "
             f"load): **n^{res['scaling_exponent_cpu']:.2f}** (computing all n² pairs is quadratic at best; "
             f"fixed start-up costs pull the exponent down at small n).\n")
    L.append(topk_series_text(res))
    c = res["topk_vs_dense"]
    L.append(f"Top-k 64 against dense at n = {c['n']} (same preset): stored + dropped row sums minus dense row sums: "
             f"mean {c['mean_signed']:.1e}, mean |·| {c['mean_abs']:.1e}, max |·| {c['max_abs']:.1e} (the dropped mass "
             f"of the tree search is evaluated in full when a row's tail holds at most 2t patches, else estimated from "
             f"t sampled points: 128 with the fast preset, 256 with accurate; see the cube top-k rows of 1a and "
             f"bench/PERF.md §16). Top-k wall {c['wall']:.1f} s vs dense "
             + ", ".join(f"{x['wall']:.1f} s" for x in res['scaling'] if x['n'] == c['n'] and x['config'] == 'embedded --threads 2')
             + f": `{c['cmd']}`\n")
    L.append("![scaling](plots/scaling.png)\n")

    # ---- 3
    L.append("## 3. I/O and memory\n")
    L.append("Rank 0 idle fraction, throughput and compression of the scaling runs (dense, preset fast) and the "
             "top-k run. Throughput = bytes / compute wall (raw = uncompressed row bytes).\n")
    rows = []
    for x in res["scaling"]:
        if x["config"] != "embedded --threads 2":
            continue
        rows.append(["dense", x["n"], x["wall"], x["idle"], x["raw_mb"] / x["wall"], x["disk_mb"] / x["wall"],
                     x["ratio"], x["disk_mb"], f"`{x['cmd']}`"])
    rows.append([f"top-k {t['k']}", t["n"], t["wall"], t["idle"], t["raw_mb"] / t["wall"], t["disk_mb"] / t["wall"],
                 t["ratio"], t["disk_mb"], f"`{t['cmd']}`"])
    for x in res["io"]:
        if x["mode"] == "streaming":
            rows.append(["dense, point", x["n"], x["wall"], x["idle"], x["raw_mb"] / x["wall"], x["disk_mb"] / x["wall"],
                         x["ratio"], x["disk_mb"], f"`{x['cmd']}`"])
    L.append(table(["layout", "n", "wall [s]", "rank 0 idle", "raw MB/s", "disk MB/s", "compression", "file MB", "command"], rows) + "\n")
    dense = [x for x in res["scaling"] if x["config"] == "embedded --threads 2"]
    if dense:
        d = dense[-1]
        L.append(f"File size: dense f32 would be 4·n² bytes = {4 * d['n'] ** 2 / 1e6:.1f} MB at n = {d['n']} "
                 f"(file {d['disk_mb']:.1f} MB); top-k {t['k']} stores ~ n·k entries: n·k·8 bytes = "
                 f"{t['n'] * t['k'] * 8 / 1e6:.1f} MB raw at n = {t['n']} (file {t['disk_mb']:.2f} MB, "
                 f"{t['raw_mb']:.2f} MB raw).\n")
    L.append("### Streaming vs `--gather` (the paper's design)\n")
    L.append("Cluttered room (`builtin:room:64` full, `:32` quick), `--method point` (1 ray per pair: the cheapest "
             "kernel, so I/O and memory dominate), embedded mode with 2 threads: one process, so its peak RSS "
             "(VmHWM from /proc, the figure `/usr/bin/time -v` reports) covers the I/O master, the workers and, "
             "with `--gather`, the dense f64 matrix (8·n² bytes). Peak anonymous = largest RssAnon seen when "
             "sampling /proc/PID/status every 20 ms (heap only, no file pages).\n")
    rows = [[x["mode"], x["n"], x["wall"], x["process_wall"], x["process_rss"], x["anon"], x["master_rss"],
             8 * x["n"] ** 2 / 1e6, x["disk_mb"], f"`{x['cmd']}`"] for x in res["io"]]
    L.append(table(["mode", "n", "compute wall [s]", "process wall [s]", "process peak RSS [MB]", "peak anonymous [MB]",
                    "summary peak RSS [MB]", "8·n² [MB]", "file MB", "command"], rows) + "\n")
    L.append("### Solver memory vs file size\n")
    L.append("`ffstream solve` (Gauss–Seidel, rows read in file order through the memory map; tolerance 1e-4 to keep "
             "it short) on the streaming files above. Peak RSS counts the resident pages of the memory-mapped file "
             "that the kernel has not yet dropped, so it tracks the file size without the solver holding the "
             "matrix; the anonymous column (RssAnon, sampled every 20 ms) is the solver's own memory.\n")
    rows = [[x["n"], x["file_mb"], x["raw_mb"], x["rss"], x["anon"], x["file"], x["wall"], f"`{x['cmd']}`"]
            for x in res["io_solve"]]
    L.append(table(["n", "file MB", "raw row MB", "solve peak RSS [MB]", "peak anonymous [MB]", "peak file-backed [MB]",
                    "solve wall [s]", "command"], rows) + "\n")

    # ---- 4
    L.append("## 4. Peers\n")
    p = res.get("peers", {})
    if "error" in p:
        L.append(f"pyviewfactor was not run: {p['error']}.\n")
    else:
        L.append(f"pyviewfactor {p['version']} (`compute_viewfactor_matrix`, its SA-30 semi-analytic kernel, "
                 "numba-parallel) on exactly the patches of the ffstream file (one polygon cell per patch), "
                 "same machine, same group-to-group error measure. Its first call includes numba compilation; "
                 "the second call is the one compared. ffstream: contour, accurate preset, 2 threads.\n")
        rows = [[x["case"], x["n"], x["ff_wall"], x["ff_err"], x["pvf_wall"], x["pvf_first"], x["pvf_err"],
                 f"`{x['cmd']}`"] for x in p["rows"]]
        L.append(table(["case", "n", "ffstream wall [s]", "ffstream error", "pyviewfactor wall [s]",
                        "pyviewfactor 1st call [s]", "pyviewfactor error", "ffstream command"], rows) + "\n")
    L.append("OpenFOAM `viewFactorsGen` was not run (not installed; not trivial to set up here).\n")

    # ---- checks
    L.append("## 5. Kernel modes at the paper's largest mesh and beyond (issue 6)\n")
    m = res["modes"]
    L.append("Cluttered room (`builtin:room`, 16 boxes, 188 occluder triangles), accurate preset, 2 threads. "
             "Wall and CPU seconds and rays are extrapolated to the whole matrix from an evenly spread sample of "
             "rows timed by `bench/perf_rows.rs` (the row engine alone: no file, no master; `symmetric` times the "
             "half row each worker computes); errors are against exact visibility to 1e-3 of each entry's unoccluded value "
             "(`--ref-mode exact1e-3r1024`: 1024 rays for the pairs with more than 32 candidate occluders) on "
             "random rows: largest entry difference, largest row-sum "
             "difference, mean |ΔF| per entry. The machine has 2 cores and may be shared (load column): CPU "
             "seconds are the steadier figure.\n")
    L.append(table(["n", "mode", "what", "wall [s]", "CPU [s]", "rays", "far-field %", "no-ray %", "max abs err",
                    "max row-sum err", "mean abs err", "rows timed / checked", "load", "command"],
                   [[x["n"], x["mode"], MODE_FLAGS.get(x["mode"], ""), fmt(x["wall"]), fmt(x["cpu"]), fmt(x["rays"]),
                     f"{x['far']:.1f}", f"{x['noray']:.1f}", fmt(x["max_abs"]), fmt(x["rowsum"]), fmt(x["mean_abs"]),
                     f"{x['timed']} / {x['ref']}", f"{x['load']:.1f}", f"`{x['cmd']}`"] for x in m["rows"]]) + "\n")
    L.append("The whole service (`ffstream compute`, embedded, 2 threads: merge of half rows at the I/O master "
             "included), issue 6's target being 15 s wall for ~8.5k patches on 2 cores:\n")
    L.append(table(["mode", "n", "wall [s]", "CPU [s]", "load", "command"],
                   [[x["mode"], x["n"], fmt(x["wall"]), fmt(x["cpu"]), f"{x['load']:.1f}", f"`{x['cmd']}`"]
                    for x in m["real"]]) + "\n")
    walls = sorted(x["wall"] for x in m["real"] if x["mode"].startswith("half"))
    if walls:
        L.append(f"Default (half rows), {len(walls)} run(s): best {walls[0]:.2f} s, median "
                 f"{walls[len(walls) // 2]:.2f} s wall.\n")
    L.append("Profile, gap and next steps: [PERF.md](PERF.md) sections 1, 6, 7 and 8.\n")
    L.append("## Checks made by this run\n")
    L.append(table(["check", "result", "detail"], [[n, "ok" if ok else "FAILED", d] for n, ok, d in res["checks"]]) + "\n")
    with open(path, "w") as fh:
        fh.write("\n".join(L))


def recommendation(res: dict) -> str:
    an = {}
    ncases = len({x["case"] for x in res["analytic"]})
    for x in res["analytic"]:
        a = an.setdefault(x["label"], {"wall": 0.0, "err": 0.0, "cases": 0})
        a["wall"] += x["wall"]
        a["err"] = max(a["err"], x["err"])
        a["cases"] += 1
    an = {k: v for k, v in an.items() if v["cases"] == ncases}  # configurations run on every case
    obs = {x["label"]: x for x in res["obstructed"]}
    cb = {}
    for x in res["cornell"]["rows"]:
        cb.setdefault(x["curve"], []).append(x)
    acc = an.get("contour accurate")
    unc = res["obstructed_ref"]["unc"]
    lines = []
    if acc:
        lines.append(f"`contour` with the `accurate` preset (the binary's default): analytic cases in {acc['wall']:.2f} s "
                     f"total, max error {acc['err']:.1e} (target 1e-5: {'met' if acc['err'] <= 1e-5 else 'NOT met'}); "
                     f"obstructed plates {obs['contour accurate']['wall']:.2f} s, error "
                     f"{obs['contour accurate']['err']:.1e} (reference uncertainty ±{unc:.1e}); Cornell box at "
                     + ", ".join(f"{x['n']} patches {x['wall']:.1f} s / {x['err']:.1e}" for x in cb.get("contour accurate", []))
                     + ".")
    ok = [(v["wall"], k) for k, v in an.items() if v["err"] <= 1e-5]
    if ok:
        lines.append(f" Cheapest configuration meeting 1e-5 on every analytic case here: `{min(ok)[1]}` "
                     f"({min(ok)[0]:.2f} s). `point` and `mc` never reach 1e-5 at these patch counts: their error "
                     f"is {an['point']['err']:.1e} (point) and {an['mc S=256']['err']:.1e} (mc S=256).")
    both = [(v["wall"] + obs[k]["wall"], k) for k, v in an.items()
            if v["err"] <= 1e-5 and k in obs and obs[k]["err"] <= max(1e-5, unc)]
    if acc and obs["contour accurate"]["err"] > max(1e-5, unc):
        lines.append(f"\n\n**With occlusion the default misses the 1e-5 target**: on the obstructed plates `contour "
                     f"accurate` is off by {obs['contour accurate']['err']:.1e}, while `contour fast` (4 rays, no early "
                     f"stop possible) gets {obs['contour fast']['err']:.1e} and `contour reference` (exact visibility) "
                     f"{obs['contour reference']['err']:.1e}.")
        if max(obs["contour fast"]["err"], obs["contour reference"]["err"]) < obs["contour accurate"]["err"]:
            lines.append(" Both presets without an early stop do better, which points at the early-stop bias "
                         "documented in src/formfactor/visibility.rs (a first batch of 4 rays that all agree ends "
                         "the pair).")
    if both:
        w, k = min(both)
        lines.append(f" Cheapest configuration within 1e-5 (or the reference uncertainty) on the analytic cases "
                     f"**and** the obstructed plates: **`{k}`** ({an[k]['wall']:.2f} s analytic, "
                     f"{obs[k]['wall']:.2f} s obstructed, errors {an[k]['err']:.1e} / {obs[k]['err']:.1e}).")
    return "".join(lines)


# --------------------------------------------------------------------------- main


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny sizes, output in bench/out-quick/, non-zero exit on failure")
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "ffstream"), help="ffstream binary")
    ap.add_argument("--out", help="output directory for RESULTS.md and plots (default: bench/ full, bench/out-quick/ quick)")
    ap.add_argument("--sections", default="1,2,3,4,5", help="comma-separated sections to run (default all)")
    args = ap.parse_args()
    if not os.path.exists(args.bin):
        print(f"run.py: {args.bin} not found: run `cargo build --release` first", file=sys.stderr)
        return 2
    t_start = time.perf_counter()
    out_dir = args.out or (os.path.join(HERE, "out-quick") if args.quick else HERE)
    os.makedirs(out_dir, exist_ok=True)
    work = os.path.join(out_dir, "scratch") if args.quick or args.out else os.path.join(HERE, "out")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    r = Runner(os.path.abspath(args.bin), os.path.abspath(work))
    res: dict = {"meta": machine_info(args.bin)}
    sections = {"1": section_time_error, "2": section_scaling, "3": section_io, "4": section_peers,
                "5": section_modes}
    wanted = [s.strip() for s in args.sections.split(",")]
    errors = []
    for s in wanted:
        try:
            sections[s](r, args.quick, res)
        except CheckFailed as e:
            errors.append(str(e))
        except Exception as e:  # a failed run: record it, keep going, exit non-zero
            errors.append(f"section {s}: {type(e).__name__}: {e}")
            traceback.print_exc()
    res["checks"] = r.checks
    res["meta"]["load_end"] = os.getloadavg()
    res["meta"]["total_wall"] = time.perf_counter() - t_start
    command = "python3 bench/run.py" + (" --quick" if args.quick else "") + (
        f" --sections {args.sections}" if args.sections != "1,2,3,4,5" else "")
    notes = []
    if not errors and set(wanted) == {"1", "2", "3", "4", "5"}:  # every section ran (checks may fail)
        notes = make_plots(res, os.path.join(out_dir, "plots"))
        write_results(res, os.path.join(out_dir, "RESULTS.md"), notes, command)
        print(f"wrote {os.path.join(out_dir, 'RESULTS.md')}")
    elif not errors:
        print("partial run (--sections): RESULTS.md not written")
    failed = [c for c in r.checks if not c[1]]
    for c in failed:
        errors.append(f"check failed: {c[0]}: {c[2]}")
    print(f"total wall time {res['meta']['total_wall'] / 60:.1f} min")
    if errors:
        print("\nFAILED:\n  " + "\n  ".join(errors), file=sys.stderr)
        return 1
    print("all runs succeeded, all checks hold")
    return 0


if __name__ == "__main__":
    sys.exit(main())
