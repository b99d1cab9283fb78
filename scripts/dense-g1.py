#!/usr/bin/env python3
"""Write a dense CAM-like G1 program: the bundled butterfly NURBS sampled every STEP mm of arc
length as G1 lines, pass after pass back and forth (odd passes reversed), each pass DZ lower
than the one before, joined by a short Z line, until LINES lines are written.

    scripts/dense-g1.py --lines 20000 [--step 0.02] [--dz 0.05] [--feed 500] > dense.ngc

Used by the scale measurements (docs/performance.md) and their tests; the files are generated,
never committed. Deterministic: the same arguments give the same bytes.
"""
import argparse
import bisect
import json
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def find_span(n, p, u, knots):
    if u >= knots[n + 1]:
        return n
    lo, hi = p, n + 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if u < knots[mid]:
            hi = mid
        else:
            lo = mid
    return lo


def curve_point(p, knots, points, weights, u):
    """Rational de Boor evaluation (Piegl & Tiller A4.1 by homogeneous de Boor)."""
    n = len(points) - 1
    k = find_span(n, p, u, knots)
    d = []
    for j in range(p + 1):
        i = k - p + j
        w = weights[i]
        d.append([points[i][0] * w, points[i][1] * w, w])
    for r in range(1, p + 1):
        for j in range(p, r - 1, -1):
            i = k - p + j
            denom = knots[i + p - r + 1] - knots[i]
            a = 0.0 if denom == 0 else (u - knots[i]) / denom
            d[j] = [(1 - a) * d[j - 1][c] + a * d[j][c] for c in range(3)]
    x, y, w = d[p]
    return x / w, y / w


def resample(curve, step):
    p, knots, pts = curve["degree"], curve["knots"], curve["control_points"]
    weights = curve.get("weights") or [1.0] * len(pts)
    fine = 400_000
    u0, u1 = knots[p], knots[-p - 1]
    xy = [curve_point(p, knots, pts, weights, u0 + (u1 - u0) * i / fine) for i in range(fine + 1)]
    s = [0.0]
    for a, b in zip(xy, xy[1:]):
        s.append(s[-1] + math.hypot(b[0] - a[0], b[1] - a[1]))
    out = [xy[0]]
    count = int(s[-1] / step)
    for k in range(1, count + 1):
        target = k * step
        i = min(bisect.bisect_left(s, target), len(s) - 1)
        if i == 0:
            continue
        f = (target - s[i - 1]) / (s[i] - s[i - 1]) if s[i] > s[i - 1] else 0.0
        a, b = xy[i - 1], xy[i]
        out.append((a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])))
    if math.hypot(out[-1][0] - xy[-1][0], out[-1][1] - xy[-1][1]) > 1e-6:
        out.append(xy[-1])
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lines", type=int, required=True, help="G1 lines to write")
    ap.add_argument("--step", type=float, default=0.02, help="arc length per line (mm)")
    ap.add_argument("--dz", type=float, default=0.05, help="Z step between passes (mm)")
    ap.add_argument("--feed", type=float, default=500.0, help="programmed feed (mm/s)")
    ap.add_argument("--curve", default=os.path.join(HERE, "..", "examples", "butterfly.json"))
    args = ap.parse_args()
    with open(args.curve) as f:
        curve = json.load(f)
    path = resample(curve, args.step)
    w = sys.stdout.write
    w(f"(dense-g1: {os.path.basename(args.curve)} every {args.step} mm, {args.lines} G1 lines,")
    w(f" passes back and forth {args.dz} mm apart in Z)\n")
    w(f"G21 G17 G90 G94 G64\nF{args.feed * 60:.0f}\n")
    x0, y0 = path[0]
    w(f"G0 X{x0:.4f} Y{y0:.4f} Z0\n")
    written, z, forward = 0, 0.0, True
    while written < args.lines:
        points = path[1:] if forward else list(reversed(path))[1:]
        for x, y in points:
            if written == args.lines:
                break
            w(f"G1 X{x:.4f} Y{y:.4f}\n")
            written += 1
        if written < args.lines:
            z -= args.dz
            w(f"G1 Z{z:.4f}\n")
            written += 1
        forward = not forward
    w("M2\n")


if __name__ == "__main__":
    main()
