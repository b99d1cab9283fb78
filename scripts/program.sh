#!/bin/bash
# A whole G-code program as the machine runs it: `nurbs-filter` cuts its runs (LinuxCNC's
# interpreter reads it; offline, tool words are left out), and every run is planned by each
# planner at the limits of configs/nurbs-sim (V 1000 A 1e4 J 1e5 mm, s; tolerance 0.001 mm, or
# the program's G64 P; T 0.25 ms), checked by `nurbs-plan verify`. Prints per planner the summed
# motion and planning time, the largest distance of a setpoint to the programmed polyline and
# the verdict (a planner that refuses a run says so). With TP=1, LinuxCNC 2.9's own planner on
# the same runs too (scripts/linuxcnc-tp.sh, one headless LinuxCNC per run, as root: its time
# runs in real time, and it blends within G64 P = 0.001 mm: give G64=0.001 to plan the runs that
# way too, whatever path mode the program sets). With TP=program, one LinuxCNC on the whole
# program instead (for programs of many runs; compare its moving time with our summed motion:
# both leave out the time the machine stands while M-codes run). PLANNERS="erwinski reach"
# plans with those only.
# Usage: scripts/program.sh PROGRAM.ngc  (after `cargo build --release --bin nurbs-plan`)
# shellcheck source=scripts/common.sh
source "$(dirname "$0")/common.sh"
program=$(realpath "$1")
XDG_CACHE_HOME="$dir/cache" linuxcnc/nurbs-filter "$program" >/dev/null 2>"$dir/filter.log" \
  || { cat "$dir/filter.log"; exit 1; }
grep -m1 "run(s)" "$dir/filter.log"
mapfile -t runs < <(ls "$dir"/cache/nurbs-filter/*/run-*.ngc | sort -V)
limits=(--feed 1000 --vel 1000 --accel 10000 --jerk 100000 --period 0.00025)
echo "| planner | runs planned | motion (s) | plan (s) | from the program (mm) | verify |"
echo "|---|---|---|---|---|---|"
for planner in ${PLANNERS:-erwinski vpop reach}; do
  motion=0 plan=0 worst=0 planned=0 ok=pass
  for run in "${runs[@]}"; do
    mapfile -t mode <"${run%.ngc}.args"  # the program's G64 P / G61 there
    [ -n "${G64:-}" ] && mode=(--chord-tol "$G64" --round-corners auto)
    [[ " ${mode[*]} " == *" --chord-tol "* ]] || mode+=(--chord-tol 0.001)
    flags=("${limits[@]}" "${mode[@]}")
    if ! $bin plan "$run" "${flags[@]}" --planner "$planner" --out "$dir/o.csv" --summary "$dir/s.json" \
        >"$dir/plan.log" 2>&1; then
      ok="refused: $(tail -n 1 "$dir/plan.log" | cut -c1-120)"
      continue
    fi
    $bin verify "$dir/o.csv" "$run" "${flags[@]}" >/dev/null 2>&1 || ok=FAIL
    read -r m p d < <(python3 -c "import json,sys; s=json.load(open(sys.argv[1])); print(s['motion_time_s'], s['plan_time_s'], s['max_deviation_from_program_mm'])" "$dir/s.json")
    motion=$(python3 -c "print($motion + $m)") plan=$(python3 -c "print($plan + $p)")
    worst=$(python3 -c "print(max($worst, $d))") planned=$((planned + 1))
  done
  printf "| %s | %d of %d | %.3f | %.2f | %.6f | %s |\n" "$planner" "$planned" "${#runs[@]}" "$motion" "$plan" "$worst" "$ok"
done
if [ "${TP:-0}" = 1 ]; then
  for run in "${runs[@]}"; do
    scripts/linuxcnc-tp.sh "$run" 1000 10000 100000 0.001
  done
elif [ "${TP:-0}" = program ]; then
  scripts/linuxcnc-tp.sh "$program" 1000 10000 100000 "${G64:-0.001}"
fi
