#!/usr/bin/env python3
"""Check the samples of test_stream.sh against the records nurbs-planner sent.

Every servo period is one sample (sample numbers consecutive: no sampler overrun). The first
RECORDS samples carry record k in period k, positions equal bit for bit; afterwards the module
reports one underrun per period and holds the last position; no fault at any time.
"""
import argparse
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--expected", required=True)
    ap.add_argument("--samples", required=True)
    ap.add_argument("--records", type=int, required=True)
    ap.add_argument("--extra", type=int, required=True)
    a = ap.parse_args()

    expected = []
    with open(a.expected) as f:
        for line in f:
            seq, x, y, _z = line.split()
            expected.append((int(seq), float(x), float(y)))
    samples = []
    with open(a.samples) as f:
        for line in f:
            n, x, y, active, seq, under, fault = line.split()
            samples.append((int(n), float(x), float(y), active == "1", int(seq), int(under), fault == "1"))

    errors = []
    if len(expected) != a.records:
        errors.append(f"planner sent {len(expected)} records, expected {a.records}")
    if len(samples) != a.records + a.extra:
        errors.append(f"{len(samples)} samples, expected {a.records + a.extra}")
    for i in range(1, len(samples)):
        if samples[i][0] != samples[i - 1][0] + 1:
            errors.append(f"sample numbers jump at {i}: {samples[i - 1][0]} -> {samples[i][0]}")
            break
    for k, (n, x, y, active, seq, under, fault) in enumerate(samples):
        if fault:
            errors.append(f"fault at sample {k}")
            break
        if k < len(expected):
            es, ex, ey = expected[k]
            if not (active and seq == es and x == ex and y == ey and under == 0):
                errors.append(f"sample {k}: got x={x!r} y={y!r} active={active} seq={seq} underruns={under}, "
                              f"expected x={ex!r} y={ey!r} seq={es}")
                break
        else:
            lx = expected[-1][1] if expected else 0.0
            if active or x != lx or under != k - len(expected) + 1:
                errors.append(f"sample {k} (after the data): x={x!r} active={active} underruns={under}")
                break
    if errors:
        print("FAIL:\n  " + "\n  ".join(errors))
        sys.exit(1)
    print(f"ok: {len(samples)} samples, {a.records} records matched bit for bit, "
          f"{a.extra} underrun periods holding x={samples[-1][1]!r}")


if __name__ == "__main__":
    main()
