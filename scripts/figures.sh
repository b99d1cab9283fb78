#!/bin/bash
# Plans every benchmark case with the release build, verifies each output with
# `nurbs-plan verify`, and prints the README's table of motion and planning times.
# Plan time is the median of RUNS runs (default 5): single runs on this shared machine vary by
# 20 % and more.
# Usage: scripts/figures.sh  (after `cargo build --release --bin nurbs-plan`)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
# Lower bound and best known plan (examples/CURVES.md), where there are.
declare -A bounds=(
  ["butterfly|lab set 1"]="2.404|3.163" ["butterfly|lab set 2"]="1.609|"
  ["trident|lab set 1"]="0.721|" ["trident|lab set 2"]="0.483|"
  ["fan|lab set 1"]="1.783|" ["fan|lab set 2"]="1.194|"
  ["butterfly|F250 A2000 J2e4"]="3.512|4.562" ["trident|VPOp limits"]="1.650|1.668"
)
echo "| curve | limits | motion time (s) | / lower bound | / best known | plan time (ms) | plan / motion | max jerk / limit | verify |"
echo "|---|---|---|---|---|---|---|---|---|"
for c in "${bench_cases[@]}"; do
  IFS='|' read -r curve name lim <<<"$c"
  IFS='|' read -r lb best <<<"${bounds[$curve|$name]:-|}"
  for run in $(seq "${RUNS:-5}"); do
    # shellcheck disable=SC2086
    $bin plan examples/$curve.json $lim --out "$dir/o.csv" --summary "$dir/run$run.json" 2>/dev/null
  done
  # shellcheck disable=SC2086
  if $bin verify "$dir/o.csv" examples/$curve.json $lim >/dev/null; then ok=pass; else ok=FAIL; fi
  python3 - "$curve" "$name" "$lb" "$best" "$ok" "$dir"/run*.json <<'PY'
import json, statistics, sys
curve, name, lb, best, ok = sys.argv[1:6]
runs = [json.load(open(f)) for f in sys.argv[6:]]
s = runs[-1]
t = s["motion_time_s"]
assert all(r["motion_time_s"] == t for r in runs), "the runs planned different motions"
plan = statistics.median(r["plan_time_s"] for r in runs)
ratio = lambda x: f"{t / float(x):.2f}" if x else "-"
jr = max(a / b for a, b in zip(s["max_axial_jerk"], s["limits"]["jerk"]))
print(f"| {curve} | {name} | {t:.4f} | {ratio(lb)} | {ratio(best)} | {plan*1e3:.1f} | {100*plan/t:.1f} % | {jr:.4f} | {ok} |")
PY
  rm -f "$dir"/run*.json
done
