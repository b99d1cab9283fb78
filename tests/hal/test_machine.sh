#!/bin/bash
# The product inside a complete LinuxCNC machine (motion, task, interpreter, homing; headless):
# configs/nurbs-sim as shipped, with only its display replaced by a test UI and a recorder
# added. The UI homes the machine (non-zero motor offsets) and runs demo.ngc: LinuxCNC's own
# moves, then o<nurbs_run> twice (M101 plans a toolpath, motion moves to its start, M102 hands
# the drives to nurbs_interp and runs it, motion's catch-up move to its end, M103 takes the
# drives back: the trident, closed, in XY; the open pocket's tool tip in XYZ), with LinuxCNC's
# moves between and after. check_machine.py checks every recorded period.
#   MACHINE_WIRING=naive: the negative control (the drive command switched between motion
#   and nurbs_interp by a mux2 on `engaged`): the same checks must fail.
#   MACHINE_ACTION=abort|estop: the operator's abort (or an E-stop) 0.3 s into the first
#   toolpath instead of running the program to its end (check_machine.py --action);
#   MACHINE_ACTION=pause-abort: the operator's pause there, then an abort while held;
#   MACHINE_ACTION=pause: the operator's pause 0.3 s into the first toolpath (halui holds our
#   path at its next checked stop), resumed: the rest is re-planned from there and the program
#   runs to its end;
#   MACHINE_ACTION=override: the operator's feed override to 10 % 0.1 s into the first toolpath
#   (the planner plans the rest again, the motion runs into it), back to 100 % after it;
#   MACHINE_ACTION=travel: the INI's Y travel ends at 20 mm, inside the trident (Y to 27): M101
#   must refuse it before any motion and abort the program.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"
repo=$(cd "$here/../.." && pwd)
work=$(mktemp -d /tmp/nurbs-machine.XXXXXX)
chmod 755 "$work"
trap 'hal_cleanup; [ -n "${KEEP_WORK:-}" ] || rm -rf "$work"' EXIT

mkdir -p "$work/configs"
cp -r "$repo/configs/nurbs-sim" "$work/configs/"
cp -r "$repo/examples" "$work/"
config="$work/configs/nurbs-sim"
sed -i -e "s|^DISPLAY = .*|DISPLAY = $here/machine/test-ui.py|" \
    -e "s|^HALFILE = nurbs-sim.hal|HALFILE = nurbs-sim.hal\nHALFILE = record.hal|" "$config/nurbs-sim.ini"
sed "s|@WORK@|$work|g" "$here/machine/record.hal" >"$config/record.hal"
if [ "${MACHINE_WIRING:-}" = naive ]; then
    python3 "$here/machine/naive_wiring.py" "$config/nurbs-sim.hal"
fi

action=${MACHINE_ACTION:-}
# The plans the machine must run (demo.ngc runs toolpaths 1 and 2), offline, with the INI.
toolpaths=("$work/examples/trident.json" "$work/examples/open_pocket_tip.json")
plans=()
for k in 0 1; do
    nurbs-plan plan "${toolpaths[$k]}" --ini "$config/nurbs-sim.ini" --stream --out "$work/offline-$k.csv" >/dev/null
    plans+=(--offline "$work/offline-$k.csv" --recorded-csv "$work/recorded-$k.csv")
done

if [ "$action" = travel ]; then
    python3 - "$config/nurbs-sim.ini" <<'PY'
import re, sys
ini = open(sys.argv[1]).read()
ini, n = re.subn(r"(\[AXIS_Y\][^\[]*?MAX_LIMIT = )100", r"\g<1>20", ini)
assert n == 1
open(sys.argv[1], "w").write(ini)
PY
fi

hal_cleanup
started=$(date +%s.%N)
(cd "$config" && TMPDIR="$work" NURBS_TEST_PROGRAM="$config/demo.ngc" NURBS_TEST_RESULT="$work/result.json" NURBS_TEST_ACTION="$action" \
    env -u DISPLAY timeout 600 script -qec "linuxcnc $config/nurbs-sim.ini" /dev/null \
    >"$work/linuxcnc.log" 2>&1) || { echo "linuxcnc failed:"; cat "$work/linuxcnc.log"; exit 1; }
hal_cleanup
echo "LinuxCNC ran for $(python3 -c "print(round($(date +%s.%N) - $started, 1))") s"
if [ ! -s "$work/result.json" ]; then
    echo "no result from the test UI:"; cat "$work/linuxcnc.log"; exit 1
fi
grep "^nurbs" "$work/linuxcnc.log" "$work/nurbs-planner.log" || true
python3 "$here/machine/check_machine.py" --samples "$work/samples.txt" --result "$work/result.json" \
    --ini "$config/nurbs-sim.ini" "${plans[@]}" ${action:+--action $action} \
    || { echo "--- LinuxCNC log:"; tail -n 40 "$work/linuxcnc.log"; exit 1; }
if [ -z "$action" ] || [ "$action" = travel ] || [ "$action" = pause ] || [ "$action" = override ]; then
    [ "$action" = travel ] && exit 0
    for k in 0 1; do
        nurbs-plan verify "$work/recorded-$k.csv" "${toolpaths[$k]}" --ini "$config/nurbs-sim.ini"
    done
elif [ "$action" = abort ] || [ "$action" = pause-abort ]; then
    # Stopped on the path: every limit held, only the path's end not reached. (After an E-stop
    # the setpoints are the plan's up to it and the drives are off: nothing to verify.)
    verify=$(nurbs-plan verify "$work/recorded-0.csv" "${toolpaths[0]}" --ini "$config/nurbs-sim.ini" || true)
    echo "$verify"
    if grep "^VIOLATION" <<<"$verify" | grep -v "not the end of the path"; then exit 1; fi
fi
