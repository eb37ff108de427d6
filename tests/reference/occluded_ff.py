#!/usr/bin/env python3
"""Independent reference values for the occluded patch-to-patch form factor.

What is computed
----------------
For two planar convex polygons A_i, A_j (3D vertex lists, counter-clockwise seen from
their front side, front normal by the right-hand rule) and a set of two-sided occluder
triangles,

    F_ij = (1/A_i) * integral over x in A_i of F(x -> V_j(x)) dA_x

where V_j(x) is the part of A_j visible from x and F(x -> P) is the point-to-polygon
form factor of a planar region P seen from x (unit normal n_i), by the contour
(Lambert) formula, applied to every ring of P:

    F(x -> P) = (1/2pi) * sum_k theta_k * n_i . (R_k x R_k+1) / |R_k x R_k+1|,
    R_k = vertex_k - x,  theta_k = angle between R_k and R_k+1.

The rings come from shapely with the outer ring counter-clockwise and holes clockwise
in the (e1, e2) frame of A_j's plane, with e1 x e2 = n_j.  That is counter-clockwise
as seen from x (x is in front of A_j), so holes subtract.  The whole sum has one fixed
sign for such rings (SIGN = -1, checked by `self_check_sign` against the closed-form
point-to-square value); it is multiplied by SIGN so that the result is positive.

Before anything else each polygon is clipped to the closed front half-space of the
other's plane (A_j to n_i.(p - o_i) >= 0, A_i to n_j.(p - o_j) >= 0).

Visibility (the integrand at one point x)
-----------------------------------------
Let d(p) = n_j.(p - o_j) be the signed distance to A_j's plane (d(x) > 0).  The
shadow of an occluder triangle T is the part of T strictly between x and A_j's plane,
projected centrally from x onto that plane, p -> x + (p - x) d(x) / (d(x) - d(p)).
To get it:
  * T is clipped to the slab 0 <= d(p) <= d(x) (Sutherland-Hodgman in 3D);
  * and also to the pyramid with apex x over a square Q around A_j (A_j's bounding
    box in its plane, enlarged by 25 % of its diagonal on every side).  The pyramid
    lies inside the slab, so this removes nothing that could fall on A_j; it only
    cuts away the parts near the plane d = d(x) that project to infinity, so every
    projected vertex is finite and the 2D polygons stay of the size of A_j.  This
    3D clip is done only when T is not already well inside the slab (some vertex with
    d < 0 or d > (1 - 1/16) d(x)); otherwise T's three vertices are projected
    directly (a magnification of at most 16).
  * Degenerate cases: a triangle whose plane contains x (|distance| <= 1e-12 times the
    scene size) casts a shadow of zero area and is skipped -- this is what happens to
    a face lying in A_i's own plane (the cube's floor face in "perpendicular_box": for
    x under the cube the cube's other faces then shadow all of A_j, so the floor under
    the box is dark).  Triangles entirely behind A_j's plane, or entirely at or beyond
    the plane through x parallel to A_j, are skipped.  Projected pieces with area below
    1e-15 A_j are dropped (their form factor is below ~1e-15).  A triangle lying in
    A_j's plane (d = 0) is kept: its shadow is itself.
The visible region is shapely's A_j.difference(union of the shadows), in an
orthonormal 2D frame of A_j's plane.  Shapely/GEOS works in doubles, so the integrand
carries rounding noise of order 1e-16.

Outer integral (cubature over A_i)
----------------------------------
The integrand is continuous except where an occluder touches A_i's plane (the cube:
a jump at the footprint) and has kinks wherever the combinatorics of the visible
region changes.  For polygonal geometry every such event is "a point P, a line S and x
coplanar" -- P a vertex of an occluder or of A_j (or a point where an occluder edge
pierces A_j's plane), S an edge of an occluder or of A_j -- so the event sets are
straight lines of A_i's plane: the plane through P and S cut by A_i's plane.  This
includes "a triangle seen edge-on" (P and S from one triangle) which gives the jumps at
the cube's footprint.  (Events of three skew edges -- the crossing of two shadow edges
of different occluders sliding along a third edge -- would be conics; in the
configurations here every such triple has two parallel edges and degenerates to
lines, which the pairs already give.)  Edges shared by two coplanar triangles (the
diagonal of a square made of two triangles) are not shadow boundaries and are left
out.  A_i is first cut along all these lines into convex cells, each fan-triangulated;
on every cell the integrand is analytic (only isolated point singularities remain,
e.g. the two ends of a shared edge in Howell C-14).

Each triangle is then integrated by globally adaptive cubature: a collapsed Gauss
product rule (Gauss-Jacobi x Gauss-Legendre, 5 x 5 = 25 points, exact for degree 9);
the error estimate of a leaf is |Q(T) - sum Q(children)| with the 4 midpoint children,
the leaf's value is the children's sum, and every round refines all leaves whose
estimate is at least 1/8 of the largest, until the sum of the estimates is below
tol * A_i (tol = 1e-11 by default: 1e-11 absolute in F_ij).  The rule for choosing
leaves does not depend on the tolerance, so the run passes through exactly the state
a run at the looser tolerance (1e-9) would stop in: the value recorded at that moment
IS the loose-tolerance result (no second run is needed; `--separate-loose` does it
anyway).  Both values, their difference and the final error estimate are printed.

Validation (printed before the cases)
-------------------------------------
  (a) no occluders: Howell C-11 (parallel unit squares at distance 1, 0.1998248957;
      squares of side 0.5 at distance 1, 0.0685896) and C-14 (perpendicular unit
      squares sharing an edge, 0.2000437761), each against the closed form.
  (b) every axis-aligned parallel case ("obstructed", "obstructed_patch",
      "obstructed_patch_partial", "off_centre", "two_blockers", "covered",
      "edge_touch") also by an independent
      closed form: from x = (px, 0, pz) facing +y, a rectangle [x1,x2]x[z1,z2] in the
      plane y = c facing -y has
          F = G(x2-px, z2-pz) - G(x1-px, z2-pz) - G(x2-px, z1-pz) + G(x1-px, z1-pz),
          G(a, b) = 1/(2pi) [ a/sqrt(a^2+c^2) atan(b/sqrt(a^2+c^2))
                            + b/sqrt(b^2+c^2) atan(a/sqrt(b^2+c^2)) ]
      (derivation: F = (1/pi) int int c^2/(s^2+t^2+c^2)^2 ds dt; the inner integral
      is c^2 [t/(2k^2(k^2+t^2)) + atan(t/k)/(2k^3)], k^2 = s^2+c^2, and integrating
      that in s gives G; G is odd in a and in b, hence the signed corner sum).
      A blocker square [a,b]x[e,f] at height h casts, from x, the rectangle with
      corners (c/h) q + (1 - c/h) x, so the visible part of J is J minus a union of
      axis-aligned rectangles and, by inclusion-exclusion,
          F(visible) = sum over subsets T of blockers (-1)^|T| F(J cap S_T).
      The kinks are at the values of px (pz) where two of the moving or fixed edge
      coordinates coincide; the outer integral is a tensor Gauss-Legendre rule on the
      sub-rectangles between them (24 and 32 points per direction, both printed).
      F_ji uses the mirror image y -> 1 - y.  The two methods must agree to 1e-10.
  (c) point values F(x -> visible part of A_j) of the non-axis-aligned cases against
      brute-force ray casting (midpoint rule over A_j, segment-triangle tests; only
      O(1/n) accurate, so a coarse check of the geometry: clipping, projection, sign),
      and the cube's floor face shown to change nothing (degenerate handling).
  Reciprocity |A_i F_ij - A_j F_ji| is printed for every case (F_ji is an independent
  computation with the roles swapped).

How to run
----------
    python3 tests/reference/occluded_ff.py                        # validate and print
    python3 tests/reference/occluded_ff.py --write tests/data/occluded_refs.json
Options: --tol, --tol-loose, --cases a,b,c, --skip-validation, --separate-loose.
Needs numpy, scipy and shapely >= 2.1 (`pip install shapely`).  One core, about 4 minutes
(3 of them for "perpendicular_box", whose integrand clips the cube in 3D per point).
The exit status is 1 if any check fails or any run misses its tolerance.

Output (--write): a JSON list, one object per case: name; i, j (vertex lists); occluders
(list of triangles, each three [x,y,z]); F_ij, F_ij_loose; F_ji, F_ji_loose (roles
swapped, same occluders); A_i, A_j; err_est_ij, err_est_ji (final error estimates,
absolute in F); tol, tol_loose; note; and, for the axis-aligned cases,
closed_form_F_ij / closed_form_F_ji from validation (b).
"""

