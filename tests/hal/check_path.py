#!/usr/bin/env python3
"""Check the samples of path_test.sh against the offline setpoints of `nurbs-plan plan`.

- one sample per setpoint: the count equals the offline row count, the sample numbers are
  consecutive (no sampler overrun) and `done` rises on the last sample only;
- every position equals the offline one to --tol mm (u and feed too);
- no fault, no underrun;
- the motion ends at the end of the last curve, C(1), to --tol mm;
- writes the recorded setpoints as a CSV in the offline format for `nurbs-plan verify`.
"""
import argparse
import csv
import json
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--expected", required=True, help="nurbs-plan plan --out CSV")
    ap.add_argument("--samples", required=True, help="nurbs-hal-record output")
    ap.add_argument("--toolpath", required=True, help="JSON toolpath (for C(1))")
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
    if len(samples) != len(rows):
        errors.append(f"{len(samples)} samples, offline plan has {len(rows)}")
    for i in range(1, len(samples)):
        if samples[i]["n"] != samples[i - 1]["n"] + 1:
            errors.append(f"sample numbers jump at {i}: {samples[i - 1]['n']} -> {samples[i]['n']}")
            break
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

    with open(a.toolpath) as f:
        end = json.load(f)["control_points"][-1]
    if samples:
        last = samples[-1]
        dist = max(abs(last[c] - end[i]) for i, c in enumerate(axes))
        if dist > a.tol:
            errors.append(f"ends at {[last[c] for c in axes]}, C(1) = {end} (off by {dist:.3e} mm)")

    with open(a.recorded_csv, "w") as f:
        f.write("t,u," + ",".join(axes) + ",feed,element\n")
        for j, s in enumerate(samples):
            f.write(f"{j * a.period!r},{s['u']!r}," + ",".join(repr(s[c]) for c in axes)
                    + f",{s['feed']!r},{s['curve']}\n")

    if errors:
        print("FAIL:\n  " + "\n  ".join(errors))
        sys.exit(1)
    diffs = ", ".join(f"{c} {worst[c]:.1e}" for c in worst)
    print(f"ok: {len(samples)} samples = offline setpoints; max |difference|: {diffs}; "
          f"ends at C(1) {end}")


if __name__ == "__main__":
    main()
