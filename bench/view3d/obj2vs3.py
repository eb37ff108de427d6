#!/usr/bin/env python3
"""Convert an OBJ mesh into a View3D (uDALES fork) input file (.vs3, geometry format F 3).

    python3 obj2vs3.py SCENE.obj OUT.vs3 [--eps 1e-4] [--maxU 12] [--maxO 8] [--minO 0]
                       [--out 1] [--row N] [--title TEXT]

Every OBJ face becomes one View3D surface, in file order: View3D's surface k is the
OBJ's k-th face, i.e. ffstream's patch k-1 when ffstream does not subdivide the face
(give ffstream a --max-edge above every face edge). Faces must have 3 or 4 vertices;
anything else is refused (split it first, e.g. with subdivide_obj.py for quads).

Surfaces are written as `S` (radiating) surfaces. View3D treats every radiating surface
as a possible view obstruction as well (test3d.c SetPosObstr3D: any surface with
vertices of other surfaces on both sides of its plane), so no separate `O` surfaces
are needed: every face both radiates and obstructs, as in ffstream.

Orientation: View3D wants the vertices "counter-clockwise as viewed from the front"
and the active side is the positive side by the right-hand rule (manual, section
"Surface Types"; the cube example's zeq0 = 1 2 3 4 faces +z, into the cube). That is
the OBJ convention (counter-clockwise = front), so the vertex order is kept.
`--reverse` flips every face (only for the convention check: two unit squares 1 apart
facing each other give F = 0.19982 with the order kept and 0 when flipped).

The control line: encl=0 (an open scene: no enclosure normalisation, which would
rescale rows to sum to 1), emit=0 (black surfaces: plain view factors), list=0, out=
output format (0 text %.6f, 1 binary float32 [default here: the text format rounds
every entry to 1e-6], 2 sparse text `i j F` with F >= 5e-7 and 6 decimals), eps =
adaptive-integration convergence (View3D default 1e-4; it warns below 1e-6), maxU /
maxO = max recursions of the unobstructed / obstructed integration (defaults 12 / 8;
4..12), minO = min obstructed recursions (default 0; 1-2 catches obstructions near
the edges of a view), row = compute one row only (0 = all).
"""

from __future__ import annotations

import argparse
import math
import sys


class ObjError(Exception):
    pass


def read_obj(path):
    """Vertices (list of (x, y, z)) and faces (list of (line number, [0-based indices]))."""
    verts = []
    faces = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        pending = ""
        for lineno, raw in enumerate(fh, 1):
            line = pending + raw.rstrip("\n")
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            pending = ""
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            tag = parts[0]
            if tag == "v":
                if len(parts) < 4:
                    raise ObjError(f"{path}:{lineno}: vertex with fewer than 3 coordinates")
                verts.append(tuple(float(p) for p in parts[1:4]))
            elif tag == "f":
                idx = []
                for p in parts[1:]:
                    s = p.split("/")[0]
                    try:
                        k = int(s)
                    except ValueError:
                        raise ObjError(f"{path}:{lineno}: bad vertex reference {p!r}")
                    if k < 0:
                        k = len(verts) + k + 1
                    if k < 1 or k > len(verts):
                        raise ObjError(f"{path}:{lineno}: vertex {s} out of range")
                    idx.append(k - 1)
                faces.append((lineno, idx))
    return verts, faces


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def norm(a):
    return math.sqrt(dot(a, a))


