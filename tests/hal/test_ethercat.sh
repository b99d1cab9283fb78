#!/bin/bash
# halfiles/ethercat.hal, unmodified, in a complete LinuxCNC machine (headless), with stand-ins
# of our own for the parts that cannot be installed here (tests/hal/ethercat/: `lcec_conf`, the
# `lcec` driver with simulated CiA402 drives in CSP mode, and the `cia402` helper), built with
# halcompile and installed for the test only. The machine (two joints, X and Y) is
# configs/nurbs-sim's with that HAL file: homed, it runs LinuxCNC's moves and a G1 program (a
# zigzag, its corners rounded) through o<nurbs_run>; check_machine.py checks every period as
# for test_machine, with the drives' resolution (1 count = 1e-4 mm) as the following error
# allowed. Motion's following error within one count everywhere also checks the thread order:
# with a drive that is at its target by the next read, it holds only if the feedback, motion,
# our update and the drive write run in this order within each period.
# What it does not prove: anything about a real bus (no EtherCAT frames, no distributed clocks,
# no drive dynamics or lag), or the real lcec and cia402, whose code this does not contain.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"
repo=$(cd "$here/../.." && pwd)
modules=$(dirname "$(find /usr/lib/linuxcnc/modules -name 'motmod.so' -print -quit)")
work=$(mktemp -d /tmp/nurbs-ethercat.XXXXXX)
chmod 755 "$work"
installed=()
cleanup() {
    hal_cleanup
    for m in "${installed[@]}"; do rm -f "$modules/$m.so"; done
    rm -rf "$work"
}
trap cleanup EXIT

# The stand-ins must never replace the real components on a machine that has them.
for m in lcec cia402; do
    if [ -e "$modules/$m.so" ] && ! grep -q "nurbs-motion tests" "$modules/$m.so"; then
        echo "a real $m is installed in $modules: not replacing it with the test's stand-in"; exit 1
    fi
done
(cd "$work" && cp "$here/ethercat/lcec.c" "$here/ethercat/cia402.comp" . \
    && halcompile --install lcec.c >"$work/halcompile.log" 2>&1 \
    && halcompile --install cia402.comp >>"$work/halcompile.log" 2>&1) \
    || { echo "halcompile failed:"; cat "$work/halcompile.log"; exit 1; }
installed=(lcec cia402)

# The machine: configs/nurbs-sim with two joints and halfiles/ethercat.hal.
cfg="$work/machine"
mkdir -p "$cfg/examples"
cp -r "$repo/halfiles" "$repo/configs/nurbs-sim/mcodes" "$repo/configs/nurbs-sim/subroutines" "$cfg/"
cp "$repo/examples/zigzag_g1.ngc" "$cfg/examples/"
cp "$here/ethercat/loops.hal" "$repo/configs/nurbs-sim/tool.tbl" "$cfg/"
sed "s|@WORK@|$work|g" "$here/ethercat/record.hal" >"$cfg/record.hal"
python3 - "$repo/configs/nurbs-sim/nurbs-sim.ini" "$cfg/ethercat.ini" "$here/machine/test-ui.py" <<'PY'
import re, sys
ini = open(sys.argv[1]).read()
for section in ("AXIS_Z", "JOINT_2"):
    ini, n = re.subn(rf"\[{section}\][^\[]*", "", ini)
    assert n == 1, section
subs = [(r"JOINTS = 3", "JOINTS = 2"), (r"COORDINATES = X Y Z", "COORDINATES = X Y"),
        (r"DISPLAY = axis", f"DISPLAY = {sys.argv[3]}"),
        (r"HALFILE = nurbs-sim.hal", "HALFILE = halfiles/ethercat.hal\nHALFILE = loops.hal\nHALFILE = record.hal"),
        (r"TOOLPATH_1 = .*", "TOOLPATH_1 = examples/zigzag_g1.ngc"), (r"TOOLPATH_2 = .*\n", "")]
for pattern, value in subs:
    ini, n = re.subn(pattern, value, ini)
    assert n == 1, pattern
open(sys.argv[2], "w").write(ini)
PY
cat >"$cfg/demo.ngc" <<'NGC'
(LinuxCNC's moves around a G1 zigzag run by nurbs_interp, on the two EtherCAT joints)
G21 G17 G90 G94
G53 G0 X5 Y5
G1 X15 Y-2 F6000
o<nurbs_run> call [1]
G1 X30 Y30 F6000
G0 X5 Y5
M2
NGC
nurbs-plan plan "$cfg/examples/zigzag_g1.ngc" --ini "$cfg/ethercat.ini" --stream --out "$work/offline.csv" >/dev/null

hal_cleanup
(cd "$cfg" && PATH="$here/ethercat:$PATH" TMPDIR="$work" NURBS_TEST_PROGRAM="$cfg/demo.ngc" \
    NURBS_TEST_RESULT="$work/result.json" env -u DISPLAY timeout 600 script -qec "linuxcnc $cfg/ethercat.ini" /dev/null \
    >"$work/linuxcnc.log" 2>&1) || { echo "linuxcnc failed:"; cat "$work/linuxcnc.log"; exit 1; }
hal_cleanup
if [ ! -s "$work/result.json" ]; then
    echo "no result from the test UI:"; cat "$work/linuxcnc.log"; exit 1
fi
python3 "$here/machine/check_machine.py" --joints 2 --ferror-engaged 1e-4 --ferror-max 1e-4 --samples "$work/samples.txt" \
    --result "$work/result.json" --ini "$cfg/ethercat.ini" --offline "$work/offline.csv" \
    --recorded-csv "$work/recorded.csv" \
    || { echo "--- LinuxCNC log:"; tail -n 40 "$work/linuxcnc.log"; exit 1; }
nurbs-plan verify "$work/recorded.csv" "$cfg/examples/zigzag_g1.ngc" --ini "$cfg/ethercat.ini"
