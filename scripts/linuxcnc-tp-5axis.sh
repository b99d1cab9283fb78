#!/bin/bash
# LinuxCNC 2.9's own trajectory planner on a 5-axis (XYZAC or XYZBC) G-code program, for
# comparison with ours: the 5-axis sibling of linuxcnc-tp.sh. A full LinuxCNC (motion, task,
# interpreter, iocontrol) runs headless on a simulated table-rotary-tilting machine
# (xyzac-trt-kins or xyzbc-trt-kins at zero geometry: x/y/z-rot-point, x/y/z-offset and
# tool-offset all 0) with a 250 us servo thread (basic_sim.tcl), homes (HOME_SEARCH_VEL 0: in
# place, at 0), runs PROGRAM to its end in AUTO, and every servo period's five joint commands
# (joint.0..4.pos-cmd) and motion.motion-type are recorded (sampler + halsampler; the positions
# go through `scale` x 1e6 first, because halsampler prints floats with 6 decimals only).
# Prints:
#   - the motion time: first to last period in which a joint command moves (the rapid from the
#     home position to the program's start included), in servo periods x 250 us; also the time
#     from the first feed move (motion-type 2 or 3) and how many of the periods move;
#   - per joint the largest |velocity|, |acceleration| and |jerk| by first, second and third
#     finite differences at the servo period, each also as a ratio to that joint's
#     [JOINT_n]MAX_VELOCITY / MAX_ACCELERATION and to the jerk given on the command line;
#   - the largest ratios over the joints, over the whole motion and in feed moves only.
# What LinuxCNC does here: its TP plans in world space (tool tip in table coordinates) within the
# [AXIS_*] limits, which this script sets to the joints' values, blending within G64 P. It has no
# jerk limit (the jerk ratio is a yardstick only) and in coordinated motion it does not check
# joint velocity or acceleration at all: the trt kinematics move the linear joints when the
# table turns, so joint ratios above 1 are LinuxCNC's, not a measuring error.
# What it does not measure: the tool path's accuracy (world pose, blend deviation, chord error),
# feedback or following error (the simulated drives pass the command through), wall-clock timing
# (the times are counted in servo periods; uspace may run them late on a busy machine), the
# rotation-point / offset / tool-length geometry of a real machine (all zero here; the tool table
# has zero lengths, so G43 changes nothing).
#
#   scripts/linuxcnc-tp-5axis.sh PROGRAM [MACHINE [LIN_VEL LIN_ACC LIN_JERK ANG_VEL ANG_ACC ANG_JERK] [TOL]]
#   MACHINE xyzac (default) or xyzbc. Limits per joint (X, Y, Z in mm; A/B, C in degrees),
#   defaults 100 mm/s, 1000 mm/s^2, 1e4 mm/s^3 and 90 deg/s, 900 deg/s^2, 9000 deg/s^3 (the
#   jerks are only the ratios' yardsticks). TOL (default 0.01) goes in as `G64 P<TOL>` at the
#   program's top unless the program sets its own G64, which is then kept as it is.
#   [TRAJ] MAX_LINEAR_VELOCITY / MAX_ANGULAR_VELOCITY and the accelerations are 10x the joint
#   values, so that only the axis limits bind. Joint travel: X, Y, Z +-1000 mm, A/B +-360 deg,
#   C +-36000 deg.
# The program runs as a copy, which the script changes only so (and prints the changes):
#   - LinuxCNC's sample 5-axis programs switch kinematics with M428 (to xyzac/xyzbc TCP) and
#     M429 (back to identity), remaps of the sample config's switchkins (M430: user kins); this
#     machine has the trt kinematics only, always on, so the words M428/M429/M430 are removed
#     (the rest of their lines, comments, kept);
#   - `G64 P<TOL>` inserted (after a leading `%` line) if the program has no G64.
#   Tool changes (T.. M6) run as they are: the tool table lists every T number in the program
#   (length and diameter 0) and the tool-change handshake loops back in HAL (basic_sim.tcl).
# As root; needs linuxcnc-uspace (make setup) and /usr/bin/python3 with numpy. The run takes the
# program's machining time in real time. Not part of the test suite.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
source "$here/../tests/hal/lib.sh"
program=$(realpath "$1")
machine=${2:-xyzac}
lin_vel=${3:-100} lin_acc=${4:-1000} lin_jerk=${5:-10000}
ang_vel=${6:-90} ang_acc=${7:-900} ang_jerk=${8:-9000}
tol=${9:-0.01}
case $machine in
    xyzac | xyzbc) ;;
    *) echo "MACHINE must be xyzac or xyzbc, not $machine" >&2; exit 2 ;;
