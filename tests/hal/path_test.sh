#!/bin/bash
# path_test.sh TOOLPATH [PLANNER [FLAGS]]: the product end to end in real LinuxCNC. nurbs-planner
# plans TOOLPATH (with PLANNER, erwinski, vpop or reach; default erwinski; the streaming planners,
# erwinski and reach, compared with the offline `nurbs-plan plan --stream`; FLAGS go to
# nurbs-planner, the offline nurbs-plan plan and verify)
# and streams it through the channel, nurbs_interp.update interpolates it on a 250 us servo
# thread, LinuxCNC's sampler records every setpoint, nurbs-hal-record writes them at full
# precision. Checks (check_path.py, nurbs-plan verify): the samples are the offline
# `nurbs-plan plan` setpoints (count, and every position to 1e-9 mm), zero axial violations by
# finite differences, the motion ends at C(1) and the planner exits cleanly on SIGTERM.
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

toolpath=$(realpath "$1")
planner=${2:-erwinski}
flags=${3:-}
PERIOD=0.00025
LIMITS="--limits lab1"

work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
offline_flags=$flags
# The streaming planners: the offline plan of the same stream (the reachability planner in windows).
[ "$planner" != vpop ] && offline_flags="$flags --stream"
nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --planner "$planner" $offline_flags --out "$work/offline.csv"
SAMPLES=$(($(wc -l <"$work/offline.csv") - 1))
sed -e "s|@TOOLPATH@|$toolpath|g" -e "s|@LIMITS@|$LIMITS --period $PERIOD --planner $planner $flags|g" \
    -e "s|@SAMPLES@|$SAMPLES|g" -e "s|@WORK@|$work|g" \
    "$here/path.hal.in" >"$work/path.hal"

cat >"$work/rss.sh" <<'SH'
#!/bin/sh
# The running planner's peak resident memory.
grep VmHWM "/proc/$(pidof nurbs-planner)/status" | sed 's/^/nurbs-planner peak /'
SH
chmod 755 "$work/rss.sh"
cat >"$work/stamp.sh" <<SH
#!/bin/sh
# The wall-clock time, into the file named by the argument.
date +%s.%N >"$work/\$1"
SH
chmod 755 "$work/stamp.sh"
hal_session "$work/path.hal" "$work/halrun.log"
cat "$work/halrun.log"
python3 -c "import sys; print(f'motion started {1e3 * (float(sys.argv[2]) - float(sys.argv[1])):.1f} ms after the planner was loaded')" \
    "$(cat "$work/t-loadusr")" "$(cat "$work/t-start")"
python3 "$here/check_path.py" --expected "$work/offline.csv" --samples "$work/samples.txt" \
    --toolpath "$toolpath" --period $PERIOD --recorded-csv "$work/recorded.csv"
nurbs-plan verify "$work/recorded.csv" "$toolpath" $LIMITS --period $PERIOD $flags
grep -q "nurbs-planner: stopped by signal, exiting cleanly" "$work/halrun.log" || {
    echo "nurbs-planner did not exit cleanly on SIGTERM"; exit 1; }
rm -rf "$work"
