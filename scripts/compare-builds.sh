#!/bin/bash
# Compares two builds of `nurbs-plan` (e.g. copies of target/release/nurbs-plan from two
# commits): whether every bundled case plans the same setpoints bit for bit (the whole plan,
# and the streamed plan the machine runs), the motion times,
# `verify` on the second build's output; then the median plan time and time to the first
# record (`--stream`) of RUNS alternate runs of each (default 11) at lab set 1, and the median
# plan time of the streamed dense G1 program of scripts/dense-g1.py (DENSE_LINES lines, default
# 2,000) at F500 A1e4 J6e4. Alternate runs
# share the machine's drift in speed, so their ratio is what to compare.
# Usage: scripts/compare-builds.sh OLD_BINARY NEW_BINARY
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
old=$(realpath "$1")
new=$(realpath "$2")
cases=()
for c in "${bench_cases[@]}"; do
  cases+=("${c%%|*}.json|${c#*|}")
done
for program in examples/*.ngc examples/*.dxf; do
  cases+=("$(basename "$program")|lab set 1|$lab1")
done
motion() { python3 -c "import json, sys; print('%.4f' % json.load(open(sys.argv[1]))['motion_time_s'])" "$1"; }
echo "| path | limits | setpoints | streamed | motion old (s) | motion new (s) | verify new |"
echo "|---|---|---|---|---|---|---|"
for c in "${cases[@]}"; do
  IFS='|' read -r path name lim <<<"$c"
  # shellcheck disable=SC2086
  "$old" plan "examples/$path" $lim --out "$dir/old.csv" --summary "$dir/old.json" >/dev/null 2>&1
  # shellcheck disable=SC2086
  "$new" plan "examples/$path" $lim --out "$dir/new.csv" --summary "$dir/new.json" >/dev/null 2>&1
  if cmp -s "$dir/old.csv" "$dir/new.csv"; then same=same; else same=DIFFER; fi
  for which in old new; do
    # shellcheck disable=SC2086
    "${!which}" plan "examples/$path" $lim --stream --out "$dir/$which-stream.csv" >/dev/null 2>&1
  done
  if cmp -s "$dir/old-stream.csv" "$dir/new-stream.csv"; then streamed=same; else streamed=DIFFER; fi
  # shellcheck disable=SC2086
  if "$new" verify "$dir/new.csv" "examples/$path" $lim >/dev/null 2>&1; then ok=pass; else ok=FAIL; fi
  echo "| $path | $name | $same | $streamed | $(motion "$dir/old.json") | $(motion "$dir/new.json") | $ok |"
done
echo
echo "| curve (lab set 1) | whole plan old / new (ms) | ratio | first record old / new (ms) | ratio |"
echo "|---|---|---|---|---|"
for curve in trident butterfly fan; do
  for _ in $(seq "${RUNS:-11}"); do
    for which in old new; do
      bin=${!which}
      # shellcheck disable=SC2086
      "$bin" plan "examples/$curve.json" $lab1 --out "$dir/o.csv" --summary "$dir/whole.json" >/dev/null 2>&1
      # shellcheck disable=SC2086
      "$bin" plan "examples/$curve.json" $lab1 --stream --out "$dir/o.csv" --summary "$dir/stream.json" >/dev/null 2>&1
      python3 -c "import json, sys; print(sys.argv[1], json.load(open(sys.argv[2]))['plan_time_s'], \
json.load(open(sys.argv[3]))['first_segment_time_s'])" "$which" "$dir/whole.json" "$dir/stream.json"
    done
  done >"$dir/times.txt"
  python3 - "$curve" "$dir/times.txt" <<'PY'
import statistics, sys
curve, path = sys.argv[1:3]
times = {"old": ([], []), "new": ([], [])}
for line in open(path):
    which, whole, first = line.split()
    times[which][0].append(float(whole) * 1e3)
    times[which][1].append(float(first) * 1e3)
(wo, fo), (wn, fn) = [tuple(statistics.median(x) for x in times[k]) for k in ("old", "new")]
print(f"| {curve} | {wo:.1f} / {wn:.1f} | {wn / wo:.2f} | {fo:.2f} / {fn:.2f} | {fn / fo:.2f} |")
PY
done
echo
echo "| program (streamed) | plan old / new (s) | ratio |"
echo "|---|---|---|"
lines=${DENSE_LINES:-2000}
python3 scripts/dense-g1.py --lines "$lines" >"$dir/dense.ngc"
for _ in $(seq "${RUNS:-11}"); do
  for which in old new; do
    # shellcheck disable=SC2086
    "${!which}" plan "$dir/dense.ngc" $lab1 --feed 500 --stream --out "$dir/o.csv" --summary "$dir/dense.json" >/dev/null 2>&1
    python3 -c "import json, sys; print(sys.argv[1], json.load(open(sys.argv[2]))['plan_time_s'])" "$which" "$dir/dense.json"
  done
done >"$dir/dense-times.txt"
python3 - "$lines" "$dir/dense-times.txt" <<'PY'
import statistics, sys
lines, path = int(sys.argv[1]), sys.argv[2]
times = {"old": [], "new": []}
for line in open(path):
    which, t = line.split()
    times[which].append(float(t))
old, new = statistics.median(times["old"]), statistics.median(times["new"])
print(f"| dense G1, {lines:,} lines | {old:.3f} / {new:.3f} | {new / old:.2f} |")
PY
