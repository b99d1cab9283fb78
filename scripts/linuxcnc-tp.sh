#!/bin/bash
# LinuxCNC 2.9's own trajectory planner on a G-code program, for comparison with ours: a full
# LinuxCNC (motion, task, interpreter) runs headless on a simulated XYZ machine with a 250 us
# servo thread and the given limits (TP: blends within G64 P, acceleration-limited, no jerk
# limit), homes, runs PROGRAM to its end, and every servo period's joint commands are recorded
# (sampler + halsampler). Prints the motion time (first to last moving period) and the largest
# axis velocity, acceleration and jerk by finite differences at the period, as our `verify`
# measures them.
#   scripts/linuxcnc-tp.sh PROGRAM [FEED_MM_S ACCEL JERK_FOR_RATIO CHORD_TOL]
#   (defaults 500 1e4 6e4 0.001: the dense program's limits; G64 is set to P = CHORD_TOL)
# As root; needs linuxcnc-uspace (make setup). Not part of the test suite.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
source "$here/../tests/hal/lib.sh"
program=$(realpath "$1")
feed=${2:-500} accel=${3:-10000} jerk=${4:-60000} tol=${5:-0.001}
work=$(mktemp -d /tmp/nurbs-lcnc.XXXXXX)
chmod 755 "$work"
trap 'hal_cleanup; rm -rf "$work"' EXIT

# The program with G64 P = our chord tolerance (LinuxCNC's blend tolerance).
sed -E "s/G64( P[0-9.]+)?/G64 P$tol/" "$program" >"$work/program.ngc"
grep -q "G64 P$tol" "$work/program.ngc" || sed -i "1i G64 P$tol" "$work/program.ngc"

joint() {
    cat <<INI
[JOINT_$1]
TYPE = LINEAR
HOME = 0
MAX_VELOCITY = $feed
MAX_ACCELERATION = $accel
MIN_LIMIT = -1000
MAX_LIMIT = 1000
FERROR = 1
MIN_FERROR = 1
HOME_SEARCH_VEL = 0
HOME_LATCH_VEL = 0
HOME_SEQUENCE = 0
INI
}
axis() {
    cat <<INI
[AXIS_$1]
MAX_VELOCITY = $feed
MAX_ACCELERATION = $accel
MIN_LIMIT = -1000
MAX_LIMIT = 1000
INI
}
cat >"$work/tp.ini" <<INI
[EMC]
VERSION = 1.1
MACHINE = nurbs-motion TP comparison
[DISPLAY]
DISPLAY = $work/run.py
[TASK]
TASK = milltask
CYCLE_TIME = 0.001
[RS274NGC]
PARAMETER_FILE = $work/tp.var
[EMCMOT]
EMCMOT = motmod
COMM_TIMEOUT = 1.0
SERVO_PERIOD = 250000
[EMCIO]
EMCIO = io
CYCLE_TIME = 0.100
TOOL_TABLE = $work/tp.tbl
[HAL]
HALFILE = $work/tp.hal
[TRAJ]
COORDINATES = X Y Z
LINEAR_UNITS = mm
ANGULAR_UNITS = degree
DEFAULT_LINEAR_VELOCITY = $feed
MAX_LINEAR_VELOCITY = $feed
DEFAULT_LINEAR_ACCELERATION = $accel
MAX_LINEAR_ACCELERATION = $accel
[KINS]
KINEMATICS = trivkins
JOINTS = 3
$(axis X)
$(axis Y)
$(axis Z)
$(joint 0)
$(joint 1)
$(joint 2)
INI
: >"$work/tp.var"
printf 'T1 P1 D0 Z0 ;\n' >"$work/tp.tbl"

cat >"$work/tp.hal" <<HAL
loadrt [KINS]KINEMATICS
loadrt [EMCMOT]EMCMOT servo_period_nsec=[EMCMOT]SERVO_PERIOD num_joints=[KINS]JOINTS
loadrt sampler depth=16000 cfg=fffs
addf motion-command-handler servo-thread
addf motion-controller servo-thread
addf sampler.0 servo-thread
net x joint.0.motor-pos-cmd => joint.0.motor-pos-fb sampler.0.pin.0
net y joint.1.motor-pos-cmd => joint.1.motor-pos-fb sampler.0.pin.1
net z joint.2.motor-pos-cmd => joint.2.motor-pos-fb sampler.0.pin.2
net type motion.motion-type => sampler.0.pin.3
net estop-loop iocontrol.0.user-enable-out iocontrol.0.emc-enable-in
net tool-prep-loop iocontrol.0.tool-prepare iocontrol.0.tool-prepared
net tool-change-loop iocontrol.0.tool-change iocontrol.0.tool-changed
setp sampler.0.enable 1
loadusr halsampler -c 0 $work/samples.txt
HAL

