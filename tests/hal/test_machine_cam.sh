#!/bin/bash
# Whole G-code programs in a complete LinuxCNC machine (headless), through nurbs-filter as the
# [FILTER] of the configuration: the configuration as `make install` installs it, copied to a
# fresh folder (as LinuxCNC's configuration picker copies a sample), only its display replaced
# by the test UI and a recorder added. The test UI sets G54 by MDI (the operator's touch-off),
# runs the program through the filter as AXIS would, and runs the filtered program. Four
# programs, one machine run each:
#   cam_post  - a CAM post-processor's pocket: G53, T1 M6 (tool 1 is 12.5 mm long), S M3, G54,
#               M8, G43 H1, rapids, plunges, G1/G2/G3 with I J, M9 M5 M30, % lines;
#   3d_chips  - LinuxCNC's own 3D_Chips.ngc, its first 300 lines (parameters, expressions,
#               T M6, M8, S M3, G64 P) and M2;
#   cam_post_abort - the pocket, the operator's abort 0.3 s into its first run: the run stops
#               on the path within the limits, motion catches up and takes the drives back,
#               the machine stays on and homed (check_machine.py --action abort);
#   sub_loop  - named parameters, a subroutine called in a loop (LinuxCNC's moves) between
#               top-level feed moves (ours), a G92 offset, G54 rotated by 15 degrees, and a
#               toolpath file the program names, (NURBS_TOOLPATH, trident.json), found among
#               the installed examples;
#   laser_nest - a laser post's contours of short lines (a circle of 36, a star), each cut
#               twice with M3/M5 and G4 P0 around every pass, `;` comments, G64 P0.01, and
#               before each second pass a rapid to where the first ended (zero length: no run).
# Checked: the program ran to its end with no error, homed, on, released; every run the
# filter cut (feed moves, rapids, the G43 line) ran through nurbs_interp (one engagement each) with the offline plan of that run
# file in the offsets the test set (G54 by MDI + the tool table's length, computed here, not
# read from LinuxCNC) bit for bit (1e-9 mm), no step at any hand-over edge, every engaged period
# within the axis limits (check_machine.py), and `nurbs-plan verify` of every recorded run
# against the run file placed the same way; where LinuxCNC's planner moves nothing after the
# first move (cam_post, 3d_chips, laser_nest), every period from the first engagement to the end.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"
installed=${NURBS_MOTION_DATA:-/usr/local/share/nurbs-motion}
chips=/usr/share/linuxcnc/ncfiles/3D_Chips.ngc
work=$(mktemp -d /tmp/nurbs-cam.XXXXXX)
chmod 755 "$work"
trap 'hal_cleanup; [ -n "${KEEP_WORK:-}" ] || rm -rf "$work"' EXIT

[ -d "$installed/configs/nurbs-sim" ] || { echo "no installed configuration in $installed (make install)"; exit 1; }
[ -f "$chips" ] || { echo "$chips is missing (linuxcnc-uspace installs it)"; exit 1; }
head -n 300 "$chips" >"$work/3d_chips.ngc"
echo "M2" >>"$work/3d_chips.ngc"
cp "$here/machine/programs/cam_post.ngc" "$here/machine/programs/sub_loop.ngc" "$here/machine/programs/laser_nest.ngc" "$work/"

# G54 per program (the operator's G10 L2 by MDI), inside the travel below, and where the
# program's coordinates are on the machine: machine = Rz(R) (p + G92) + G54 + tool length
# offset, worked out here from the programs (G43 H1: tool 1 is 12.5 mm long; sub_loop's
# G92 X5 Y5 where the tool stands at X10 Y10), not read from LinuxCNC.
tool_length=12.5
declare -A g54=([cam_post]="X20 Y15 Z-5" [3d_chips]="X60 Y60 Z-20" [sub_loop]="X5 Y-5 Z0 R15" [laser_nest]="X20 Y15 Z-5")
# Where every move after the first (from an unknown position) is ours, every period from the
# first engagement on is checked against the limits (LinuxCNC's own moves are not jerk-limited).
declare -A all_ours=([cam_post]=--all-ours-after [3d_chips]=--all-ours-after [laser_nest]=--all-ours-after)
declare -A program_of=([cam_post]=cam_post [cam_post_abort]=cam_post [3d_chips]=3d_chips [sub_loop]=sub_loop
    [laser_nest]=laser_nest)
declare -A action=([cam_post_abort]=abort)
g54[cam_post_abort]=${g54[cam_post]}
declare -A placement=(
    [cam_post]="--work-offset 20,15,7.5"
    [cam_post_abort]="--work-offset 20,15,7.5"
    [3d_chips]="--work-offset 60,60,-20"
    [sub_loop]="--work-offset 5,-5,0 --rotation-xy 15 --g92-offset 5,5,0"
    [laser_nest]="--work-offset 20,15,-5")

