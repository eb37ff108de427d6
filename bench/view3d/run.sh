#!/bin/sh
# View3D against ffstream on the same facets: accuracy against two tight references and CPU.
#
#   bench/view3d/run.sh [quick|full|all]        (default: all = quick then full)
#
# What it does
#   1. Gets View3D (the uDALES fork, commit bdb2aff): from $VIEW3D_SRC (a source tree with
#      src/Makefile, or a git directory, bare or not, holding that commit), else a
#      `git clone https://github.com/uDALES/View3D` into $V3D_CACHE. Builds it with
#      `make CC=cc CFLAGS="-O3 -march=native"` (its Makefile takes both from the command line).
#   2. Checks the orientation convention on two unit squares 1 apart facing each other
#      (F = 0.19982 with the OBJ's counter-clockwise-front order kept, 0 when reversed, the
#      same with ffstream); stops if it fails.
#   3. For each case (quick: edges <= $E_QUICK, a few hundred facets; full: edges <= $E_FULL,
#      about 3000 facets) and each scene:
#        cut      builtin:city with the ground cut around the building footprints
#                 (cut_ground.py; what uDALES meshes: no facet under a building)
#        asbuilt  builtin:city as ffstream writes it (one ground quad under every building)
#      writes the facets (subdivide_obj.py), then runs, all single-threaded:
#        v3d-default   View3D at its defaults (eps 1e-4, maxU 12, maxO 8, minO 0)
#        v3d-tight     View3D eps 1e-6 maxU 12 maxO 12 minO 2
#        ff-default    ffstream compute (accurate preset: rays, 16 per pair); the occluders
#                      are then the facets themselves (2 triangles per quad facet)
#        ff-default+occ    the same with --occluders city_in.obj (visibility against the
#                      unsplit faces of the same geometry, as ffstream does for a scene it
#                      subdivides itself)
#        ff-exact1e-2  --visibility exact --shadow-tol 1e-2 (and ff-exact1e-2+occ)
#        ff-ref        --preset reference --occluders city_in.obj (exact visibility to 1e-6
#                      for pairs with <= 32 candidate occluder triangles, 256 rays for the
#                      others, quadrature near machine
#                      precision); only every $REF_EVERY-th row (quick: $REF_EVERY_QUICK-th; the facets
#                      written with a black material elsewhere and --rows needed
#                      --symmetric off: same geometry, only those rows computed)
#      each CPU time taken by timed.py (os.wait4 of the child), then compare.py against
#      ff-ref and v3d-tight, then mc_rows.py (independent Monte Carlo) on the rows where the
#      two references disagree most, and compare.py again with those.
#   Results: $OUT/<case>-<scene>/table.md (and the runs' logs and times.json there),
#   $OUT/summary.md (all tables, the View3D commit, ffstream --version, load averages).
#
# Environment
#   VIEW3D_SRC   View3D source tree or git dir (e.g. /work/.mirror/uDALES+View3D/repo)
#   V3D_CACHE    clone cache (default ${XDG_CACHE_HOME:-$HOME/.cache}/ffstream-view3d)
#   FFSTREAM     ffstream binary (default target/release/ffstream; copied into $OUT first so a
#                rebuild during the run does not change it)
#   PYTHON       python with numpy, scipy, zstandard, crc32c and ffz (pip install ./formats)
#                (default: ./venv, ./.venv or /tmp/v3dvenv if they exist, else python3)
#   OUT          output directory (default bench/view3d/out)
#   E_QUICK      facet edge of the quick case (default 10: 551 / 424 facets)
#   E_FULL       facet edge of the full case (default 3: 3131 / 3009 facets)
#   REF_EVERY    full case: ff-ref on every REF_EVERY-th row (default 10; 1 = all rows)
#   REF_EVERY_QUICK  the same for the quick case (default 5: its 10 m facets make exact
#                visibility slow, ~1.7 CPU-s a row)
#   SCENES       scenes to run (default "cut asbuilt")
#   JOBS         1 (default) or 2: run v3d-tight and ff-ref side by side (CPU times stay
#                per process)
#   MC_ROWS      rows checked by Monte Carlo per scene (default 4; 0 = none)
#   MC_RAYS      rays per Monte Carlo row (default 200000)
set -eu

