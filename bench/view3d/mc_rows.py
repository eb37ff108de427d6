#!/usr/bin/env python3
"""A third, independent opinion on a few rows: brute-force Monte Carlo ray casting in numpy.

    python3 mc_rows.py FACETS.obj --rows 0,44,120 [--rays 1000000] [--seed 1] [--out mc.npz]

For each row i (0-based face index = ffstream patch i = View3D surface i+1): points
uniform on face i, cosine-weighted directions about its front normal
(counter-clockwise = front), each ray's first hit among all faces (both sides block);
a hit on the front side of face j counts for F_ij, a hit on a back side counts for no
one (the ray is absorbed), a miss is sky. F_ij = hits_j / rays, standard error
sqrt(F (1 - F) / rays). Shares no code with ffstream or View3D: used to tell which of
them is right where they disagree. Slow (all triangles tested for every ray): meant
for a few rows of a few hundred to a few thousand faces.

Writes an .npz with rows, F (len(rows) x n) and rays, and prints each row's sum.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from obj2vs3 import read_obj  # noqa: E402


def triangles(verts, faces):
    V = np.asarray(verts, float)
    tri, owner = [], []
    for k, (_, idx) in enumerate(faces):
        for t in ([idx[0], idx[1], idx[2]],) if len(idx) == 3 else \
                ([idx[0], idx[1], idx[2]], [idx[0], idx[2], idx[3]]):
            tri.append(V[t])
            owner.append(k)
    return np.asarray(tri), np.asarray(owner)


def face_normal(p):
    n = np.zeros(3)
    for i in range(len(p)):
        a, b = p[i], p[(i + 1) % len(p)]
        n += np.cross(a, b)
    return n / np.linalg.norm(n)


def mc_row(i, verts, faces, T, owner, rays, rng, chunk=None):
    V = np.asarray(verts, float)
    n = len(faces)
    p = V[faces[i][1]]
    nrm = face_normal(p)
    # sample triangles of the face by area, then uniform points in each (stratified in sqrt)
    tris = [p[[0, 1, 2]]] if len(p) == 3 else [p[[0, 1, 2]], p[[0, 2, 3]]]
    areas = np.array([0.5 * np.linalg.norm(np.cross(t[1] - t[0], t[2] - t[0])) for t in tris])
    scale = np.sqrt(areas.sum())
    # tangent frame
    a = np.array([1.0, 0, 0]) if abs(nrm[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = np.cross(nrm, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(nrm, t1)
    # the triangles (and their normals) of every face, for the hit test
    E1 = T[:, 1] - T[:, 0]
    E2 = T[:, 2] - T[:, 0]
    own_n = np.array([face_normal(V[f[1]]) for f in faces])[owner]
    chunk = chunk or max(16, int(1.5e6 // len(T)))
    counts = np.zeros(n, np.int64)
    back = 0
    done = 0
    while done < rays:
        k = min(chunk, rays - done)
        u1 = rng.random(k)
        u2 = rng.random(k)
        w = rng.random(k) * areas.sum()
        which = (w > areas[0]).astype(int) if len(tris) == 2 else np.zeros(k, int)
        su = np.sqrt(u1)
        b0 = 1 - su
        b1 = su * (1 - u2)
        b2 = su * u2
        tt = np.asarray(tris)[which]
        org = b0[:, None] * tt[:, 0] + b1[:, None] * tt[:, 1] + b2[:, None] * tt[:, 2]
        org = org + nrm * (1e-9 * scale + 1e-12)
        r1 = rng.random(k)
        r2 = rng.random(k)
        rr = np.sqrt(r1)
        ph = 2 * np.pi * r2
        d = (rr * np.cos(ph))[:, None] * t1 + (rr * np.sin(ph))[:, None] * t2 \
            + np.sqrt(np.maximum(0, 1 - r1))[:, None] * nrm
        # Moller-Trumbore against every triangle: (k, ntri)
        pv = np.cross(d[:, None, :], E2[None, :, :])
        det = np.einsum("tk,rtk->rt", E1, pv)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = org[:, None, :] - T[None, :, 0, :]
        uu = np.einsum("rtk,rtk->rt", tv, pv) * inv
        qv = np.cross(tv, E1[None, :, :])
        vv = np.einsum("rk,rtk->rt", d, qv) * inv
        tt_ = np.einsum("tk,rtk->rt", E2, qv) * inv
        hit = ok & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt_ > 1e-9 * scale)
        hit &= owner[None, :] != i
        tt_ = np.where(hit, tt_, np.inf)
        j = np.argmin(tt_, axis=1)
        anyhit = np.isfinite(tt_[np.arange(k), j])
        tri_j = j[anyhit]
        front = np.einsum("rk,rk->r", d[anyhit], own_n[tri_j]) < 0
        np.add.at(counts, owner[tri_j[front]], 1)
        back += int((~front).sum())
        done += k
    return counts / rays, back / rays


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("obj")
    ap.add_argument("--rows", required=True, help="comma-separated 0-based rows")
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    verts, faces = read_obj(a.obj)
    T, owner = triangles(verts, faces)
    rows = [int(x) for x in a.rows.split(",") if x.strip()]
    rng = np.random.default_rng(a.seed)
    F = np.zeros((len(rows), len(faces)))
    for r, i in enumerate(rows):
        t0 = time.time()
        F[r], back = mc_row(i, verts, faces, T, owner, a.rays, rng)
        print(f"row {i}: sum {F[r].sum():.5f} +- {np.sqrt(F[r].sum() * (1 - F[r].sum()) / a.rays):.1e}"
              f" (back-side hits {back:.4f}, sky {1 - F[r].sum() - back:.4f}; {time.time() - t0:.0f} s)",
              flush=True)
    if a.out:
        np.savez(a.out, rows=np.asarray(rows), F=F, rays=a.rays)
    return 0


if __name__ == "__main__":
    sys.exit(main())
