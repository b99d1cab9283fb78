"""What the user interfaces of a headless LinuxCNC ([DISPLAY]DISPLAY) share: task's command,
status and error channels, errors (and messages, where the result keeps them) drained into the
result, waiting on a condition with a timeout that becomes an error, and the machine switched
on and homed. Used by test-ui.py and kins-ui.py here and by scripts/linuxcnc-tp-5axis.sh."""
import time

import linuxcnc


class Session:
    """A UI's connection to task. `result` gets the errors ("errors"), the other messages where
    it has "messages", and the highest program line seen where it has "last_line"; `who` names
    the UI in a timeout's error."""

    def __init__(self, result, who):
        self.c, self.s, self.e = linuxcnc.command(), linuxcnc.stat(), linuxcnc.error_channel()
        self.result, self.who = result, who

    def drain(self):
        while (m := self.e.poll()):
            kind, text = m
            if kind in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
                self.result["errors"].append(text)
            elif "messages" in self.result:
                self.result["messages"].append(text)

    def wait(self, cond, timeout, what):
        """Polls until `cond()` holds (True) or `timeout` s have passed (False, and an error)."""
        s = self.s
        end = time.time() + timeout
        while time.time() < end:
            s.poll()
            self.drain()
            if "last_line" in self.result:
                self.result["last_line"] = max(self.result["last_line"], s.current_line, s.motion_line)
            if cond():
                return True
            time.sleep(0.01)
        self.result["errors"].append(f"{self.who}: timed out waiting for {what} (task state {s.task_state}, "
                                     f"exec {s.exec_state}, interp {s.interp_state}, mode {s.task_mode})")
        return False

    def on_and_homed(self):
        """E-stop reset, machine on, every joint homed (True), or an error (False)."""
        c, s = self.c, self.s
        c.state(linuxcnc.STATE_ESTOP_RESET)
        c.state(linuxcnc.STATE_ON)
        if not self.wait(lambda: s.task_state == linuxcnc.STATE_ON, 10, "machine on"):
            return False
        c.mode(linuxcnc.MODE_MANUAL)
        c.wait_complete()
        c.home(-1)
        return self.wait(lambda: s.joints > 0 and all(s.homed[: s.joints]), 30, "homing")

    def switch_off(self):
        """Machine off, which ends a headless LinuxCNC."""
        self.c.state(linuxcnc.STATE_OFF)
        self.c.wait_complete()
