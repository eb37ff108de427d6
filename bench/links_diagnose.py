#!/usr/bin/env python3
"""Where a linked file's radiosity error comes from (issue 44; bench/LINKS.md).

Reads a dense file and a linked top-k file of the same mesh (`ffstream compute ... -o`)
with the Python reader, solves B = E + rho F B directly (scipy) for several models of
the linked mass, and prints each model's worst surface and total radiosity power
against the dense rows:

- the file as stored (kept entries plus links expanded by spec 5.7);
- true link masses (dense rows summed over each link's patches), stored slopes,
  plus the "orphans" (dense mass on columns neither kept nor in a stored link);
- slopes from the exact F-weighted centroid of each link (dense rows), with the
  stored or the true masses, limited at several least weights or not at all.

    python3 bench/links_diagnose.py DENSE.ffz LINKED.ffz

Slow (Python loops over every link): minutes at 3k patches.
"""
import os
import sys

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "formats"))
import ffz  # noqa: E402


def main(dense_path, linked_path):
    d = ffz.open(dense_path).read()
    dense = sp.csr_matrix(d.matrix, dtype=np.float64)
    r = ffz.open(linked_path)
    kept = sp.csr_matrix(r.read().matrix, dtype=np.float64)
    links = r.link_matrix().tocsr()
    n, area = r.n, r.patches["area"]
    rho, emit = r.patches["rho"].astype(float), r.patches["emission"].astype(float)
    group = r.patches["group"]
    x, order = r.centroids(), r.cluster_order

    def solve(m):
        b = np.zeros((n, 3))
        for c in range(3):
            a = sp.identity(n, format="csc") - sp.diags(rho[:, c]) @ m
            b[:, c] = sla.spsolve(a.tocsc(), emit[:, c])
        return b

    ref = solve(dense)

    def report(tag, m):
        b = solve(m)
        worst = (0.0, None)
        for g in np.unique(group):
            s = group == g
            for c in range(3):
                e = (area[s] @ b[s, c]) / (area[s] @ ref[s, c]) - 1
                if abs(e) > abs(worst[0]):
                    worst = (e, r.groups[g] if r.groups is not None else g)
        power = (area @ b.sum(1)) / (area @ ref.sum(1)) - 1
        print(f"{tag:58s} worst {worst[0] * 100:+.2f} % ({worst[1]}), power {power * 100:+.2f} %", flush=True)

    report("as stored", kept + links)
    cover = ((kept != 0).astype(float) + (links != 0).astype(float)).tocsr()
    cover.data[:] = 1.0
    orphans = dense - dense.multiply(cover)
    lost = np.asarray(orphans.sum(1)).ravel()
    print(f"orphan mass a row: mean {lost.mean():.4f}, max {lost.max():.4f}")

    def model(true_mass, centroid, limit):
        rows, cols, vals = [], [], []
        for i in range(n):
            starts, lens, values, slopes = r.links(i)
            own = set(kept.indices[kept.indptr[i] : kept.indptr[i + 1]].tolist()) | {i}
            drow = dense.getrow(i).toarray().ravel()
            for a, ln, v, q in zip(starts.tolist(), lens.tolist(), values.tolist(), slopes.astype(float)):
                rng = order[a : a + ln].astype(np.int64)
                total = area[rng].sum()
                mean = area[rng] @ x[rng] / total
                js = rng[~np.isin(rng, list(own))]
                mass = drow[js].sum() if true_mass else v
                if mass <= 0:
                    continue
                if centroid:
                    c = drow[js] @ x[js] / drow[js].sum() if drow[js].sum() > 0 else mean
                    dx = x[rng] - mean
                    w_, v_ = np.linalg.eigh((area[rng][:, None] * dx).T @ dx)
                    inv = np.where(w_ > 1e-6 * w_.max(), 1 / np.where(w_ > 0, w_, 1), 0)
                    q = total * (v_ @ (inv * (v_.T @ (c - mean))))
                    if limit is not None:
                        lo, hi = x[rng].min(0), x[rng].max(0)
                        least = np.minimum(q * (lo - mean), q * (hi - mean)).sum()
                        if least < limit - 1:
                            q = q * ((1 - limit) / -least)
                w = area[js] * (1 + (x[js] - mean) @ q)
                if w.sum() > 0:
                    rows.append(np.full(len(js), i))
                    cols.append(js)
                    vals.append(mass * w / w.sum())
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))

    report("true masses, stored slopes, orphans added", kept + model(True, False, None) + orphans)
    report("stored masses, exact centroid, weights >= 0 at the box", kept + model(False, True, 0.0))
    report("true masses, exact centroid, weights >= 0, orphans", kept + model(True, True, 0.0) + orphans)
    report("true masses, exact centroid, weights >= 1/4, orphans", kept + model(True, True, 0.25) + orphans)
    report("true masses, exact centroid, no limit, orphans", kept + model(True, True, None) + orphans)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
