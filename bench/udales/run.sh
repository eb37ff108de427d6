#!/usr/bin/env bash
# uDALES's own preprocessing checks on ffstream's files (bench/udales/README.md).
#
#   bench/udales/run.sh [UDALES] [EXPNR]
#
# UDALES: a uDALES checkout (a directory), or a git URL to clone (default
# https://github.com/uDALES/u-dales). EXPNR: the example (default 201: 994 facets, the
# one that ships its STL and View3D's sky view factors). Computes the example's STL one
# patch per facet, exports it with `ffstream export --udales`, and runs
# bench/udales/check.py (uDALES's read and condition path) in a virtual environment
# with the packages that path imports (numpy, scipy, trimesh). With UDPREP=1 it also
# installs uDALES's tools/python/requirements.txt in a second environment (about 1.5 GB:
# VTK, PyVista, numba) and runs bench/udales/udprep_path.py: UDPrep itself on a copy of
# the example with ffstream's files. Prints the uDALES commit.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
src=${1:-https://github.com/uDALES/u-dales}
expnr=${2:-201}
ffstream=${FFSTREAM:-$root/target/release/ffstream}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if [ -d "$src" ]; then
  udales=$(cd "$src" && pwd)
else
  git clone -q --depth 1 "$src" "$work/u-dales"
  udales=$work/u-dales
fi
echo "uDALES: $src at $(git -C "$udales" rev-parse HEAD)"
echo "ffstream: $(git -C "$root" rev-parse --short HEAD) ($("$ffstream" --version))"
example=$udales/examples/$expnr
stl=$(find "$example" -maxdepth 1 -iname "*.stl" | sort | head -1)
[ -n "$stl" ] || { echo "no STL in $example" >&2; exit 1; }
exp=$work/exp
mkdir -p "$exp"
cp "$stl" "$exp/"
stl=$exp/$(basename "$stl")
/usr/bin/time -f "compute: %e s wall, %U s user, %M KiB max RSS" \
  "$ffstream" compute "$stl" --max-edge 1e9 --quiet -o "$work/F.ffz"
"$ffstream" export "$work/F.ffz" --udales "$exp" --expnr "$expnr"
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install -q --disable-pip-version-check numpy scipy trimesh
reference=$example/svf.inp.$expnr
"$work/venv/bin/python" "$here/check.py" "$udales" "$exp" "$expnr" "$stl" "$reference"
if [ "${UDPREP:-0}" = 1 ]; then
  case=$work/cases/$expnr  # udprep wants the directory named as the experiment
  mkdir -p "$work/cases"
  cp -r "$example" "$case"
  cp "$exp/vfsparse.inp.$expnr" "$exp/svf.inp.$expnr" "$case/"
  python3 -m venv "$work/full"
  "$work/full/bin/pip" install -q --disable-pip-version-check -r "$udales/tools/python/requirements.txt"
  "$work/full/bin/python" "$here/udprep_path.py" "$udales" "$case" "$expnr"
fi
