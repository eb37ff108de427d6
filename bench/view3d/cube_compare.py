"""The unit cube as pre-split facets: accuracy of ffstream and View3D against known answers.

    python3 cube_compare.py FACETS.obj NAME=FILE ...      (FILE: .ffz, or View3D's F.bin)

For each matrix: the row sums against 1 (the cube is closed), the 36 face-to-face group
factors against the closed forms (opposite faces 0.1998248957 (Howell C-11), adjacent
faces (1 - 0.1998248957) / 4 = 0.2000437761), and the mean row L1 difference from the
first matrix given (facet k is row k in both tools: obj2vs3.py keeps the OBJ's order,
and ffstream keeps one patch per facet at --max-edge just above the facet edge).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare import read_ffz, read_view3d  # noqa: E402
from obj2vs3 import read_obj  # noqa: E402

OPPOSITE = 0.19982489569838746
ADJACENT = (1.0 - OPPOSITE) / 4.0


def faces_of(obj):
    """The cube face (0..5: x=0, x=1, y=0, y=1, z=0, z=1) of each facet, and its area."""
    verts, faces = read_obj(obj)
    face, area = [], []
    for _, idx in faces:
        p = np.array([verts[k] for k in idx])
        c = p.mean(0)
        axis = int(np.argmin([min(abs(c[a]), abs(c[a] - 1)) for a in range(3)]))
        face.append(2 * axis + (1 if c[axis] > 0.5 else 0))
        a = 0.0
        for k in range(1, len(p) - 1):
            a += 0.5 * np.linalg.norm(np.cross(p[k] - p[0], p[k + 1] - p[0]))
        area.append(a)
    return np.array(face), np.array(area)


def main():
    obj, runs = sys.argv[1], [a.split("=", 1) for a in sys.argv[2:]]
    face, area = faces_of(obj)
    first = None
    print("| run | mean abs(row sum - 1) | max | max group factor error | mean row L1 vs first |")
    print("|---|---|---|---|---|")
    for name, path in runs:
        F = read_view3d(path)[1] if path.endswith(".bin") else read_ffz(path)[1]
        if F.shape != (len(face), len(face)):
            raise SystemExit(f"{path}: {F.shape}, expected {len(face)} facets")
        rs = np.abs(F.sum(1) - 1.0)
        worst = 0.0
        for a in range(6):
            ia = face == a
            for b in range(6):
                if a == b:
                    continue
                g = (area[ia][:, None] * F[np.ix_(ia, face == b)]).sum() / area[ia].sum()
                want = OPPOSITE if a // 2 == b // 2 else ADJACENT
                worst = max(worst, abs(g - want))
        l1 = "(first)" if first is None else f"{np.abs(F - first).sum(1).mean():.2e}"
        if first is None:
            first = F
        print(f"| {name} | {rs.mean():.2e} | {rs.max():.2e} | {worst:.2e} | {l1} |")


if __name__ == "__main__":
    main()