import argparse
import json
import math
import sys
import time

import numpy as np
import shapely
from scipy.special import roots_jacobi, roots_legendre

TWO_PI = 2.0 * math.pi
SIGN = -1.0  # sign of the contour sum for rings counter-clockwise as seen from x

# ----------------------------------------------------------------------------------
# geometry helpers


def unit(v):
    return v / np.linalg.norm(v)


def poly_normal(P):
    """Newell normal (area-weighted) of a planar polygon, unnormalised = 2 * vector area."""
    P = np.asarray(P, float)
    Q = np.roll(P, -1, axis=0)
    return np.cross(P, Q).sum(axis=0)


class Plane:
    """Plane of a polygon with an orthonormal frame (e1, e2, n), e1 x e2 = n."""

    def __init__(self, P):
        P = np.asarray(P, float)
        self.o = P[0].copy()
        self.n = unit(poly_normal(P))
        e1 = P[1] - P[0]
        e1 = e1 - np.dot(e1, self.n) * self.n
        self.e1 = unit(e1)
        self.e2 = np.cross(self.n, self.e1)

    def dist(self, X):
        return (np.asarray(X) - self.o) @ self.n

    def to2d(self, X):
        D = np.asarray(X, float) - self.o
        return np.stack([D @ self.e1, D @ self.e2], axis=-1)

    def to3d(self, U):
        U = np.asarray(U, float)
        return self.o + U[..., 0:1] * self.e1 + U[..., 1:2] * self.e2


def check_polygon(P, name):
    P = np.asarray(P, float)
    pl = Plane(P)
    off = np.abs(pl.dist(P)).max()
    size = np.ptp(P, axis=0).max()
    if off > 1e-12 * size:
        raise ValueError(f"{name}: not planar ({off})")
    U = pl.to2d(P)
    for k in range(len(U)):
        a, b, c = U[k], U[(k + 1) % len(U)], U[(k + 2) % len(U)]
        if (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]) < -1e-14:
            raise ValueError(f"{name}: not convex / not counter-clockwise")
    return pl


def clip3(poly, n, c):
    """Keep the part of a convex 3D polygon (list of arrays) with n.p - c >= 0.

    The crossing point of an edge is computed from its lexicographically smaller end,
    so two triangles sharing an edge get bitwise the same point."""
    m = len(poly)
    if m == 0:
        return poly
    d = [float(np.dot(n, p)) - c for p in poly]
    if min(d) >= 0.0:
        return poly
    if max(d) < 0.0:
        return []
    out = []
    for k in range(m):
        a, b = poly[k], poly[(k + 1) % m]
        da, db = d[k], d[(k + 1) % m]
        if da >= 0.0:
            out.append(a)
        if (da >= 0.0) != (db >= 0.0):
            if tuple(a) <= tuple(b):
                out.append(a + (da / (da - db)) * (b - a))
            else:
                out.append(b + (db / (db - da)) * (a - b))
    return out


def clip2_convex(U, a, b, c):
    """Keep the part of a convex 2D polygon (k,2) with a u + b v + c >= 0."""
    d = U[:, 0] * a + U[:, 1] * b + c
    out = []
    m = len(U)
    for k in range(m):
        p, q = U[k], U[(k + 1) % m]
        dp, dq = d[k], d[(k + 1) % m]
        if dp >= 0:
            out.append(p)
        if (dp >= 0) != (dq >= 0):
            out.append(p + (dp / (dp - dq)) * (q - p))
    return np.array(out) if out else np.zeros((0, 2))


