#!/bin/bash
# test_machine.sh with the operator's feed override turned to 10 % 0.1 s into the first
# toolpath: nurbs-planner plans the rest of the path again at 10 % from the end of the motion
# queued in the ring, and the module runs into the new plan there. The same checks (every
# limit, the hand-over, the catch-up), the setpoints the plan's up to the join, the feed under
# 10 % of [NURBS]FEED from there to the path's end (the time from the knob reported), and the
# second toolpath, back at 100 %, as planned.
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=override exec bash "$here/test_machine.sh"
