#!/usr/bin/python3
"""The test UI of test_machine_kins.sh (a headless LinuxCNC's [DISPLAY]DISPLAY): E-stop reset,
machine on, home, then for each world pose in $NURBS_KINS_POSES (JSON: a list of [x, y, z, tilt,
c]) an MDI G0 there; at rest it records motion's commanded world pose and joints and its
feedback pose and joints, and the kinematics module's geometry pins. Writes
$NURBS_TEST_RESULT (JSON) and switches off, which ends LinuxCNC."""
import json
import os
import sys
import time

import hal
import linuxcnc

from session import Session

ui = hal.component("nurbs-kins-ui")
ui.ready()
kins = os.environ["NURBS_KINS_MODULE"]
tilt = os.environ["NURBS_KINS_TILT"]  # "a" or "b"
result = {"errors": [], "poses": []}
session = Session(result, "kins-ui")
c, s, wait = session.c, session.s, session.wait


def finish():
    session.drain()
    with open(os.environ["NURBS_TEST_RESULT"], "w") as f:
        json.dump(result, f, indent=1)
    session.switch_off()
    sys.exit(0)


def world(position):
    """x, y, z, tilt, c of a 9-coordinate pose (x y z a b c u v w)."""
    return [position[0], position[1], position[2], position[3 if tilt == "a" else 4], position[5]]


if not session.on_and_homed():
    finish()
if s.joints != 5:
    result["errors"].append(f"kins-ui: {s.joints} joints, not the 5 of {kins}")
    finish()
result["geometry"] = {pin: hal.get_value(f"{kins}.{pin}") for pin in
                      ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset",
                       "tool-offset")}
c.mode(linuxcnc.MODE_MDI)
c.wait_complete()
for pose in json.loads(os.environ["NURBS_KINS_POSES"]):
    x, y, z, t, cc = pose
    c.mdi(f"G90 G0 X{x} Y{y} Z{z} {tilt.upper()}{t} C{cc}")
    c.wait_complete()
    if not wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0 and s.inpos, 60,
                f"the move to {pose}"):
        finish()
    time.sleep(0.05)  # a few servo periods at rest: feedback settled on the command
    s.poll()
    result["poses"].append({
        "programmed": pose,
        "world_cmd": world(s.position),
        "joints_cmd": list(s.joint_position[:5]),
        "world_fb": world(s.actual_position),
        "joints_fb": list(s.joint_actual_position[:5]),
    })
finish()
