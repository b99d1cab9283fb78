#!/bin/bash
# Underrun in real LinuxCNC: nurbs-planner streams the butterfly with a 0.1 s margin (limits and
# period from halfiles/sim.ini, the same as $LIMITS below) and is unloaded (SIGTERM) after 1 s; nurbs_interp runs out of records mid-path and stops on the path
# with its own jerk-limited ramp. Checks (check_underrun.py, nurbs-plan verify): the samples are
# the offline plan up to the cut, then a stop with a never-rising feed that ends at rest, no
# position jump and no axial violation (verify's only complaint: the path's end is not reached),
# underrun set, no fault. The stop limits are the planner's per-boundary choice (plan_geometry.rs).
# Then resume: a second nurbs-planner plans the rest of the path from rest at the stop point the
# module published, `setp nurbs_interp.resume 1` starts it, and the motion must end at C(1) at rest
# with the whole sampled run (to the stop, then resumed) free of jumps and axial violations.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

toolpath=$(realpath "$here/../../examples/butterfly.json")
PERIOD=0.00025
JERK=6e4
LIMITS="--feed 2500 --accel 1e4 --jerk $JERK --chord-tol 0.001"

work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --out "$work/offline.csv"
sed -e "s|@TOOLPATH@|$toolpath|g" -e "s|@INI@|$(realpath "$here/../../halfiles/sim.ini")|g" \
    -e "s|@MARGIN@|0.1|g" -e "s|@KILL_AFTER@|1|g" -e "s|@WORK@|$work|g" \
    "$here/underrun.hal.in" >"$work/underrun.hal"

hal_session "$work/underrun.hal" "$work/halrun.log"
cat "$work/halrun.log"
python3 "$here/check_underrun.py" --expected "$work/offline.csv" --samples "$work/samples.txt" \
    --period $PERIOD --jerk $JERK --recorded-csv "$work/recorded.csv" --resumed "$work/resumed.txt"
verify=$(nurbs-plan verify "$work/recorded.csv" "$toolpath" $LIMITS --period $PERIOD || true)
echo "$verify"
if grep "^VIOLATION" <<<"$verify"; then
    echo "the stop and resume violate the limits"; exit 1
fi
grep -q "the module stopped (underrun) at curve" "$work/halrun.log" || {
    echo "the second nurbs-planner did not plan from the stop point"; exit 1; }
grep -q "nurbs-planner: stopped by signal, exiting cleanly" "$work/halrun.log" || {
    echo "nurbs-planner did not exit cleanly on SIGTERM"; exit 1; }
rm -rf "$work"
