"""uDALES's preprocessing itself on ffstream's files (bench/udales/README.md).

Loads the experiment with `UDPrep(expnr, expdir, load_geometry=True)` (geometry read by
UDGeom through trimesh, namoptions through f90nml) and calls
`prep.radiation.calc_view_factors()`: with vfsparse.inp.NNN and svf.inp.NNN present it
takes the branch "using existing output; external solver not run", reads both files,
conditions them (UDALES_VIEW_FACTOR_POLICY, default `repair`; `strict` validates only)
and prints what it found. This script prints what the call returns, and which of the
two files uDALES rewrote.

Usage: udprep_path.py UDALES_DIR EXPDIR EXPNR
"""
import hashlib
import sys
from pathlib import Path

import numpy as np

udales, expdir, expnr = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
sys.path.insert(0, str(udales / "tools" / "python"))
from udprep import UDPrep  # noqa: E402

files = [expdir / f"vfsparse.inp.{expnr}", expdir / f"svf.inp.{expnr}"]
before = {f: hashlib.sha256(f.read_bytes()).hexdigest() for f in files}
svf_before = np.loadtxt(files[1])
prep = UDPrep(expnr, expdir, load_geometry=True)
print(f"[udprep] view3d_out={prep.radiation.view3d_out} lvfsparse={prep.radiation.lvfsparse} "
      f"policy={prep.radiation.view_factor_policy}")
vf, svf, paths = prep.radiation.calc_view_factors()
print(f"[udprep] calc_view_factors returned vf {vf.shape[0]}x{vf.shape[1]} nnz {vf.nnz}, "
      f"svf {svf.shape[0]} values (min {svf.min():.6f}, max {svf.max():.6f})")
for f in files:
    same = hashlib.sha256(f.read_bytes()).hexdigest() == before[f]
    print(f"[udprep] {f.name}: {'left as ffstream wrote it' if same else 'rewritten by uDALES'}")
print(f"[udprep] largest |svf(uDALES) - svf(ffstream)|: {np.max(np.abs(svf - svf_before)):.3e}")
