#!/usr/bin/env python3
"""Compare View3D and ffstream form-factor matrices of the same facets.

    python3 compare.py --obj FACETS.obj --times times.json \
        --v3d v3d-default=v3d_default.bin --v3d v3d-tight=v3d_tight.bin \
        --ffz ff-default=ff_default.ffz --ffz ff-exact1e-2=ff_exact.ffz --ffz ff-ref=ff_ref.ffz \
        --ref ff-ref --ref v3d-tight [--footprints] [--mc mc.npz] [--out table.md]

Inputs
- View3D output in its binary format (out=1, savevf.c SaveF1): a 32-byte text header
  "View3D 4.0.0 out encl emit N", then N float32 areas, then N rows of N float32
  F(n, m) (row n = emitter, column m; View3D computes A_n F_nm once per pair, m < n,
  and writes F_nm = AF/A_n and F_mn = AF/A_m: reciprocal by construction), then N
  float32 emissivities. The text format (out=0) is read too (it rounds to 1e-6).
  Surface k is facet k-1.
- .ffz files (formats/ffz.py): row i = patch i = facet i (checked: same count, each
  patch's corners are its face's vertices), F_ij float32. Rows marked skipped (a
  sampled reference made with --rows needed) are left out of every statistic that
  involves that file.
- times.json from timed.py: CPU s (user + system) of each run; for a run of sampled
  rows also the CPU extrapolated to all rows.

Both tools give F_ij with row i the emitter, so no conversion beyond the reading.

Printed: one table, each setting's CPU and, against each reference, the mean row L1
error (sum_j |F_ij - R_ij| averaged over the reference's rows), the largest entry
error and the largest row-sum error; the two references against each other; the
largest row sum of each run (the scene is open to the sky: rows sum below 1, the rest
is sky view; above 1 is an error); and the rows where the two references disagree
most. --footprints (box cities such as builtin:city): ground facets (group `ground`)
that overlap the x-z footprint of a building (another group) are marked and the errors
are also given with their rows and columns left out.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from obj2vs3 import read_obj  # noqa: E402


def read_view3d(path):
    with open(path, "rb") as fh:
        b = fh.read()
    head = b[:32].decode("ascii", "replace").split()
    if len(head) < 6 or head[0] != "View3D":
        raise SystemExit(f"compare: {path}: not a View3D output file")
    out_fmt, n = int(head[2]), int(head[5])
    if int(head[4]) != 0:
        raise SystemExit(f"compare: {path}: written with emit=1 (script-F factors), not view factors")
    if out_fmt == 1:
        a = np.frombuffer(b, dtype="<f4", offset=32)
        if a.size != n * (n + 2):
            raise SystemExit(f"compare: {path}: {a.size} floats, expected {n * (n + 2)}")
        area = a[:n].astype(float)
        F = a[n:n + n * n].reshape(n, n).astype(float)
    elif out_fmt == 0:
        lines = b.decode().splitlines()
        area = np.array(lines[1].split(), float)
        F = np.array([l.split() for l in lines[2:2 + n]], float)
    else:
        raise SystemExit(f"compare: {path}: sparse format (out=2) not read here; use out=1")
    return area, F


def read_ffz(path):
    import ffz
    f = ffz.open(path)
    F = f.to_csr().toarray().astype(float)
    present = np.asarray(f.presence) == 1
    return f, F, present


def stats(T, R, rows, cols=None):
    """Mean row L1 error, largest entry error, largest row-sum error of T against R."""
    if cols is None:
        T2, R2 = T[rows], R[rows]
    else:
        T2, R2 = T[np.ix_(rows, cols)], R[np.ix_(rows, cols)]
    if T2.size == 0:
        return float("nan"), float("nan"), float("nan")
    d = np.abs(T2 - R2)
    return d.sum(1).mean(), d.max(), np.abs(T2.sum(1) - R2.sum(1)).max()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--obj", required=True, help="the facets given to both tools")
    ap.add_argument("--times", default=None)
    ap.add_argument("--v3d", action="append", default=[], metavar="NAME=PATH")
    ap.add_argument("--ffz", action="append", default=[], metavar="NAME=PATH")
    ap.add_argument("--ref", action="append", default=[], metavar="NAME",
                    help="reference run (one or two)")
    ap.add_argument("--footprints", action="store_true")
    ap.add_argument("--mc", default=None, help="mc_rows.py output, for the disagreement list")
    ap.add_argument("--worst", type=int, default=10)
    ap.add_argument("--worst-rows", default=None,
                    help="write the rows where the references disagree most here, one a line")
    ap.add_argument("--out", default=None, help="also write the report (markdown) here")
    a = ap.parse_args(argv)

    verts, faces = read_obj(a.obj)
    V = np.asarray(verts, float)
    n = len(faces)
    out = []

    def say(s=""):
        print(s)
        out.append(s)

    runs = {}   # name -> (F, present rows mask, kind)
    areas = None
    groups = None
    group_names = None
    for spec in a.ffz:
        name, path = spec.split("=", 1)
        f, F, present = read_ffz(path)
        if f.n != n:
            raise SystemExit(f"compare: {path}: {f.n} patches but {a.obj} has {n} faces: "
                             "ffstream subdivided (give it a --max-edge above every edge)")
        P = f.patches
        err = 0.0
        for k, (_, idx) in enumerate(faces):
            c = P["corners"][k][: P["n_corners"][k]]
            if len(idx) != len(c):
                raise SystemExit(f"compare: {path}: patch {k} has {len(c)} corners, face {len(idx)}")
            err = max(err, np.abs(c - V[idx]).max())
        if err > 1e-9 * max(1.0, np.abs(V).max()):
            raise SystemExit(f"compare: {path}: patch corners differ from the faces by {err:g}")
        if not np.array_equal(np.asarray(P["face"]), np.arange(n)):
            raise SystemExit(f"compare: {path}: patches are not the faces in order")
        areas = np.asarray(P["area"], float)
        groups = np.asarray(P["group"])
        group_names = list(f.groups)
        runs[name] = (F, present, "ffstream")
    for spec in a.v3d:
        name, path = spec.split("=", 1)
        ar, F = read_view3d(path)
        if len(ar) != n:
            raise SystemExit(f"compare: {path}: {len(ar)} surfaces but {a.obj} has {n} faces")
        if areas is not None:
            rel = np.abs(ar - areas).max() / areas.max()
            if rel > 1e-5:
                raise SystemExit(f"compare: {path}: surface areas differ from the patches' ({rel:.1e})")
        runs[name] = (F, np.ones(n, bool), "View3D")
    if areas is None:
        areas = runs[next(iter(runs))][0] * 0  # unused
    times = json.load(open(a.times)) if a.times and os.path.exists(a.times) else {}
    refs = a.ref[:2]
    for r in refs:
        if r not in runs:
            raise SystemExit(f"compare: reference {r} not among the runs")

    # facets of the ground under a footprint
    under = np.zeros(n, bool)
    if a.footprints and groups is not None and "ground" in group_names:
        g0 = group_names.index("ground")
        fps = []
        for gi in range(len(group_names)):
            if gi == g0 or not (groups == gi).any():
                continue
            pts = np.concatenate([V[faces[k][1]] for k in np.where(groups == gi)[0]])
            fps.append((pts[:, 0].min(), pts[:, 0].max(), pts[:, 2].min(), pts[:, 2].max()))
        for k in np.where(groups == g0)[0]:
            p = V[faces[k][1]]
            x0, x1, z0, z1 = p[:, 0].min(), p[:, 0].max(), p[:, 2].min(), p[:, 2].max()
            for (a0, a1, b0, b1) in fps:
                if min(x1, a1) - max(x0, a0) > 1e-9 and min(z1, b1) - max(z0, b0) > 1e-9:
                    under[k] = True
                    break

    say(f"facets: {n} ({a.obj}); references: "
        + ", ".join(f"{r} ({runs[r][1].sum()} rows)" for r in refs)
        + "; each comparison on the reference's rows")
    if a.footprints:
        say(f"ground facets overlapping a building footprint: {under.sum()}"
            + (" (their rows and columns are left out of the 'clean' columns)" if under.any() else ""))
    say()
    hdr = ["run", "CPU s"]
    for r in refs:
        hdr += [f"L1 vs {r}", f"max entry vs {r}", f"max row-sum vs {r}"]
    if under.any():
        hdr += [f"L1 vs {refs[0]}, clean"]
    hdr += ["max row sum"]
    say("| " + " | ".join(hdr) + " |")
    say("|" + "---|" * len(hdr))
    clean = np.where(~under)[0]
    for name, (F, present, kind) in runs.items():
        t = times.get(name, {})
        if "cpu_all_rows_s" in t:
            cpu = f"{t['cpu_s']:.1f} ({t['rows_computed']} rows; all ~{t['cpu_all_rows_s']:.0f})"
        elif "cpu_s" in t:
            cpu = f"{t['cpu_s']:.1f}"
        else:
            cpu = "-"
        row = [f"{kind} {name}", cpu]
        for r in refs:
            R, rp, _ = runs[r]
            rows = np.where(rp & present)[0]
            if r == name:
                row += ["(ref)", "", ""]
                continue
            l1, mx, rs = stats(F, R, rows)
            row += [f"{l1:.2e}", f"{mx:.2e}", f"{rs:.2e}"]
        if under.any():
            R, rp, _ = runs[refs[0]]
            rows = np.where(rp & present & ~under)[0]
            row += ["(ref)" if name == refs[0] else f"{stats(F, R, rows, clean)[0]:.2e}"]
        row += [f"{F[present].sum(1).max():.6f}"]
        say("| " + " | ".join(row) + " |")
    say()
    if a.times:
        for name in runs:
            t = times.get(name)
            if t:
                say(f"- {name}: `{' '.join(os.path.basename(c) if i == 0 else c for i, c in enumerate(t['cmd']))}`"
                    f" (wall {t['wall_s']:.1f} s, load {' '.join(t.get('loadavg_before') or [])}"
                    f" -> {' '.join(t.get('loadavg_after') or [])})")
        say()

    if len(refs) == 2:
        R1, p1, _ = runs[refs[0]]
        R2, p2, _ = runs[refs[1]]
        rows = np.where(p1 & p2)[0]
        d = np.abs(R1[rows] - R2[rows])
        l1 = d.sum(1)
        say(f"{refs[0]} against {refs[1]} on {len(rows)} rows: mean row L1 {l1.mean():.2e}, "
            f"median {np.median(l1):.2e}, largest entry {d.max():.2e}")
        if under.any():
            m = ~under[rows]
            dc = np.abs(R1[np.ix_(rows[m], clean)] - R2[np.ix_(rows[m], clean)])
            say(f"  without the ground facets under footprints (rows and columns): "
                f"mean row L1 {dc.sum(1).mean():.2e}, largest entry {dc.max():.2e}; "
                f"the rows of those facets alone: mean row L1 {l1[~m].mean() if (~m).any() else float('nan'):.2e}")
        mc = None
        if a.mc and os.path.exists(a.mc):
            z = np.load(a.mc)
            mc = {int(i): z["F"][k] for k, i in enumerate(z["rows"])}
            mc_rays = int(z["rays"])
        order = rows[np.argsort(-l1)][: a.worst]
        if a.worst_rows:
            with open(a.worst_rows, "w") as fh:
                fh.write("".join(f"{i}\n" for i in order))
        say(f"\nRows where the references disagree most (0-based facet = patch; View3D surface = +1):\n")
        cols = ["row", "group", "centroid", "normal", "area", f"L1 {refs[0]}-{refs[1]}",
                f"sum {refs[0]}", f"sum {refs[1]}", "worst column (F ref1 / ref2)"]
        if a.footprints:
            cols.insert(2, "under footprint")
        if mc:
            cols.append(f"MC sum ({mc_rays} rays)")
        say("| " + " | ".join(cols) + " |")
        say("|" + "---|" * len(cols))
        for i in order:
            p = V[faces[i][1]]
            c = p.mean(0)
            e1, e2 = p[1] - p[0], p[2] - p[1]
            nn = np.cross(e1, e2)
            nn = nn / np.linalg.norm(nn)
            j = int(np.argmax(np.abs(R1[i] - R2[i])))
            cells = [str(i), group_names[groups[i]] if group_names else "",
                     "(%.1f, %.1f, %.1f)" % tuple(c), "(%.0f, %.0f, %.0f)" % tuple(np.round(nn) + 0.0),
                     f"{areas[i]:.3g}", f"{np.abs(R1[i] - R2[i]).sum():.2e}",
                     f"{R1[i].sum():.5f}", f"{R2[i].sum():.5f}",
                     f"{j}: {R1[i, j]:.5f} / {R2[i, j]:.5f}"]
            if a.footprints:
                cells.insert(2, "yes" if under[i] else "no")
            if mc:
                if i in mc:
                    s = mc[i].sum()
                    cells.append(f"{s:.5f} ± {np.sqrt(s * (1 - s) / mc_rays):.5f}")
                else:
                    cells.append("")
            say("| " + " | ".join(cells) + " |")
        if mc:
            say(f"\nMonte Carlo rows ({mc_rays} rays each) against the references:\n")
            say("(L1 MC-ref is mostly the Monte Carlo's own noise, expected about the 'MC noise'"
                " column, sum_j sqrt(2 F_ij (1 - F_ij) / (pi rays)); the row sums are the test.)\n")
            say("| row | MC sum | MC noise | " + " | ".join(f"{r} sum | L1 MC-{r}" for r in refs) + " |")
            say("|---|---|---|" + "---|---|" * len(refs))
            for i, f in sorted(mc.items()):
                noise = np.sqrt(2 * f * (1 - f) / (np.pi * mc_rays)).sum()
                cells = [str(i), f"{f.sum():.5f}", f"{noise:.1e}"]
                for r in refs:
                    R, rp, _ = runs[r]
                    cells += ([f"{R[i].sum():.5f}", f"{np.abs(f - R[i]).sum():.2e}"] if rp[i]
                              else ["(row not computed)", ""])
                say("| " + " | ".join(cells) + " |")
    if a.out:
        with open(a.out, "w") as fh:
            fh.write("\n".join(out) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
