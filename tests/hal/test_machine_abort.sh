#!/bin/bash
# test_machine.sh with the operator's abort 0.3 s into the first toolpath: our path stops on
# the path within the limits (at its next checked stop), the program is aborted, motion catches
# up with where the path stopped and takes the drives back with the machine on (M102's abort
# handler), and an MDI move runs afterwards; nothing jumps.
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=abort exec bash "$here/test_machine.sh"
