#!/bin/bash
# test_hold.sh [PLANNER TOOLPATH HOLD_AFTER]: feed hold in real LinuxCNC. By default the
# butterfly runs with the Erwinski planner, `setp nurbs_interp.hold 1` after 1.5 s (HOLD_AFTER),
# released 2.8 s later. The module stops at the next segment boundary with the stop the planner
# checked from there, publishes its stop point; the running nurbs-planner re-plans the rest of the
# path from rest at that point; the release runs it. Checks (check_hold.py, nurbs-plan verify):
# the offline plan up to the hold, the feed down to rest and back, the end at C(1) with done, and
# the axial limits by finite differences over every sample with verify's relative slack of 1e-6
# and nothing more: any VIOLATION fails.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

planner=${1:-erwinski}
toolpath=$(realpath "${2:-$here/../../examples/butterfly.json}")
hold_after=${3:-1.5}
PERIOD=0.00025
LIMITS="--limits lab1"

work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --planner "$planner" --out "$work/offline.csv"
sed -e "s|@TOOLPATH@|$toolpath|g" -e "s|@LIMITS@|$LIMITS --period $PERIOD --planner $planner|g" \
    -e "s|@HOLD_AFTER@|$hold_after|g" -e "s|@WORK@|$work|g" "$here/hold.hal.in" >"$work/hold.hal"

hal_session "$work/hold.hal" "$work/halrun.log"
cat "$work/halrun.log"
python3 "$here/check_hold.py" --expected "$work/offline.csv" --samples "$work/samples.txt" \
    --toolpath "$toolpath" --period $PERIOD --recorded-csv "$work/recorded.csv" \
    $([ "$planner" != erwinski ] && echo --jerk 6e4)
verify=$(nurbs-plan verify "$work/recorded.csv" "$toolpath" $LIMITS --period $PERIOD || true)
echo "$verify"
if grep "^VIOLATION" <<<"$verify"; then
    echo "hold/resume violates the limits"; exit 1
fi
grep -q "the module stopped (hold) at curve" "$work/halrun.log" || {
    echo "nurbs-planner did not re-plan from the hold's stop point"; exit 1; }
grep -q "nurbs-planner: stopped by signal, exiting cleanly" "$work/halrun.log" || {
    echo "nurbs-planner did not exit cleanly on SIGTERM"; exit 1; }
rm -rf "$work"
