#!/bin/bash
# The trident planned by VPOp (`nurbs-planner --planner vpop`: path blocks) end to end in real
# LinuxCNC: see path_test.sh. Every sampled period equals the offline `nurbs-plan plan
# --planner vpop` position (to 1e-9 mm) and the run passes `nurbs-plan verify`.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/path_test.sh" "$here/../../examples/trident.json" vpop
