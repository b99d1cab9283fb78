#!/bin/bash
# LinuxCNC's own example 3D_Chips.ngc (a 3-D surfacing program: parameters, expressions, a
# tool change), read by LinuxCNC's interpreter (`nurbs-filter`: one run; its 4,681 feed
# moves), prepared as by default (corners rounded, runs of short lines fitted), planned at F100
# A5000 J5e4 and a 0.01 mm tolerance by the default and the reachability planners: every plan passes `nurbs-plan verify` (axis limits
# by finite differences and every setpoint within 0.01 mm of the programmed polyline; a fit
# across a sharp corner beside a 0.007 mm line once left it by 0.027 mm).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
program=/usr/share/linuxcnc/ncfiles/3D_Chips.ngc
XDG_CACHE_HOME="$work/cache" nurbs-filter "$program" >/dev/null 2>"$work/filter.log" || { cat "$work/filter.log"; exit 1; }
runs=("$work"/cache/nurbs-filter/*/run-*.ngc)
[ "${#runs[@]}" = 1 ] || { cat "$work/filter.log"; echo "FAIL: one run expected, got ${#runs[@]}"; exit 1; }
# Its feed moves: the run ends with the program's retract (a rapid, at the filter's rapid feed).
sed '/F60000000\.0$/,$d' "${runs[0]}" >"$work/chips.ngc"
echo M2 >>"$work/chips.ngc"
moves=$(grep -c '^G1 ' "$work/chips.ngc")
echo "3D_Chips.ngc read by LinuxCNC's interpreter: one run of $moves feed moves"
[ "$moves" = 4681 ] || { echo "FAIL: expected the program's 4,681 feed moves"; exit 1; }
limits=(--feed 100 --accel 5000 --jerk 5e4 --chord-tol 0.01 --period 0.00025)
for planner in erwinski reach; do
    nurbs-plan plan "$work/chips.ngc" --planner "$planner" "${limits[@]}" --out "$work/$planner.csv" \
        --summary "$work/$planner.json" 2>"$work/$planner.log" || { cat "$work/$planner.log"; echo "FAIL: $planner"; exit 1; }
    tail -n 1 "$work/$planner.log"
    nurbs-plan verify "$work/$planner.csv" "$work/chips.ngc" "${limits[@]}" >"$work/verify.log" 2>&1 \
        || { tail -n 5 "$work/verify.log"; echo "FAIL: $planner plan does not verify"; exit 1; }
    python3 -c "import json,sys; s=json.load(open(sys.argv[1])); print(f\"$planner: motion {s['motion_time_s']:.3f} s, {s['max_deviation_from_program_mm']:.6f} mm from the program\")" "$work/$planner.json"
done
echo "PASS"
