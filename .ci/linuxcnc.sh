#!/bin/bash
# Real-LinuxCNC stage of CI: install LinuxCNC (uspace) and the generator tools, check the
# committed generated files, build and install the module and the planner, run tests/hal/.
# Prints 'N passed, N failed' (from tests/hal/run.sh). Idempotent; needs root (CI runs as root).
set -euo pipefail
cd "$(dirname "$0")/.."

need=()
for p in linuxcnc-uspace linuxcnc-uspace-dev bindgen libclang-dev; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || need+=("$p")
done
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
make tools >/dev/null

make check-generated
make all
make install
bash tests/hal/run.sh
