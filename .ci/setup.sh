#!/bin/bash
# Everything a fresh Debian bookworm machine needs beyond the Rust toolchain: LinuxCNC (uspace,
# with headers) for the realtime module and its tests, and the binding generators whose output
# is committed. Idempotent; needs root.
set -euo pipefail
cd "$(dirname "$0")/.."
need=()
for p in linuxcnc-uspace linuxcnc-uspace-dev bindgen libclang-dev python3; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || need+=("$p")
done
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
rustup component add rustfmt clippy >/dev/null 2>&1 || true
make --no-print-directory tools >/dev/null
