#!/bin/bash
# A program longer than the channel, in real LinuxCNC: a generated dense G1 program (the
# butterfly every 0.02 mm, passes back and forth in Z; LINES lines, default 52,000, some 67,000
# path elements once its corners are rounded: more than the 65,536 the channel held before and
# four times its ring of curve descriptors) streamed by nurbs-planner into nurbs_interp on a
# 250 us thread. The samples equal `nurbs-plan plan --stream` (count, every position to 1e-9 mm),
# pass `nurbs-plan verify`, with no underrun; the log shows the planner's peak RSS and how much
# motion it kept queued (path_test.sh, check_path.py).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
lines=${LINES:-52000}
work=$(mktemp -d /tmp/nurbs-long.XXXXXX)
trap 'rm -rf "$work"' EXIT
python3 "$here/../../scripts/dense-g1.py" --lines "$lines" >"$work/dense.ngc"
# The motion takes about 4.6 s per 1,000 lines.
# Corners only rounded (`--round-corners round`), so that the path has that many elements (the
# default fits the runs of short lines into a few hundred splines).
HAL_TIMEOUT=$((lines * 6 / 1000 + 120)) bash "$here/path_test.sh" "$work/dense.ngc" erwinski "--round-corners round" | tee "$work/run.log"
elements=$(sed -n 's/.*nurbs-planner: all .* records sent .*; \([0-9]*\) path elements and .*/\1/p' "$work/run.log" | head -1)
elements=${elements:-0}
echo "$lines lines, $elements path elements"
[ "$elements" -gt 65536 ] || { echo "only $elements path elements: not longer than the old channel"; exit 1; }