esac
tilt=${machine:3:1}
TILT=${tilt^^}
times10() { awk -v x="$1" 'BEGIN { printf "%.10g", 10 * x }'; }
started=$(date +%s.%N)
work=$(mktemp -d /tmp/nurbs-lcnc5.XXXXXX)
chmod 755 "$work"
trap 'hal_cleanup; [ -n "${KEEP_WORK:-}" ] || rm -rf "$work"' EXIT

# The program's copy: no switchkins M-codes; G64 P<TOL> unless it blends as it says itself.
sed -E 's/\b[Mm]0*4(28|29|30)([^0-9.]|$)/\2/g' "$program" >"$work/program.ngc"
if grep -v '^\s*[(;]' "$work/program.ngc" | grep -qiE '\bG0*64([^0-9.]|$)'; then
    blending="the program's own G64 (TOL not used)"
else
    if head -n 1 "$work/program.ngc" | grep -qE '^\s*%'; then
        sed -i "1a G64 P$tol" "$work/program.ngc"
    else
        sed -i "1i G64 P$tol" "$work/program.ngc"
    fi
    blending="G64 P$tol (added)"
fi
changes=$(diff "$program" "$work/program.ngc" || true)

joint() { # joint NUMBER LETTER
    local type=LINEAR vel=$lin_vel acc=$lin_acc range=1000
    if [ "$1" -ge 3 ]; then type=ANGULAR vel=$ang_vel acc=$ang_acc range=360; fi
    [ "$1" = 4 ] && range=36000
    for section in "AXIS_$2" "JOINT_$1"; do
        cat <<INI
[$section]
TYPE = $type
HOME = 0
HOME_SEARCH_VEL = 0
HOME_LATCH_VEL = 0
HOME_SEQUENCE = 0
MAX_VELOCITY = $vel
MAX_ACCELERATION = $acc
MIN_LIMIT = -$range
MAX_LIMIT = $range
FERROR = 1000
MIN_FERROR = 1000
INI
    done
}
cat >"$work/tp.ini" <<INI
[EMC]
VERSION = 1.1
MACHINE = nurbs-motion TP comparison ($machine-trt-kins)
[DISPLAY]
DISPLAY = $work/run.py
[KINS]
KINEMATICS = $machine-trt-kins
JOINTS = 5
[HAL]
HALFILE = LIB:basic_sim.tcl -no_make_ddts -no_use_hal_manualtoolchange -no_sim_spindle
HALFILE = $work/record.hal
HALCMD = setp $machine-trt-kins.x-rot-point 0
HALCMD = setp $machine-trt-kins.y-rot-point 0
HALCMD = setp $machine-trt-kins.z-rot-point 0
HALCMD = setp $machine-trt-kins.x-offset 0
HALCMD = setp $machine-trt-kins.y-offset 0
HALCMD = setp $machine-trt-kins.z-offset 0
HALCMD = setp $machine-trt-kins.tool-offset 0
[TRAJ]
COORDINATES = XYZ${TILT}C
LINEAR_UNITS = mm
ANGULAR_UNITS = deg
DEFAULT_LINEAR_VELOCITY = $lin_vel
MAX_LINEAR_VELOCITY = $(times10 "$lin_vel")
DEFAULT_LINEAR_ACCELERATION = $lin_acc
MAX_LINEAR_ACCELERATION = $(times10 "$lin_acc")
DEFAULT_ANGULAR_VELOCITY = $ang_vel
MAX_ANGULAR_VELOCITY = $(times10 "$ang_vel")
DEFAULT_ANGULAR_ACCELERATION = $ang_acc
MAX_ANGULAR_ACCELERATION = $(times10 "$ang_acc")
[EMCMOT]
EMCMOT = motmod
COMM_TIMEOUT = 1.0
SERVO_PERIOD = 250000
[TASK]
TASK = milltask
CYCLE_TIME = 0.001
[RS274NGC]
PARAMETER_FILE = $work/tp.var
[EMCIO]
EMCIO = io
CYCLE_TIME = 0.100
TOOL_TABLE = $work/tp.tbl
$(joint 0 X)
$(joint 1 Y)
$(joint 2 Z)
$(joint 3 "$TILT")
$(joint 4 C)
INI
: >"$work/tp.var"
{ echo 1; grep -oiE '\bT *[0-9]+' "$work/program.ngc" | tr -dc '0-9\n' || true; } | sed 's/^0*//' | grep . |
    sort -un | awk '{ printf "T%d P%d D0 Z0 ;\n", $1, $1 }' >"$work/tp.tbl"

