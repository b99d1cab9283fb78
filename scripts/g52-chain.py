#!/usr/bin/env python3
"""Write a long G5.2 program: BLOCKS random cubic NURBS pieces (G5.2 L4, five control points
with the current position, weights 1), each starting where the one before ended and along its
end tangent, so that the path is tangent-continuous at every join (the first leg of a piece
continues the last leg of the one before, exactly: control points lie on a 1e-4 mm grid and
Q1 = 2 P4 - P3). The direction turns by a random angle of at most TURN degrees per leg, and
turns back towards the centre once the path strays more than 40 mm from it.

    scripts/g52-chain.py --blocks 100000 [--leg 1.0] [--turn 15] [--seed 1] [--feed 500] > chain.ngc

Used by the scale measurements (docs/performance.md); generated, never committed.
Deterministic: the same arguments give the same bytes.
"""
import argparse
import math
import random
import sys

GRID = 10_000  # control points on a 1e-4 mm grid: the joins' collinearity is exact


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--blocks", type=int, required=True, help="G5.2 blocks to write")
    ap.add_argument("--leg", type=float, default=1.0, help="length of a control-polygon leg (mm)")
    ap.add_argument("--turn", type=float, default=15.0, help="largest turn per leg (degrees)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--feed", type=float, default=500.0, help="F (mm/s)")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    leg = round(args.leg * GRID)
    max_turn = math.radians(args.turn)
    out = sys.stdout
    out.write(f"(g52-chain: {args.blocks} random G5.2 cubic pieces, legs {args.leg} mm, turns up to {args.turn} deg, tangent-continuous joins, seed {args.seed})\n")
    out.write("G21 G17 G90 G94 G64\n")
    out.write(f"F{args.feed * 60:.0f}\n")
    out.write("G0 X0 Y0\n")
    fmt = lambda p: f"X{p[0] / GRID:.4f} Y{p[1] / GRID:.4f}"
    p = (0, 0)
    prev = (-leg, 0)  # the leg before the start: the path leaves along +X
    heading = 0.0
    for _ in range(args.blocks):
        # Q1 continues the last leg exactly; Q2..Q4 turn by random angles.
        q = [(2 * p[0] - prev[0], 2 * p[1] - prev[1])]
        heading = math.atan2(q[0][1] - p[1], q[0][0] - p[0])
        for _ in range(3):
            x, y = q[-1]
            turn = rng.uniform(-max_turn, max_turn)
            if math.hypot(x, y) > 40 * GRID:
                # Steer back towards the centre, at most TURN per leg.
                back = math.atan2(-y, -x) - heading
                back = (back + math.pi) % (2 * math.pi) - math.pi
                turn = max(-max_turn, min(max_turn, back))
            heading += turn
            length = leg * rng.uniform(0.8, 1.2)
            q.append((x + round(length * math.cos(heading)), y + round(length * math.sin(heading))))
        out.write(f"G5.2 {fmt(q[0])} P1 L4\n")
        for c in q[1:]:
            out.write(f"{fmt(c)} P1\n")
        out.write("G5.3\n")
        prev, p = q[-2], q[-1]
    out.write("M2\n")


if __name__ == "__main__":
    main()
