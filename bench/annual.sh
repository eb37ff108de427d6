#!/usr/bin/env bash
# Issue 22's benchmark: `ffstream annual` on a 5k-patch room with about 100 sensors for
# every hour of a year, timed after the form factors, and its peak RSS against the same
# run on a quarter of the year (memory must not grow with the hours beyond the output).
#
#   bench/annual.sh [BINARY] [PATCHES]    (default: target/release/ffstream 5000)
#
# Prints one Markdown table row per run: hours, patches, sensors, wall s of `annual`
# (form factors excluded: they are computed first, once), peak RSS MB, outputs MB.
set -euo pipefail
bin=${1:-target/release/ffstream}
patches=${2:-5000}
weather=tests/data/weather/723170TYA.CSV.zst
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
"$bin" compute builtin:office --patches "$patches" -q -o "$dir/f.ffz" 2>/dev/null
zstd -dcq "$weather" -o "$dir/year.csv"
head -n 2192 "$dir/year.csv" > "$dir/quarter.csv"   # 2 header lines + 2190 hours
echo "| hours | patches | sensors | annual wall s | peak RSS MB | outputs MB | load |"
echo "|---|---|---|---|---|---|---|"
for w in "$weather" "$dir/quarter.csv"; do
  out="$dir/out"
  rm -rf "$out"
  start=$(date +%s.%N)
  "$bin" annual builtin:office --ffz "$dir/f.ffz" --weather "$w" --grid floor:0.49 \
    -o "$out" > "$dir/stdout" 2> "$dir/stderr"
  end=$(date +%s.%N)
  rss=$(sed -n 's/.*peak RSS \([0-9]*\) MB.*/\1/p' "$dir/stderr" | tail -1)
  hours=$(( $(wc -l < "$out/illuminance.csv") - 1 ))
  sensors=$(( $(wc -l < "$out/metrics.csv") - 1 ))
  n=$("$bin" info "$dir/f.ffz" | sed -n 's/^n: *\([0-9]*\) patches.*/\1/p')
  mb=$(( $(du -sb "$out" | cut -f1) / 1000000 ))
  echo "| $hours | $n | $sensors | $(echo "$end - $start" | awk '{printf "%.1f", $1 - $3}') | $rss | $mb | $(cut -d' ' -f1 /proc/loadavg) |"
done
