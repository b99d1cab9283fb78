#!/bin/bash
# test_machine.sh with the operator's pause 0.3 s into the first toolpath (our path held at its
# next checked stop), then an abort while held: the held motion is over, motion catches up with
# where the path stands and takes the drives back with the machine on; nothing jumps.
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=pause-abort exec bash "$here/test_machine.sh"
