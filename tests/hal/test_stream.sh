#!/bin/bash
# The data path end to end: nurbs-planner streams RECORDS segment records through the channel,
# nurbs_interp.update (250 us servo thread) takes one per period and writes them to its pins,
# LinuxCNC's sampler records the pins every period, nurbs-hal-record writes the samples at full
# precision, and check_stream.py compares them with what the planner sent, bit for bit.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

RECORDS=${RECORDS:-4000}   # 1 s of motion; more than the channel holds, so it streams
EXTRA=200                  # periods after the data ends: underruns, positions hold
SAMPLES=$((RECORDS + EXTRA))

work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
sed -e "s|@RECORDS@|$RECORDS|g" -e "s|@SAMPLES@|$SAMPLES|g" -e "s|@WORK@|$work|g" \
    "$here/stream.hal.in" >"$work/stream.hal"

hal_session "$work/stream.hal" "$work/halrun.log"
cat "$work/halrun.log"
python3 "$here/check_stream.py" --expected "$work/expected.txt" --samples "$work/samples.txt" \
    --records "$RECORDS" --extra "$EXTRA"
grep -q "nurbs-planner: stopped by signal, exiting cleanly" "$work/halrun.log" || {
    echo "nurbs-planner did not exit cleanly on SIGTERM"; exit 1; }
rm -rf "$work"