def area2(U):
    if len(U) < 3:
        return 0.0
    x, y = U[:, 0], U[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def clip_to_front(P, pl):
    """Clip a 3D convex polygon to the closed front half-space of plane pl."""
    out = clip3([np.asarray(p, float) for p in P], pl.n, float(np.dot(pl.n, pl.o)))
    return np.array(out)


# ----------------------------------------------------------------------------------
# contour formula


def contour_sum(X, n_i, V1, V2, owner, npts):
    """sum_k theta_k n_i.(R1 x R2)/|R1 x R2| per point, for edges V1[k] -> V2[k] of the
    point owner[k]; returns an array of length npts."""
    R1 = V1 - X[owner]
    R2 = V2 - X[owner]
    C = np.cross(R1, R2)
    cn = np.sqrt(np.einsum("ij,ij->i", C, C))
    dot = np.einsum("ij,ij->i", R1, R2)
    th = np.arctan2(cn, dot)
    cni = C @ n_i
    term = np.where(cn > 1e-300, th * cni / np.where(cn > 1e-300, cn, 1.0), 0.0)
    return np.bincount(owner, weights=term, minlength=npts)


def ff_point_polygon(x, n_i, P3):
    """Unoccluded point-to-polygon form factor (P3 counter-clockwise seen from x)."""
    X = np.asarray(x, float)[None, :]
    P3 = np.asarray(P3, float)
    owner = np.zeros(len(P3), dtype=np.int64)
    return SIGN * contour_sum(X, np.asarray(n_i, float), P3, np.roll(P3, -1, axis=0),
                              owner, 1)[0] / TWO_PI


# ----------------------------------------------------------------------------------
# the integrand


class Integrand:
    FAST_MARGIN = 1.0 / 16.0

    def __init__(self, Ai, Aj, occluders):
        Ai = np.asarray(Ai, float)
        Aj = np.asarray(Aj, float)
        pi0, pj0 = check_polygon(Ai, "A_i"), check_polygon(Aj, "A_j")
        # clip each to the front of the other
        self.Ai = clip_to_front(Ai, pj0)
        self.Aj = clip_to_front(Aj, pi0)
        self.pi, self.pj = pi0, pj0
        self.n_i = pi0.n
        self.scale = max(np.ptp(np.vstack([Ai, Aj] + [np.asarray(t, float) for t in occluders]),
                                axis=0).max(), 1e-300)
        self.area_i = 0.5 * np.linalg.norm(poly_normal(self.Ai)) if len(self.Ai) >= 3 else 0.0
        self.area_j = 0.5 * np.linalg.norm(poly_normal(self.Aj)) if len(self.Aj) >= 3 else 0.0
        if self.area_j == 0.0:
            return
        U = pj0.to2d(self.Aj)
        if area2(U) < 0:
            raise AssertionError("A_j frame orientation")
        self.aj2 = U
        self.aj_poly = shapely.Polygon(U)
        lo, hi = U.min(axis=0), U.max(axis=0)
        m = 0.25 * np.linalg.norm(hi - lo)
        lo, hi = lo - m, hi + m
        Q2 = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        self.Q3 = pj0.to3d(Q2)
        self.Qc = self.Q3.mean(axis=0)
        # occluders
        tris = []
        for t in occluders:
            t = np.asarray(t, float)
            nt = np.cross(t[1] - t[0], t[2] - t[0])
            if np.linalg.norm(nt) <= 1e-14 * self.scale ** 2:
                continue
            if pj0.dist(t).max() < 0.0:      # entirely behind A_j's plane: blocks nothing
                continue
            tris.append(t)
        self.T = np.array(tris).reshape(-1, 3, 3)
        self.nt = np.zeros((0, 3))
        self.dq = np.zeros((0, 3))
        if len(self.T):
            nt = np.cross(self.T[:, 1] - self.T[:, 0], self.T[:, 2] - self.T[:, 0])
            self.nt = nt / np.linalg.norm(nt, axis=1)[:, None]
            self.dq = pj0.dist(self.T)          # (M,3)
        self.stats = dict(points=0, slow=0)

    # -- shadow of triangle m from point x, slow (3D clipping) path
    def _shadow_slow(self, x, dx, m, pyr):
        poly = [self.T[m, 0], self.T[m, 1], self.T[m, 2]]
        pj = self.pj
        c0 = float(np.dot(pj.n, pj.o))
        poly = clip3(poly, pj.n, c0)                      # d >= 0
        if len(poly) >= 3:
            poly = clip3(poly, -pj.n, -(c0 + dx))         # d <= d(x)
        for (N, c) in pyr:                                # pyramid x -> Q
            if len(poly) < 3:
                break
            poly = clip3(poly, N, c)
        if len(poly) < 3:
            return None
        P = np.array(poly)
        dp = (P - pj.o) @ pj.n
        P = x + (P - x) * (dx / (dx - dp))[:, None]
        U = pj.to2d(P)
        if abs(area2(U)) <= 1e-15 * self.area_j:
            return None
        return U

    def _pyramid(self, x):
        out = []
        for k in range(4):
            a, b = self.Q3[k], self.Q3[(k + 1) % 4]
            N = np.cross(a - x, b - x)
            if np.dot(N, self.Qc - x) < 0:
                N = -N
            out.append((N, float(np.dot(N, x))))
        return out

    def __call__(self, X):
        X = np.asarray(X, float)
        N = len(X)
        out = np.zeros(N)
        if self.area_j == 0.0 or N == 0:
            return out
        self.stats["points"] += N
        dx = self.pj.dist(X)
        good = dx > 0.0
        M = len(self.T)
        n_i = self.n_i
        if M:
            s = np.einsum("nmk,mk->nm", X[:, None, :] - self.T[None, :, 0, :], self.nt)
            contains = np.abs(s) <= 1e-12 * self.scale
            dmin = self.dq.min(axis=1)[None, :]
            dmax = self.dq.max(axis=1)[None, :]
            dxx = dx[:, None]
            skip = contains | (dmax < 0.0) | (dmin >= dxx) | ~good[:, None]
            fast = ~skip & (dmin >= 0.0) & (dmax <= dxx * (1.0 - self.FAST_MARGIN))
            slow = ~skip & ~fast
            shadowed = (fast | slow).any(axis=1)
        else:
            shadowed = np.zeros(N, bool)
        # points without any shadow: the whole A_j
        plain = np.nonzero(good & ~shadowed)[0]
        if len(plain):
            A = self.Aj
            nv = len(A)
            owner = np.repeat(np.arange(len(plain)), nv)
            V1 = np.tile(A, (len(plain), 1))
            V2 = np.tile(np.roll(A, -1, axis=0), (len(plain), 1))
            out[plain] = SIGN * contour_sum(X[plain], n_i, V1, V2, owner, len(plain)) / TWO_PI
        rows = np.nonzero(good & shadowed)[0]
        if len(rows) == 0:
            return out
        G = np.full((len(rows), M), None, dtype=object)
        # fast path: project the three vertices directly (vectorised)
        fi, fm = np.nonzero(fast[rows])
        if len(fi):
            Xr = X[rows[fi]][:, None, :]
            d = dx[rows[fi]][:, None]
            P = Xr + (self.T[fm] - Xr) * (d / (d - self.dq[fm]))[:, :, None]
            U = self.pj.to2d(P)
            ar = 0.5 * ((U[:, 1, 0] - U[:, 0, 0]) * (U[:, 2, 1] - U[:, 0, 1])
                        - (U[:, 1, 1] - U[:, 0, 1]) * (U[:, 2, 0] - U[:, 0, 0]))
            keep = np.abs(ar) > 1e-15 * self.area_j
            polys = shapely.polygons(U[keep])
            G[fi[keep], fm[keep]] = polys
        # slow path: 3D clipping
        si, sm = np.nonzero(slow[rows])
        if len(si):
            self.stats["slow"] += len(si)
            cache = {}
            for a, m in zip(si, sm):
                r = rows[a]
                if r not in cache:
                    cache[r] = self._pyramid(X[r])
                U = self._shadow_slow(X[r], float(dx[r]), m, cache[r])
                if U is not None:
                    G[a, m] = shapely.Polygon(U)
        U = shapely.union_all(G, axis=1)
        V = shapely.difference(self.aj_poly, U)
        V = shapely.orient_polygons(V, exterior_cw=False)
        parts, pidx = shapely.get_parts(V, return_index=True)
        if len(parts) == 0:
            return out
        ispoly = shapely.get_type_id(parts) == 3
        parts, pidx = parts[ispoly], pidx[ispoly]
        rings, ridx = shapely.get_rings(parts, return_index=True)
        coords, cidx = shapely.get_coordinates(rings, return_index=True)
        if len(coords) < 2:
            return out
        same = cidx[:-1] == cidx[1:]
        k = np.nonzero(same)[0]
        C3 = self.pj.to3d(coords)
        owner = pidx[ridx[cidx[k]]]
        vals = SIGN * contour_sum(X[rows], n_i, C3[k], C3[k + 1], owner, len(rows)) / TWO_PI
        out[rows] = vals
        return out

    # ------------------------------------------------------------------------------
    # event lines in A_i's plane (2D frame of self.pi)

    def event_lines(self):
        pj, pi = self.pj, self.pi
        tol = 1e-12 * self.scale
        pts = []    # (point, kind)  kind: 'occ' (occluder) or 'jp' (lies in A_j's plane)
        segs = []   # (a, b, kind)
        for p in self.Aj:
            pts.append((p, "jp"))
        for k in range(len(self.Aj)):
            segs.append((self.Aj[k], self.Aj[(k + 1) % len(self.Aj)], "jp"))
        # occluder vertices / edges
        verts = {}
        edges = {}

        def key(p):
            return tuple(np.round(p / self.scale, 12))

        for m, t in enumerate(self.T):
            for v in t:
                verts.setdefault(key(v), v)
            for a, b in ((0, 1), (1, 2), (2, 0)):
                ka, kb = key(t[a]), key(t[b])
                ek = (ka, kb) if ka <= kb else (kb, ka)
                edges.setdefault(ek, (t[a], t[b], []))[2].append(m)
        for v in verts.values():
            if pj.dist(v) >= -tol:
                pts.append((v, "occ"))
        for ek, (a, b, ms) in edges.items():
            if len(ms) == 2:
                n1, n2 = self.nt[ms[0]], self.nt[ms[1]]
                if np.linalg.norm(np.cross(n1, n2)) < 1e-12:
                    # coplanar neighbours: are they on opposite sides of the edge?
                    t1, t2 = self.T[ms[0]], self.T[ms[1]]
                    c1 = t1.mean(axis=0) - a
                    c2 = t2.mean(axis=0) - a
                    e = b - a
                    if np.dot(np.cross(e, c1), np.cross(e, c2)) < 0:
                        continue          # interior edge of a planar polygon
            da, db = pj.dist(a), pj.dist(b)
            if max(da, db) < -tol:
                continue
            if min(da, db) < -tol:        # pierces A_j's plane: keep the front part
                pcut = a + (da / (da - db)) * (b - a)
                pts.append((pcut, "jp"))
                a, b = (a, pcut) if da > db else (pcut, b)
            segs.append((a, b, "occ"))
        # triangles cut by A_j's plane: the cut segment lies in A_j's plane
        for t, d in zip(self.T, self.dq):
            if d.min() < -tol and d.max() > tol:
                cut = []
                for a, b in ((0, 1), (1, 2), (2, 0)):
                    if (d[a] < 0) != (d[b] < 0):
                        cut.append(t[a] + (d[a] / (d[a] - d[b])) * (t[b] - t[a]))
                if len(cut) == 2:
                    segs.append((cut[0], cut[1], "jp"))
        lines = []
        A2 = pi.to2d(self.Ai)
        for P, pk in pts:
            for a, b, sk in segs:
                if pk == "jp" and sk == "jp":
                    continue                       # A_j's plane itself
                Nrm = np.cross(a - P, b - P)
                nn = np.linalg.norm(Nrm)
                if nn <= 1e-12 * self.scale ** 2:
                    continue                       # P on the line of S
                Nrm = Nrm / nn
                la, lb = float(Nrm @ pi.e1), float(Nrm @ pi.e2)
                h = math.hypot(la, lb)
                if h <= 1e-12:
                    continue                       # plane parallel to A_i's plane
                lc = float(Nrm @ (pi.o - P))
                la, lb, lc = la / h, lb / h, lc / h
                if la < -1e-14 or (abs(la) <= 1e-14 and lb < 0):
                    la, lb, lc = -la, -lb, -lc
                dd = A2[:, 0] * la + A2[:, 1] * lb + lc
                if dd.max() <= 1e-12 * self.scale or dd.min() >= -1e-12 * self.scale:
                    continue                       # does not cut A_i's interior
                lines.append((la, lb, lc))
        # dedupe
        lines.sort()
        uniq = []
        for l in lines:
            if uniq and all(abs(l[q] - uniq[-1][q]) <= 1e-10 for q in range(3)):
                continue
            if any(all(abs(l[q] - u[q]) <= 1e-10 for q in range(3)) for u in uniq):
                continue
            uniq.append(l)
        return uniq

    def cells(self):
        """Convex cells of A_i (2D, frame self.pi) between the event lines."""
        A2 = self.pi.to2d(self.Ai)
        cells = [A2]
        lines = self.event_lines()
        eps = 1e-12 * self.scale
        for (a, b, c) in lines:
            new = []
            for C in cells:
                d = C[:, 0] * a + C[:, 1] * b + c
                if d.max() <= eps or d.min() >= -eps:
                    new.append(C)
                    continue
                for sgn in (1.0, -1.0):
                    P = clip2_convex(C, sgn * a, sgn * b, sgn * c)
                    if len(P) >= 3 and area2(P) > 1e-16 * self.scale ** 2:
                        new.append(P)
            cells = new
        return cells, lines


# ----------------------------------------------------------------------------------
# adaptive cubature on triangles


def collapsed_rule(n):
    xl, wl = roots_legendre(n)
    t, wt = 0.5 * (xl + 1.0), 0.5 * wl
    xj, wj = roots_jacobi(n, 0.0, 1.0)           # weight (1 + x) on [-1, 1]
    s, ws = 0.5 * (xj + 1.0), 0.25 * wj          # weight s on [0, 1]
    S, Tt = np.meshgrid(s, t, indexing="ij")
    W = 2.0 * np.outer(ws, wt)                   # sums to 1
    S, Tt, W = S.ravel(), Tt.ravel(), W.ravel()
    lam = np.stack([1.0 - S, S * (1.0 - Tt), S * Tt], axis=1)
    return lam, W


RULE_N = 5
LAM, WQ = collapsed_rule(RULE_N)
assert abs(WQ.sum() - 1.0) < 1e-14


def tri_area(T):
    return 0.5 * np.abs((T[:, 1, 0] - T[:, 0, 0]) * (T[:, 2, 1] - T[:, 0, 1])
                        - (T[:, 1, 1] - T[:, 0, 1]) * (T[:, 2, 0] - T[:, 0, 0]))


def children(T):
    A, B, C = T[:, 0], T[:, 1], T[:, 2]
    ab, bc, ca = 0.5 * (A + B), 0.5 * (B + C), 0.5 * (C + A)
    return np.stack([np.stack([A, ab, ca], 1), np.stack([ab, B, bc], 1),
                     np.stack([ca, bc, C], 1), np.stack([bc, ca, ab], 1)], axis=1)


class Cubature:
    CHUNK = 6000

    def __init__(self, f, plane):
        self.f, self.plane = f, plane
        self.npts = 0

    def quad(self, T):
        if len(T) == 0:
            return np.zeros(0)
        P2 = np.einsum("kv,tvd->tkd", LAM, T).reshape(-1, 2)
        X = self.plane.to3d(P2)
        vals = np.empty(len(X))
        for s in range(0, len(X), self.CHUNK):
            vals[s:s + self.CHUNK] = self.f(X[s:s + self.CHUNK])
        self.npts += len(X)
        return tri_area(T) * (vals.reshape(len(T), -1) @ WQ)

    def run(self, T0, tol, tol_loose=None, max_points=6_000_000, min_area=1e-26):
        """Global adaptive integration; returns dict with value, err, loose value..."""
        T0 = np.asarray(T0, float)
        q0 = self.quad(T0)
        ch = children(T0)
        qc = self.quad(ch.reshape(-1, 3, 2)).reshape(-1, 4)
        leaves_T = T0
        leaves_qc = qc
        leaves_err = np.abs(q0 - qc.sum(axis=1))
        loose = None
        rounds = 0
        status = "converged"
        while True:
            total_err = float(leaves_err.sum())
            value = math.fsum(leaves_qc.ravel())
            if tol_loose is not None and loose is None and total_err <= tol_loose:
                loose = dict(value=value, err=total_err, points=self.npts,
                             leaves=len(leaves_T))
            if total_err <= tol:
                break
            if self.npts > max_points:
                status = "point budget exhausted"
                break
            refinable = tri_area(leaves_T) > min_area
            e = np.where(refinable, leaves_err, 0.0)
            emax = e.max()
            if emax <= 0.0:
                status = "no refinable leaf"
                break
            sel = e >= emax / 8.0
            rounds += 1
            kids = children(leaves_T[sel]).reshape(-1, 3, 2)        # (4S,3,2)
            kids_q = leaves_qc[sel].reshape(-1)
            g = self.quad(children(kids).reshape(-1, 3, 2)).reshape(-1, 4)
            kids_err = np.abs(kids_q - g.sum(axis=1))
            leaves_T = np.concatenate([leaves_T[~sel], kids])
            leaves_qc = np.concatenate([leaves_qc[~sel], g])
            leaves_err = np.concatenate([leaves_err[~sel], kids_err])
        res = dict(value=value, err=total_err, points=self.npts, leaves=len(leaves_T),
                   rounds=rounds, status=status)
        if tol_loose is not None:
            res["loose"] = loose
        return res


def form_factor(Ai, Aj, occluders, tol=1e-11, tol_loose=1e-9, separate_loose=False,
                max_points=6_000_000):
    """F_ij and its loose-tolerance value; tolerances are absolute in F_ij."""
    f = Integrand(Ai, Aj, occluders)
    if f.area_i == 0.0 or f.area_j == 0.0:
        return dict(F=0.0, F_loose=0.0, err=0.0, cells=0, lines=0, points=0)
    cells, lines = f.cells()
    tris = []
    for C in cells:
        for k in range(1, len(C) - 1):
            t = np.array([C[0], C[k], C[k + 1]])
            if tri_area(t[None])[0] > 1e-18 * f.scale ** 2:
                tris.append(t)
    tris = np.array(tris)
    A = f.area_i
    cub = Cubature(f, f.pi)
    r = cub.run(tris, tol * A, None if separate_loose else tol_loose * A,
                max_points=max_points)
    out = dict(F=r["value"] / A, err=r["err"] / A, cells=len(cells), lines=len(lines),
               tris=len(tris), points=r["points"], leaves=r["leaves"], rounds=r["rounds"],
               status=r["status"], slow=f.stats["slow"], area_i=A, area_j=f.area_j)
    if separate_loose:
        cub2 = Cubature(f, f.pi)
        r2 = cub2.run(tris, tol_loose * A, None, max_points=max_points)
        out["F_loose"] = r2["value"] / A
        out["err_loose"] = r2["err"] / A
    else:
        lo = r["loose"]
        out["F_loose"] = None if lo is None else lo["value"] / A
        out["err_loose"] = None if lo is None else lo["err"] / A
    return out


# ----------------------------------------------------------------------------------
# closed forms (independent of everything above)


def howell_c11(X, Y):
    """Parallel, directly opposed equal rectangles a x b at distance c, X=a/c, Y=b/c."""
    t1 = math.log(math.sqrt((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y)))
    t2 = X * math.sqrt(1 + Y * Y) * math.atan(X / math.sqrt(1 + Y * Y))
    t3 = Y * math.sqrt(1 + X * X) * math.atan(Y / math.sqrt(1 + X * X))
    return 2.0 / (math.pi * X * Y) * (t1 + t2 + t3 - X * math.atan(X) - Y * math.atan(Y))


def howell_c14(W, H):
    """Perpendicular rectangles sharing an edge; emitter width W, receiver height H
    (both relative to the common edge)."""
    s = H * H + W * W
    a = W * math.atan(1 / W) + H * math.atan(1 / H) - math.sqrt(s) * math.atan(1 / math.sqrt(s))
    l1 = math.log((1 + W * W) * (1 + H * H) / (1 + s))
    l2 = W * W * math.log(W * W * (1 + s) / ((1 + W * W) * s))
    l3 = H * H * math.log(H * H * (1 + s) / ((1 + H * H) * s))
    return (a + 0.25 * (l1 + l2 + l3)) / (math.pi * W)


def G_corner(a, b, c):
    """Point-to-parallel-rectangle [0,a]x[0,b] at height c, corner over the point;
    odd in a and in b."""
    ra = np.sqrt(a * a + c * c)
    rb = np.sqrt(b * b + c * c)
    return (a / ra * np.arctan(b / ra) + b / rb * np.arctan(a / rb)) / TWO_PI


def F_rect(px, pz, x1, x2, z1, z2, c):
    """Point (px, 0, pz) facing +y to the rectangle [x1,x2]x[z1,z2] at y=c facing -y;
    arrays broadcast; empty rectangles give 0."""
    val = (G_corner(x2 - px, z2 - pz, c) - G_corner(x1 - px, z2 - pz, c)
           - G_corner(x2 - px, z1 - pz, c) + G_corner(x1 - px, z1 - pz, c))
    return np.where((x2 > x1) & (z2 > z1), val, 0.0)


def closed_form_parallel(irect, jrect, c, blockers, n_gauss):
    """F_ij for i = rectangle irect=(x1,x2,z1,z2) at y=0 facing +y, j = jrect at y=c
    facing -y, blockers = [(h, (a, b), (e, f)), ...] axis-aligned squares at heights
    0 < h < c.  Tensor Gauss-Legendre on sub-rectangles split at the kink values."""
    def edge_funcs(axis):
        # edge coordinate as alpha * q + (1 - alpha) * p:  (slope on p, constant)
        fs = [(0.0, jrect[2 * axis]), (0.0, jrect[2 * axis + 1])]
        for h, xr, zr in blockers:
            al = c / h
            r = xr if axis == 0 else zr
            fs += [(1.0 - al, al * r[0]), (1.0 - al, al * r[1])]
        return fs

    def breaks(axis):
        lo, hi = irect[2 * axis], irect[2 * axis + 1]
        fs = edge_funcs(axis)
        bs = {lo, hi}
        for p in range(len(fs)):
            for q in range(p + 1, len(fs)):
                s1, c1 = fs[p]
                s2, c2 = fs[q]
                if abs(s1 - s2) > 1e-15:
                    v = (c2 - c1) / (s1 - s2)
                    if lo + 1e-14 < v < hi - 1e-14:
                        bs.add(v)
        return sorted(bs)

    xg, wg = roots_legendre(n_gauss)

    def nodes(bs):
        P, W = [], []
        for a, b in zip(bs[:-1], bs[1:]):
            P.append(0.5 * (a + b) + 0.5 * (b - a) * xg)
            W.append(0.5 * (b - a) * wg)
        return np.concatenate(P), np.concatenate(W)

    px, wx = nodes(breaks(0))
    pz, wz = nodes(breaks(1))
    PX, PZ = np.meshgrid(px, pz, indexing="ij")
    Wt = np.outer(wx, wz)
    nb = len(blockers)
    total = np.zeros_like(PX)
    for mask in range(1 << nb):
        x1 = np.full_like(PX, jrect[0])
        x2 = np.full_like(PX, jrect[1])
        z1 = np.full_like(PX, jrect[2])
        z2 = np.full_like(PX, jrect[3])
        sign = 1.0
        for k in range(nb):
            if mask >> k & 1:
                sign = -sign
                h, xr, zr = blockers[k]
                al = c / h
                x1 = np.maximum(x1, al * xr[0] + (1 - al) * PX)
                x2 = np.minimum(x2, al * xr[1] + (1 - al) * PX)
                z1 = np.maximum(z1, al * zr[0] + (1 - al) * PZ)
                z2 = np.minimum(z2, al * zr[1] + (1 - al) * PZ)
        total += sign * F_rect(PX, PZ, x1, x2, z1, z2, c)
    A = (irect[1] - irect[0]) * (irect[3] - irect[2])
    return float((total * Wt).sum() / A)


def closed_form_point(px, pz, jrect, c, blockers):
    total = 0.0
    nb = len(blockers)
    for mask in range(1 << nb):
        x1, x2, z1, z2 = jrect
        sign = 1.0
        for k in range(nb):
            if mask >> k & 1:
                sign = -sign
                h, xr, zr = blockers[k]
                al = c / h
                x1 = max(x1, al * xr[0] + (1 - al) * px)
                x2 = min(x2, al * xr[1] + (1 - al) * px)
                z1 = max(z1, al * zr[0] + (1 - al) * pz)
                z2 = min(z2, al * zr[1] + (1 - al) * pz)
        total += sign * float(F_rect(px, pz, x1, x2, z1, z2, c))
    return total


def bruteforce_point(x, n_i, Aj, tris, n):
    """F(x -> visible part of A_j) by brute force: midpoint rule on an n x n grid over
    A_j's bounding box (samples outside the convex A_j dropped), the kernel
    cos_i cos_j / (pi r^2), and visibility by a segment-triangle test (Moller-Trumbore,
    two-sided, hits with 0 < t < 1, edges counted as hits so that rays through the
    shared diagonal of two triangles do not leak) against every occluder triangle.  Shares nothing
    with the shadow projection / shapely path; O(1/n) accurate."""
    Aj = np.asarray(Aj, float)
    x = np.asarray(x, float)
    pl = Plane(Aj)
    U = pl.to2d(Aj)
    lo, hi = U.min(axis=0), U.max(axis=0)
    h = (hi - lo) / n
    gu = lo[0] + h[0] * (np.arange(n) + 0.5)
    gv = lo[1] + h[1] * (np.arange(n) + 0.5)
    GU, GV = np.meshgrid(gu, gv, indexing="ij")
    S = np.stack([GU.ravel(), GV.ravel()], axis=1)
    inside = np.ones(len(S), bool)
    for k in range(len(U)):
        a, b = U[k], U[(k + 1) % len(U)]
        inside &= (b[0] - a[0]) * (S[:, 1] - a[1]) - (b[1] - a[1]) * (S[:, 0] - a[0]) >= 0
    P = pl.to3d(S[inside])
    D = P - x
    r2 = np.einsum("ij,ij->i", D, D)
    ci = (D @ n_i) / np.sqrt(r2)
    cj = -(D @ pl.n) / np.sqrt(r2)
    w = np.where((ci > 0) & (cj > 0), ci * cj / (math.pi * r2), 0.0) * h[0] * h[1]
    vis = np.ones(len(P), bool)
    for t in tris:
        t = np.asarray(t, float)
        e1, e2 = t[1] - t[0], t[2] - t[0]
        pv = np.cross(D, e2)
        det = pv @ e1
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = x - t[0]
        uu = (pv @ tv) * inv
        qv = np.cross(tv, e1)
        vv = (D @ qv) * inv
        tt = (qv @ e2) * inv
        vis &= ~(ok & (uu >= -1e-12) & (vv >= -1e-12) & (uu + vv <= 1 + 1e-12)
                 & (tt > 0) & (tt < 1))
    return float(w[vis].sum())


# ----------------------------------------------------------------------------------
# configurations


def bottom_rect(x1, x2, z1, z2):
    P = [(x1, 0.0, z1), (x1, 0.0, z2), (x2, 0.0, z2), (x2, 0.0, z1)]
    assert poly_normal(P)[1] > 0
    return P


def top_rect(x1, x2, z1, z2):
    P = [(x1, 1.0, z1), (x2, 1.0, z1), (x2, 1.0, z2), (x1, 1.0, z2)]
    assert poly_normal(P)[1] < 0
    return P


def square_at(h, xr, zr):
    (a, b), (e, f) = xr, zr
    return [[(a, h, e), (b, h, e), (b, h, f)], [(a, h, e), (b, h, f), (a, h, f)]]


def rotate_x(p, centre, deg):
    t = math.radians(deg)
    d = np.asarray(p, float) - centre
    y = d[1] * math.cos(t) - d[2] * math.sin(t)
    z = d[1] * math.sin(t) + d[2] * math.cos(t)
    return tuple(float(v) for v in centre + np.array([d[0], y, z]))


def cube_triangles(lo, side):
    x0, y0, z0 = lo
    x1, y1, z1 = x0 + side, y0 + side, z0 + side
    v = {(i, j, k): (x1 if i else x0, y1 if j else y0, z1 if k else z0)
         for i in (0, 1) for j in (0, 1) for k in (0, 1)}
    faces = [  # outward counter-clockwise quads
        [(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)],   # x = x0, normal -x
        [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)],   # x = x1, normal +x
        [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)],   # y = y0, normal -y
        [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)],   # y = y1, normal +y
        [(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)],   # z = z0, normal -z
        [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],   # z = z1, normal +z
    ]
    tris = []
    for f in faces:
        q = [v[k] for k in f]
        tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return tris