# The recording: joint commands x 1e6 (full precision through halsampler's %f) and the motion
# type, every servo period while the UI enables the sampler (from the run's start to its end).
{
    echo "loadrt scale count=5"
    echo "loadrt sampler depth=40000 cfg=fffffs"
    for j in 0 1 2 3 4; do
        echo "addf scale.$j servo-thread"
        echo "setp scale.$j.gain 1000000"
        echo "net rec-j$j joint.$j.pos-cmd => scale.$j.in"
        echo "net rec-j$j-e6 scale.$j.out => sampler.0.pin.$j"
    done
    echo "net rec-type motion.motion-type => sampler.0.pin.5"
    echo "addf sampler.0 servo-thread"
    echo "setp sampler.0.enable 0"
    echo "loadusr halsampler -t -c 0 $work/samples.txt"
} >"$work/record.hal"

cat >"$work/run.py" <<PY
#!/usr/bin/python3
"""Machine on, home, AUTO, run the program to its end with the sampler on, report, switch off."""
import json, sys, time
import hal, linuxcnc
sys.path.insert(0, "$here/../tests/hal/machine")
from session import Session
ui = hal.component("nurbs-tp5-ui")  # HAL's Python API sets pins only from a component of its own
ui.ready()
result = {"errors": [], "messages": [], "last_line": 0}
session = Session(result, "run.py")
c, s, wait = session.c, session.s, session.wait
def finish():
    session.drain()
    hal.set_p("sampler.0.enable", "0")
    wait(lambda: hal.get_value("sampler.0.curr-depth") == 0, 60, "halsampler to empty the FIFO")
    time.sleep(0.5)
    result["overruns"] = hal.get_value("sampler.0.overruns")
    s.poll()
    result["end"] = [s.position[i] for i in (0, 1, 2, 3 if s.axis_mask & 8 else 4, 5)]
    json.dump(result, open("$work/result.json", "w"), indent=1)
    session.switch_off()
    sys.exit(0)
if not session.on_and_homed():
    finish()
if s.joints != 5:
    result["errors"].append(f"run.py: {s.joints} joints, not the 5 of the 5-axis machine")
    finish()
c.mode(linuxcnc.MODE_AUTO)
c.wait_complete()
c.program_open("$work/program.ngc")
c.wait_complete()
hal.set_p("sampler.0.enable", "1")
c.auto(linuxcnc.AUTO_RUN, 0)
if wait(lambda: s.exec_state != linuxcnc.EXEC_DONE or s.interp_state != linuxcnc.INTERP_IDLE, 10, "the start"):
    wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.exec_state == linuxcnc.EXEC_DONE, 7200, "the end")
    time.sleep(0.2)
finish()
PY
chmod 755 "$work/run.py"

hal_cleanup
run_start=$(date +%s.%N)
(cd "$work" && env -u DISPLAY timeout 9000 script -qec "linuxcnc $work/tp.ini" /dev/null >"$work/linuxcnc.log" 2>&1) || {
    echo "linuxcnc failed:"; cat "$work/linuxcnc.log"; exit 1; }
run_end=$(date +%s.%N)
hal_cleanup
[ -s "$work/result.json" ] || { echo "no result from the UI:"; cat "$work/linuxcnc.log"; exit 1; }

echo "program: $program ($(wc -l <"$program") lines), run as a copy with $blending"
if [ -n "$changes" ]; then echo "changes to the copy (diff original copy):"; echo "$changes" | sed 's/^/  /'; fi
/usr/bin/python3 - "$work" "$machine" "$lin_vel" "$lin_acc" "$lin_jerk" "$ang_vel" "$ang_acc" "$ang_jerk" <<'PY'
import json, sys
import numpy as np

work, machine = sys.argv[1], sys.argv[2]
lv, la, lj, av, aa, aj = map(float, sys.argv[3:9])
T = 0.00025
r = json.load(open(f"{work}/result.json"))
for m in r["messages"]:
    print(f"LinuxCNC message: {m}")
if r["errors"]:
    print("LinuxCNC errors:\n  " + "\n  ".join(r["errors"]))
    sys.exit(1)
