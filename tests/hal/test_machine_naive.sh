#!/bin/bash
# The negative control of test_machine.sh: the same machine, program and checks with the naive
# wiring (a mux2 switching each drive between motion and nurbs_interp, machine/naive_wiring.py)
# must fail: a following-error trip or a step in the drive command.
here=$(cd "$(dirname "$0")" && pwd)
out=$(MACHINE_WIRING=naive bash "$here/test_machine.sh" 2>&1)
rc=$?
echo "$out" | grep -E "FAIL|LinuxCNC error|exceeds|following error|differ" | head -n 8
if [ $rc = 0 ]; then
    echo "the naive wiring passed the machine test: the test cannot tell a jump from a hand-over"
    exit 1
fi
echo "$out" | grep -q -E "following error|exceeds" || { echo "failed for another reason:"; echo "$out" | tail -n 30; exit 1; }
echo "ok: the naive wiring fails the machine test"
