#!/bin/bash
# A dense G1 program as nurbs-planner runs it by default (`--round-corners auto`: runs of short
# lines fitted with splines within the chord tolerance) end to end in real LinuxCNC:
# scripts/dense-g1.py, 5,000 lines of 0.02 mm. The samples equal the offline `nurbs-plan plan
# --stream` (count, every position to 1e-9 mm) and pass `nurbs-plan verify` (see path_test.sh).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d /tmp/nurbs-smooth.XXXXXX)
trap 'rm -rf "$work"' EXIT
python3 "$here/../../scripts/dense-g1.py" --lines 5000 >"$work/dense.ngc"
# Equal samples also show that nurbs-planner fitted: the plan with the corners only rounded
# (`--round-corners round`) takes 13 times longer.
bash "$here/path_test.sh" "$work/dense.ngc" erwinski
