#!/bin/sh
# The unit cube as 6144 OBJ facets (each face split 32 x 32), against builtin:cube at the
# same patches and against View3D on the same facets (issue 19, bench/PERF.md §21).
#
#   VIEW3D=/path/to/View3D sh bench/view3d/cube.sh     (View3D built by run.sh:
#                                                       $OUT/build/view3d/src/View3D)
# Environment: FFSTREAM (default target/release/ffstream, copied first), PYTHON (with
# numpy and ffz, as for run.sh), OUT (default bench/view3d/out/cube), AB (default 5:
# after the single runs, AB rounds that alternate ffstream at --quad-tol 1e-3 and 0.1
# with View3D at its default and at eps 1e-6, for CPU ratios taken in one run:
# medians printed at the end, every run in ab.json; 0 skips them).
set -eu
HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../.." && pwd)
OUT=${OUT:-$HERE/out/cube}
PYTHON=${PYTHON:-python3}
: "${VIEW3D:?set VIEW3D to the View3D binary (run.sh builds it)}"
mkdir -p "$OUT/v3d"
cp "${FFSTREAM:-$REPO/target/release/ffstream}" "$OUT/ffstream"
cd "$OUT"
F=./ffstream
T="$PYTHON $HERE/timed.py times.json"
rm -f times.json
$F scene cube -o cube.obj
$PYTHON "$HERE/subdivide_obj.py" --max-edge 0.03125 cube.obj facets.obj
$PYTHON "$HERE/obj2vs3.py" facets.obj v3d_default.vs3
$PYTHON "$HERE/obj2vs3.py" facets.obj v3d_tight.vs3 --eps 1e-6
uptime > load.txt
$T ff-builtin -- $F compute builtin:cube --max-edge 0.03125 --threads 1 -q --force -o builtin.ffz
$T ff-facets -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o facets.ffz
$T ff-facets-fast -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o fast.ffz --preset fast
$T ff-facets-nomerge -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o nomerge.ffz --no-merge-occluders
$T ff-facets-qtol1e-3 -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o qtol1e-3.ffz --quad-tol 1e-3
$T ff-facets-qtol1e-1 -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o qtol1e-1.ffz --quad-tol 0.1
mkdir -p v3d_tight
(cd v3d && $PYTHON "$HERE/timed.py" ../times.json v3d-default -- "$VIEW3D" ../v3d_default.vs3 F.bin)
(cd v3d_tight && $PYTHON "$HERE/timed.py" ../times.json v3d-tight -- "$VIEW3D" ../v3d_tight.vs3 F.bin)
uptime >> load.txt
$PYTHON "$HERE/cube_compare.py" facets.obj ff-facets=facets.ffz ff-facets-fast=fast.ffz \
  ff-facets-qtol1e-3=qtol1e-3.ffz ff-facets-qtol1e-1=qtol1e-1.ffz v3d-default=v3d/F.bin \
  v3d-tight=v3d_tight/F.bin
# The same runs alternating, AB rounds: CPU ratios that the machine's drift (tens of
# per cent between minutes under other load) does not decide.
rm -f ab.json
k=0
while [ "$k" -lt "${AB:-5}" ]; do
  k=$((k + 1))
  $PYTHON "$HERE/timed.py" ab.json "ff-qtol1e-3-$k" -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o ab.ffz --quad-tol 1e-3
  (cd v3d && $PYTHON "$HERE/timed.py" ../ab.json "v3d-default-$k" -- "$VIEW3D" ../v3d_default.vs3 F.bin)
  $PYTHON "$HERE/timed.py" ab.json "ff-qtol1e-1-$k" -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o ab.ffz --quad-tol 0.1
  (cd v3d_tight && $PYTHON "$HERE/timed.py" ../ab.json "v3d-tight-$k" -- "$VIEW3D" ../v3d_tight.vs3 F.bin)
done
if [ -f ab.json ]; then
  $PYTHON - <<'PY'
import json
import statistics

runs = json.load(open("ab.json"))
cpu = {}
for name, r in runs.items():
    cpu.setdefault(name.rsplit("-", 1)[0], []).append(r["cpu_s"])
med = {k: statistics.median(v) for k, v in cpu.items()}
for k, v in cpu.items():
    print(f"  {k}: CPU s {' '.join(f'{x:.2f}' for x in v)}, median {med[k]:.2f}")
for ff in ("ff-qtol1e-3", "ff-qtol1e-1"):
    for v3 in ("v3d-default", "v3d-tight"):
        print(f"  {ff} / {v3}: {med[ff] / med[v3]:.2f}")
PY
fi
