#!/usr/bin/env python3
"""Cut the ground of a box city (ffstream's builtin:city) around the building footprints.

    python3 cut_ground.py city.obj city_cut.obj [--ground GROUP]

ffstream's built-in city has one ground quad (y = 0, facing +y) running under every
building (the buildings have no floor). Ground facets that lie partly under a building
break View3D (see README.md / PERF.md "View3D on the same facets": View3D keeps, as view
obstructions, only faces whose front the radiating surface can see, so a part of a
surface inside a closed body is not shadowed by that body). uDALES never meshes the
ground under a building; this script writes the same city with the ground replaced by
axis-aligned rectangles covering the ground minus the footprints (the footprint of a
group = the x-z bounding box of its vertices; every non-ground group must be an
axis-aligned box standing on y = 0). The rectangles come from the x and z edges of the
footprints, merged greedily (along x in each z strip, then strips with the same
intervals); thin rectangles where two footprint edges nearly line up remain and are
reported. Everything else (vertices, faces, groups, materials) is copied unchanged.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("obj")
    ap.add_argument("out")
    ap.add_argument("--ground", default="ground", help="name of the ground group (default ground)")
    a = ap.parse_args(argv)

    lines = open(a.obj, encoding="utf-8").read().splitlines()
    verts = []
    group = None
    groups = {}  # group -> vertex indices of its faces
    ground_faces = []  # line numbers
    for n, line in enumerate(lines):
        p = line.split("#", 1)[0].split()
        if not p:
            continue
        if p[0] == "v":
            verts.append(tuple(float(x) for x in p[1:4]))
        elif p[0] == "g":
            group = " ".join(p[1:])
        elif p[0] == "f":
            idx = [int(s.split("/")[0]) for s in p[1:]]
            idx = [k - 1 if k > 0 else len(verts) + k for k in idx]
            if group == a.ground:
                ground_faces.append((n, idx))
            else:
                groups.setdefault(group, []).extend(idx)
    if len(ground_faces) != 1:
        sys.exit(f"cut_ground: error: expected one face in group {a.ground!r}, found {len(ground_faces)}")
    gl, gidx = ground_faces[0]
    G = [verts[i] for i in gidx]
    if any(abs(v[1]) > 1e-12 for v in G):
        sys.exit("cut_ground: error: the ground face is not in the plane y = 0")
    gx0, gx1 = min(v[0] for v in G), max(v[0] for v in G)
    gz0, gz1 = min(v[2] for v in G), max(v[2] for v in G)
    fps = []
    for g, idx in groups.items():
        P = [verts[i] for i in set(idx)]
        x0, x1 = min(v[0] for v in P), max(v[0] for v in P)
        z0, z1 = min(v[2] for v in P), max(v[2] for v in P)
        for v in P:  # a box: every vertex on the bounding box of its footprint
            if min(abs(v[0] - x0), abs(v[0] - x1), abs(v[2] - z0), abs(v[2] - z1)) > 1e-9:
                sys.exit(f"cut_ground: error: group {g!r} is not an axis-aligned box")
        if min(v[1] for v in P) > 1e-9:
            continue  # does not stand on the ground
        fps.append((x0, x1, z0, z1))

    def breaks(vals, lo, hi):
        out = []
        for v in sorted(set(vals) | {lo, hi}):
            if lo - 1e-9 <= v <= hi + 1e-9 and (not out or v - out[-1] > 1e-9):
                out.append(min(max(v, lo), hi))
        out[-1] = hi
        return out

    def decompose(fps, gx0, gx1, gz0, gz1):
        """Free rectangles (x0, x1, z0, z1): x intervals per z strip, strips merged."""
        xs = breaks([c for f in fps for c in f[:2]], gx0, gx1)
        zs = breaks([c for f in fps for c in f[2:]], gz0, gz1)

        def covered(x, z):
            return any(f[0] < x < f[1] and f[2] < z < f[3] for f in fps)

        strips = []
        for j in range(len(zs) - 1):
            zc = 0.5 * (zs[j] + zs[j + 1])
            ivs, cur = [], None
            for i in range(len(xs) - 1):
                free = not covered(0.5 * (xs[i] + xs[i + 1]), zc)
                if free and cur is None:
                    cur = xs[i]
                if not free and cur is not None:
                    ivs.append((cur, xs[i]))
                    cur = None
            if cur is not None:
                ivs.append((cur, xs[-1]))
            strips.append(ivs)
        rects = []
        open_ = {}  # (x0, x1) -> z0 of the rectangle growing upward
        for j, ivs in enumerate(strips):
            s = set(ivs)
            for iv in list(open_):
                if iv not in s:
                    rects.append((iv[0], iv[1], open_.pop(iv), zs[j]))
            for iv in ivs:
                open_.setdefault(iv, zs[j])
        for iv, z0 in open_.items():
            rects.append((iv[0], iv[1], z0, zs[-1]))
        return rects

    def thinness(rects):
        return min(min(r[1] - r[0], r[3] - r[2]) for r in rects)

    # strips along x and along z: keep the decomposition whose thinnest rectangle is thicker
    ra = decompose(fps, gx0, gx1, gz0, gz1)
    rb = [(r[2], r[3], r[0], r[1]) for r in
          decompose([(f[2], f[3], f[0], f[1]) for f in fps], gz0, gz1, gx0, gx1)]
    rects = ra if (thinness(ra), -len(ra)) >= (thinness(rb), -len(rb)) else rb
    rects.sort(key=lambda r: (r[2], r[0]))
    area = sum((r[1] - r[0]) * (r[3] - r[2]) for r in rects)
    want = (gx1 - gx0) * (gz1 - gz0) - sum((f[1] - f[0]) * (f[3] - f[2]) for f in fps)
    if abs(area - want) > 1e-6 * want:
        sys.exit(f"cut_ground: error: rectangles cover {area} instead of {want} (overlapping footprints?)")

    nv = len(verts)
    new_v = []
    new_f = []
    for (x0, x1, z0, z1) in rects:  # counter-clockwise seen from +y, as the input ground
        b = nv + len(new_v) + 1
        new_v += [(x0, 0.0, z0), (x0, 0.0, z1), (x1, 0.0, z1), (x1, 0.0, z0)]
        new_f.append(f"f {b} {b + 1} {b + 2} {b + 3}")
    out = []
    last_v = max(n for n, l in enumerate(lines) if l.startswith("v "))
    for n, line in enumerate(lines):
        if n == gl:
            out.extend(new_f)
            continue
        out.append(line)
        if n == last_v:
            out.extend(f"v {v[0]!r} {v[1]!r} {v[2]!r}" for v in new_v)
    with open(a.out, "w") as fh:
        fh.write("\n".join(out) + "\n")
    thin = thinness(rects)
    print(f"{a.out}: ground cut around {len(fps)} footprints into {len(rects)} rectangles "
          f"(area {area:.6g}; thinnest {thin:.3g})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
