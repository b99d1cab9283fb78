#!/bin/bash
# Feed hold in real LinuxCNC: the butterfly runs, `setp nurbs_interp.hold 1` after 1.5 s,
# released 2.8 s later (ramp-time 2 s). Checks (check_hold.py, nurbs-plan verify): the offline
# plan up to the hold, the feed down to rest and back, the end at C(1) with done, and the axial
# limits by finite differences over every sample; the hold ramp is not planner-checked, so a jerk
# excess of at most 0.01 % is tolerated (where the plan itself runs at a jerk limit as the ramp
# starts; see the hold test in hal/src/tests.rs).
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

toolpath=$(realpath "$here/../../examples/butterfly.json")
PERIOD=0.00025
LIMITS="--feed 2500 --accel 1e4 --jerk 6e4 --chord-tol 0.001"

work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --out "$work/offline.csv"
sed -e "s|@TOOLPATH@|$toolpath|g" -e "s|@LIMITS@|$LIMITS --period $PERIOD|g" \
    -e "s|@WORK@|$work|g" "$here/hold.hal.in" >"$work/hold.hal"

hal_session "$work/hold.hal" "$work/halrun.log"
cat "$work/halrun.log"
python3 "$here/check_hold.py" --expected "$work/offline.csv" --samples "$work/samples.txt" \
    --toolpath "$toolpath" --period $PERIOD --recorded-csv "$work/recorded.csv"
verify=$(nurbs-plan verify "$work/recorded.csv" "$toolpath" $LIMITS --period $PERIOD || true)
echo "$verify"
python3 - "$verify" <<'PY'
import re, sys
bad = []
for line in sys.argv[1].splitlines():
    if not line.startswith("VIOLATION"):
        continue
    m = re.match(r"VIOLATION: axis \d+: jerk ([0-9.e+-]+) exceeds limit ([0-9.e+-]+)", line)
    if not (m and float(m.group(1)) <= 1.0001 * float(m.group(2))):
        bad.append(line)
if bad:
    print("hold/resume violates the limits:\n  " + "\n  ".join(bad))
    sys.exit(1)
PY
grep -q "nurbs-planner: stopped by signal, exiting cleanly" "$work/halrun.log" || {
    echo "nurbs-planner did not exit cleanly on SIGTERM"; exit 1; }
rm -rf "$work"
