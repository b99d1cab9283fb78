#!/usr/bin/env python3
"""Check the samples of test_underrun.sh: the planner was unloaded mid-path.

- the samples start as the offline plan, equal to --tol mm, up to a segment boundary;
- then the stop: the feed never rises and ends at rest (below J dt^2 / 2); with --stop-may-rise
  (a planned stop segment, which may speed up before it brakes) or --stop-from-acceleration (a
  stop from a path block's end, where the motion may still be accelerating) the feed may rise
  first, but once it falls it never rises again; with
  --any-stop (a stored stop sequence: the plan's next positions, then a deceleration) the feed
  is not checked here, only by the limit check, and each axis's last step may be up to J dt^2;
- underrun set, no fault, not done;
- with --resumed (the samples after a planner re-planned from the stop point and the module got
  its resume command): the first resumed sample is where the stop ended (no jump), the motion ends
  at C(1) (the offline plan's last point, to --tol mm) at rest (VPOp, --stop-from-acceleration:
  its last step's feed below J dt^2), done, no fault, underrun cleared.
The recorded setpoints (stop and resumed samples as the sampler saw them, with three held
periods between) go to a CSV for `nurbs-plan verify`, which must find no violation (but the missing end of the path when
there is no resume).
"""
import sys

from samples import load_run, parse_args, planned_prefix, read_samples, sample_gap, write_recorded_csv


def main():
    a = parse_args(("--jerk", dict(type=float, required=True)), ("--resumed", {}),
                   ("--stop-from-acceleration", dict(action="store_true")),
                   ("--stop-may-rise", dict(action="store_true")),
                   ("--any-stop", dict(action="store_true")))
    rows, axes, samples, errors = load_run(a)
    planned = planned_prefix(samples, rows, axes, a.tol)
    if not 1000 <= planned < len(rows) - 1:
        errors.append(f"{planned} samples follow the plan (of {len(rows)}): not a mid-path cut")
    stop = samples[planned:]
    if len(stop) < 2:
        errors.append(f"only {len(stop)} samples after the cut: no stop ramp")
    falling = not (a.stop_from_acceleration or a.stop_may_rise)
    for k in range(1, 0 if a.any_stop else len(stop)):
        if stop[k]["feed"] < stop[k - 1]["feed"] - 1e-9:
            falling = True
        elif falling and stop[k]["feed"] > stop[k - 1]["feed"] + 1e-9:
            errors.append(f"feed rises during the stop at sample {planned + k}")
            break
    # The last moving sample's feed: a sampled S-curve ends below J dt^2 / 2. A stored sequence
    # (VPOp's discrete stop) ends with a step onto rest, whose jerk (step / dt^3) each axis must
    # hold on its own: each axis's last step below J dt^2 (the path speed, their norm, may exceed
    # that on a diagonal).
    last = samples[-1] if samples else None
    if a.any_stop:
        before = samples[-2] if len(samples) >= 2 else None
        step = max(abs(last[c] - before[c]) for c in axes) / a.period if before else float("inf")
        if step > a.jerk * a.period ** 2 * (1 + 1e-6):
            errors.append(f"not at rest at the end: last axis step {step} mm/s over J dt^2")
    elif last is None or abs(last["feed"]) > a.jerk * a.period ** 2 / 2:
        errors.append(f"not at rest at the end: feed {last and last['feed']}")
    if last is None or not last["underrun"] or last["fault"] or last["done"]:
        errors.append(f"end state: {last}")
    if any(s["fault"] for s in samples):
        errors.append("fault during the run")

    resumed = read_samples(a.resumed) if a.resumed else []
    if a.resumed:
        if not resumed:
            errors.append("no samples after the resume command")
        else:
            gap = sample_gap(samples + resumed)
            if gap:
                errors.append("stop -> resumed: " + gap)
            first, end = resumed[0], resumed[-1]
            jump = max(abs(first[c] - last[c]) for c in axes) if last else float("inf")
            if jump > a.tol:
                errors.append(f"position jump at the resume: {jump} mm")
            if first["feed"] != 0.0:
                errors.append(f"the resumed motion does not start at rest: feed {first['feed']}")
            goal = max(abs(end[c] - float(rows[-1][c])) for c in axes)
            # A VPOp plan ends with its last step (feed below J dt^2) and then stays there.
            end_feed = a.jerk * a.period ** 2 if a.stop_from_acceleration else 0.0
            if goal > a.tol or abs(end["feed"]) > end_feed:
                errors.append(f"the resumed motion ends {goal} mm from C(1), feed {end['feed']}")
            if not end["done"] or end["fault"] or end["underrun"]:
                errors.append(f"end state after the resume: {end}")
            if any(s["fault"] for s in resumed):
                errors.append("fault after the resume")
    # The sampler records only active periods; between the stop and the resume the machine
    # stood still for many periods (at least the re-planning time): three of them here, so that
    # the finite differences see it at rest there, as it was.
    held = [dict(last, feed=0.0)] * 3 if (last and resumed) else []
    write_recorded_csv(a.recorded_csv, samples + held + resumed, axes, a.period)
    if errors:
        print("FAIL:\n  " + "\n  ".join(errors))
        sys.exit(1)
    if stop and planned:
        print(f"the stop runs from curve {samples[planned - 1]['curve']} (the last planned sample) "
              f"to curve {stop[-1]['curve']}")
    print(f"ok: {planned} planned samples, then a {len(stop)}-sample stop from "
          f"{stop[0]['feed']:.3f} mm/s to {last['feed']:.2e} mm/s; underruns={last['underruns']}"
          + (f"; resumed: {len(resumed)} samples to C(1)" if resumed else ""))


if __name__ == "__main__":
    main()
