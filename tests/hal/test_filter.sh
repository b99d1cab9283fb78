#!/bin/bash
# nurbs-filter offline, with LinuxCNC's interpreter module and no machine running
# (tests/hal/filter/check_filter.py says what is checked): our G-code reader against LinuxCNC's
# interpreter on every bundled G-code example (the same setpoints to 1e-9 mm), and what the
# filter makes of units, incremental moves, arcs, helices, other planes, G93, parameters,
# M-codes, NURBS blocks, errors and tool words.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"
work=$(mktemp -d /tmp/nurbs-filter-test.XXXXXX)
trap '[ -n "${KEEP_WORK:-}" ] || rm -rf "$work"' EXIT
/usr/bin/python3 "$here/filter/check_filter.py" "$(command -v nurbs-filter)" "$(command -v nurbs-plan)" \
    "$here/../../examples" "$work"
