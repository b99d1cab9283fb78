#!/bin/bash
# test_machine.sh with the machine's Y travel ending at 20 mm, inside the first toolpath: M101
# refuses it before any motion with the point and the limit in LinuxCNC's error channel, the
# program is aborted, nothing was handed over.
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=travel exec bash "$here/test_machine.sh"
