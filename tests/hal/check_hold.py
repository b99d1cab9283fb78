#!/usr/bin/env python3
"""Check the samples of test_hold.sh: feed hold mid-path, then release.

- the samples start as the offline plan (to --tol mm) and leave it only when the hold's stop
  starts (at a segment boundary); the feed then falls to rest and comes back (the plan from the
  stop point); no position jump between consecutive samples beyond the feed's reach;
- the motion ends at C(1) with `done` on the last sample; no fault, no underrun;
- writes the recorded setpoints as a CSV for `nurbs-plan verify`.
"""
import json
import sys

from samples import load_run, parse_args, planned_prefix, write_recorded_csv


def main():
    a = parse_args(("--toolpath", dict(required=True, help="JSON toolpath (for C(1))")),
                   ("--jerk", dict(type=float, help="a stop of per-period positions (VPOp): its last "
                                                    "step may move at up to J dt^2")))
    rows, axes, samples, errors = load_run(a)
    planned = planned_prefix(samples, rows, axes, a.tol)
    if not 1000 <= planned < len(rows) - 1:
        errors.append(f"{planned} samples follow the plan (of {len(rows)}): the hold did not start mid-path")
    for k in range(1, len(samples)):
        step = max(abs(samples[k][c] - samples[k - 1][c]) for c in axes)
        # (+1e-6 mm: the last sample lands exactly on C(1), a few nm from where the integration
        # of the feed put it; the limits themselves are verify's business)
        reach = max(samples[k]["feed"], samples[k - 1]["feed"]) * a.period * 1.01 + 1e-6
        if step > reach:
            errors.append(f"position jump at sample {k}: {step} mm (feed allows {reach})")
            break
    slowest = min((s["feed"] for s in samples[planned:-10]), default=None)
    rest = max(1e-3, a.jerk * a.period ** 2) if a.jerk else 1e-3
    if slowest is None or slowest > rest:
        errors.append(f"the feed never came to rest during the hold (min {slowest})")
    if any(s["fault"] or s["underrun"] for s in samples):
        errors.append("fault or underrun")
    if not samples or not samples[-1]["done"] or any(s["done"] for s in samples[:-1]):
        errors.append("done is not set on exactly the last sample")
    with open(a.toolpath) as f:
        end = json.load(f)["control_points"][-1]
    if samples:
        dist = max(abs(samples[-1][c] - end[i]) for i, c in enumerate(axes))
        if dist > a.tol:
            errors.append(f"ends {dist:.3e} mm from C(1)")
    # The sampler records only active periods; during the hold the machine stood still for
    # seconds. The resumed motion's first sample is the held position at feed 0: three held
    # periods go before it, so that the finite differences see the machine at rest there, as it
    # was (a stop of per-period positions ends with a last step, not with an S-curve's zero
    # acceleration, so the gap matters).
    resumed = next((k for k in range(planned + 1, len(samples))
                    if samples[k]["feed"] == 0.0 and all(samples[k][c] == samples[k - 1][c] for c in axes)),
                   None)
    recorded = samples if resumed is None else samples[:resumed] + [samples[resumed]] * 3 + samples[resumed:]
    write_recorded_csv(a.recorded_csv, recorded, axes, a.period)
    if errors:
        print("FAIL:\n  " + "\n  ".join(errors))
        sys.exit(1)
    print(f"ok: {planned} planned samples, hold (stop at a boundary) to {slowest:.2e} mm/s and resume, "
          f"{len(samples)} samples in all (plan: {len(rows)}), ends at C(1) {end}")


if __name__ == "__main__":
    main()
