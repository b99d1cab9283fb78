#!/bin/bash
# A streamed plan that fails, in real LinuxCNC: nurbs-planner --stream on a curve the streamed
# Erwinski planner refuses at u = 0.85 (tests/hal/refused_stream.json, case 917 of the property
# test), after records are final: a record handed out ends too fast for the segment after it.
# The module is enabled on a running servo thread of the curve's period. nurbs-planner must
# put nothing into the ring before the start rule holds, so the failure comes first: it exits
# with the planner's error, and the module has taken no record (nothing moved).
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

toolpath="$here/refused_stream.json"
PERIOD=0.003883148472995906
LIMITS="--feed 2256.621831466748 --accel 80318.24008344664 --jerk 80538.6767781366 --chord-tol 0.00010472580239299676"

if nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --stream --out /dev/null 2>/dev/null; then
    echo "the curve is no longer refused: this test lost its subject"; exit 1
fi
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
loadrt threads name1=servo period1=3883148
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
