#!/usr/bin/env python3
"""Check the samples of path_test.sh against the offline setpoints of `nurbs-plan plan`.

- one sample per setpoint: the count equals the offline row count, the sample numbers are
  consecutive (no sampler overrun) and `done` rises on the last sample only;
- every position equals the offline one to --tol mm (u and feed too);
- no fault, no underrun;
- the motion ends at the end of the last curve, C(1), to --tol mm;
- writes the recorded setpoints as a CSV in the offline format for `nurbs-plan verify`;
- prints the least motion time that was queued ahead of the module, before the last records
  went out (the margin the planner kept).
"""
import json
import sys

from samples import load_run, parse_args, write_recorded_csv


def main():
    a = parse_args(("--toolpath", dict(required=True, help="toolpath (a JSON one gives C(1))")))
    rows, axes, samples, errors = load_run(a)
    if len(samples) != len(rows):
        errors.append(f"{len(samples)} samples, offline plan has {len(rows)}")
    worst = {k: 0.0 for k in axes + ["u", "feed"]}
    for k, (s, r) in enumerate(zip(samples, rows)):
        if s["fault"] or s["underrun"] or s["underruns"]:
            errors.append(f"sample {k}: fault={s['fault']} code={s['fault_code']} "
                          f"underrun={s['underrun']} underruns={s['underruns']}")
            break
        if s["done"] != (k == len(rows) - 1):
            errors.append(f"sample {k}: done={s['done']}")
            break
        if s["curve"] != int(r["element"]):
            errors.append(f"sample {k}: curve {s['curve']}, offline {r['element']}")
            break
        for c in worst:
            worst[c] = max(worst[c], abs(s[c] - float(r[c])))
    for c in axes:
        if worst[c] > a.tol:
            errors.append(f"{c} differs from the offline plan by {worst[c]:.3e} mm (> {a.tol:g})")
    for c in ("u", "feed"):
        if worst[c] > 1e-9:
            errors.append(f"{c} differs from the offline plan by {worst[c]:.3e}")

    if a.toolpath.endswith(".json"):
        with open(a.toolpath) as f:
            end = json.load(f)["control_points"][-1]
    else:
        # A G-code program: C(1) as the offline plan (checked by `verify`) ends there.
        end = [float(rows[-1][c]) for c in axes] if rows else []
    if samples:
        last = samples[-1]
        dist = max(abs(last[c] - end[i]) for i, c in enumerate(axes))
        if dist > a.tol:
            errors.append(f"ends at {[last[c] for c in axes]}, C(1) = {end} (off by {dist:.3e} mm)")

    write_recorded_csv(a.recorded_csv, samples, axes, a.period)
    queued = [s["buffered"] for s in samples if s["buffered"] is not None]
    # Toward the end the queue drains: the margin is what was queued while at least 3 s of
    # motion lay ahead.
    ahead = len(queued) - int(3.0 / a.period)
    if ahead > 0:
        print(f"queued ahead of the module: at least {min(queued[:ahead]):.3f} s "
              f"while 3 s or more of motion lay ahead")

    if errors:
        print("FAIL:\n  " + "\n  ".join(errors))
        sys.exit(1)
    diffs = ", ".join(f"{c} {worst[c]:.1e}" for c in worst)
    print(f"ok: {len(samples)} samples = offline setpoints; max |difference|: {diffs}; "
          f"ends at C(1) {end}")


if __name__ == "__main__":
    main()
