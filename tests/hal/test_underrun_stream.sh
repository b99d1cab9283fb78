#!/bin/bash
# Underrun of a streamed plan in real LinuxCNC (see underrun_test.sh): nurbs-planner --stream on
# examples/star_g1.ngc with a 0.1 s margin is unloaded 1 s in; the module stops with the stop
# checked for that boundary (its stop points and any stored sequence appended after the motion
# started), a new streaming planner re-plans from the stop point, the resume command runs it to
# the end, and the whole sampled run passes `nurbs-plan verify`.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/underrun_test.sh" unload erwinski "$here/../../examples/star_g1.ngc" 1 any --stream
