#!/bin/bash
# LinuxCNC's own 3D_Chips.ngc (a 3-D surfacing program), its moves as LinuxCNC's interpreter
# reads them (the one run `nurbs-filter` cuts from it: all 4,681 feed moves), planned at F100
# A5000 J5e4 with a 0.01 mm tolerance by the default (Erwinski, streamed as on the machine) and
# the reachability planners (whole stretches, and in look-ahead windows with --stream), corners
# only rounded (`--round-corners round`) and as by default (`auto`: runs of short lines fitted);
# each plan checked by `nurbs-plan verify`. Prints motion time, planning time, when the first
# setpoints (Erwinski: the first record) were ready, peak RSS of the command, the largest
# distance of a setpoint to the programmed polyline, and the verdict. With TP=1, LinuxCNC 2.9's own planner
# on the same program too (scripts/linuxcnc-tp.sh: a full headless LinuxCNC, as root).
# Usage: scripts/chips.sh  (after `cargo build --release --bin nurbs-plan`; needs linuxcnc-uspace)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
XDG_CACHE_HOME="$dir/cache" "$(dirname "$0")/../linuxcnc/nurbs-filter" /usr/share/linuxcnc/ncfiles/3D_Chips.ngc \
  >/dev/null 2>"$dir/filter.log" || { cat "$dir/filter.log"; exit 1; }
# Its feed moves (the run ends with the program's retract, a rapid at the filter's rapid feed).
sed '/F60000000\.0$/,$d' "$dir"/cache/nurbs-filter/*/run-1.ngc >"$dir/chips.ngc"
echo M2 >>"$dir/chips.ngc"
limits=(--feed 100 --accel 5000 --jerk 5e4 --chord-tol 0.01 --period 0.00025)
echo "| planner | corners | motion (s) | plan (s) | first setpoints (ms) | peak RSS (MB) | from the program (mm) | verify |"
echo "|---|---|---|---|---|---|---|---|"
# The Erwinski planner as it runs on the machine (a stream); the reachability planner whole
# stretch by stretch and in look-ahead windows (--stream).
for run in "erwinski --stream" "reach" "reach --stream"; do
  for mode in round auto; do
    read -r planner stream <<<"$run"
    # shellcheck disable=SC2086
    /usr/bin/time -f "%M" -o "$dir/rss" $bin plan "$dir/chips.ngc" "${limits[@]}" --planner "$planner" $stream --round-corners "$mode" \
      --out "$dir/o.csv" --summary "$dir/s.json" >/dev/null 2>&1
    if $bin verify "$dir/o.csv" "$dir/chips.ngc" "${limits[@]}" --round-corners "$mode" >/dev/null 2>&1; then ok=pass; else ok=FAIL; fi
    python3 - "$dir/s.json" "$run" "$mode" "$ok" "$(cat "$dir/rss")" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
first = s.get("first_segment_time_s", s.get("first_points_time_s"))
print(f"| {sys.argv[2]} | {sys.argv[3]} | {s['motion_time_s']:.3f} | {s['plan_time_s']:.2f} | {first * 1e3:.0f} "
      f"| {int(sys.argv[5]) / 1024:.0f} | {s['max_deviation_from_program_mm']:.6f} | {sys.argv[4]} |")
PY
  done
done
if [ "${TP:-0}" = 1 ]; then
  scripts/linuxcnc-tp.sh "$dir/chips.ngc" 100 5000 50000 0.01
fi