HERE=$(cd "$(dirname "$0")" && pwd)
REPO=$(cd "$HERE/../.." && pwd)
MODE=${1:-all}
OUT=${OUT:-$HERE/out}
E_QUICK=${E_QUICK:-10}
E_FULL=${E_FULL:-3}
REF_EVERY=${REF_EVERY:-10}
REF_EVERY_QUICK=${REF_EVERY_QUICK:-5}
SCENES=${SCENES:-"cut asbuilt"}
JOBS=${JOBS:-1}
MC_ROWS=${MC_ROWS:-4}
MC_RAYS=${MC_RAYS:-200000}
V3D_COMMIT=bdb2aff
V3D_URL=https://github.com/uDALES/View3D
V3D_CACHE=${V3D_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/ffstream-view3d}

die() { echo "run.sh: error: $*" >&2; exit 1; }
case $MODE in quick|full|all) ;; *) die "usage: $0 [quick|full|all]" ;; esac

if [ -z "${PYTHON:-}" ]; then
  for p in "$REPO/venv/bin/python" "$REPO/.venv/bin/python" /tmp/v3dvenv/bin/python; do
    if [ -x "$p" ]; then PYTHON=$p; break; fi
  done
  PYTHON=${PYTHON:-python3}
fi
"$PYTHON" -c "import numpy, scipy, ffz" 2>/dev/null || die "$PYTHON lacks numpy/scipy/ffz:
  python3 -m venv /tmp/v3dvenv && /tmp/v3dvenv/bin/pip install $REPO/formats; then PYTHON=/tmp/v3dvenv/bin/python"

mkdir -p "$OUT/bin"
FFSRC=${FFSTREAM:-$REPO/target/release/ffstream}
[ -x "$FFSRC" ] || die "no ffstream binary at $FFSRC (set FFSTREAM)"
cp "$FFSRC" "$OUT/bin/ffstream"
FF=$OUT/bin/ffstream
FF_VERSION=$("$FF" --version)

# ---- View3D: source, build -------------------------------------------------------------
V3D_BUILD=$OUT/build/view3d
get_view3d() {
  rm -rf "$V3D_BUILD"; mkdir -p "$V3D_BUILD"
  src=${VIEW3D_SRC:-}
  if [ -n "$src" ]; then
    if [ -f "$src/src/Makefile" ]; then
      cp -R "$src/." "$V3D_BUILD/"
      V3D_REV=$(git -C "$src" rev-parse --short HEAD 2>/dev/null || echo "unknown (tree $src)")
      return 0
    elif git -C "$src" rev-parse --git-dir >/dev/null 2>&1; then
      git -C "$src" archive "$V3D_COMMIT" | tar -x -C "$V3D_BUILD" \
        || die "$src holds no commit $V3D_COMMIT"
      V3D_REV=$(git -C "$src" rev-parse --short "$V3D_COMMIT")
      return 0
    else
      die "VIEW3D_SRC=$src is neither a View3D source tree (src/Makefile) nor a git directory"
    fi
  fi
  if [ ! -d "$V3D_CACHE/View3D/.git" ]; then
    mkdir -p "$V3D_CACHE"
    git clone -q "$V3D_URL" "$V3D_CACHE/View3D" \
      || die "cannot clone $V3D_URL into $V3D_CACHE (offline?); set VIEW3D_SRC to a View3D tree or git dir"
  fi
  git -C "$V3D_CACHE/View3D" archive "$V3D_COMMIT" | tar -x -C "$V3D_BUILD" \
    || die "the clone in $V3D_CACHE/View3D has no commit $V3D_COMMIT"
  V3D_REV=$(git -C "$V3D_CACHE/View3D" rev-parse --short "$V3D_COMMIT")
}
get_view3d
make -s -C "$V3D_BUILD/src" CC=cc CFLAGS="-O3 -march=native" >"$OUT/build/make.log" 2>&1 \
  || die "View3D build failed, see $OUT/build/make.log"
V3D=$V3D_BUILD/src/View3D
[ -x "$V3D" ] || die "no View3D binary after the build"
echo "View3D $V3D_REV built: $V3D (cc -O3 -march=native); $FF_VERSION"

