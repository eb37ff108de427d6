#!/usr/bin/env python3
"""Per-surface radiosity of sparse rows against dense rows on the same mesh (issue 44).

Computes `builtin:room` (16 boxes, one ceiling light) at --patches N with dense rows,
with top-k rows whose dropped mass is pooled (`--links off`), and with top-k rows that
link to clusters (`--links M`, several M), solves each with the default solver and
prints, for each sparse variant, the worst surface (area-weighted mean radiosity of a
group, any of R, G, B) against the dense solve, the total radiosity power, the file size
and the compute wall time (all runs in one invocation, for A/B on one machine).

    python3 bench/links_room.py --patches 3000 [--top-k 64] [--links 64 256 1024]
                                [--baseline OTHER/ffstream]

With --baseline, each links variant is also computed by that other build (say, the
commit before a change), in the same run, against the same dense reference.
"""
import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
EXE = os.path.join(HERE, "..", "target", "release", "ffstream")


def groups(path):
    sums = {}
    with open(path) as fh:
        for r in csv.DictReader(fh):
            a = float(r["area"])
            s = sums.setdefault(r["group"], [0.0, 0.0, 0.0, 0.0])
            s[0] += a
            for c, ch in enumerate("rgb"):
                s[c + 1] += a * float(r["B_" + ch])
    return {k: (v[0], [x / v[0] for x in v[1:]]) for k, v in sums.items()}


def run(args, work, name, extra, exe=EXE):
    out = os.path.join(work, name + ".ffz")
    t = time.time()
    subprocess.run([exe, "compute", "builtin:room", "--patches", str(args.patches), "-q", "-o", out, *extra], check=True)
    wall = time.time() - t
    csv_path = os.path.join(work, name + ".csv")
    subprocess.run([EXE, "solve", out, "-q", "-o", csv_path], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out, groups(csv_path), wall


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--patches", type=int, default=3000)
    ap.add_argument("--top-k", type=int, default=64)
    ap.add_argument("--links", type=int, nargs="+", default=[64, 256, 1024])
    ap.add_argument("--baseline", metavar="EXE", help="another ffstream binary to compute each links variant with too")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as work:
        _, ref, wall = run(args, work, "dense", [])
        print(f"dense: {wall:.1f} s wall")
        power = lambda g: sum(a * sum(b) for a, b in g.values())
        variants = [("pool", ["--links", "off"], EXE)]
        for m in args.links:
            variants.append((f"links {m}", ["--links", str(m)], EXE))
            if args.baseline:
                variants.append((f"baseline links {m}", ["--links", str(m)], args.baseline))
        for name, extra, exe in variants:
            path, g, wall = run(args, work, name.replace(" ", "_"), ["--top-k", str(args.top_k), *extra], exe)
            worst, where = max((abs(g[k][1][c] / ref[k][1][c] - 1), k) for k in ref for c in range(3))
            print(f"{name}: worst surface {100 * worst:.1f} % ({where}), power {100 * (power(g) / power(ref) - 1):+.2f} %, "
                  f"file {os.path.getsize(path) / 1e6:.2f} MB, compute {wall:.1f} s wall")


if __name__ == "__main__":
    sys.exit(main())
