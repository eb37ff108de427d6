#!/usr/bin/env bash
# Peak RSS of `ffstream export` (Matrix Market, sparse text, .npz and the patch table in
# one run) on dense files of two sizes: streaming export must not grow with n^2.
#
#   bench/export_memory.sh [BINARY] [N1] [N2]     (default: target/release/ffstream 2000 8000)
#
# Needs GNU time (/usr/bin/time, `make deps` installs it). Prints one Markdown table row
# per size: n, file MB, output MB, wall s, peak RSS MB.
set -euo pipefail
bin=${1:-target/release/ffstream}
sizes=("${2:-2000}" "${3:-8000}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
echo "| n | .ffz MB | dense n^2 f32 MB | outputs MB | export wall s | export peak RSS MB |"
echo "|---|---|---|---|---|---|"
for n in "${sizes[@]}"; do
  "$bin" compute builtin:room:16 --patches "$n" --preset fast -q -o "$dir/f$n.ffz" 2>/dev/null
  real=$("$bin" info "$dir/f$n.ffz" | sed -n 's/^n: *\([0-9]*\) patches.*/\1/p')
  /usr/bin/time -f '%e %M' -o "$dir/time$n" "$bin" export "$dir/f$n.ffz" \
    --matrix "$dir/f$n.mtx" --sparse "$dir/f$n.txt" --npz "$dir/f$n.npz" --patches-csv "$dir/f$n.csv"
  read -r wall rss_kb < "$dir/time$n"
  ffz_mb=$(( $(stat -c %s "$dir/f$n.ffz") / 1000000 ))
  out_mb=$(( ( $(stat -c %s "$dir/f$n.mtx") + $(stat -c %s "$dir/f$n.txt") + $(stat -c %s "$dir/f$n.npz") + $(stat -c %s "$dir/f$n.csv") ) / 1000000 ))
  echo "| $real | $ffz_mb | $(( real * real * 4 / 1000000 )) | $out_mb | $wall | $(( rss_kb / 1000 )) |"
  rm -f "$dir"/f"$n".*
done