# ---- orientation check -----------------------------------------------------------------
CHK=$OUT/convention
mkdir -p "$CHK"
cat >"$CHK/squares.obj" <<'EOF'
# two unit squares 1 apart facing each other (counter-clockwise = front)
mtllib squares.mtl
usemtl grey
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 0 1 1
v 1 1 1
v 1 0 1
f 1 2 3 4
f 5 6 7 8
EOF
printf 'newmtl grey\nKd 0.5 0.5 0.5\nKe 1 1 1\n' >"$CHK/squares.mtl"
"$PYTHON" "$HERE/obj2vs3.py" "$CHK/squares.obj" "$CHK/kept.vs3" --out 0
"$PYTHON" "$HERE/obj2vs3.py" "$CHK/squares.obj" "$CHK/reversed.vs3" --out 0 --reverse
(cd "$CHK" && "$V3D" kept.vs3 kept.txt >/dev/null 2>&1 && "$V3D" reversed.vs3 reversed.txt >/dev/null 2>&1) \
  || die "View3D failed on the squares (see $CHK/View3D.log)"
"$FF" compute "$CHK/squares.obj" --max-edge 2 --threads 1 -q --force -o "$CHK/squares.ffz" 2>"$CHK/ff.log" \
  || die "ffstream failed on the squares (see $CHK/ff.log)"
"$PYTHON" - "$CHK" >"$CHK/result.txt" <<'EOF' || { cat "$CHK/result.txt"; die "orientation check failed"; }
import sys, ffz
d = sys.argv[1]
kept = float(open(d + "/kept.txt").read().splitlines()[2].split()[1])
rev = float(open(d + "/reversed.txt").read().splitlines()[2].split()[1])
ff = float(ffz.open(d + "/squares.ffz").row(0)[1][1])
exact = 0.1998248957
print(f"orientation check: View3D order kept F12 = {kept:.6f}, reversed {rev:.6f}; "
      f"ffstream {ff:.7f}; exact {exact}")
ok = abs(kept - exact) < 2e-5 and rev == 0.0 and abs(ff - exact) < 1e-6
sys.exit(0 if ok else 1)
EOF
cat "$CHK/result.txt"

# ---- the cases ---------------------------------------------------------------------------
SUMMARY=$OUT/summary.md
{
  echo "# View3D against ffstream, $(date -u +%Y-%m-%dT%H:%MZ)"
  echo
  echo "- View3D: uDALES fork, commit $V3D_REV, cc -O3 -march=native ($(cc --version | head -1))"
  echo "- $FF_VERSION ($FFSRC)"
  echo "- $(cat "$CHK/result.txt")"
  echo "- load average at start: $(cat /proc/loadavg)"
  echo
} >"$SUMMARY"

tsec() { "$PYTHON" "$HERE/timed.py" "$@"; }

