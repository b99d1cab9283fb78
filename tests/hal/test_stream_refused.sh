#!/bin/bash
# A streamed plan that fails, in real LinuxCNC: nurbs-planner (which streams) on a curve the Erwinski
# planner refuses at u = 0 (tests/hal/refused_stream.json, case 1246 of the property test, the
# only one of its 10,000 curves still refused: over its first 1e-8 mm the sampled positions step
# back and forth, an axial jerk only a crawl at 0.2 % of the jerk limit avoids; the planner
# refuses it "even from its lowest start feed", after some 13 s). The ones refused after records were final (208,
# 917, 4669) and 7406 all plan now.
# The module is enabled on a running servo thread of the curve's period. nurbs-planner must
# put nothing into the ring before the start rule holds, so the failure comes first: it exits
# with the planner's error, and the module has taken no record (nothing moved).
here=$(cd "$(dirname "$0")" && pwd)
source "$here/lib.sh"

toolpath="$here/refused_stream.json"
PERIOD=0.00016582130356203076
LIMITS="--feed 4191.755008993316 --accel 1462.5546584086417 --jerk 1654.3689664315684 --chord-tol 0.00153557848570954"

if offline=$(nurbs-plan plan "$toolpath" $LIMITS --period $PERIOD --stream --out /dev/null 2>&1); then
    echo "the curve is no longer refused: this test lost its subject"; exit 1
fi
work=$(mktemp -d /tmp/nurbs-hal-test.XXXXXX)
chmod 755 "$work"
cat >"$work/plan.sh" <<SH
#!/bin/sh
nurbs-planner "$toolpath" $LIMITS --period $PERIOD >"$work/planner.log" 2>&1
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
loadrt threads name1=servo period1=165821
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
