#!/bin/bash
# The trident planned by the reachability planner (`nurbs-planner --planner reach`: the whole
# plan before the motion, sent as path blocks with a checked stop at every block end) end to
# end in real LinuxCNC: every sample equals the offline `nurbs-plan plan --planner reach`
# position (to 1e-9 mm) and the run passes `nurbs-plan verify`.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/path_test.sh" "$here/../../examples/trident.json" reach
