"""uDALES's own checks on ffstream's files (bench/udales/README.md).

Runs the part of uDALES's preprocessing that takes existing view-factor output and
conditions it (`RadiationSection.calc_view_factors` in
tools/python/udprep/udprep_radiation.py, branch "using existing output; external
solver not run", with view3d_out=2 and lvfsparse=true): read vfsparse.inp with
`read_view3d_output(..., outformat=2)`, svf.inp with `np.loadtxt`, then
`_condition_view_factors`: the strict policy's `validate_view_factors` and the
default policy's `repair_view_factors`, with the facet areas of the STL as
`UDGeom` loads it (`trimesh.load_mesh`). uDALES's functions are imported from the
checkout's tools/python/udgeom/view3d.py itself (by path, so the udgeom package's other
modules and their dependencies are not needed); this script only calls them and prints
what they return. Also compares ffstream's sky view factors with the ones View3D gave
for the example, when the example ships them (REFERENCE_SVF).

Usage: check.py UDALES_DIR EXPDIR EXPNR STL [REFERENCE_SVF]
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np

udales, expdir, expnr, stl = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], sys.argv[4]
reference = Path(sys.argv[5]) if len(sys.argv) > 5 else None
sys.path.insert(0, str(udales / "tools" / "python"))  # view3d.py imports `exceptions`
spec = importlib.util.spec_from_file_location(
    "udales_view3d", udales / "tools" / "python" / "udgeom" / "view3d.py"
)
view3d = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = view3d  # dataclasses look their module up there
spec.loader.exec_module(view3d)
import trimesh  # noqa: E402  (view3d.py needs it too)

mesh = trimesh.load_mesh(str(stl))
nfacets = mesh.faces.shape[0]
areas = np.asarray(mesh.area_faces, dtype=float)
vf_path = expdir / f"vfsparse.inp.{expnr}"
svf_path = expdir / f"svf.inp.{expnr}"
print(f"[check] STL {stl}: {nfacets} facets (trimesh.load_mesh, as UDGeom)")
print(f"[check] lines in {vf_path.name}: {view3d.count_sparse_entries(vf_path)}")
vf = view3d.read_view3d_output(vf_path, nfacets=nfacets, outformat=2)
svf = np.loadtxt(svf_path)
print(f"[check] read_view3d_output: {vf.shape[0]}x{vf.shape[1]}, nnz {vf.nnz}; svf: {svf.shape[0]} values")

limits = view3d.ViewFactorRepairLimits()
report = view3d.inspect_view_factors(
    vf, svf, areas=areas, reciprocity_tolerance=limits.max_reciprocity_l1_relative
)
print(f"[check] inspect_view_factors: {report}")
print(f"[check] is_valid: {report.is_valid}")
for line in report.problem_messages():
    print(f"[check]   problem: {line}")
status = 0
try:
    view3d.validate_view_factors(
        vf, svf, areas=areas, reciprocity_tolerance=limits.max_reciprocity_l1_relative
    )
    print("[check] strict policy (validate_view_factors): passed")
except Exception as e:  # what uDALES would raise
    print(f"[check] strict policy (validate_view_factors): {type(e).__name__}: {e}")
    status = 1
try:
    repaired, sky, rep = view3d.repair_view_factors(vf, areas, limits=limits)
    print(f"[check] repair policy (repair_view_factors, uDALES's default): repaired={rep.repaired}")
    print(f"[check]   {rep}")
    moved = float(np.max(np.abs(sky - svf)))
    print(f"[check]   largest change of a sky view factor by the repair: {moved:.3e}")
except Exception as e:
    print(f"[check] repair policy: {type(e).__name__}: {e}")
    status = 1
if reference is not None and reference.exists():
    ref = np.loadtxt(reference)
    d = svf - ref
    w = areas / areas.sum()
    print(
        f"[check] svf against View3D's {reference.name}: mean |diff| {np.mean(np.abs(d)):.4f}, "
        f"max |diff| {np.max(np.abs(d)):.4f} (facet {int(np.argmax(np.abs(d))) + 1}), "
        f"area-weighted mean svf ffstream {np.dot(w, svf):.4f}, View3D {np.dot(w, ref):.4f}"
    )
sys.exit(status)
