#!/bin/bash
# test_machine.sh with an E-stop 0.3 s into the first toolpath: the hand-over releases at once
# to the drives' feedback (no step in the drive command; the drives are off), our motion ends,
# and after reset and machine on LinuxCNC has the drives' position, still homed.
here=$(cd "$(dirname "$0")" && pwd)
MACHINE_ACTION=estop exec bash "$here/test_machine.sh"
