#!/bin/bash
# Side by side in one run: every benchmark case of figures.sh (every bundled curve at both lab
# sets of Erwinski et al. 2022, the three Table III sets on the butterfly, the trident at the
# VPOp limits) planned by `--planner erwinski`, `vpop`, `reach` and `reach --stream` (look-ahead
# windows; a stretch shorter than a window is planned whole, as without), each output checked by
# `nurbs-plan verify`. Prints the comparison table of docs/planners.md: motion time, its ratio to
# the best known plan where there is one (../shared/curves), planning time of one run and its
# share of the motion. The 5-axis curves are planned by their tool tip, but by VPOp, which plans
# their joints (x, y, z, a, c at the same limits): its times there answer another problem.
# Then the open pocket on the 5-axis machine with VPOp's Table 1 joint limits (VPOp only).
# Usage: scripts/compare.sh  (after `cargo build --release --bin nurbs-plan`)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
declare -A best=(
  ["butterfly|lab set 1"]=3.163 ["butterfly|F250 A2000 J2e4"]=4.562 ["trident|VPOp limits"]=1.668
)
cell() {
  local t=$1 p=$2 v=$3 b=$4
  if [ "$t" = refused ]; then echo "refused"; return; fi
  python3 -c "
t, p, b = float('$t'), float('$p'), '$b'
r = f' = {t / float(b):.3f} x' if b else ''
print(f'{t:.4f}{r}, {p:.0f} ms ({100 * p / 1e3 / t:.1f} %), $v')"
}
echo "| curve | limits | Erwinski | VPOp | reach | reach --stream |"
echo "|---|---|---|---|---|---|"
for c in "${bench_cases[@]}"; do
  IFS='|' read -r curve name lim <<<"$c"
  b=${best[$curve|$name]:-}
  row="| $curve | $name"
  for run in erwinski vpop reach "reach --stream"; do
    read -r planner extra <<<"$run"
    IFS='|' read -r t p v <<<"$(plan_verified "$planner" "$curve" "$lim" "$extra")"
    row="$row | $(cell "$t" "$p" "$v" "$b")"
  done
  echo "$row |"
done
IFS='|' read -r vt vp vv <<<"$(plan_verified vpop open_pocket "$table1")"
echo
echo "open_pocket, XYZAC joints, Table 1 limits, VPOp: motion $vt s, plan $vp ms, verify $vv"
