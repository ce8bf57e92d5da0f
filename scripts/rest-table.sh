#!/usr/bin/env bash
# Issue 52's rest table: a liquid that moves and then comes to rest, baked
# from its first frame as a user bakes it, measured over its rest frames by
# `lapflow eval` and by the independent checker (../shared/tools/check_bake.py
# change, Debian python3-numpy, python3-scipy, python3-openimageio):
#   settle 1-150 (--min-speed 0.15), rest frames 100-150
#   viscous_drop 1-72 (--min-speed 0.05), rest frames 60-72
# 1024², pebbles, --aov. Needs a Release build in build/ (`bash
# scripts/test.sh` makes one) and ../shared/data. About 6 minutes on 2 cores,
# 1.5 GB of disk in OUT.
#
#   bash scripts/rest-table.sh [OUT] [-- extra bake options]
#
# Prints one line per scene: the checker's share of the rest surface changed
# per frame (mean, max), eval's rest change (the checker's definition), drift,
# popping, p99 distortion (first and last rest frame, max), contrast (min),
# births per frame (max) and patches alive (min-max) over the rest frames.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
out=/tmp/lapflow_rest
if [ $# -gt 0 ] && [ "$1" != "--" ]; then out=$1; shift; fi
[ "${1:-}" = "--" ] && shift
data=$root/../shared/data
[ -x build/lapflow ] || { echo "rest-table: build/lapflow missing: build first (bash scripts/test.sh)" >&2; exit 2; }
for s in settle viscous_drop; do
  [ -d "$data/$s" ] || { echo "rest-table: $data/$s missing" >&2; exit 2; }
done
mkdir -p "$out"

row() {  # scene frames min-speed rest-frames
  local s=$1 frames=$2 speed=$3 rest=$4 d=$out/$1
  shift 4
  build/lapflow bake --mesh "$data/$s/$s.%04d.ply" --frames "$frames" --exemplar pebbles --resolution 1024 \
    --min-speed "$speed" --aov --out "$d" -q "$@"
  build/lapflow eval "$d" --frames "$rest" --min-speed "$speed" --json "$d/eval.json" -q
  /usr/bin/python3 "$root/../shared/tools/check_bake.py" change "$d" --name "$s" --frames "$rest" \
    --mesh "$data/$s/$s.%04d.ply" --min-speed "$speed" >"$d/change.log"
  /usr/bin/python3 - "$s" "$d" <<'EOF'
import json, sys
scene, d = sys.argv[1], sys.argv[2]
rows = [json.loads(l) for l in open(d + '/change.log') if l.startswith('{')]
rc = [r['rest_changed'] for r in rows if r['rest_changed'] is not None]
e = json.load(open(d + '/eval.json'))
fr, sm = e['frames'], e['summary']
p99 = [f['distortion_p99'] for f in fr if f['distortion_p99'] is not None]
alive = [f['alive'] for f in fr if f['alive'] is not None]
pct = lambda k, q: 100 * sm[k][q]
print(f"{scene}: checker rest changed {100 * sum(rc) / len(rc):.2f}% (max {100 * max(rc):.2f}) | "
      f"eval rest change {pct('rest_change', 'mean'):.2f}% drift {pct('drift', 'mean'):.2f}% "
      f"popping {pct('popping', 'mean'):.2f}% (max {pct('popping', 'max'):.2f}) | "
      f"p99 {p99[0]:.2f} -> {p99[-1]:.2f} (max {max(p99):.2f}) | contrast min {min(f['contrast'] for f in fr):.3f} | "
      f"born max {sm['born']['max']:.0f} | alive {min(alive)}-{max(alive)}")
EOF
}

row settle 1-150 0.15 100-150 "$@"
row viscous_drop 1-72 0.05 60-72 "$@"
