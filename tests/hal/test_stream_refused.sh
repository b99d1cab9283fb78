#!/bin/bash
# A streamed plan that fails, in real LinuxCNC: nurbs-planner --stream on a curve the Erwinski
# planner refuses at u = 0.50 (tests/hal/refused_stream.json, case 4669 of the property test),
# after 2 records (0.207 s of motion, less than the 2 s margin) are final.
# The module is enabled on a running servo thread of the curve's period. nurbs-planner must
# put nothing into the ring before the start rule holds, so the failure comes first: it exits
# with the planner's error, and the module has taken no record (nothing moved).
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

toolpath="$here/refused_stream.json"
PERIOD=0.004631443939417643
LIMITS="--feed 11.366381205569331 --accel 713.9459143953733 --jerk 428466.83921094495 --chord-tol 0.00018094343202521352"

if offline=$(nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --stream --out /dev/null 2>&1); then
    echo "the curve is no longer refused: this test lost its subject"; exit 1
fi
grep -Eq "\(([1-9][0-9]*) records? had been handed out" <<<"$offline" || {
    echo "no record is final before the refusal: this test lost its subject"; echo "$offline"; exit 1; }
work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
cat >"$work/plan.sh" <<SH
#!/bin/sh
nurbs-planner "$toolpath" $LIMITS --period $PERIOD --stream >"$work/planner.log" 2>&1
echo \$? >"$work/rc"
exit 0
SH
cat >"$work/pins.sh" <<SH
#!/bin/sh
halcmd getp nurbs_interp.records >"$work/records"
halcmd getp nurbs_interp.active >"$work/active"
exit 0
SH
chmod 755 "$work/plan.sh" "$work/pins.sh"
cat >"$work/refused.hal" <<HAL
loadrt threads name1=servo period1=4631444
loadrt nurbs_interp
addf nurbs_interp.update servo
setp nurbs_interp.enable 1
start
loadusr -w $work/plan.sh
loadusr -w sleep 0.5
loadusr -w $work/pins.sh
HAL
hal_session "$work/refused.hal" "$work/halrun.log"
cat "$work/planner.log"
[ "$(cat "$work/rc")" != 0 ] || { echo "nurbs-planner did not fail"; exit 1; }
grep -q "no feed profile within the limits" "$work/planner.log" || {
    echo "nurbs-planner did not report the planner's error"; exit 1; }
[ "$(cat "$work/records")" = 0 ] || { echo "the module took $(cat "$work/records") records"; exit 1; }
[ "$(cat "$work/active")" = FALSE ] || { echo "the module is moving"; exit 1; }
echo "ok: the streamed plan failed before the start; nothing moved"
rm -rf "$work"