cat >"$work/run.py" <<PY
#!/usr/bin/python3
"""Machine on, home, run the program to its end, report errors, shut down."""
import linuxcnc, sys, time
c, s, e = linuxcnc.command(), linuxcnc.stat(), linuxcnc.error_channel()
def wait(cond, timeout, what):
    end = time.time() + timeout
    while time.time() < end:
        s.poll()
        if cond():
            return
        time.sleep(0.01)
    sys.exit(f"timed out waiting for {what}")
c.state(linuxcnc.STATE_ESTOP_RESET); c.state(linuxcnc.STATE_ON)
wait(lambda: s.task_state == linuxcnc.STATE_ON, 10, "machine on")
c.mode(linuxcnc.MODE_MANUAL); c.home(-1)
wait(lambda: all(s.homed[:3]), 30, "homing")
c.mode(linuxcnc.MODE_AUTO); c.wait_complete()
c.program_open("$work/program.ngc"); c.wait_complete()
c.auto(linuxcnc.AUTO_RUN, 0)
wait(lambda: s.exec_state != linuxcnc.EXEC_DONE or s.interp_state != linuxcnc.INTERP_IDLE, 10, "the start")
wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.exec_state == linuxcnc.EXEC_DONE, 3600, "the end")
time.sleep(0.2)
errors = []
while (m := e.poll()):
    errors.append(m[1])
open("$work/errors.txt", "w").write("\n".join(errors))
c.state(linuxcnc.STATE_OFF)
PY
chmod 755 "$work/run.py"

hal_cleanup
(cd "$work" && env -u DISPLAY timeout 7200 script -qec "linuxcnc $work/tp.ini" /dev/null >"$work/linuxcnc.log" 2>&1) || {
    echo "linuxcnc failed:"; cat "$work/linuxcnc.log"; exit 1; }
if [ -s "$work/errors.txt" ]; then echo "LinuxCNC errors:"; cat "$work/errors.txt"; exit 1; fi
python3 - "$work/samples.txt" "$jerk" <<'PY'
import sys
T = 0.00025
rows = [l.split()[-4:] for l in open(sys.argv[1]) if l.strip()]
q = [list(map(float, r[:3])) for r in rows]
kind = [int(r[3]) for r in rows]
# The feed motion: from the first period of a feed move (motion-type 2 line, 3 arc) to the last
# period that moves (the rapid to the start before it is not part of the program's path).
feed = [k for k in range(1, len(q)) if kind[k] in (2, 3) and q[k] != q[k - 1]]
moving = [k for k in range(1, len(q)) if q[k] != q[k - 1]]
a, b = feed[0] - 1, moving[-1]
peak = [[0.0] * 3 for _ in range(3)]
for k in range(a, b + 4):
    for i in range(3):
        v = (q[k][i] - q[k - 1][i]) / T
        acc = (q[k][i] - 2 * q[k - 1][i] + q[k - 2][i]) / T**2
        j = (q[k][i] - 3 * q[k - 1][i] + 3 * q[k - 2][i] - q[k - 3][i]) / T**3
        for d, x in enumerate((v, acc, j)):
            peak[d][i] = max(peak[d][i], abs(x))
# Periods that move: a program whose M-codes stop the machine (a laser's beam on and off)
# also spends time standing while the task runs them, which is not the planner's.
moves = sum(1 for k in range(a + 1, b + 1) if q[k] != q[k - 1])
print(f"LinuxCNC 2.9 TP: motion {(b - a) * T:.4f} s ({b - a} periods, {moves * T:.4f} s of them moving); max |v| {[round(x, 1) for x in peak[0]]}, "
      f"|a| {[round(x, 1) for x in peak[1]]}, |jerk| {[round(x) for x in peak[2]]} "
      f"({max(peak[2]) / float(sys.argv[2]):.1f} x a jerk limit of {float(sys.argv[2]):g})")
PY
