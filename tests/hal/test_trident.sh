#!/bin/bash
# The trident (examples/trident.json) end to end in real LinuxCNC: see path_test.sh.
here=$(cd "$(dirname "$0")" && pwd)
exec bash "$here/path_test.sh" "$here/../../examples/trident.json"
