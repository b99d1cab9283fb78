#!/bin/bash
# Underrun on a G1 program in real LinuxCNC: examples/star_g1.ngc, its corners rounded by
# nurbs-planner exactly as by `nurbs-plan plan` (so every segment boundary lies at an element
# join, and the records running into a corner end there at speed). The planner is unloaded 1 s
# in; the module stops at the end of its last group with the stop the planner made there (the
# next segment, perhaps on the next element, re-planned to rest), a new planner re-plans from
# the stop point, the resume command runs it to the end, and the whole sampled run passes
# `nurbs-plan verify`.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/underrun_test.sh" unload erwinski "$here/../../examples/star_g1.ngc" 1