# The runs the filter cut and the toolpath files it copied, in order.
runs() {
    ls "$1"/cache/nurbs-filter/*/run-* | grep -v -e '\.args$' -e '\.from-file$' | sort -V
}

failed=0
for case in ${CASES:-cam_post cam_post_abort 3d_chips sub_loop laser_nest}; do
    echo "--- $case"
    run="$work/$case"
    mkdir -p "$run"
    chmod 755 "$run"
    cp -r "$installed/configs/nurbs-sim" "$run/config"
    config="$run/config"
    sed -i -e "s|^DISPLAY = .*|DISPLAY = $here/machine/test-ui.py|" \
        -e "s|^HALFILE = nurbs-sim.hal|HALFILE = nurbs-sim.hal\nHALFILE = record.hal|" "$config/nurbs-sim.ini"
    sed "s|@WORK@|$run|g" "$here/machine/record.hal" >"$config/record.hal"
    # A tool with a length, and travel for 3D_Chips' 112 mm block.
    echo "T1 P1 D10 Z$tool_length ;12.5 mm ball nose" >"$config/tool.tbl"
    python3 - "$config/nurbs-sim.ini" <<'PY'
import re, sys
ini = open(sys.argv[1]).read()
for axis, lo, hi in (("X", -100, 200), ("Y", -100, 200), ("Z", -60, 60)):
    for section in (f"AXIS_{axis}", f"JOINT_{'XYZ'.index(axis)}"):
        ini, n = re.subn(rf"(\[{section}\][^\[]*?MIN_LIMIT = )\S+", rf"\g<1>{lo}", ini)
        ini, m = re.subn(rf"(\[{section}\][^\[]*?MAX_LIMIT = )\S+", rf"\g<1>{hi}", ini)
        assert n == m == 1, section
open(sys.argv[1], "w").write(ini)
PY
    hal_cleanup
    (cd "$config" && TMPDIR="$run" XDG_CACHE_HOME="$run/cache" NURBS_TEST_PROGRAM="$work/${program_of[$case]}.ngc" NURBS_TEST_ACTION="${action[$case]:-}" \
        NURBS_TEST_RESULT="$run/result.json" NURBS_TEST_SETUP="G10 L2 P1 ${g54[$case]}" \
        NURBS_TEST_FILTER="$(command -v nurbs-filter)" \
        env -u DISPLAY timeout 600 script -qec "linuxcnc $config/nurbs-sim.ini" /dev/null \
        >"$run/linuxcnc.log" 2>&1) || { echo "linuxcnc failed:"; tail -n 40 "$run/linuxcnc.log"; failed=1; continue; }
    hal_cleanup
    if [ ! -s "$run/result.json" ]; then
        echo "no result from the test UI:"; tail -n 40 "$run/linuxcnc.log"; failed=1; continue
    fi
    python3 -c "import json,sys; print(json.load(open(sys.argv[1])).get('filter', ''), end='')" "$run/result.json" | head -n 8
    if ! ls "$run"/cache/nurbs-filter/*/run-*.ngc >/dev/null 2>&1; then
        echo "the filter cut no run"; failed=1; continue
    fi
    read -r -a place <<<"${placement[$case]}"
    plans=() k=0
    for file in $(runs "$run"); do
        # The program's G64 P / G61 where the run starts, as the filter passes them to M101.
        mapfile -t mode <"${file%.*}.args"
        nurbs-plan plan "$file" --ini "$config/nurbs-sim.ini" "${place[@]}" "${mode[@]}" --stream --out "$run/offline-$k.csv" >/dev/null \
            || { echo "offline plan of $file failed"; failed=1; }
        plans+=(--offline "$run/offline-$k.csv" --recorded-csv "$run/recorded-$k.csv")
        k=$((k + 1))
    done
    echo "$k run(s)"
    if [ -n "${action[$case]:-}" ]; then
        # Aborted in its first run: that one engagement, stopped on the path (every limit held,
        # only the path's end not reached), then the program is over.
        python3 "$here/machine/check_machine.py" --samples "$run/samples.txt" --result "$run/result.json" \
            --ini "$config/nurbs-sim.ini" "${plans[@]:0:4}" --action "${action[$case]}" \
            || { echo "--- LinuxCNC log:"; tail -n 30 "$run/linuxcnc.log"; failed=1; continue; }
        file=$(runs "$run" | head -n 1)
        mapfile -t mode <"${file%.*}.args"
        v=$(nurbs-plan verify "$run/recorded-0.csv" "$file" --ini "$config/nurbs-sim.ini" "${place[@]}" "${mode[@]}" || true)
        if grep "^VIOLATION" <<<"$v" | grep -v "not the end of the path"; then failed=1; fi
        continue
    fi
    if ! python3 "$here/machine/check_machine.py" --samples "$run/samples.txt" --result "$run/result.json" \
        --ini "$config/nurbs-sim.ini" "${plans[@]}" ${all_ours[$case]:-}; then
        echo "--- LinuxCNC log:"; tail -n 30 "$run/linuxcnc.log"; grep "^nurbs" "$run/nurbs-planner.log"* || true
        failed=1; continue
    fi
    k=0
    for file in $(runs "$run"); do
        mapfile -t mode <"${file%.*}.args"
        verify=(nurbs-plan verify "$run/recorded-$k.csv" "$file" --ini "$config/nurbs-sim.ini" "${place[@]}" "${mode[@]}")
        "${verify[@]}" | tail -n 1 | grep -q "^OK" || { echo "verify of run $k failed"; "${verify[@]}"; failed=1; }
        k=$((k + 1))
    done
done
exit $failed
