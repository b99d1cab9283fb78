#!/usr/bin/python3
"""The test's user interface for a headless LinuxCNC ([DISPLAY]DISPLAY): E-stop reset, machine
on, home, run the program named by $NURBS_TEST_PROGRAM to its end with the sampler recording,
then write what the machine says of itself to $NURBS_TEST_RESULT (JSON) and switch off, which
ends LinuxCNC. $NURBS_TEST_ACTION: `abort` (the operator's abort 0.3 s into the first toolpath;
motion catches up with where our path stopped and takes the drives back, then moves 1 mm in X
by MDI), `pause-abort` (the same after a pause), `estop` (E-stop there, then
reset and on), `pause` (the operator's pause there, resumed 0.3 s after our path is held) or
`override` (the operator's feed override to 10 % 0.1 s into the first toolpath, back to 100 %
once it is over). $NURBS_TEST_SETUP: MDI commands (separated by `;`) run before the program, as
an operator's touch-off; $NURBS_TEST_FILTER: the program goes through that program filter
first, as AXIS runs a [FILTER] (its report kept in the result's "filter")."""
import json
import os
import subprocess
import sys
import time

import hal
import linuxcnc

from session import Session

# HAL's Python API reads and sets pins only from a component of its own.
ui = hal.component("nurbs-test-ui")
ui.ready()
result = {"errors": [], "messages": []}
session = Session(result, "test-ui")
c, s, drain, wait = session.c, session.s, session.drain, session.wait


def finish():
    drain()
    s.poll()
    joints = range(s.joints)
    result["homed"] = list(s.homed[: s.joints])
    result["position"] = list(s.position[: s.joints])  # motion's commanded position (machine coordinates)
    result["actual"] = list(s.actual_position[: s.joints])
    result["joint_pos_cmd"] = [hal.get_value(f"joint.{j}.pos-cmd") for j in joints]
    result["motor_offset"] = [hal.get_value(f"joint.{j}.motor-offset") for j in joints]
    result["drive"] = [hal.get_value(f"nurbs_interp.joint.{j}.drive-cmd") for j in joints]
    result["engaged"] = hal.get_value("nurbs_interp.engaged")
    result["task_state"] = s.task_state
    with open(os.environ["NURBS_TEST_RESULT"], "w") as f:
        json.dump(result, f, indent=1)
    session.switch_off()
    sys.exit(0)


if not session.on_and_homed():
    finish()
c.mode(linuxcnc.MODE_AUTO)
c.wait_complete()
program = os.environ["NURBS_TEST_PROGRAM"]
setup = [m.strip() for m in os.environ.get("NURBS_TEST_SETUP", "").split(";") if m.strip()]
if setup:
    c.mode(linuxcnc.MODE_MDI)
    c.wait_complete()
    for command in setup:
        c.mdi(command)
        c.wait_complete()
        wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE, 10, f"MDI {command}")
    c.mode(linuxcnc.MODE_AUTO)
    c.wait_complete()
if os.environ.get("NURBS_TEST_FILTER"):
    # As AXIS does: the filter's standard output is the program LinuxCNC runs.
    filtered = os.path.join(os.path.dirname(os.environ["NURBS_TEST_RESULT"]), "filtered.ngc")
    with open(filtered, "w") as out:
        run = subprocess.run([os.environ["NURBS_TEST_FILTER"], program], stdout=out, stderr=subprocess.PIPE, text=True)
    result["filter"] = run.stderr
    if run.returncode != 0:
        result["errors"].append(f"filter: {run.stderr.strip()}")
        finish()
    program = filtered
hal.set_p("sampler.0.enable", "1")
c.program_open(program)
c.wait_complete()
c.auto(linuxcnc.AUTO_RUN, 0)
wait(lambda: s.exec_state != linuxcnc.EXEC_DONE or s.interp_state != linuxcnc.INTERP_IDLE, 10, "the program to start")
action = os.environ.get("NURBS_TEST_ACTION", "")
if action in ("abort", "estop", "pause", "pause-abort", "override"):
    # 0.3 s after our path starts moving (not after the hand-over: on a slow machine the
    # planner's start can take a good part of that), so the check's 0.25 s of planned
    # setpoints before the action holds whatever the start took.
    wait(lambda: hal.get_value("nurbs_interp.active"), 60, "our path to move")
    time.sleep(0.1 if action == "override" else 0.3)
    result["action_moving"] = hal.get_value("nurbs_interp.active")
    if action == "override":
        c.feedrate(0.1)
        # Where our path was when the operator turned the knob (located in the samples).
        result["override_at"] = [hal.get_value("nurbs_interp.curve"), hal.get_value("nurbs_interp.u")]
        wait(lambda: not hal.get_value("nurbs_interp.engaged"), 60, "the first toolpath's end")
        c.feedrate(1.0)
    if action == "pause":
        c.auto(linuxcnc.AUTO_PAUSE)
        wait(lambda: hal.get_value("nurbs_interp.held"), 5, "our path held")
        result["paused_at_rest"] = hal.get_value("nurbs_interp.held")
        time.sleep(0.3)
        c.auto(linuxcnc.AUTO_RESUME)
    if action in ("abort", "pause-abort"):
        if action == "pause-abort":
            c.auto(linuxcnc.AUTO_PAUSE)
            wait(lambda: hal.get_value("nurbs_interp.held"), 5, "our path held")
            result["paused_at_rest"] = hal.get_value("nurbs_interp.held")
            time.sleep(0.3)
        c.abort()
        c.wait_complete()
        # The path stops on the path (at its next checked stop; paused, it stands already);
        # M102's abort handler then has motion catch up with it and the drives released, the
        # machine staying on.
        result["released_after_abort"] = wait(lambda: not hal.get_value("nurbs_interp.engaged"), 30,
                                              "the release after the abort")
        # The helper restores the mode it found; then the machine runs MDI again.
        wait(lambda: s.task_mode != linuxcnc.MODE_MDI, 10, "the catch-up to hand back the mode")
        time.sleep(0.1)
        c.mode(linuxcnc.MODE_MDI)
        c.wait_complete()
        c.mdi("G91 G1 X1 F600")
        c.wait_complete()
        wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE, 10, "an MDI move after the abort")
        c.mdi("G90")
        c.wait_complete()
        wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE, 10, "G90")
        result["moved_after_abort"] = True
    elif action == "estop":
        c.state(linuxcnc.STATE_ESTOP)
        wait(lambda: s.task_state == linuxcnc.STATE_ESTOP, 5, "E-stop")
        time.sleep(0.1)
        c.state(linuxcnc.STATE_ESTOP_RESET)
    if action == "estop":
        time.sleep(0.1)
        c.state(linuxcnc.STATE_ON)
        wait(lambda: s.task_state == linuxcnc.STATE_ON, 5, "machine on again")
        time.sleep(0.1)
wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.exec_state == linuxcnc.EXEC_DONE, 600, "the program's end")
time.sleep(0.1)
hal.set_p("sampler.0.enable", "0")
# The recorder ends once no sample came for its idle time.
wait(lambda: not hal.component_exists("nurbs-hal-record0"), 30, "the recorder to finish")
finish()