lines = sum(1 for _ in open(f"{work}/program.ngc"))
print(f"program ran to its end without errors (highest current_line/motion_line in stat {r['last_line']} of the "
      f"copy's {lines} lines; ended at X Y Z {machine[3].upper()} C = {' '.join(f'{x:.4f}' for x in r['end'])}, "
      f"machine = program coordinates unless it set offsets)")
if r["overruns"]:
    sys.exit(f"the sampler's FIFO overran ({r['overruns']} times): samples lost")
try:
    data = np.loadtxt(f"{work}/samples.txt", ndmin=2)  # halsampler marks a gap by a line `overrun`
except ValueError as error:
    sys.exit(f"unreadable samples (an overrun?): {error}")
tags = data[:, 0].astype(np.int64)
if tags[0] != 0 or np.any(np.diff(tags) != 1):
    sys.exit("the samples' numbers are not consecutive from 0: samples lost")
q = data[:, 1:6]  # joint commands x 1e6 (um, micro-degrees)
kind = data[:, 6].astype(int)
d1 = np.diff(q, axis=0)  # d1[i]: period i+1 against period i
moving = np.flatnonzero(np.any(d1 != 0, axis=1)) + 1
if len(moving) == 0:
    sys.exit("no joint moved")
a, b = moving[0] - 1, moving[-1]  # the last standing period before the motion, its last moving period
if b + 3 >= len(q):
    sys.exit("the recording ends while the joints move")
feed = [k for k in moving if kind[k] in (2, 3)]
v = np.abs(d1) / 1e6 / T
acc = np.abs(np.diff(q, 2, axis=0)) / 1e6 / T**2
jerk = np.abs(np.diff(q, 3, axis=0)) / 1e6 / T**3
names = ["X", "Y", "Z", machine[3].upper(), "C"]
limits = np.array([[lv, la, lj]] * 3 + [[av, aa, aj]] * 2)
units = ["mm"] * 3 + ["deg"] * 2


def peaks(mask_of_period):
    """Per joint max |v|, |a|, |jerk| over the periods k where mask_of_period[k] (the differences
    ending at period k)."""
    return np.array([np.max(x[mask_of_period[o:]], axis=0, initial=0.0) for x, o in
                     ((v, 1), (acc, 2), (jerk, 3))]).T  # joints x (v, a, jerk)


everything = np.ones(len(q), bool)
is_feed = np.isin(kind, (2, 3))
whole, infeed = peaks(everything), peaks(is_feed)
print(f"LinuxCNC 2.9 TP, {machine}-trt-kins (zero geometry), servo period {T * 1e6:.0f} us: "
      f"motion {(b - a) * T:.4f} s ({b - a} periods from the first to the last moving period, "
      f"{len(moving)} of them moving; {(b - feed[0] + 1) * T if feed else 0:.4f} s from the first feed move)")
print("joint      max |v|              v/vmax  max |a|               a/amax  max |jerk|              jerk/j")
for i in range(5):
    u = units[i]
    pv, pa, pj = whole[i]
    print(f"{i} {names[i]}  {pv:12.4f} {u + '/s':7}  {pv / limits[i][0]:6.3f}  {pa:12.2f} {u + '/s^2':8}  "
          f"{pa / limits[i][1]:6.3f}  {pj:12.4g} {u + '/s^3':8}  {pj / limits[i][2]:8.2f}")
print(f"   (limits: linear {lv:g} mm/s, {la:g} mm/s^2, jerk {lj:g} mm/s^3; "
      f"angular {av:g} deg/s, {aa:g} deg/s^2, jerk {aj:g} deg/s^3)")
for label, p in (("whole motion", whole), ("feed moves only (motion-type 2/3)", infeed)):
    ratio = p / limits
    worst = np.argmax(ratio, axis=0)
    print(f"max over joints, {label}: v/vmax {ratio[worst[0], 0]:.3f} ({names[worst[0]]}), "
          f"a/amax {ratio[worst[1], 1]:.3f} ({names[worst[1]]}), jerk/j {ratio[worst[2], 2]:.2f} ({names[worst[2]]})")
PY
ended=$(date +%s.%N)
awk -v a="$started" -v b="$run_start" -v c="$run_end" -v d="$ended" \
    'BEGIN { printf "wall time: %.1f s (LinuxCNC %.1f s, analysis %.1f s)\n", d - a, c - b, d - c }'
