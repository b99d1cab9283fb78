#!/bin/bash
# The butterfly sampled every 0.02 mm as one G1 pass (scripts/dense-g1.py, 19,142 lines) at lab
# set 1, F500, chord tolerance 0.001 mm, its runs fitted (`--round-corners auto`, the
# default), against the same planner on the exact curve: reach whole-path, Erwinski streamed;
# each dense plan checked by `nurbs-plan verify`. Prints motion times, their ratio and the verdict.
# Usage: scripts/dense-butterfly.sh  (after `cargo build --release --bin nurbs-plan`)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
python3 scripts/dense-g1.py --lines 19142 --feed 500 >"$dir/dense.ngc"
limits=(--limits lab1 --feed 500 --chord-tol 0.001)
motion() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['motion_time_s'])" "$1"; }
echo "| planner | dense, fitted (s) | exact curve (s) | ratio | verify |"
echo "|---|---|---|---|---|"
for planner in reach erwinski; do
  flags=(--planner "$planner")
  [ "$planner" = erwinski ] && flags+=(--stream)
  $bin plan "$dir/dense.ngc" "${limits[@]}" "${flags[@]}" --out "$dir/d.csv" --summary "$dir/d.json" >/dev/null 2>&1
  $bin plan examples/butterfly.json "${limits[@]}" "${flags[@]}" --out "$dir/e.csv" --summary "$dir/e.json" >/dev/null 2>&1
  if $bin verify "$dir/d.csv" "$dir/dense.ngc" "${limits[@]}" >/dev/null 2>&1; then ok=pass; else ok=FAIL; fi
  d=$(motion "$dir/d.json"); e=$(motion "$dir/e.json")
  echo "| $planner | $d | $e | $(python3 -c "print(f'{$d / $e:.3f}')") | $ok |"
done
