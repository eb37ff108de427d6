#!/usr/bin/env python3
"""Split every face of an OBJ into sub-faces with edges <= E, keeping groups and materials.

    python3 subdivide_obj.py IN.obj OUT.obj --max-edge E [--sample-every K --sample-mtl NAME]

Quads: a uniform nu x nv grid on the bilinear map of the quad (nu from the longer of
the two edges 0-1 / 3-2, nv from 0-3 / 1-2), so every sub-quad edge is at most E and a
planar convex quad gives planar convex sub-quads. Triangles: a uniform n-grid of n^2
similar sub-triangles (n = ceil(longest edge / E); n = 2^L is L rounds of midpoint
splits). Faces with more than 4 vertices are refused. Sub-faces keep the winding
(hence the front side) of their face, and are written in face order, each face's
sub-faces row by row, so the output face k is the same facet for every tool that keeps
faces as they are (obj2vs3.py, and ffstream with a --max-edge a little above E).

`g`, `o`, `usemtl`, `mtllib` and `s` lines are copied where they stand. With
--sample-every K, every K-th output face (faces 0, K, 2K, ... 0-based) is written
with material --sample-mtl and all the others with material `v3d_black` (Kd 0, Ke 0),
and a `v3d_sample.mtl` with both is written beside the output and named by mtllib
(for `ffstream compute --rows needed`, which then computes only the sampled rows:
the geometry, hence every form factor, is unchanged). The face count is printed.
"""

from __future__ import annotations

import argparse
import math
import os
import sys


def lerp(a, b, t):
    return (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t)


def dist(a, b):
    return math.sqrt(sum((a[i] - b[i]) ** 2 for i in range(3)))


def split_quad(p, e):
    nu = max(1, math.ceil(max(dist(p[0], p[1]), dist(p[3], p[2])) / e - 1e-9))
    nv = max(1, math.ceil(max(dist(p[0], p[3]), dist(p[1], p[2])) / e - 1e-9))
    grid = {}
    for j in range(nv + 1):
        a = lerp(p[0], p[3], j / nv)
        b = lerp(p[1], p[2], j / nv)
        for i in range(nu + 1):
            grid[i, j] = lerp(a, b, i / nu)
    verts = [grid[i, j] for j in range(nv + 1) for i in range(nu + 1)]
    vid = lambda i, j: j * (nu + 1) + i
    faces = [[vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)]
             for j in range(nv) for i in range(nu)]
    return verts, faces


def split_tri(p, e):
    n = max(1, math.ceil(max(dist(p[0], p[1]), dist(p[1], p[2]), dist(p[2], p[0])) / e - 1e-9))
    # barycentric grid: point (i, j) = p0 + i/n (p1 - p0) + j/n (p2 - p0), i + j <= n
    idx = {}
    verts = []
    for j in range(n + 1):
        for i in range(n + 1 - j):
            idx[i, j] = len(verts)
            u, v = i / n, j / n
            verts.append(tuple(p[0][k] + u * (p[1][k] - p[0][k]) + v * (p[2][k] - p[0][k])
                               for k in range(3)))
    faces = []
    for j in range(n):
        for i in range(n - j):
            faces.append([idx[i, j], idx[i + 1, j], idx[i, j + 1]])
            if i + j + 1 < n:
                faces.append([idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]])
    return verts, faces


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("obj")
    ap.add_argument("out")
    ap.add_argument("--max-edge", type=float, required=True)
    ap.add_argument("--sample-every", type=int, default=0)
    ap.add_argument("--sample-mtl", default="v3d_sample")
    a = ap.parse_args(argv)
    if not a.max_edge > 0:
        sys.exit("subdivide_obj: error: --max-edge must be > 0")

    verts = []
    out_v = []
    out_body = []
    nface = 0
    nsrc = 0
    with open(a.obj, encoding="utf-8", errors="replace") as fh:
        for lineno, raw in enumerate(fh, 1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            tag = parts[0]
            if tag == "v":
                verts.append(tuple(float(x) for x in parts[1:4]))
            elif tag == "f":
                idx = []
                for s in parts[1:]:
                    k = int(s.split("/")[0])
                    idx.append(k - 1 if k > 0 else len(verts) + k)
                if len(idx) not in (3, 4):
                    sys.exit(f"subdivide_obj: error: {a.obj}:{lineno}: face with {len(idx)} "
                             f"vertices (only triangles and quads are split)")
                p = [verts[i] for i in idx]
                sv, sf = (split_quad if len(p) == 4 else split_tri)(p, a.max_edge)
                base = len(out_v)
                out_v.extend(sv)
                nsrc += 1
                for f in sf:
                    if a.sample_every:
                        mtl = a.sample_mtl if nface % a.sample_every == 0 else "v3d_black"
                        out_body.append(f"usemtl {mtl}")
                    out_body.append("f " + " ".join(str(base + i + 1) for i in f))
                    nface += 1
            elif tag in ("g", "o", "s"):
                out_body.append(line)
            elif tag == "usemtl":
                if not a.sample_every:
                    out_body.append(line)
            elif tag == "mtllib":
                if not a.sample_every:
                    mtl = " ".join(parts[1:])
                    src = os.path.join(os.path.dirname(os.path.abspath(a.obj)), mtl)
                    dst = os.path.join(os.path.dirname(os.path.abspath(a.out)), mtl)
                    if os.path.exists(src) and not os.path.exists(dst):
                        with open(src) as s, open(dst, "w") as d:
                            d.write(s.read())
                    out_body.insert(0, line)
            # vt, vn, l, p and anything else: dropped
    with open(a.out, "w") as out:
        out.write(f"# {a.obj} split to edges <= {a.max_edge:g} by subdivide_obj.py: "
                  f"{nsrc} faces -> {nface}\n# counter-clockwise = front (kept from the input)\n")
        if a.sample_every:
            mtlname = "v3d_sample.mtl"
            with open(os.path.join(os.path.dirname(os.path.abspath(a.out)), mtlname), "w") as m:
                m.write(f"newmtl {a.sample_mtl}\nKd 0.5 0.5 0.5\nKe 1 1 1\n"
                        "newmtl v3d_black\nKd 0 0 0\nKe 0 0 0\n")
            out.write(f"mtllib {mtlname}\n")
        for v in out_v:
            out.write(f"v {v[0]!r} {v[1]!r} {v[2]!r}\n")
        out.write("\n".join(out_body) + "\n")
    print(f"{a.out}: {nface} faces (from {nsrc}, edges <= {a.max_edge:g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
