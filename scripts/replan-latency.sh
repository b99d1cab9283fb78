#!/bin/bash
# Re-plans deep into a long program in real LinuxCNC: a generated dense G1 program of LINES
# lines (default 100,000), its runs of short lines fitted (the default), streamed by nurbs-planner into
# our module on a 250 us thread; a hold HOLD_AT seconds in (default 20), released 3 s later;
# the feed override to 0.8 five seconds after the release, back to 1.0 three seconds after
# that. Prints the planner's lines that give the figures: when the first records of the motion
# and of the plan after the hold were queued (`first N records ... queued after`), and how long
# after each override change the motion ran into the new plan (`... ms after the override was
# asked for`). A measurement, not a test: it checks nothing (the suite's tests check holds,
# overrides and their limits).
# Usage: make install && scripts/replan-latency.sh   (as root; not part of the test suite)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
source "$here/../tests/hal/lib.sh"
lines=${LINES:-100000}
hold_at=${HOLD_AT:-20}
work=$(mktemp -d /tmp/nurbs-replan.XXXXXX)
chmod 755 "$work"
python3 "$here/dense-g1.py" --lines "$lines" >"$work/dense.ngc"
cat >"$work/replan.hal" <<EOF
loadrt threads name1=servo period1=250000
loadrt nurbs_interp
loadusr -W nurbs-planner $work/dense.ngc --limits lab1 --feed 500 --period 0.00025
addf nurbs_interp.update servo
setp nurbs_interp.enable 1
start
loadusr -w sleep $hold_at
setp nurbs_interp.hold 1
loadusr -w sleep 3
setp nurbs_interp.hold 0
loadusr -w sleep 5
setp nurbs-planner.feed-override 0.8
loadusr -w sleep 3
setp nurbs-planner.feed-override 1.0
loadusr -w sleep 3
stop
EOF
# (hal_session sets its own EXIT trap: the scratch directory is removed here, whatever happened.)
status=0
HAL_TIMEOUT=$((hold_at + 80)) hal_session "$work/replan.hal" "$work/halrun.log" || status=$?
grep -E "nurbs-planner: (first .* records|the module stopped|feed override .* runs into)" "$work/halrun.log" || true
rm -rf "$work"
exit "$status"