def check_face(path, lineno, k, p):
    """Refuse what View3D would refuse (degenerate, non-planar or non-convex faces)."""
    if len(p) not in (3, 4):
        raise ObjError(
            f"{path}:{lineno}: face {k} has {len(p)} vertices; View3D takes triangles and "
            f"convex quadrilaterals only (split the face first)")
    n = (0.0, 0.0, 0.0)
    for i in range(len(p)):  # Newell normal
        a, b = p[i], p[(i + 1) % len(p)]
        n = (n[0] + (a[1] - b[1]) * (a[2] + b[2]),
             n[1] + (a[2] - b[2]) * (a[0] + b[0]),
             n[2] + (a[0] - b[0]) * (a[1] + b[1]))
    ln = norm(n)
    c = tuple(sum(q[j] for q in p) / len(p) for j in range(3))
    rc = max(norm(sub(q, c)) for q in p)
    if ln <= 1e-12 * rc * rc:
        raise ObjError(f"{path}:{lineno}: face {k} is degenerate (zero area)")
    if len(p) == 4:
        u = (n[0] / ln, n[1] / ln, n[2] / ln)
        dev = max(abs(dot(sub(q, c), u)) for q in p) / rc
        if dev > 3e-6:  # View3D warns above 3e-6 and fails above 3e-5 (getdat.c SetPlane)
            raise ObjError(f"{path}:{lineno}: quad face {k} is not planar "
                           f"(deviation {dev:.1e} of its radius)")
        for i in range(4):
            e = cross(sub(p[(i + 1) % 4], p[i]), sub(p[(i + 2) % 4], p[(i + 1) % 4]))
            if dot(e, n) <= 0:
                raise ObjError(f"{path}:{lineno}: quad face {k} is not convex")


def fmt(x):
    r = repr(float(x))
    return "0" if r in ("0.0", "-0.0") else r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("obj")
    ap.add_argument("vs3")
    ap.add_argument("--eps", type=float, default=None, help="View3D eps (default: View3D's 1e-4)")
    ap.add_argument("--maxU", type=int, default=None)
    ap.add_argument("--maxO", type=int, default=None)
    ap.add_argument("--minO", type=int, default=None)
    ap.add_argument("--out", type=int, default=1, choices=(0, 1, 2),
                    help="View3D output format: 0 text, 1 binary float32 (default), 2 sparse text")
    ap.add_argument("--row", type=int, default=0, help="compute this row only (1-based; 0 = all)")
    ap.add_argument("--title", default=None)
    ap.add_argument("--reverse", action="store_true",
                    help="flip every face (for the orientation check only)")
    a = ap.parse_args(argv)

    try:
        verts, faces = read_obj(a.obj)
        if not faces:
            raise ObjError(f"{a.obj}: no faces")
        for k, (lineno, idx) in enumerate(faces, 1):
            check_face(a.obj, lineno, k, [verts[i] for i in idx])
    except (ObjError, OSError, ValueError) as e:
        print(f"obj2vs3: error: {e}", file=sys.stderr)
        return 2

    ctrl = ["encl=0", "emit=0", "list=0", f"out={a.out}"]
    if a.eps is not None:
        ctrl.append(f"eps={a.eps:g}")
    if a.maxU is not None:
        ctrl.append(f"maxU={a.maxU}")
    if a.maxO is not None:
        ctrl.append(f"maxO={a.maxO}")
    if a.minO is not None:
        ctrl.append(f"minO={a.minO}")
    if a.row:
        if not 1 <= a.row <= len(faces):
            print(f"obj2vs3: error: --row {a.row} outside 1..{len(faces)}", file=sys.stderr)
            return 2
        ctrl.append(f"row={a.row}")
    title = (a.title or f"{a.obj} ({len(faces)} faces)").replace("\n", " ")
    with open(a.vs3, "w") as out:
        out.write(f"T {title}\n")
        out.write(f"C {' '.join(ctrl)}\n")
        out.write("F 3\n")
        out.write("!  #   x y z\n")
        for i, v in enumerate(verts, 1):
            out.write(f"V {i} {fmt(v[0])} {fmt(v[1])} {fmt(v[2])}\n")
        out.write("!  #  v1 v2 v3 v4 base cmb emit name   (surface k = OBJ face k)\n")
        for k, (_, idx) in enumerate(faces, 1):
            vv = [i + 1 for i in (reversed(idx) if a.reverse else idx)]
            if len(vv) == 3:
                vv.append(0)
            out.write(f"S {k} {vv[0]} {vv[1]} {vv[2]} {vv[3]} 0 0 0.9 f{k}\n")
        out.write("End of data\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
