#!/bin/sh
# A/B of the exact visibility route: two ffstream binaries, alternating, on the same
# scenes in one run (bench/PERF.md §27). CPU from os.wait4 (bench/view3d/timed.py).
#
#   BASE=/path/to/old/ffstream NEW=target/release/ffstream OUT=/tmp/exact-ab \
#     sh bench/exact_ab.sh
#
# Optional: CASES (default below: scene:patches:shadow-tol), ROUNDS (default 1),
# THREADS (default 2). Each case's files are compared with `verify --against`
# (the largest entry difference, which must stay within the shadow tolerance).
set -eu
: "${BASE:?set BASE to the ffstream binary to compare against}"
NEW=${NEW:-target/release/ffstream}
OUT=${OUT:-/tmp/exact-ab}
ROUNDS=${ROUNDS:-1}
THREADS=${THREADS:-2}
CASES=${CASES:-"cornell:2000:1e-3 room:2000:1e-3 city:1000:1e-2"}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT"
TIMES="$OUT/times.json"
round=1
while [ "$round" -le "$ROUNDS" ]; do
    for case in $CASES; do
        scene=${case%%:*}
        rest=${case#*:}
        patches=${rest%%:*}
        tol=${rest#*:}
        for side in base new; do
            if [ "$side" = base ]; then bin=$BASE; else bin=$NEW; fi
            name="$scene-$patches-$tol-$side-r$round"
            python3 "$HERE/view3d/timed.py" "$TIMES" "$name" -- \
                "$bin" compute "builtin:$scene" --patches "$patches" --visibility exact \
                --shadow-tol "$tol" --threads "$THREADS" -o "$OUT/$name.ffz" --force
        done
        "$NEW" verify "$OUT/$scene-$patches-$tol-new-r$round.ffz" \
            --against "$OUT/$scene-$patches-$tol-base-r$round.ffz" \
            >"$OUT/$scene-$patches-$tol-verify-r$round.txt" 2>&1 || true
    done
    round=$((round + 1))
done
python3 - "$TIMES" "$OUT" <<'EOF'
import json, sys, glob, re
times = json.load(open(sys.argv[1]))
for name, t in sorted(times.items()):
    print(f"{name:32s} cpu {t['cpu_s']:8.1f} s  wall {t['wall_s']:7.1f} s  load {t.get('loadavg_before')}")
for f in sorted(glob.glob(sys.argv[2] + "/*-verify-*.txt")):
    line = [l for l in open(f) if "rows compared" in l]
    print(f.split("/")[-1], line[0].strip() if line else "(no comparison)")
EOF
