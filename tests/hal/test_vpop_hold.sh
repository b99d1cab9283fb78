#!/bin/bash
# Feed hold of a VPOp motion in real LinuxCNC: the trident with --planner vpop (path blocks), hold
# 0.4 s into the motion, released 2.8 s later. The module stops at the end of the current block
# with the stop the planner checked there (tangential, or VPOp's stored deceleration), the running
# nurbs-planner re-plans with VPOp from the stop point, the release runs it (see test_hold.sh).
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/test_hold.sh" vpop "$here/../../examples/trident.json" 0.4
