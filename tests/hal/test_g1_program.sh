#!/bin/bash
# A G1 program end to end in real LinuxCNC (see path_test.sh): examples/zigzag_g1.ngc, 40 lines
# whose corners nurbs-planner rounds as `nurbs-plan plan` does: 79 path elements, more than the
# 64 the channel held before layout version 7.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/path_test.sh" "$here/../../examples/zigzag_g1.ngc"
