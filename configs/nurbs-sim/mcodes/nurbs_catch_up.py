#!/usr/bin/python3
"""After an abort during M102: once our path has stopped on the path, motion's command moves to
where it stopped (the catch-up move, as after a toolpath's end: the drives stand still) and
nurbs_interp gives the drives back (its `engage` is already false). Without it motion would
believe the tool stands at the toolpath's start until the machine is switched off and on.

M102's abort handler starts it in a session of its own: task, which aborts the program, waits
neither for it nor kills it. It ends at once if the drives are already released (the machine
switched off, E-stop)."""
import time

import linuxcnc

import nurbs_mcodes as m


last_moving = [time.monotonic()]


def stopped():
    # `held` after the abort's stop; an abort while held (paused) ends that motion at once, and
    # nothing moves any more (no sample for 50 ms).
    if m.pin("active"):
        last_moving[0] = time.monotonic()
    still = time.monotonic() - last_moving[0] > 0.05
    return not m.pin("engaged") or m.pin("held") or m.pin("done") or m.pin("fault") or still


m.wait_until(stopped, 10, lambda: "our path to stop after the abort (" + m.positions() + ")")
if not m.pin("engaged"):
    raise SystemExit(0)
axes = "xyz" if m.pin("path-3d") else "xy"
target = {a: m.pin(f"pos-cmd-{a}") for a in axes}
stat, command = linuxcnc.stat(), linuxcnc.command()
AFTER = "; switch the machine off and on to give motion the drives' position"


def task_idle():
    stat.poll()
    if stat.task_state != linuxcnc.STATE_ON:
        m.fail("after the abort the machine is not on: motion has not caught up with our path" + AFTER)
    return stat.interp_state == linuxcnc.INTERP_IDLE and stat.state != linuxcnc.RCS_EXEC


m.wait_until(task_idle, 10, "LinuxCNC to finish the abort" + AFTER)
mode = stat.task_mode
command.mode(linuxcnc.MODE_MDI)
command.wait_complete(5.0)
stat.poll()
if stat.task_mode != linuxcnc.MODE_MDI:
    m.fail("after the abort LinuxCNC did not take MDI for the catch-up move" + AFTER)
move = "G53 G0 " + " ".join(f"{a.upper()}{v:.9f}" for a, v in target.items())
m.log(f"after the abort: the catch-up move {move} (the drives stand still)")
command.mdi(move)
m.wait_until(lambda: not m.pin("engaged"), 120, lambda: "the release after the catch-up move: " + m.positions() + AFTER)
m.wait_until(task_idle, 10, "the catch-up move to end")
command.mode(mode)
command.wait_complete(5.0)
m.log("after the abort: motion stands where our path stopped, the drives are released")
