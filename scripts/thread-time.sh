#!/bin/bash
# Per-period cost of nurbs_interp.update in real LinuxCNC (uspace, 250 us servo thread).
#
#   sudo make install && sudo scripts/thread-time.sh [TOOLPATH]     (default: the butterfly)
#
# Runs halrun with the module, nurbs-planner (limits of halfiles/sim.ini) and a sampler that
# records, every servo period, the function's own time pin `nurbs_interp.update.time` (TSC
# cycles, as `show thread` reports them) and `nurbs_interp.active`. Prints `show thread` and the
# function's time/tmax as halcmd shows them mid-run (1.5 s into the motion) and after the motion,
# then the distribution over all recorded periods (motion periods and idle ones), in cycles and
# in microseconds at the TSC frequency the kernel detected.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/tests/hal/lib.sh"

toolpath=$(realpath "${1:-$root/examples/butterfly.json}")
periods=${PERIODS:-24000}
work=$(mktemp -d /tmp/nurbs-thread-time.XXXXXX)
chmod 755 "$work"
cat >"$work/time.hal" <<HAL
loadrt threads name1=servo period1=250000
loadrt nurbs_interp
# sampler: update.time (s32), active (bit); enable left at its default (TRUE): every period.
loadrt sampler depth=40000 cfg=sb
loadusr -W nurbs-planner $toolpath --ini $root/halfiles/sim.ini
net update-time nurbs_interp.update.time => sampler.0.pin.0
net active      nurbs_interp.active      => sampler.0.pin.1
addf nurbs_interp.update servo
addf sampler.0           servo
setp nurbs_interp.enable 1
start
loadusr -w sleep 1.5
loadusr -w /bin/echo === mid-run
show thread
show pin nurbs_interp.update
show param nurbs_interp.update
loadusr -w nurbs-hal-record --samples $periods --out $work/times.txt --timeout 60
loadusr -w /bin/echo === after the motion
show thread
show pin nurbs_interp.update
show param nurbs_interp.update
show pin nurbs_interp.done
stop
HAL
hal_session "$work/time.hal" "$work/halrun.log"
grep -v "^Running with fallback_uid\|^Note: Using POSIX" "$work/halrun.log"
mhz=$(dmesg 2>/dev/null | sed -n 's/.*tsc: Detected \([0-9.]*\) MHz.*/\1/p' | head -1)
mhz=${mhz:-$(awk -F: '/cpu MHz/ {print $2+0; exit}' /proc/cpuinfo)}
python3 - "$work/times.txt" "$mhz" <<'PY'
import sys
rows = [l.split() for l in open(sys.argv[1])]
mhz = float(sys.argv[2])
def stats(name, xs):
    if not xs:
        print(f"{name}: no periods"); return
    xs = sorted(xs)
    q = lambda p: xs[int((len(xs) - 1) * p)]
    mean = sum(xs) / len(xs)
    print(f"{name}: {len(xs)} periods: cycles median {q(0.5)}, mean {mean:.0f}, p99 {q(0.99)}, "
          f"max {xs[-1]} | us median {q(0.5) / mhz:.3f}, mean {mean / mhz:.3f}, "
          f"p99 {q(0.99) / mhz:.3f}, max {xs[-1] / mhz:.3f}")
t = [int(r[1]) for r in rows]
active = [int(r[1]) for r in rows if r[2] == "1"]
idle = [int(r[1]) for r in rows if r[2] == "0"]
print(f"nurbs_interp.update per period (TSC {mhz} MHz):")
stats("  motion (active)", active)
stats("  idle (before/after the motion)", idle)
stats("  all", t)
slow = sorted(range(len(t)), key=lambda i: -t[i])[:5]
print("  slowest periods (sample, cycles, active):", [(i, t[i], rows[i][2]) for i in slow])
PY
rm -rf "$work"
