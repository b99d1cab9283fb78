"""What M101-M103 share: the INI, nurbs_interp's pins, waiting, and errors LinuxCNC shows.

LinuxCNC runs a user M-code (M100-M199) as a program with P and Q as its arguments, once motion
is idle, and waits for it to exit; a non-zero exit aborts the G-code program. On abort or
E-stop the program gets SIGINT.
"""
import glob
import os
import signal
import subprocess
import sys
import time

import hal
import linuxcnc

# HAL's Python API reads and sets pins only from a component of its own (gone at exit).
_component = hal.component(f"nurbs-mcode-{os.getpid()}")
_component.ready()

# Values of nurbs_interp.handover-refused.
REFUSALS = {
    1: "the machine is off (or was switched off since the request)",
    2: "no toolpath is loaded",
    3: "the machine is not at rest",
    4: "the machine does not stand at the toolpath's start",
    5: "motion does not stand at the toolpath's end yet (offset left)",
}


def fail(message):
    """Show `message` in LinuxCNC's error channel and abort the G-code program."""
    linuxcnc.command().error_msg(f"nurbs: {message}")
    print(f"nurbs: {message}", file=sys.stderr, flush=True)
    sys.exit(1)


def log(message):
    print(f"nurbs: {message}", file=sys.stderr, flush=True)


def ini():
    """The machine's INI (parsed) and its file name."""
    name = os.environ.get("INI_FILE_NAME")
    if not name:
        fail("INI_FILE_NAME is not set (not started by linuxcnc?)")
    return linuxcnc.ini(name), name


def p_word():
    """The integer P word of the M-code."""
    try:
        return int(float(sys.argv[1]))
    except (IndexError, ValueError):
        fail(f"{os.path.basename(sys.argv[0])} needs a P word (the toolpath's number)")


def q_word():
    """The integer Q word of the M-code (0 when not given)."""
    try:
        return int(float(sys.argv[2]))
    except (IndexError, ValueError):
        return 0


# Where installed data lives (`make install`): toolpaths named in the INI are looked for beside
# the INI first, then among the installed examples.
DATA_DIRS = [d for d in (os.environ.get("NURBS_MOTION_DATA"), "/usr/local/share/nurbs-motion", "/usr/share/nurbs-motion") if d]


def find_toolpath(name, ini_name):
    """The file [NURBS]TOOLPATH_<n> names: absolute, relative to the INI's folder, or an
    installed example; None if there is none."""
    if os.path.isabs(name):
        return name if os.path.isfile(name) else None
    for folder in [os.path.dirname(os.path.abspath(ini_name))] + [os.path.join(d, "examples") for d in DATA_DIRS]:
        path = os.path.join(folder, name)
        if os.path.isfile(path):
            return os.path.normpath(path)
    return None


def filter_run(program_id, n):
    """Run `n` of the program nurbs-filter cut with id `program_id` (nurbs-filter's cache)."""
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    stem = os.path.join(cache, "nurbs-filter", str(program_id), f"run-{n}")
    # A run cut from the program is G-code; a (NURBS_TOOLPATH, ...) file keeps its extension.
    found = [p for p in glob.glob(stem + ".*") if not p.endswith((".args", ".from-file"))]
    return found[0] if found else stem + ".ngc"


def from_file(run_path):
    """Whether the run is a toolpath file the program named (the machine moves to its start)
    rather than moves cut from the program (which start where the tool stands)."""
    return os.path.exists(os.path.splitext(run_path)[0] + ".from-file")


def filter_run_args(run_path):
    """The planner flags nurbs-filter wrote beside a run (from G64 P and G61 in the program)."""
    try:
        with open(os.path.splitext(run_path)[0] + ".args") as f:
            return [line.strip() for line in f if line.strip()]
    except OSError:
        return []


def offsets():
    """nurbs-planner's placement flags for a toolpath in program coordinates: the offsets the
    interpreter has active now (LinuxCNC's G5x, G92, XY rotation and tool length offset, as its
    canonical layer adds them: docs/integration.md)."""
    s = linuxcnc.stat()
    s.poll()
    work = [s.g5x_offset[i] + s.tool_offset[i] for i in range(3)]
    return [
        "--work-offset", ",".join(repr(v) for v in work),
        "--g92-offset", ",".join(repr(v) for v in s.g92_offset[:3]),
        "--rotation-xy", repr(s.rotation_xy),
    ], s


# nurbs-planner's messages (M101 starts it with its standard error here; the last line says
# why it refused or stopped).
PLANNER_LOG = os.path.join(os.environ.get("TMPDIR", "/tmp"), "nurbs-planner.log")


def planner_said():
    """The planner's last message, for an error shown in LinuxCNC."""
    try:
        with open(PLANNER_LOG) as f:
            lines = [line.strip() for line in f if line.strip()]
        return lines[-1] if lines else "(no message)"
    except OSError as e:
        return f"(its log {PLANNER_LOG}: {e})"


def pin(name):
    return hal.get_value(f"nurbs_interp.{name}")


def set_pin(name, value):
    hal.set_p(f"nurbs_interp.{name}", "1" if value is True else "0" if value is False else str(value))


def wait_until(condition, timeout, what, poll=0.005):
    """Polls `condition` until it returns a true value (returned) or `timeout` s pass (fail)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(poll)
    fail(f"timed out after {timeout} s waiting for {what() if callable(what) else what}")


def positions():
    """Our position and motion's, for messages."""
    ours = [pin(f"pos-cmd-{a}") for a in "xyz"]
    motion = []
    for j in range(3):
        try:
            motion.append(hal.get_value(f"joint.{j}.pos-cmd"))
        except RuntimeError:  # a machine with fewer joints
            break
    fmt = lambda p: "(" + ", ".join(f"{v:.6f}" for v in p) + ")"
    return f"toolpath at {fmt(ours)}, motion at {fmt(motion)}"


def abort_on_signal():
    """On SIGINT/SIGTERM (LinuxCNC's abort or E-stop): nurbs_interp stops on the path, and
    nurbs_catch_up.py, in a session of its own, then moves motion's command there and releases
    the drives (no machine off and on needed)."""

    def handler(signum, frame):
        set_pin("abort", True)
        # Released as soon as that is possible without a step: when motion stands where our path
        # stopped (the catch-up), or at once when the machine is switched off.
        set_pin("engage", False)
        helper = os.path.join(os.path.dirname(os.path.abspath(__file__)), "nurbs_catch_up.py")
        subprocess.Popen([sys.executable, helper], start_new_session=True)
        log("aborted: nurbs_interp stops on the path; motion then catches up with it and takes the drives back")
        sys.exit(1)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
