#!/bin/bash
# The 5-axis figures: LinuxCNC's own impeller-7bl-xyzac.ngc (the vismach table-rotary-tilting
# sample's demo: G93 inverse time, A and C turning, C past -360°), its first operation's first
# 291 moves (program lines 5-300: G93, the positioning rapids, the moves), planned in joint space
# by VPOp on XYZAC (the negative-tilt branch, as the program's A) and checked by
# `nurbs-plan verify`, then run through LinuxCNC 2.9's own planner (scripts/linuxcnc-tp-5axis.sh,
# a complete headless LinuxCNC on xyzac-trt-kins; as root, about 80 s) at the same joint limits
# (that script's defaults), servo period and tolerance. Prints both motion times from the first
# feed move and their ratio; LinuxCNC's joint peaks are in its report above.
# Usage: scripts/five-axis.sh  (after `cargo build --release --bin nurbs-plan`; needs linuxcnc-uspace)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
demos=/usr/share/doc/linuxcnc/examples/sample-configs/sim/axis/vismach/5axis/table-rotary-tilting/demos
{ sed -n '5,300p' "$demos/impeller-7bl-xyzac.ngc"; echo M2; } >"$dir/impeller.ngc"
limits=(--feed 100 --vel 100,100,100,90,90 --accel 1000,1000,1000,900,900 --jerk 1e4,1e4,1e4,9000,9000
  --chord-tol 0.01 --period 0.00025)
machine=(--machine xyzac --negative-tilt)
$bin plan "$dir/impeller.ngc" --planner vpop "${machine[@]}" "${limits[@]}" --out "$dir/o.csv" --summary "$dir/s.json" >/dev/null
$bin verify "$dir/o.csv" "$dir/impeller.ngc" "${machine[@]}" "${limits[@]}" | tail -n 1
ours=$(python3 -c "import json, sys; print(json.load(open(sys.argv[1]))['motion_time_s'])" "$dir/s.json")
report=$(bash scripts/linuxcnc-tp-5axis.sh "$dir/impeller.ngc")
echo "$report"
theirs=$(sed -nE 's/.*; ([0-9.]+) s from the first feed move.*/\1/p' <<<"$report")
python3 -c "import sys; o, t = map(float, sys.argv[1:]); print(f'impeller, first 291 moves: ours (VPOp) {o:.3f} s, LinuxCNC {t:.3f} s: {o / t:.3f} x')" "$ours" "$theirs"
