#!/bin/bash
# underrun_test.sh unload|freeze [PLANNER TOOLPATH KILL_AFTER STOP FLAGS]: a planner that falls behind, in
# real LinuxCNC (PLANNER erwinski, the default, or vpop: then the module stops from the end of a
# path block, where the acceleration is not zero, and the feed may rise before it falls;
# TOOLPATH default examples/butterfly.json, cut after KILL_AFTER s, default 1). nurbs-planner
# streams the butterfly with a 0.1 s margin (limits and period from halfiles/sim.ini, the same as
# $LIMITS below); after 1 s it is either unloaded (SIGTERM; a second nurbs-planner is started
# later) or frozen (SIGSTOP, by its pid; later continued with SIGCONT and it must notice the
# published stop point by itself). nurbs_interp runs out of records mid-path and stops on the path
# at the end of the last group it has, with the stop the planner made and checked there (the
# next segment re-planned to rest; VPOp: its stored deceleration sequence from the block end,
# or the module's tangential stop). The planner then plans the rest of the path from rest at the stop point and queues
# it; `setp nurbs_interp.resume 1` runs it. Checks (check_underrun.py, nurbs-plan verify): the
# samples are the offline plan (erwinski: `nurbs-plan plan --stream`, what the machine runs) up
# to the cut, then a stop whose feed, once it falls, never rises and that ends at rest, no
# position jump, underrun set and no fault; the resumed motion ends at C(1) at rest; the whole
# sampled run (to the stop, then resumed) has no axial violation. STOP=any: the stop may be a
# stored sequence (the plan's next positions, then a deceleration; e.g. across an element join),
# whose feed need not fall monotonically: only the limit check judges it. FLAGS go to every
# nurbs-planner and to the offline nurbs-plan plan.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

mode=$1
planner=${2:-erwinski}
toolpath=$(realpath "${3:-$here/../../examples/butterfly.json}")
kill_after=${4:-1}
stop_check=${5:-}
flags=${6:-}
case $mode in
    unload)
        cut="unloadusr nurbs-planner"
        replan="loadusr -W nurbs-planner @TOOLPATH@ --ini @INI@ --margin 2 --planner $planner $flags" ;;
    freeze)
        cut="loadusr -w @WORK@/signal.sh STOP"
        replan="loadusr -w @WORK@/signal.sh CONT\nloadusr -w @WORK@/wait-ready.sh" ;;
    *) echo "usage: underrun_test.sh unload|freeze"; exit 2 ;;
esac

PERIOD=0.00025
JERK=6e4
LIMITS="--limits lab1 --jerk $JERK"

work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
offline_flags=$flags
[ "$planner" = erwinski ] && offline_flags="$flags --stream"
nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --planner "$planner" $offline_flags --out "$work/offline.csv"
sed -e "s|@CUT@|$cut|" -e "s|@REPLAN@|$replan|" -e "s|@TOOLPATH@|$toolpath|g" \
    -e "s|@INI@|$(realpath "$here/../../halfiles/sim.ini")|g" \
    -e "s|@MARGIN@|0.1|g" -e "s|@PLANNER@|$planner $flags|g" -e "s|@KILL_AFTER@|$kill_after|g" -e "s|@WORK@|$work|g" \
    "$here/underrun.hal.in" >"$work/underrun.hal"

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
    --period $PERIOD --jerk $JERK --recorded-csv "$work/recorded.csv" --resumed "$work/resumed.txt" \
    $([ "$planner" = vpop ] && echo --stop-from-acceleration || echo --stop-may-rise) \
    $([ "$stop_check" = any ] && echo --any-stop)
verify=$(nurbs-plan verify "$work/recorded.csv" "$toolpath" $LIMITS --period $PERIOD || true)
echo "$verify"
if grep "^VIOLATION" <<<"$verify"; then
    echo "the stop and resume violate the limits"; exit 1
fi
grep -q "the module stopped (underrun) at curve" "$work/halrun.log" || {
    echo "the planner did not plan from the stop point"; exit 1; }
grep -q "nurbs-planner: stopped by signal, exiting cleanly" "$work/halrun.log" || {
    echo "nurbs-planner did not exit cleanly on SIGTERM"; exit 1; }
rm -rf "$work"
