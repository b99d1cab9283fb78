#!/bin/bash
# The trident planned by the reachability planner (`nurbs-planner --planner reach`: planned in a
# thread of its own as the motion runs, sent as path blocks in groups that end at a checked stop)
# end to end in real LinuxCNC: every sample equals the offline
# `nurbs-plan plan --planner reach --stream` position (to 1e-9 mm) and the run passes
# `nurbs-plan verify`.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/path_test.sh" "$here/../../examples/trident.json" reach
