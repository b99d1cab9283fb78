#!/bin/bash
# Underrun with a planner that falls behind but lives on, in real LinuxCNC: nurbs-planner streams
# the butterfly with a 0.1 s margin and is frozen (SIGSTOP, by its pid) after 1 s; nurbs_interp
# runs out of records and stops on the path with the planner-checked stop. The planner is then
# continued (SIGCONT): it must notice the published stop point by itself, plan the rest of the
# path from rest there and queue it; `setp nurbs_interp.resume 1` runs it. Same checks as
# test_underrun.sh: the plan up to the cut, a stop to rest, no jump, the end at C(1) at rest, and
# `nurbs-plan verify` finds no violation over the whole sampled run.
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
    "$here/stall.hal.in" >"$work/underrun.hal"

cat >"$work/signal.sh" <<'SH'
#!/bin/sh
# signal.sh STOP|CONT: freeze or continue the nurbs-planner of this session (by its pid).
pid=$(pidof nurbs-planner) || { echo "no nurbs-planner running"; exit 1; }
kill -"$1" $pid
SH
cat >"$work/wait-ready.sh" <<'SH'
#!/bin/sh
# Wait (at most 20 s) until nurbs_interp has a plan from the stop point queued.
for i in $(seq 200); do
    [ "$(halcmd getp nurbs_interp.resume-ready)" = TRUE ] && exit 0
    sleep 0.1
done
echo "no plan from the stop point after 20 s"; exit 1
SH
chmod 755 "$work/signal.sh" "$work/wait-ready.sh"
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
