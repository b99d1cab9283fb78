# Sourced by the figure scripts: the release binary, a scratch directory removed on exit, and
# the limit sets of the papers by their preset names (`nurbs-plan presets`).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${CARGO_TARGET_DIR:-target}/release/nurbs-plan
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
lab1="--limits lab1"
lab2="--limits lab2"
vpop_limits="--limits vpop-trident"
# VPOp, Table 1: joint limits of the XYZAC machine (x,y,z in mm, a,c in degrees).
table1="--limits vpop-table1"
# The benchmark cases of figures.sh and compare-builds.sh ("curve|limits name|flags"; the curve
# is examples/<curve>.json): every bundled curve at both lab sets, the three Table III sets of
# Erwinski et al. 2022 on the butterfly, the trident at the VPOp limits.
bench_cases=(
  "butterfly|lab set 1|$lab1" "butterfly|lab set 2|$lab2"
  "trident|lab set 1|$lab1" "trident|lab set 2|$lab2"
  "fan|lab set 1|$lab1" "fan|lab set 2|$lab2"
  "open_pocket|lab set 1 (tip)|$lab1" "open_pocket|lab set 2 (tip)|$lab2"
  "fan_5axis|lab set 1 (tip)|$lab1" "fan_5axis|lab set 2 (tip)|$lab2"
  "butterfly|F40 A500 J2e4|--limits table3-f40"
  "butterfly|F250 A2000 J2e4|--limits table3-f250"
  "butterfly|F300 A2500 J5e4|--limits table3-f300"
  "trident|VPOp limits|$vpop_limits"
)

# plan_verified PLANNER CURVE "LIMIT FLAGS" ["PLAN FLAGS"]: `nurbs-plan plan` of examples/CURVE.json,
# checked by `nurbs-plan verify`; prints "motion s|plan ms|pass or FAIL" ("refused|-|-" where no
# plan).
plan_verified() {
  local planner=$1 curve=$2 lim=$3 extra=${4:-} ok
  # shellcheck disable=SC2086
  if ! $bin plan "examples/$curve.json" --planner "$planner" $lim $extra --out "$dir/o.csv" --summary "$dir/s.json" >/dev/null 2>&1; then
    echo "refused|-|-"
    return
  fi
  # shellcheck disable=SC2086
  if $bin verify "$dir/o.csv" "examples/$curve.json" $lim >/dev/null 2>&1; then ok=pass; else ok=FAIL; fi
  python3 - "$dir/s.json" "$ok" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
print(f"{s['motion_time_s']:.4f}|{s['plan_time_s'] * 1e3:.1f}|{sys.argv[2]}")
PY
}
