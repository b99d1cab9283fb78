#!/usr/bin/env python3
"""Check the samples of test_hold.sh: feed hold mid-path, then release.

- the samples start as the offline plan (to --tol mm) and leave it only when the hold ramp
  starts; the feed then falls to rest and comes back;
- the motion ends at C(1) with `done` on the last sample; no fault, no underrun;
- writes the recorded setpoints as a CSV for `nurbs-plan verify`.
"""
import argparse
import csv
import json
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--expected", required=True)
    ap.add_argument("--samples", required=True)
    ap.add_argument("--toolpath", required=True)
    ap.add_argument("--period", type=float, required=True)
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--recorded-csv", required=True)
    a = ap.parse_args()

    with open(a.expected) as f:
        rows = list(csv.DictReader(f))
    axes = [c for c in ("x", "y", "z") if rows and c in rows[0]]
    samples = []
    with open(a.samples) as f:
        for line in f:
            v = line.split()
            samples.append({
                "n": int(v[0]), "x": float(v[1]), "y": float(v[2]), "z": float(v[3]),
                "u": float(v[4]), "feed": float(v[5]), "curve": int(v[6]), "underruns": int(v[7]),
                "fault_code": int(v[8]), "done": v[9] == "1", "fault": v[10] == "1",
                "underrun": v[11] == "1",
            })
    errors = []
    for i in range(1, len(samples)):
        if samples[i]["n"] != samples[i - 1]["n"] + 1:
            errors.append(f"sample numbers jump at {i}")
            break
    planned = 0
    for s, r in zip(samples, rows):
        if max(abs(s[c] - float(r[c])) for c in axes) > a.tol:
            break
        planned += 1
    if not 1000 <= planned < len(rows) - 1:
        errors.append(f"{planned} samples follow the plan (of {len(rows)}): the hold did not start mid-path")
    if len(samples) <= len(rows):
        errors.append(f"{len(samples)} samples, not more than the plan's {len(rows)}: no hold")
    slowest = min((s["feed"] for s in samples[planned:-10]), default=None)
    if slowest is None or slowest > 1e-3:
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
    with open(a.recorded_csv, "w") as f:
        f.write("t,u," + ",".join(axes) + ",feed,element\n")
        for j, s in enumerate(samples):
            f.write(f"{j * a.period!r},{s['u']!r}," + ",".join(repr(s[c]) for c in axes)
                    + f",{s['feed']!r},{s['curve']}\n")
    if errors:
        print("FAIL:\n  " + "\n  ".join(errors))
        sys.exit(1)
    print(f"ok: {planned} planned samples, hold to {slowest:.2e} mm/s and resume, "
          f"{len(samples)} samples in all (plan: {len(rows)}), ends at C(1) {end}")


if __name__ == "__main__":
    main()
