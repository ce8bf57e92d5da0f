#!/usr/bin/env bash
# The README's "Measured performance" rows in one sitting: the shared splash
# 1-48 (`lapflow_bench bake-data N`), the shared dam_break 1-24 (`lapflow
# bake`) and the demo vortex (`lapflow_bench bake-demo N 0`), each at 6144²,
# 4096² and 2048². Needs a Release build in build/ (`bash scripts/test.sh`
# makes one) and ../shared/data; run it on an otherwise idle machine.
# About 25 minutes on 2 cores, up to 12 GB of disk while the splash rows
# run (the bench's own folder under /tmp).
#
#   bash scripts/bench-rows.sh [OUT]     raw output in OUT (default /tmp/lapflow_rows)
#
# Prints one line per row; the raw tables, `/usr/bin/time -v` reports and
# the dam_break stats stay in OUT.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
out=${1:-/tmp/lapflow_rows}
data=$root/../shared/data
for f in build/lapflow build/lapflow_bench; do
  [ -x "$f" ] || { echo "bench-rows: $f missing: build first (bash scripts/test.sh)" >&2; exit 2; }
done
[ -d "$data/splash" ] && [ -d "$data/dam_break" ] || { echo "bench-rows: $data has no splash or dam_break" >&2; exit 2; }
mkdir -p "$out"
peak_mib() { awk '/Maximum resident set size/ {printf "%d", $NF / 1024 + 0.5}' "$1"; }

for n in 6144 4096 2048; do
  echo "splash $n: started $(date +%T)" >&2
  /usr/bin/time -v build/lapflow_bench bake-data "$n" >"$out/splash_$n.txt" 2>"$out/splash_$n.time"
  echo "splash $n: $(grep '^frames 2-48' "$out/splash_$n.txt")"
done

for n in 2048 4096 6144; do
  echo "dam_break $n: started $(date +%T)" >&2
  rm -rf "$out/dam_$n"
  /usr/bin/time -v build/lapflow bake --mesh "$data/dam_break/dam_break.%04d.ply" --frames 1-24 \
    --exemplar foam --resolution "$n" --out "$out/dam_$n" -q >"$out/dam_$n.txt" 2>"$out/dam_$n.time"
  rm -f "$out/dam_$n"/*.exr
  # The mean and worst of the stats' seconds.total over frames 2-24, and frame 1's.
  summary=$(grep -o '"frame":[0-9]*\|"total":[0-9.e+-]*' "$out/dam_$n/dam_break.stats.jsonl" |
    awk -F: '/frame/ {f = $2} /total/ {if (f == 1) first = $2; else {s += $2; k++; if ($2 > w) w = $2}}
             END {printf "mean %.2f s, worst %.2f s, first %.2f s", s / k, w, first}')
  echo "dam_break $n: $summary, peak RSS $(peak_mib "$out/dam_$n.time") MiB"
done

for n in 2048 4096 6144; do
  echo "demo $n: started $(date +%T)" >&2
  /usr/bin/time -v build/lapflow_bench bake-demo "$n" 0 >"$out/demo_$n.txt" 2>"$out/demo_$n.time"
  echo "demo $n: $(tail -1 "$out/demo_$n.txt")"
done
echo "done $(date +%T)" >&2
