#!/bin/bash
# Run every real-LinuxCNC test (tests/hal/test_*.sh) one at a time. Needs the module and the
# binaries installed (`make install`). Prints 'N passed, N failed'; a failed test's name and the
# end of its output are repeated last, so a log cut in the middle still shows them.
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
exec 9>/tmp/nurbs-hal-tests.lock
flock 9
logs=$(mktemp -d)
trap 'rm -rf "$logs"' EXIT
passed=0 failed=0 failures=()
for t in "$here"/test_*.sh; do
    name=$(basename "$t" .sh)
    echo "=== $name"
    if bash "$t" 2>&1 | tee "$logs/$name.log"; then
        echo "--- PASS $name"; passed=$((passed + 1))
    else
        echo "--- FAIL $name"; failed=$((failed + 1)); failures+=("$name")
    fi
done
for name in "${failures[@]}"; do
    echo "=== FAILED: $name (the last 40 lines of its output)"
    tail -n 40 "$logs/$name.log"
done
echo "$passed passed, $failed failed${failures:+ (${failures[*]})}"
[ "$failed" = 0 ]