def build_cases():
    bottom = bottom_rect(0, 1, 0, 1)
    top = top_rect(0, 1, 0, 1)
    cases = []

    def add(name, i, j, occ, note, closed=None):
        cases.append(dict(name=name, i=[list(map(float, p)) for p in i],
                          j=[list(map(float, p)) for p in j],
                          occluders=[[list(map(float, p)) for p in t] for t in occ],
                          note=note, closed=closed))

    U = (0.0, 1.0, 0.0, 1.0)
    blk = ((0.25, 0.75), (0.25, 0.75))
    add("obstructed", bottom, top, square_at(0.5, *blk),
        "unit squares y=0 (+y) and y=1 (-y); blocker square x,z in [0.25,0.75] at y=0.5 "
        "(two triangles)",
        dict(i=U, j=U, blockers=[(0.5,) + blk]))
    add("obstructed_patch", bottom_rect(0.2, 0.4, 0.6, 0.8), top_rect(0.5, 0.7, 0.3, 0.5),
        square_at(0.5, *blk),
        "i = bottom x,z in [0.2,0.4]x[0.6,0.8], j = top x,z in [0.5,0.7]x[0.3,0.5]; same "
        "blocker as 'obstructed'. The blocker's shadow covers j from every point of i, so "
        "F = 0 exactly (see 'obstructed_patch_partial' for a partly hidden pair)",
        dict(i=(0.2, 0.4, 0.6, 0.8), j=(0.5, 0.7, 0.3, 0.5), blockers=[(0.5,) + blk]))
    add("obstructed_patch_partial", bottom_rect(0.2, 0.4, 0.6, 0.8),
        top_rect(0.6, 0.8, 0.6, 0.8), square_at(0.5, *blk),
        "extra case, not in the original list ('obstructed_patch' is fully hidden, F = 0): "
        "i = bottom x,z in [0.2,0.4]x[0.6,0.8], j = top x,z in [0.6,0.8]x[0.6,0.8]; same "
        "blocker; j is partly hidden, with a kink at pz = 0.7",
        dict(i=(0.2, 0.4, 0.6, 0.8), j=(0.6, 0.8, 0.6, 0.8), blockers=[(0.5,) + blk]))
    off = ((0.1, 0.6), (0.3, 0.8))
    add("off_centre", bottom, top, square_at(0.5, *off),
        "unit squares; blocker x in [0.1,0.6], z in [0.3,0.8] at y=0.5",
        dict(i=U, j=U, blockers=[(0.5,) + off]))
    centre = np.array([0.5, 0.5, 0.5])
    flat = [(0.25, 0.5, 0.25), (0.75, 0.5, 0.25), (0.75, 0.5, 0.75), (0.25, 0.5, 0.75)]
    q = [rotate_x(p, centre, 30.0) for p in flat]
    add("tilted", bottom, top, [[q[0], q[1], q[2]], [q[0], q[2], q[3]]],
        "unit squares; blocker: square of side 0.5 centred at (0.5,0.5,0.5), in the plane "
        "y=0.5 then rotated by +30 deg (right-hand rule) about the x-parallel axis through "
        "its centre (its z=0.25 edge goes up to y=0.625)")
    add("partial_small", bottom, top_rect(0.6, 0.9, 0.2, 0.5),
        [[(0.3, 0.4, 0.2), (0.8, 0.45, 0.35), (0.5, 0.6, 0.7)]],
        "i = bottom, j = top x,z in [0.6,0.9]x[0.2,0.5]; one blocker triangle")
    bA = ((0.2, 0.6), (0.2, 0.6))
    bB = ((0.4, 0.8), (0.4, 0.8))
    add("two_blockers", bottom, top, square_at(0.3, *bA) + square_at(0.7, *bB),
        "unit squares; blocker A x,z in [0.2,0.6] at y=0.3, blocker B x,z in [0.4,0.8] at "
        "y=0.7 (overlapping shadows)",
        dict(i=U, j=U, blockers=[(0.3,) + bA, (0.7,) + bB]))
    cov = ((0.2, 0.8), (0.2, 0.8))
    add("covered", bottom_rect(0.4, 0.6, 0.4, 0.6), top_rect(0.4, 0.6, 0.4, 0.6),
        square_at(0.5, *cov),
        "i = bottom [0.4,0.6]^2, j = top [0.4,0.6]^2, blocker [0.2,0.8]^2 at y=0.5: the "
        "shadow covers j from every point of i, F = 0 exactly",
        dict(i=(0.4, 0.6, 0.4, 0.6), j=(0.4, 0.6, 0.4, 0.6), blockers=[(0.5,) + cov]))
    et = ((0.5, 0.75), (0.25, 0.75))
    add("edge_touch", bottom, top_rect(0.0, 0.5, 0.0, 1.0), square_at(0.5, *et),
        "i = bottom, j = top x,z in [0,0.5]x[0,1]; blocker x in [0.5,0.75], z in "
        "[0.25,0.75] at y=0.5 (its shadow reaches j's edge x=0.5 exactly from px=0.5)",
        dict(i=U, j=(0.0, 0.5, 0.0, 1.0), blockers=[(0.5,) + et]))
    wall = [(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)]
    assert poly_normal(wall)[0] > 0
    add("perpendicular_box", bottom, wall, cube_triangles((0.1, 0.0, 0.35), 0.3),
        "i = floor (unit square y=0, +y), j = wall x=0 facing +x (shares the edge x=y=0); "
        "occluder: cube of side 0.3, min corner (0.1,0,0.35), 12 triangles, standing on "
        "the floor (the floor under it sees nothing)")
    return cases


