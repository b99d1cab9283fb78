#!/bin/bash
# test_machine.sh with the operator's pause 0.3 s into the first toolpath: halui's
# program.is-paused holds nurbs_interp at its next checked stop, within the limits; resumed,
# the running planner's plan from the stop point takes the path to its end and the program
# finishes as without the pause (the same checks, the setpoints the plan's up to the hold).
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=pause exec bash "$here/test_machine.sh"
