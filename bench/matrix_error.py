#!/usr/bin/env python3
"""Errors of .ffz matrices against a reference .ffz of the same scene (bench/PERF.md §27).

    PYTHONPATH=formats python3 bench/matrix_error.py REFERENCE.ffz FILE.ffz [FILE.ffz ...]

For each FILE: the largest entry error, the mean entry error, and the mean and largest
row L1 error (sum over a row of |F_ij - F_ij(ref)|), over the whole stored matrix, in
float64. Both files must have the same patches (same scene and subdivision).
"""

import sys

import numpy as np

import ffz


def dense(path):
    f = ffz.read(path)
    return f.matrix.toarray().astype(np.float64)


def main(argv):
    if len(argv) < 2:
        sys.exit(__doc__)
    ref = dense(argv[0])
    for path in argv[1:]:
        m = dense(path)
        if m.shape != ref.shape:
            sys.exit(f"{path}: {m.shape[0]} patches, the reference has {ref.shape[0]}")
        d = np.abs(m - ref)
        rows = d.sum(axis=1)
        print(f"{path}: largest entry {d.max():.2e}  mean entry {d.mean():.2e}  "
              f"mean row L1 {rows.mean():.2e}  largest row L1 {rows.max():.2e}")


if __name__ == "__main__":
    main(sys.argv[1:])
