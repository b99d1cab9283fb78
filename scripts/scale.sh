#!/bin/bash
# Programs of growing length through `nurbs-plan plan --stream` (the plan the machine runs):
# the dense CAM-like G1 program of scripts/dense-g1.py (the butterfly every 0.02 mm, passes
# back and forth in Z) at F500 A1e4 J6e4, chord tolerance 0.001 mm, 0.25 ms, for each length in
# LINES (default "10000 100000 1000000"): motion time, planning time (the planner alone) and its
# ratio to the motion, time per 1,000 lines, first record, groups and the longest, stops on the
# way (where back-tracking found no feed but rest; 0 is the aim), peak RSS of the whole command
# (planning and writing the CSV), then `verify` of the written setpoints. PLANNER=vpop runs
# VPOp instead (its first points instead of the first record; no groups: a stop of its own at
# every state it hands out). ROUND_CORNERS=round plans the program with its corners only rounded
# (default: auto, runs of short lines fitted). PLANNER=reach runs the reachability planner in
# look-ahead windows (its first points instead of the first record; its windows and the
# restarts from rest among them instead of groups).
# Usage: [PLANNER=vpop] [ROUND_CORNERS=round] scripts/scale.sh  (after `cargo build --release --bin nurbs-plan`)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
limits="--limits lab1 --feed 500"
if [ "${PLANNER:-erwinski}" = reach ]; then
  echo "| lines | elements | motion (s) | plan (s) | plan / motion | plan per 1,000 lines (s) | first setpoints (ms) | windows | restarts from rest | peak RSS (MB) | verify |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
elif [ "${PLANNER:-erwinski}" = vpop ]; then
  echo "| lines | elements | motion (s) | plan (s) | plan / motion | plan per 1,000 lines (s) | first setpoints (ms) | points held at most | elements held at most | peak RSS (MB) | verify |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
else
  echo "| lines | elements | motion (s) | plan (s) | plan / motion | plan per 1,000 lines (s) | first record (ms) | groups | longest group (s) | stops on the way | peak RSS (MB) | verify |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
fi
for lines in ${LINES:-10000 100000 1000000}; do
  python3 scripts/dense-g1.py --lines "$lines" >"$dir/dense.ngc"
  # shellcheck disable=SC2086
  /usr/bin/time -f "%M" -o "$dir/rss" $bin plan "$dir/dense.ngc" $limits --stream --planner "${PLANNER:-erwinski}" \
    --round-corners "${ROUND_CORNERS:-auto}" --out "$dir/dense.csv" --summary "$dir/dense.json" 2>/dev/null
  # shellcheck disable=SC2086
  if $bin verify "$dir/dense.csv" "$dir/dense.ngc" $limits --round-corners "${ROUND_CORNERS:-auto}" >/dev/null; then ok=pass; else ok=FAIL; fi
  python3 - "$lines" "$(cat "$dir/rss")" "$ok" "$dir/dense.json" <<'PY'
import json, sys
lines, rss, ok, path = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
s = json.load(open(path))
t, plan = s["motion_time_s"], s["plan_time_s"]
elements = s.get("elements", 0)
first = s.get("first_segment_time_s", s.get("first_points_time_s"))
if "groups" in s:
    groups = f"{s['groups']:,} | {s['longest_group_s']:.3f} | {s['stops_made']}"
elif "windows" in s:
    groups = f"{s['windows']:,} | {s['window_restarts']}"
else:
    groups = f"{s['most_points_held']:,} | {s['most_elements_held']:,}"
print(f"| {lines:,} | {elements:,} | {t:.1f} | {plan:.2f} | {100 * plan / t:.1f} % | {1000 * plan / lines:.3f} "
      f"| {first * 1e3:.1f} | {groups} | {rss / 1024:.1f} | {ok} |")
PY
done
