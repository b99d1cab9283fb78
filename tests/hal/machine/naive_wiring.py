#!/usr/bin/env python3
"""Rewires a copy of nurbs-sim.hal the naive way, for the negative control of test_machine.sh:
each drive command switched between motion's motor-pos-cmd and nurbs_interp's position by a
mux2 on `engaged`, the drive's feedback straight to motion (no hand-over offset). What that
must show: a step at the switch (our position is in machine coordinates, the drive counts in
motor coordinates) and motion's following error tripping once the path moves, since motion
compares its standing command with the moving feedback."""
import re
import sys

path = sys.argv[1]
hal = open(path).read()
axes = "xyz"
for j in range(3):
    hal, n = re.subn(rf"^net j{j}-motor-fb .*$", "", hal, flags=re.M)
    hal, m = re.subn(rf"^net j{j}-drive .*$",
                     f"net j{j}-drive mux2.{j}.out => joint.{j}.motor-pos-fb\n"
                     f"net j{j}-motor-cmd => mux2.{j}.in0\n"
                     f"net nurbs-{axes[j]} => mux2.{j}.in1\n"
                     f"net nurbs-engaged => mux2.{j}.sel", hal, flags=re.M)
    assert n == 1 and m == 1, f"joint {j}: the hand-over nets were not found"
hal = hal.replace("loadrt nurbs_interp\n", "loadrt nurbs_interp\nloadrt mux2 count=3\n", 1)
hal += "".join(f"addf mux2.{j} servo-thread\n" for j in range(3))
open(path, "w").write(hal)
