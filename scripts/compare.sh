#!/bin/bash
# Side by side in one run: every bundled curve with both lab sets of Erwinski et al. 2022 (and the trident
# with the VPOp limits), planned by `--planner erwinski` and `--planner vpop`, each output checked
# by `nurbs-plan verify`. Prints the README's comparison table (plan times: wall time of one run),
# then the open pocket on the 5-axis machine with VPOp's Table 1 joint limits (VPOp only: the
# Erwinski planner has no joint kinematics).
# Usage: scripts/compare.sh  (after `cargo build --release --bin nurbs-plan`)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
cases=("trident|VPOp limits|$vpop_limits")
for curve in trident butterfly fan open_pocket fan_5axis; do
  cases+=("$curve|lab set 1|$lab1" "$curve|lab set 2|$lab2")
done
echo "| curve | limits | Erwinski motion (s) | plan (ms) | verify | VPOp motion (s) | plan (ms) | verify |"
echo "|---|---|---|---|---|---|---|---|"
for c in "${cases[@]}"; do
  IFS='|' read -r curve name lim <<<"$c"
  IFS='|' read -r et ep ev <<<"$(plan_verified erwinski "$curve" "$lim")"
  IFS='|' read -r vt vp vv <<<"$(plan_verified vpop "$curve" "$lim")"
  echo "| $curve | $name | $et | $ep | $ev | $vt | $vp | $vv |"
done
IFS='|' read -r vt vp vv <<<"$(plan_verified vpop open_pocket "$table1")"
echo
echo "open_pocket, XYZAC joints, Table 1 limits, VPOp: motion $vt s, plan $vp ms, verify $vv"
