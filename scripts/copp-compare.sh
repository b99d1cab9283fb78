#!/bin/bash
# Side by side in one run: our two planners and the public `copp` crate (Wang, Hu, Li et al.
# 2026: jerk-limited time-optimal path parameterization by sequential conic programs) on the
# benchmark cases with one smooth curve, every output checked by `nurbs-plan verify` at the
# servo period. copp holds the limits at its grid stations only; where its motion fails the check
# between them, it is solved again with the axis limits lowered by a margin (1 %, 2 %, 5 %, 10 %,
# 20 %) until it passes, and the table gives the first margin that passed (a margin whose solve
# fails is skipped; where a later SCP iteration fails, the last one solved stands). Plan times are the
# wall time of one run each (copp: grid, solves and time conversion; not the sampling).
# Usage: scripts/copp-compare.sh  (builds tools/copp-compare, a workspace of its own, first;
#        COPP_ARGS="--iterations 4" passes options on to every copp run)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
cargo build --release -q --bin nurbs-plan
cargo build --release -q --manifest-path tools/copp-compare/Cargo.toml
copp=tools/copp-compare/target/release/copp-compare
summary() { # copp's summary.json, the margin that passed -> "motion|solve ms|margin"
  python3 - "$1" "$2" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
print(f"{s['motion_time_s']:.4f}|{s['plan_time_s'] * 1e3:.0f}|{sys.argv[2]}")
PY
}
theirs() { # curve limits -> "motion|solve ms|margin that passed"
  local curve=$1 lim=$2 margin failed=""
  for margin in 0 0.01 0.02 0.05 0.1 0.2; do
    # shellcheck disable=SC2086
    if ! $copp "examples/$curve.json" $lim --margin "$margin" ${COPP_ARGS:-} --out "$dir/c.csv" \
      --summary "$dir/c.json" >"$dir/c.log" 2>&1; then
      failed="$failed ${margin}: $(tail -1 "$dir/c.log");"
      continue
    fi
    # shellcheck disable=SC2086
    if $bin verify "$dir/c.csv" "examples/$curve.json" $lim >/dev/null 2>&1; then
      summary "$dir/c.json" "$(python3 -c "print(f'{100 * $margin:g} %')")"
      return
    fi
  done
  echo "-|-|none passed${failed:+ (solver failed at margin$failed)}"
}
echo "| curve | limits | Erwinski motion (s) | plan (ms) | verify | VPOp motion (s) | plan (ms) | verify | copp motion (s) | solve (ms) | margin that passed verify |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for c in "${bench_cases[@]}"; do
  IFS='|' read -r curve name lim <<<"$c"
  # One smooth curve only: the 5-axis G1 path has corners, which copp's path model has no place for.
  [ "$curve" = fan_5axis ] && continue
  IFS='|' read -r et ep ev <<<"$(plan_verified erwinski "$curve" "$lim")"
  IFS='|' read -r vt vp vv <<<"$(plan_verified vpop "$curve" "$lim")"
  IFS='|' read -r ct cp cm <<<"$(theirs "$curve" "$lim")"
  echo "| $curve | $name | $et | $ep | $ev | $vt | $vp | $vv | $ct | $cp | $cm |"
done
