#!/usr/bin/env bash
# Streaming vs --gather under a real mpirun (issue: the MPI service acceptance):
# rank 0's peak RSS, wall time and idle fraction, at two mesh sizes of the cluttered
# room, 1 I/O master + 2 workers (3 ranks) vs 3 computing ranks gathering at rank 0.
# The kernel is `point` (1 ray per pair that may be occluded): what is compared is the
# I/O design, not the kernel. Prints a Markdown table; usage:
#   bench/mpi_stream_vs_gather.sh [SIZES...]      (default: 5000 10000)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=./target/release/ffstream
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
sizes=("${@:-5000 10000}")
[ $# -eq 0 ] && sizes=(5000 10000)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "ffstream $(git rev-parse --short HEAD), $(date -u '+%Y-%m-%d %H:%M UTC'), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
echo
echo "| n | mode | wall [s] | rank 0 peak RSS [MB] | rank 0 idle | command |"
echo "|---|---|---|---|---|---|"
for n in "${sizes[@]}"; do
  for mode in stream gather; do
    extra=(); [ "$mode" = gather ] && extra=(--gather)
    cmd=(mpirun -n 3 --oversubscribe "$bin" compute builtin:room:200 --patches "$n" --method point --threads 1 -q --force -o "$tmp/f.ffz" "${extra[@]}")
    log=$("${cmd[@]}" 2>&1)
    wall=$(sed -n 's/^wall \([0-9.]*\) s.*/\1/p' <<<"$log")
    idle=$(sed -n 's/.*idle \([0-9.]*%\).*/\1/p' <<<"$log")
    rss=$(sed -n 's/.*peak RSS \([0-9.]*\) MB$/\1/p' <<<"$log" | head -1)
    n_real=$(sed -n 's/^rows: [0-9]* computed.*n = \([0-9]*\)$/\1/p' <<<"$log")
    echo "| $n_real | $mode | $wall | $rss | $idle | \`${cmd[*]/#$tmp/.}\` |"
  done
done
