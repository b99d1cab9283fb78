#!/bin/bash
# Feed hold of a reachability-planned motion in real LinuxCNC: the trident with --planner reach
# (path blocks), hold 0.3 s into the motion, released 2.8 s later. The module stops at the end
# of the current block with the stop the planner checked there, the running nurbs-planner plans
# the rest again from the stop point, the release runs it (see test_hold.sh).
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/test_hold.sh" reach "$here/../../examples/trident.json" 0.3
