#!/bin/bash
# Run every real-LinuxCNC test (tests/hal/test_*.sh) one at a time. Needs the module and the
# binaries installed (`make install`). Prints 'N passed, N failed'.
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
exec 9>/tmp/nurbs-hal-tests.lock
flock 9
passed=0 failed=0
for t in "$here"/test_*.sh; do
    name=$(basename "$t" .sh)
    echo "=== $name"
    if bash "$t"; then
        echo "--- PASS $name"; passed=$((passed + 1))
    else
        echo "--- FAIL $name"; failed=$((failed + 1))
    fi
done
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]
