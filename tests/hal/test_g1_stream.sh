#!/bin/bash
# A streamed plan end to end in real LinuxCNC (see path_test.sh): nurbs-planner --stream plans
# examples/zigzag_g1.ngc in a thread of its own and the motion starts once its first records and
# their stops are checked; the machine's setpoints are those of `nurbs-plan plan --stream`.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/path_test.sh" "$here/../../examples/zigzag_g1.ngc" erwinski --stream
