#!/usr/bin/python3
"""Expand a LinuxCNC program to plain G0/G1 lines through LinuxCNC's own interpreter (the `gcode`
module AXIS previews with): parameters, expressions, subroutines, loops, units and offsets are
evaluated by LinuxCNC, and every traverse and feed move comes out in millimetres at full
precision (repr), with its feed in mm/min.

    scripts/linuxcnc-expand.py PROGRAM.ngc > expanded.ngc

Tool changes (T words, M6) are dropped from the copy the interpreter reads: they look up
LinuxCNC's tool data, which exists only while a machine runs (the module crashes without it),
and they do not move the tool. Arcs are refused (this expands straight-line programs). Needs
linuxcnc-uspace (the interpreter is /usr/bin/python3's `gcode` module). Not a reader of ours:
it makes real programs into the G1 input our reader takes, for tests and measurements.
"""
import os
import re
import sys
import tempfile

import gcode

MM_PER_INCH = 25.4  # the module hands out lengths in inches


class Canon:
    """Records traverses and feeds; answers the interpreter's queries as a plain XYZ mill."""

    def __init__(self):
        self.feed = 0.0
        self.lines = []
        self.error = None

    def __getattr__(self, name):
        # Every other canonical call (spindle, coolant, offsets shown, messages) moves nothing.
        return lambda *args: None

    def get_external_length_units(self):
        return 1.0

    def get_external_angular_units(self):
        return 1.0

    def get_axis_mask(self):
        return 7

    def get_block_delete(self):
        return 0

    def get_tool(self, index):
        return (index,) + (0.0,) * 12 + (0,)

    def next_line(self, state):
        pass

    def check_abort(self):
        return False

    def set_feed_rate(self, feed):
        self.feed = feed * MM_PER_INCH

    def straight_traverse(self, x, y, z, *rest):
        self.lines.append("G0 X%r Y%r Z%r" % tuple(v * MM_PER_INCH for v in (x, y, z)))

    def straight_feed(self, x, y, z, *rest):
        self.lines.append("G1 X%r Y%r Z%r F%r" % (x * MM_PER_INCH, y * MM_PER_INCH, z * MM_PER_INCH, self.feed))

    def arc_feed(self, *args):
        self.error = "arcs are not expanded (a straight-line program was expected)"


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    work = tempfile.mkdtemp()
    source = os.path.join(work, "program.ngc")
    with open(sys.argv[1]) as f, open(source, "w") as out:
        for line in f:
            if re.search(r"M0*6(?!\d)", line, re.I):
                continue
            out.write(line)
    canon = Canon()
    canon.parameter_file = os.path.join(work, "program.var")
    open(canon.parameter_file, "w").close()
    result, sequence = gcode.parse(source, canon, "G21", "")
    if result > gcode.MIN_ERROR:
        sys.exit("%s: line %d: %s" % (sys.argv[1], sequence, gcode.strerror(result)))
    if canon.error:
        sys.exit("%s: %s" % (sys.argv[1], canon.error))
    print("G21 G90")
    print("\n".join(canon.lines))
    print("M2")


main()
