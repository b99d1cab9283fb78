#!/bin/bash
# Soak: back-to-back programs through our module and planner in real LinuxCNC for MINUTES
# (default 30), in one realtime session: each program is a new nurbs-planner process that
# streams a closed path from and to (0, 60) (so the next one starts where the machine stands), runs to `done`, and is unloaded. Reports per program kind the planner's peak RSS
# (first and last run: growth would show as a difference), rtapi_app's resident memory at the
# start and the end, the shared-memory blocks (`ipcs -m`) before and after the session, and
# the drift of the final position from the paths' common start and end point (`halcmd getp`,
# 10 significant digits).
# Usage: make install && scripts/soak.sh [MINUTES]   (as root; not part of the test suite)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
source "$here/../tests/hal/lib.sh"
minutes=${1:-30}
work=$(mktemp -d /tmp/nurbs-soak.XXXXXX)
chmod 755 "$work"
realtime=/usr/lib/linuxcnc/realtime
limits="--limits lab1"

# A closed dense G1 loop: a five-lobed flower around (0, 25), r = 35 + 5 sin(5 t) every
# ~0.05 mm, from (0, 60) back to it: the start and end of star_g1.ngc, so that every program
# starts where the machine stands.
python3 - "$work/flower.ngc" <<'PY'
import math, sys
n = 4400
with open(sys.argv[1], "w") as f:
    f.write("(soak: closed five-lobed flower, %d G1 lines)\nG21 G17 G90 G94 G64\nF30000\nG0 X0.0000 Y60.0000\n" % n)
    for k in range(1, n):
        t = 2 * math.pi * k / n
        r = 35 + 5 * math.sin(5 * t)
        f.write("G1 X%.4f Y%.4f\n" % (-r * math.sin(t), 25 + r * math.cos(t)))
    f.write("G1 X0.0000 Y60.0000\nM2\n")
PY
programs=("$here/../examples/star_g1.ngc" "$work/flower.ngc")

ipcs -m >"$work/ipcs-before"
hal_cleanup
trap 'halcmd unload all >/dev/null 2>&1 || true; hal_cleanup; rm -rf "$work"' EXIT
$realtime start >/dev/null
halcmd loadrt threads name1=servo period1=250000
halcmd loadrt nurbs_interp
halcmd addf nurbs_interp.update servo
halcmd setp nurbs_interp.enable 1
halcmd start
rss() { grep VmRSS "/proc/$(pidof rtapi_app)/status" | awk '{print $2}'; }
rtapi_start=$(rss)
end=$(($(date +%s) + 60 * minutes))
runs=0
declare -A first_hwm last_hwm
while [ "$(date +%s)" -lt "$end" ]; do
    for k in 0 1; do
        halcmd loadusr -W nurbs-planner "${programs[$k]}" $limits
        # The motion of this program begins (`done` of the last one clears), then ends.
        for want in FALSE TRUE; do
            for _ in $(seq 1 12000); do
                [ "$(halcmd getp nurbs_interp.done 2>/dev/null)" = "$want" ] && break
                sleep 0.025
            done
        done
        pid=$(pidof nurbs-planner) || { echo "nurbs-planner is not running after run $runs"; exit 1; }
        hwm=$(grep VmHWM "/proc/$pid/status" | awk '{print $2}')
        [ -n "${first_hwm[$k]:-}" ] || first_hwm[$k]=$hwm
        last_hwm[$k]=$hwm
        [ "$(halcmd getp nurbs_interp.fault)" = FALSE ] || { echo "fault $(halcmd getp nurbs_interp.fault-code)"; exit 1; }
        echo "$(halcmd getp nurbs_interp.pos-cmd-x) $(halcmd getp nurbs_interp.pos-cmd-y)" >>"$work/ends"
        halcmd unload nurbs-planner
        runs=$((runs + 1))
    done
done
rtapi_end=$(rss)
halcmd stop
halcmd unload all
$realtime stop >/dev/null
ipcs -m >"$work/ipcs-after"
echo "$runs programs in $minutes min"
for k in 0 1; do
    echo "$(basename "${programs[$k]}"): planner peak RSS ${first_hwm[$k]} kB first run, ${last_hwm[$k]} kB last run"
done
echo "rtapi_app resident: $rtapi_start kB at the start, $rtapi_end kB at the end"
python3 - "$work/ends" <<'PY'
import sys
worst = max(max(abs(float(x)), abs(float(y) - 60.0)) for x, y in (l.split() for l in open(sys.argv[1])))
print(f"final position drift from the paths' start and end point (0, 60): at most {worst:.3g} mm")
PY
if diff <(awk 'NR>3 {print $1, $2}' "$work/ipcs-before") <(awk 'NR>3 {print $1, $2}' "$work/ipcs-after") >/dev/null; then
    echo "shared memory: the same blocks before and after (ipcs -m)"
else
    echo "shared memory left behind:"; diff "$work/ipcs-before" "$work/ipcs-after" || true; exit 1
fi