run_scene() {  # case scene edge ref_every
  case_=$1; scene=$2; E=$3; every=$4
  D=$OUT/$case_-$scene
  rm -rf "$D"; mkdir -p "$D"
  T=$D/times.json
  echo "== $case_ $scene: edges <= $E (load $(cut -d' ' -f1-3 /proc/loadavg))"
  "$FF" scene city -o "$D/city.obj" -q
  if [ "$scene" = cut ]; then
    "$PYTHON" "$HERE/cut_ground.py" "$D/city.obj" "$D/city_in.obj"
  else
    cp "$D/city.obj" "$D/city_in.obj"
  fi
  "$PYTHON" "$HERE/subdivide_obj.py" "$D/city_in.obj" "$D/facets.obj" --max-edge "$E"
  N=$(grep -c '^f ' "$D/facets.obj")
  MAXE=$("$PYTHON" -c "print('%.6g' % ($E * 1.001))")
  "$PYTHON" "$HERE/obj2vs3.py" "$D/facets.obj" "$D/v3d_default.vs3"
  "$PYTHON" "$HERE/obj2vs3.py" "$D/facets.obj" "$D/v3d_tight.vs3" --eps 1e-6 --maxU 12 --maxO 12 --minO 2
  mkdir -p "$D/v3d-default" "$D/v3d-tight"
  FFC="$FF compute --max-edge $MAXE --threads 1 -q --force"
  tsec "$T" v3d-default --cwd "$D/v3d-default" -- "$V3D" ../v3d_default.vs3 F.bin
  OCC="--occluders $D/city_in.obj"
  tsec "$T" ff-default -- $FFC "$D/facets.obj" -o "$D/ff-default.ffz"
  tsec "$T" ff-default+occ -- $FFC "$D/facets.obj" -o "$D/ff-default+occ.ffz" $OCC
  tsec "$T" ff-exact1e-2 -- $FFC "$D/facets.obj" -o "$D/ff-exact1e-2.ffz" --visibility exact --shadow-tol 1e-2
  tsec "$T" ff-exact1e-2+occ -- $FFC "$D/facets.obj" -o "$D/ff-exact1e-2+occ.ffz" --visibility exact --shadow-tol 1e-2 $OCC
  if [ "$every" -gt 1 ]; then
    "$PYTHON" "$HERE/subdivide_obj.py" "$D/city_in.obj" "$D/facets_sampled.obj" --max-edge "$E" --sample-every "$every"
    NS=$(( (N + every - 1) / every ))
    set -- ff-ref --rows-computed "$NS" --rows-total "$N" -- $FFC "$D/facets_sampled.obj" -o "$D/ff-ref.ffz" \
      --preset reference --rows needed --symmetric off $OCC
  else
    set -- ff-ref -- $FFC "$D/facets.obj" -o "$D/ff-ref.ffz" --preset reference $OCC
  fi
  if [ "$JOBS" -ge 2 ]; then
    tsec "$T" v3d-tight --cwd "$D/v3d-tight" -- "$V3D" ../v3d_tight.vs3 F.bin &
    p1=$!
    tsec "$T" "$@" &
    p2=$!
    wait $p1 || die "v3d-tight failed (see $D/v3d-tight.log)"
    wait $p2 || die "ff-ref failed (see $D/ff-ref.log)"
  else
    tsec "$T" v3d-tight --cwd "$D/v3d-tight" -- "$V3D" ../v3d_tight.vs3 F.bin
    tsec "$T" "$@"
  fi
  CMP="--obj $D/facets.obj --times $T --footprints
    --v3d v3d-default=$D/v3d-default/F.bin --v3d v3d-tight=$D/v3d-tight/F.bin
    --ffz ff-default=$D/ff-default.ffz --ffz ff-default+occ=$D/ff-default+occ.ffz
    --ffz ff-exact1e-2=$D/ff-exact1e-2.ffz --ffz ff-exact1e-2+occ=$D/ff-exact1e-2+occ.ffz
    --ffz ff-ref=$D/ff-ref.ffz
    --ref ff-ref --ref v3d-tight"
  "$PYTHON" "$HERE/compare.py" $CMP --worst-rows "$D/worst.txt" --out "$D/table.md" >/dev/null
  if [ "$MC_ROWS" -gt 0 ]; then
    rows=$(head -n "$MC_ROWS" "$D/worst.txt" | paste -sd, -)
    tsec "$T" mc -- "$PYTHON" "$HERE/mc_rows.py" "$D/facets.obj" --rows "$rows" --rays "$MC_RAYS" --out "$D/mc.npz"
    "$PYTHON" "$HERE/compare.py" $CMP --mc "$D/mc.npz" --out "$D/table.md"
  else
    cat "$D/table.md"
  fi
  {
    echo "## $case_, $scene: $N facets, edges <= $E"
    echo
    cat "$D/table.md"
    echo
  } >>"$SUMMARY"
}

for case_ in quick full; do
  [ "$MODE" = all ] || [ "$MODE" = "$case_" ] || continue
  if [ "$case_" = quick ]; then E=$E_QUICK; every=$REF_EVERY_QUICK; else E=$E_FULL; every=$REF_EVERY; fi
  for scene in $SCENES; do
    run_scene "$case_" "$scene" "$E" "$every"
  done
done
echo "- load average at the end: $(cat /proc/loadavg)" >>"$SUMMARY"
echo "wrote $SUMMARY"