def mirror_closed(cl):
    """closed-form parameters with i and j swapped (mirror y -> 1 - y)."""
    return dict(i=cl["j"], j=cl["i"],
                blockers=[(1.0 - h, xr, zr) for h, xr, zr in cl["blockers"]])


# ----------------------------------------------------------------------------------
# driver


def self_check_sign():
    sq = top_rect(-0.5, 0.5, -0.5, 0.5)
    f = ff_point_polygon((0, 0, 0), (0, 1, 0), sq)
    g = float(F_rect(0.0, 0.0, -0.5, 0.5, -0.5, 0.5, 1.0))
    assert f > 0 and abs(f - g) < 1e-14, (f, g)
    # closed-form point formula against direct numerical integration of the kernel
    from scipy.integrate import dblquad
    for (a, b, c) in ((0.7, 0.3, 1.0), (2.0, 0.5, 0.4)):
        v, _ = dblquad(lambda t, s: c * c / (math.pi * (s * s + t * t + c * c) ** 2),
                       0, a, 0, b, epsabs=1e-13, epsrel=1e-13)
        assert abs(v - float(G_corner(a, b, c))) < 1e-11, (v, G_corner(a, b, c))
    return f, g


def fmt(v):
    return "None" if v is None else f"{v:.13f}"


def run_validation(tol, tol_loose, sep):
    ok = True
    print("== validation (a): no occluders, against Howell")
    f, g = self_check_sign()
    print(f"   sign check: point under a centred unit square at distance 1: contour "
          f"{f:.15f}, closed form {g:.15f}")
    checks = [
        ("C-11 unit squares, distance 1", bottom_rect(0, 1, 0, 1), top_rect(0, 1, 0, 1),
         howell_c11(1, 1), 0.1998248957),
        ("C-11 squares of side 0.5, distance 1", bottom_rect(0, 0.5, 0, 0.5),
         top_rect(0, 0.5, 0, 0.5), howell_c11(0.5, 0.5), 0.0685896),
        ("C-14 perpendicular unit squares sharing an edge", bottom_rect(0, 1, 0, 1),
         [(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)], howell_c14(1, 1), 0.2000437761),
    ]
    for name, i, j, exact, quoted in checks:
        t0 = time.time()
        r = form_factor(i, j, [], tol, tol_loose, sep)
        d = abs(r["F"] - exact)
        good = d <= 1e-9
        ok &= good
        print(f"   {name}: F = {r['F']:.13f}  closed form {exact:.13f} (quoted {quoted})  "
              f"|diff| = {d:.2e}  loose {fmt(r['F_loose'])}  err est {r['err']:.1e}  "
              f"[{r['points']} points, {r['status']}, {time.time() - t0:.1f} s]  "
              f"{'OK' if good else 'FAIL'}")
    print("== validation (c): point values against brute-force ray casting "
          "(midpoint rule, 1000 x 1000 samples of A_j; O(1/n) accurate, bound 3e-4)")
    cases = {c["name"]: c for c in build_cases()}
    probes = [("tilted", False, [(0.3, 0, 0.6), (0.7, 0, 0.2), (0.5, 0, 0.5)]),
              ("tilted", True, [(0.3, 1, 0.6), (0.5, 1, 0.5)]),
              ("partial_small", False, [(0.7, 0, 0.2), (0.5, 0, 0.5), (0.9, 0, 0.1)]),
              ("partial_small", True, [(0.7, 1, 0.3), (0.65, 1, 0.45)]),
              ("perpendicular_box", False, [(0.25, 0, 0.5), (0.25, 0, 0.75), (0.6, 0, 0.5),
                                            (0.7, 0, 0.3)]),
              ("perpendicular_box", True, [(0, 0.1, 0.5), (0, 0.5, 0.5), (0, 0.2, 0.9)])]
    worst = 0.0
    for name, swap, pts in probes:
        c = cases[name]
        i, j = (c["j"], c["i"]) if swap else (c["i"], c["j"])
        f = Integrand(i, j, c["occluders"])
        for x in pts:
            v = f(np.array([x], float))[0]
            b = bruteforce_point(x, f.n_i, j, c["occluders"], 1000)
            worst = max(worst, abs(v - b))
            print(f"   {name}{' (ji)' if swap else ''} x={x}: shadow/shapely {v:.8f}  "
                  f"ray casting {b:.8f}  |diff| {abs(v - b):.1e}")
    good = worst <= 3e-4
    ok &= good
    print(f"   worst |diff| {worst:.1e}  {'OK' if good else 'FAIL'}")
    # degenerate handling: the cube's floor face changes nothing
    c = cases["perpendicular_box"]
    nofloor = [t for t in c["occluders"] if max(p[1] for p in t) > 0.0]
    assert len(nofloor) == 10
    rng = np.random.default_rng(7)
    worst = 0.0
    under = 0.0
    for i, j in ((c["i"], c["j"]), (c["j"], c["i"])):
        f1, f2 = Integrand(i, j, c["occluders"]), Integrand(i, j, nofloor)
        U = rng.uniform(0, 1, (3000, 2))
        X = f1.pi.to3d(U)
        worst = max(worst, float(np.abs(f1(X) - f2(X)).max()))
    f1 = Integrand(c["i"], c["j"], c["occluders"])
    U = rng.uniform([0.1, 0.35], [0.4, 0.65], (1000, 2))
    X = np.stack([U[:, 0], np.zeros(1000), U[:, 1]], axis=1)
    under = float(np.abs(f1(X)).max())
    good = worst <= 1e-15 and under <= 1e-15
    ok &= good
    print(f"   perpendicular_box: cube with / without its floor face, 6000 random points: "
          f"max |diff| {worst:.1e}; floor points under the cube: max F {under:.1e}  "
          f"{'OK' if good else 'FAIL'}")
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--write", metavar="JSON", help="write the reference values here")
    ap.add_argument("--tol", type=float, default=1e-11)
    ap.add_argument("--tol-loose", type=float, default=1e-9)
    ap.add_argument("--cases", help="comma-separated subset of case names")
    ap.add_argument("--skip-validation", action="store_true")
    ap.add_argument("--separate-loose", action="store_true",
                    help="run the loose tolerance as its own run (same result)")
    args = ap.parse_args()
    t_start = time.time()
    ok = True
    if not args.skip_validation:
        ok &= run_validation(args.tol, args.tol_loose, args.separate_loose)
    cases = build_cases()
    if args.cases:
        want = args.cases.split(",")
        cases = [c for c in cases if c["name"] in want]
    print(f"== cases (tol {args.tol:g}, loose {args.tol_loose:g}, absolute in F)")
    results = []
    rows = []
    for c in cases:
        t0 = time.time()
        rij = form_factor(c["i"], c["j"], c["occluders"], args.tol, args.tol_loose,
                          args.separate_loose)
        t1 = time.time()
        rji = form_factor(c["j"], c["i"], c["occluders"], args.tol, args.tol_loose,
                          args.separate_loose)
        t2 = time.time()
        Ai, Aj = rij["area_i"], rij["area_j"]
        recip = abs(Ai * rij["F"] - Aj * rji["F"])
        print(f"-- {c['name']}: A_i {Ai:g}, A_j {Aj:g}")
        for lab, r, dt in (("F_ij", rij, t1 - t0), ("F_ji", rji, t2 - t1)):
            dl = None if r["F_loose"] is None else abs(r["F"] - r["F_loose"])
            print(f"   {lab} = {r['F']:.13f}  loose {fmt(r['F_loose'])}  |diff| "
                  f"{'-' if dl is None else f'{dl:.1e}'}  err est {r['err']:.1e}  "
                  f"[{r['lines']} event lines, {r['cells']} cells, {r['points']} points, "
                  f"{r['leaves']} leaves, {r['status']}, {dt:.1f} s]")
            if r["status"] != "converged":
                ok = False
        print(f"   reciprocity |A_i F_ij - A_j F_ji| = {recip:.1e}")
        entry = dict(name=c["name"], i=c["i"], j=c["j"], occluders=c["occluders"],
                     F_ij=rij["F"], F_ij_loose=rij["F_loose"],
                     F_ji=rji["F"], F_ji_loose=rji["F_loose"],
                     A_i=Ai, A_j=Aj, err_est_ij=rij["err"], err_est_ji=rji["err"],
                     tol=args.tol, tol_loose=args.tol_loose, note=c["note"])
        if c["closed"] is not None and not args.skip_validation:
            cl = c["closed"]
            vals = {}
            for lab, prm, r in (("F_ij", cl, rij), ("F_ji", mirror_closed(cl), rji)):
                v24 = closed_form_parallel(prm["i"], prm["j"], 1.0, prm["blockers"], 24)
                v32 = closed_form_parallel(prm["i"], prm["j"], 1.0, prm["blockers"], 32)
                d = abs(r["F"] - v32)
                good = d <= 1e-10
                ok &= good
                vals[lab] = v32
                print(f"   (b) closed form {lab}: {v32:.13f} (24 pts {v24:.13f}, "
                      f"|24-32| {abs(v24 - v32):.1e})  |cubature - closed| {d:.1e}  "
                      f"{'OK' if good else 'FAIL'}")
            entry["closed_form_F_ij"] = vals["F_ij"]
            entry["closed_form_F_ji"] = vals["F_ji"]
        results.append(entry)
        rows.append((c["name"], rij, rji, recip))
    print("== summary")
    print(f"{'case':24s} {'F_ij':>17s} {'F_ji':>17s} {'|ij-loose|':>10s} "
          f"{'|ji-loose|':>10s} {'recip':>8s}")
    for name, rij, rji, recip in rows:
        dl1 = abs(rij["F"] - rij["F_loose"]) if rij["F_loose"] is not None else float("nan")
        dl2 = abs(rji["F"] - rji["F_loose"]) if rji["F_loose"] is not None else float("nan")
        print(f"{name:24s} {rij['F']:17.13f} {rji['F']:17.13f} {dl1:10.1e} {dl2:10.1e} "
              f"{recip:8.1e}")
    print(f"total time {time.time() - t_start:.1f} s; {'ALL OK' if ok else 'SOME CHECK FAILED'}")
    if args.write:
        with open(args.write, "w") as fh:
            json.dump(results, fh, indent=1)
            fh.write("\n")
        print(f"wrote {args.write}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
