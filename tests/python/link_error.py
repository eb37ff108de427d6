"""The link error a writer stores per row (spec 5.7, LINK_ERROR) against the true error
of the row's links, measured with dense rows of the same mesh.

    python3 link_error.py FORMATS_DIR DENSE.ffz LINKED.ffz DENSE_SOLVE.csv

For every row of LINKED with a link error: the true relative error of the radiosity it
gathers, |sum_j (F_dense - F_linked)_ij B_j| / sum_j F_dense_ij B_j, with F_linked its
kept entries plus its links expanded by the spec 5.7 rule and B the dense solve's
radiosity (mean of R, G, B, as the estimate's first-bounce radiosity is). Fails when
an estimate is below its row's true error, or when rows with links carry none. Prints
the rows, the mean and largest true error and estimate, and the least ratio.
"""
import sys

import numpy as np

sys.path.insert(0, sys.argv[1])
import ffz  # noqa: E402

dense, linked = ffz.open(sys.argv[2]), ffz.open(sys.argv[3])
t = np.genfromtxt(sys.argv[4], delimiter=",", names=True, dtype=None, encoding=None)
b = (t["B_r"] + t["B_g"] + t["B_b"]) / 3.0
d = dense.to_csr()
l = linked.to_csr() + linked.link_matrix()
true_gather = d @ b
err = np.abs(true_gather - l @ b)
est = linked.link_errors()
has_links = np.array([len(linked.links(i)[0]) > 0 for i in range(linked.n)])
missing = np.flatnonzero(has_links & np.isnan(est) & (true_gather > 0))
assert len(missing) == 0, f"rows with links but no link error: {missing[:10]}"
use = ~np.isnan(est) & (true_gather > 0)
rel = err[use] / true_gather[use]
ratio = est[use] / np.maximum(rel, 1e-300)
print(f"rows {use.sum()}: true error mean {rel.mean():.3e} max {rel.max():.3e}; "
      f"estimate mean {est[use].mean():.3e} max {est[use].max():.3e}; least ratio {ratio.min():.3f}")
under = np.flatnonzero(use)[est[use] < rel]
assert len(under) == 0, (
    f"{len(under)} rows whose link error understates the true error, e.g. row {under[0]}: "
    f"estimate {est[under[0]]:.3e}, true {err[under[0]] / true_gather[under[0]]:.3e}")
