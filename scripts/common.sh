# Sourced by the figure scripts: the release binary, a scratch directory removed on exit, and
# the limit sets of the papers (mm, s).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${CARGO_TARGET_DIR:-target}/release/nurbs-plan
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
lab1="--feed 2500 --accel 1e4 --jerk 6e4 --chord-tol 0.001 --period 0.00025"
lab2="--feed 2500 --accel 1.5e4 --jerk 2e5 --chord-tol 0.001 --period 0.00025"
vpop_limits="--feed 166.667 --vel 500,500 --accel 2500,3000 --jerk 5000,5000 --chord-tol 0.02 --period 0.006"
# VPOp, Table 1: joint limits of the XYZAC machine (x,y,z in mm, a,c in degrees).
table1="--feed 83.333 --vel 500,500,500,90,120 --accel 2500,3000,2100,298.8,298.8 --jerk 5000,5000,50000,1800,36000 --chord-tol 0.02 --period 0.006"
# The benchmark cases of figures.sh and compare-builds.sh ("curve|limits name|flags"; the curve
# is examples/<curve>.json): every bundled curve at both lab sets, the three Table III sets of
# Erwinski et al. 2022 on the butterfly, the trident at the VPOp limits.
bench_cases=(
  "butterfly|lab set 1|$lab1" "butterfly|lab set 2|$lab2"
  "trident|lab set 1|$lab1" "trident|lab set 2|$lab2"
  "fan|lab set 1|$lab1" "fan|lab set 2|$lab2"
  "open_pocket|lab set 1 (tip)|$lab1" "open_pocket|lab set 2 (tip)|$lab2"
  "fan_5axis|lab set 1 (tip)|$lab1" "fan_5axis|lab set 2 (tip)|$lab2"
  "butterfly|F40 A500 J2e4|--feed 40 --accel 500 --jerk 2e4 --chord-tol 0.001 --period 0.00025"
  "butterfly|F250 A2000 J2e4|--feed 250 --accel 2000 --jerk 2e4 --chord-tol 0.001 --period 0.00025"
  "butterfly|F300 A2500 J5e4|--feed 300 --accel 2500 --jerk 5e4 --chord-tol 0.001 --period 0.00025"
  "trident|VPOp limits|$vpop_limits"
)
