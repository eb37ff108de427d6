#!/bin/sh
# The unit cube as 6144 OBJ facets (each face split 32 x 32), against builtin:cube at the
# same patches and against View3D on the same facets (issue 19, bench/PERF.md §21).
#
#   VIEW3D=/path/to/View3D sh bench/view3d/cube.sh     (View3D built by run.sh:
#                                                       $OUT/build/view3d/src/View3D)
# Environment: FFSTREAM (default target/release/ffstream, copied first), PYTHON (with
# numpy and ffz, as for run.sh), OUT (default bench/view3d/out/cube).
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
uptime > load.txt
$T ff-builtin -- $F compute builtin:cube --max-edge 0.03125 --threads 1 -q --force -o builtin.ffz
$T ff-facets -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o facets.ffz
$T ff-facets-fast -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o fast.ffz --preset fast
$T ff-facets-nomerge -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o nomerge.ffz --no-merge-occluders
$T ff-facets-qtol1e-3 -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o qtol1e-3.ffz --quad-tol 1e-3
$T ff-facets-qtol1e-1 -- $F compute facets.obj --max-edge 0.03126 --threads 1 -q --force -o qtol1e-1.ffz --quad-tol 0.1
(cd v3d && $PYTHON "$HERE/timed.py" ../times.json v3d-default -- "$VIEW3D" ../v3d_default.vs3 F.bin)
uptime >> load.txt
$PYTHON "$HERE/cube_compare.py" facets.obj ff-facets=facets.ffz ff-facets-fast=fast.ffz \
  ff-facets-qtol1e-3=qtol1e-3.ffz ff-facets-qtol1e-1=qtol1e-1.ffz v3d-default=v3d/F.bin
