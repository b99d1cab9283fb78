#!/bin/bash
# Our 5-axis kinematics (nurbs_rtcore::kinematics, through `nurbs-plan kinematics`) against
# LinuxCNC's own `xyzac-trt-kins` and `xyzbc-trt-kins` loaded in a complete LinuxCNC (motion,
# task, interpreter, homing; headless), with a non-zero rotation point, axis offsets and tool
# offset set on the module's pins. The test UI moves by MDI to world poses spread over the
# tilt's range and C past ±360°; at rest, motion's commanded joints must equal our inverse
# kinematics of its commanded world pose, and its feedback world pose our forward kinematics of
# its feedback joints, to 1e-9 (mm and degrees). The same poses with the default geometry must
# miss by more than 1 mm (the geometry reaches the joints).
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"
work=$(mktemp -d /tmp/nurbs-kins.XXXXXX)
chmod 755 "$work"
trap 'hal_cleanup; [ -n "${KEEP_WORK:-}" ] || rm -rf "$work"' EXIT

# x y z tilt c (mm, degrees): inside the travel below, both tilt signs, C beyond a turn.
poses='[[10, -20, 5, 30, 45], [-35.5, 12.25, -8.125, -60, 200], [0, 0, 0, 0, 0],
        [50, 40, 30, 85, -370], [-12.5, 33, -20, -15.5, 725.25]]'
# x-rot-point y-rot-point z-rot-point x-offset y-offset z-offset tool-offset
geometry=(12.5 -30 7.25 4 20 -10 55.5)

for machine in xyzac xyzbc; do
    tilt=${machine:3:1}
    config="$work/$machine"
    mkdir -p "$config"
    cat >"$config/machine.ini" <<INI
[EMC]
VERSION = 1.1
MACHINE = nurbs-kins-$machine
[DISPLAY]
DISPLAY = $here/machine/kins-ui.py
[KINS]
KINEMATICS = $machine-trt-kins
JOINTS = 5
[HAL]
HALFILE = LIB:basic_sim.tcl -no_make_ddts -no_use_hal_manualtoolchange -no_sim_spindle
HALCMD = setp $machine-trt-kins.x-rot-point ${geometry[0]}
HALCMD = setp $machine-trt-kins.y-rot-point ${geometry[1]}
HALCMD = setp $machine-trt-kins.z-rot-point ${geometry[2]}
HALCMD = setp $machine-trt-kins.x-offset ${geometry[3]}
HALCMD = setp $machine-trt-kins.y-offset ${geometry[4]}
HALCMD = setp $machine-trt-kins.z-offset ${geometry[5]}
HALCMD = setp $machine-trt-kins.tool-offset ${geometry[6]}
[TRAJ]
COORDINATES = XYZ${tilt^^}C
LINEAR_UNITS = mm
ANGULAR_UNITS = deg
MAX_LINEAR_VELOCITY = 500
MAX_ANGULAR_VELOCITY = 3600
[EMCMOT]
EMCMOT = motmod
SERVO_PERIOD = 1000000
COMM_TIMEOUT = 1
[TASK]
TASK = milltask
CYCLE_TIME = 0.010
[RS274NGC]
PARAMETER_FILE = machine.var
[EMCIO]
EMCIO = io
CYCLE_TIME = 0.100
INI
    for j in 0 1 2 3 4; do
        name=(X Y Z "${tilt^^}" C)
        type=LINEAR; [ $j -ge 3 ] && type=ANGULAR
        range=1000; [ $j = 4 ] && range=36000
        for section in "AXIS_${name[$j]}" "JOINT_$j"; do
            cat >>"$config/machine.ini" <<INI
[$section]
TYPE = $type
HOME = 0
HOME_SEARCH_VEL = 0
HOME_SEQUENCE = 0
MAX_VELOCITY = 500
MAX_ACCELERATION = 5000
MIN_LIMIT = -$range
MAX_LIMIT = $range
INI
        done
    done

    hal_cleanup
    (cd "$config" && NURBS_KINS_MODULE="$machine-trt-kins" NURBS_KINS_TILT="$tilt" NURBS_KINS_POSES="$poses" \
        NURBS_TEST_RESULT="$config/result.json" \
        env -u DISPLAY timeout 300 script -qec "linuxcnc $config/machine.ini" /dev/null >"$config/linuxcnc.log" 2>&1) \
        || { echo "linuxcnc failed:"; cat "$config/linuxcnc.log"; exit 1; }
    hal_cleanup
    [ -s "$config/result.json" ] || { echo "no result from the test UI:"; cat "$config/linuxcnc.log"; exit 1; }
    /usr/bin/python3 - "$config/result.json" "$machine" "${geometry[@]}" <<'PY' || { tail -n 30 "$config/linuxcnc.log"; exit 1; }
import json, subprocess, sys

result_file, machine = sys.argv[1], sys.argv[2]
g = [float(v) for v in sys.argv[3:]]
r = json.load(open(result_file))
assert not r["errors"], f"LinuxCNC reported errors: {r['errors']}"
poses = r["poses"]
assert len(poses) == 5, f"{len(poses)} poses recorded"
pins = r["geometry"]
assert [pins[p] for p in ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset",
                          "tool-offset")] == g, f"the module's pins are not the geometry set: {pins}"
flags = ["--machine", machine, f"--rot-point={g[0]},{g[1]},{g[2]}", f"--kins-offset={g[3]},{g[4]},{g[5]}",
         f"--tool-offset={g[6]}"]


def ours(rows, args):
    text = "\n".join(" ".join(repr(v) for v in row) for row in rows) + "\n"
    out = subprocess.run(["nurbs-plan", "kinematics", *args], input=text, capture_output=True, text=True,
                         check=True).stdout
    return [[float(v) for v in line.split()] for line in out.splitlines()]


def worst(a, b):
    return max(abs(x - y) for ra, rb in zip(a, b) for x, y in zip(ra, rb))


inverse = ours([p["world_cmd"] for p in poses], flags)
forward = ours([p["joints_fb"] for p in poses], flags + ["--forward"])
inverse_error = worst(inverse, [p["joints_cmd"] for p in poses])
forward_error = worst(forward, [p["world_fb"] for p in poses])
reached = worst([p["world_cmd"] for p in poses], [p["programmed"] for p in poses])
naive = worst(ours([p["world_cmd"] for p in poses], ["--machine", machine]), [p["joints_cmd"] for p in poses])
print(f"{machine}-trt-kins: {len(poses)} poses (reached within {reached:.1e}); inverse {inverse_error:.2e}, "
      f"forward {forward_error:.2e} (mm, deg); default geometry off by {naive:.1f}")
assert reached < 1e-6, "motion did not reach the programmed poses"
assert inverse_error <= 1e-9 and forward_error <= 1e-9, "our kinematics differ from LinuxCNC's"
assert naive > 1.0, "the geometry changes nothing: the check cannot fail"
PY
done
