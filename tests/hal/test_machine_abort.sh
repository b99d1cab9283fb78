#!/bin/bash
# test_machine.sh with the operator's abort 0.3 s into the first toolpath: our path stops on
# the path within the limits (at the end of its group of records), the program is aborted,
# the machine switched off and on takes the drives' position; nothing jumps.
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=abort exec bash "$here/test_machine.sh"
