#!/bin/bash
# Underrun of a VPOp motion in real LinuxCNC: the planner (--planner vpop) streaming the trident
# is unloaded 0.4 s into the motion; the module stops from the end of the last path block it has
# (non-zero acceleration; the stop the planner checked there, VPOp's own stored deceleration or
# the tangential one), a second planner re-plans with VPOp from the stop point and the resume
# command runs it to the end (see underrun_test.sh). STOP=any: the block end carries a stored
# sequence (the block-stop search takes it first), whose last step may be up to J dt^2 and
# whose feed need not fall monotonically (the limit check judges it).
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/underrun_test.sh" unload vpop "$here/../../examples/trident.json" 0.4 any
