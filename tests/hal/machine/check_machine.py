#!/usr/bin/env python3
"""Checks a recorded run of test_machine.sh, every servo period:

- LinuxCNC: the program ran to its end with an empty error channel, the joints are still
  homed, the motor offsets are not zero, and at the end the interpreter's (motion's) position,
  motion's joint command and the drive command less the motor offset agree, released;
- our paths (one per engagement, in order): the periods nurbs_interp produced a setpoint are
  the offline plan's setpoints (count, and every position to 1e-9 mm); each written as a CSV
  for `nurbs-plan verify`;
- the hand-over: while engaged the drive command is our position plus the motor offset; the
  drive command never steps: from two periods before engaging to two after releasing its
  finite differences stay within the axis velocity, acceleration and jerk (relative slack 1e-6);
  during the catch-up move (path done, still engaged) the drive stands still while motion's
  command moves to the path's end;
- with --action abort (or pause-abort: paused first, held, then aborted): one engagement whose setpoints are the plan's for at least 0.25 s, then
  the stop on the path (checked by `verify`), then the catch-up move and the release as after a
  toolpath's end, the machine staying on (and an MDI move after it); with --action estop: the
  drive never steps (its position; the drives are off, what they do then is theirs) and stands
  still after the E-stop; either way LinuxCNC takes the drives' position, homed;
- with --action override: the operator's feed override went to 10 % while the first toolpath
  ran: its setpoints are the plan's up to where the override came and further (the motion
  queued in the ring), then the re-planned rest, whose feed comes under 10 % of [NURBS]FEED and
  stays there to the path's end (the time from the knob to that point is reported); checked
  by `verify` like every path, and the second toolpath (back at 100 %) as planned;
- following error (motion's joint.N.f-error): 0 (1e-9) while engaged, and within one period of
  the largest velocity (the simulated drive's lag) everywhere (motion compares the feedback with
  its command of the period before, so with this drive it sees 0 there too).
"""
import argparse
import configparser
import csv
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from samples import write_recorded_csv  # noqa: E402  (tests/hal/samples.py)


def ini_limits(path, joints):
    # LinuxCNC INI files repeat keys (HALFILE): read leniently.
    cp = configparser.ConfigParser(strict=False, interpolation=None, inline_comment_prefixes=("#",))
    cp.optionxform = str
    cp.read(path)
    axes = "XYZ"[:joints]
    v = [float(cp[f"AXIS_{a}"]["MAX_VELOCITY"]) for a in axes]
    a = [float(cp[f"AXIS_{a}"]["MAX_ACCELERATION"]) for a in axes]
    j = [float(cp[f"AXIS_{a}"]["MAX_JERK"]) for a in axes]
    period = float(cp["EMCMOT"]["SERVO_PERIOD"]) * 1e-9
    return v, a, j, period


def read(path, joints):
    """Recorder lines: sample number, drive commands, following errors and motion's pos-cmd of
    each joint, our x y z, engaged, active, u, feed, curve and, where recorded, the operator's
    feed override."""
    rows = []
    J = joints
    with open(path) as f:
        for line in f:
            x = line.split()
            f_ = [float(t) for t in x[1 : 3 * J + 4]]
            b = 3 * J + 4
            rows.append({
                "n": int(x[0]), "drive": f_[0:J], "ferror": f_[J : 2 * J], "pos_cmd": f_[2 * J : 3 * J],
                "ours": f_[3 * J : 3 * J + 3], "engaged": x[b] == "1", "active": x[b + 1] == "1",
                "u": float(x[b + 2]), "feed": float(x[b + 3]), "curve": int(x[b + 4]),
                # (Recorded by the nurbs-sim machine; the EtherCAT machine has no knob: 1.)
                "override": float(x[b + 5]) if len(x) > b + 5 else 1.0,
            })
    return rows


def main():
    ap = argparse.ArgumentParser()
    for flag in ("--samples", "--result", "--ini"):
        ap.add_argument(flag, required=True)
    ap.add_argument("--offline", action="append", required=True, help="each toolpath's offline plan, in order")
    ap.add_argument("--recorded-csv", action="append", required=True, help="where to write each one's setpoints")
    ap.add_argument("--joints", type=int, default=3, help="the machine's joints (X, Y[, Z])")
    ap.add_argument("--ferror-engaged", type=float, default=1e-9,
                    help="largest following error while engaged (mm): the drives' resolution")
    ap.add_argument("--ferror-max", type=float,
                    help="largest following error anywhere (mm); default: one period at the largest velocity")
    ap.add_argument("--all-ours-after", action="store_true",
                    help="every move from the first engagement on is ours (nurbs-filter took them all): "
                         "the drive command within the axis limits in every period from there to the end")
    ap.add_argument("--action", choices=("abort", "estop", "travel", "pause", "pause-abort", "override"),
                    help="the run was aborted, E-stopped or paused and resumed mid-path, or its first toolpath leaves the travel")
    a = ap.parse_args()
    # Paused first, then aborted: checked as an abort, and the pause held the path.
    paused_first = a.action == "pause-abort"
    if paused_first:
        a.action = "abort"
    vmax, amax, jmax, T = ini_limits(a.ini, a.joints)
    with open(a.result) as f:
        result = json.load(f)
    rows = read(a.samples, a.joints)
    errors = []
    fail = errors.append

    # LinuxCNC's view.
    expected_error = {"estop": "switched off during the toolpath",
                      "travel": "toolpath 1 (trident.json) refused: "}.get(a.action)
    for e in result["errors"]:
        if not (expected_error and expected_error in e):
            fail(f"LinuxCNC error: {e}")
    said = [e for e in result["errors"] if a.action == "travel" and "leaves the machine's travel: Y" in e]
    if a.action == "travel" and not said:
        fail(f"no refusal naming the travel in LinuxCNC's errors: {result['errors']}")
    elif a.action in ("abort", "estop", "pause", "override") and not result.get("action_moving"):
        fail(f"the {a.action} did not come while our path moved")
    if a.action == "abort" and not (result.get("released_after_abort") and result.get("moved_after_abort")):
        fail("after the abort the drives were not released with the machine on, or MDI did not move it")
    if (a.action == "pause" or paused_first) and not result.get("paused_at_rest"):
        fail("paused, our path was not held at rest")
    if not all(result.get("homed", [])):
        fail(f"joints not homed at the end: {result.get('homed')}")
    offset = result["motor_offset"]
    if not all(abs(o) > 0.1 for o in offset):
        fail(f"motor offsets {offset}: the test needs non-zero ones")
    if result["engaged"]:
        fail("still engaged at the end")
    end_checks = [("motion's joint command", result["joint_pos_cmd"]),
                  ("drive less motor offset", [d - o for d, o in zip(result["drive"], offset)])]
    for name, p in end_checks:
        if max(abs(x - y) for x, y in zip(p, result["position"])) > 1e-9:
            fail(f"at the end, {name} {p} != the interpreter's position {result['position']}")

    if not rows:
        fail("no samples recorded")
    for k in range(1, len(rows)):
        if rows[k]["n"] != rows[k - 1]["n"] + 1:
            fail(f"sample numbers jump at {k}: {rows[k-1]['n']} -> {rows[k]['n']} (sampler overrun)")
            break
    engaged = [k for k, r in enumerate(rows) if r["engaged"]]
    windows = []
    for k in engaged:
        if windows and windows[-1][1] == k - 1:
            windows[-1][1] = k
        else:
            windows.append([k, k])
    expected = {None: len(a.offline), "pause": len(a.offline), "override": len(a.offline), "travel": 0}.get(a.action, 1)
    if len(windows) != expected:
        fail(f"engaged {len(windows)} times, {expected} expected")
    if errors:
        report(errors)
    if a.action == "travel":
        if any(r["active"] for r in rows):
            fail("refused, yet nurbs_interp produced setpoints")
            report(errors)
        print(f"ok: {len(rows)} periods; toolpath 1 refused before any motion: {said[0]}; "
              f"motor offsets {offset}; homed, positions agree at the end")
        return
    worst_ratio = [0.0, 0.0, 0.0]
    summary = []
    for k, ((e0, e1), offline, recorded) in enumerate(zip(windows, a.offline, a.recorded_csv)):
        # An action acts on the first toolpath.
        summary.append(check_window(rows, e0, e1, offline, recorded, offset, vmax, amax, jmax, T, worst_ratio, fail,
                                    a.action if k == 0 else None,
                                    (result.get("override_at"), 0.1 * ini_feed(a.ini))))
    if errors:
        report(errors)
    if not a.action and max(moved for _, _, moved in summary) < 1.0:
        fail("no toolpath with a catch-up move of 1 mm or more")

    whole = ""
    if a.all_ours_after:
        # From two periods before the first engagement to the end, LinuxCNC's own planner moves
        # nothing: every period's drive command within every limit.
        ratio = [0.0, 0.0, 0.0]
        for k in range(max(windows[0][0] - 2, 3), len(rows)):
            for i in range(len(vmax)):
                d = [rows[k - m]["drive"][i] for m in range(4)]
                diffs = ((d[0] - d[1]) / T, (d[0] - 2 * d[1] + d[2]) / T**2, (d[0] - 3 * d[1] + 3 * d[2] - d[3]) / T**3)
                for n, (x, lim) in enumerate(zip(diffs, (vmax[i], amax[i], jmax[i]))):
                    ratio[n] = max(ratio[n], abs(x) / lim)
                    if abs(x) > lim * (1 + 1e-6):
                        fail(f"period {k}, joint {i}: drive {['velocity', 'acceleration', 'jerk'][n]} {x:.6g} exceeds {lim:g}")
                        report(errors)
        whole = (f"; every period from the first engagement to the end ({len(rows) - windows[0][0]}) within the limits "
                 f"(v/a/jerk at most {ratio[0]:.3f} / {ratio[1]:.3f} / {ratio[2]:.3f})")

    # Following error as motion sees it.
    fe_engaged = max(abs(f) for k in engaged for f in rows[k]["ferror"])
    fe_all = max(abs(f) for r in rows for f in r["ferror"])
    if a.action == "estop":
        # Released by the machine switched off, motion's feedback steps to the drives' position
        # (by the offset) while motion is disabled and re-syncs to it: its error is moot there.
        fe_all = max(abs(f) for r in rows[: engaged[-1] + 1] for f in r["ferror"])
    if fe_engaged > a.ferror_engaged:
        fail(f"following error {fe_engaged:.3e} mm while engaged (> {a.ferror_engaged:g})")
    fe_max = a.ferror_max if a.ferror_max is not None else max(vmax) * T * (1 + 1e-6)
    if fe_all > fe_max:
        fail(f"following error {fe_all:.6g} mm > {fe_max:.6g} mm")
    if errors:
        report(errors)
    paths = "; ".join(text for text, _, _ in summary)
    print(f"ok: {len(rows)} periods; {paths}; drive v/a/jerk through the hand-overs at most "
          f"{worst_ratio[0]:.3f} / {worst_ratio[1]:.3f} / {worst_ratio[2]:.3f} of the limits; "
          f"following error at most {fe_engaged:.1e} mm while engaged, {fe_all:.1e} mm overall; "
          f"motor offsets {offset}; homed, positions agree at the end{whole}")


def ini_feed(path):
    cp = configparser.ConfigParser(strict=False, interpolation=None, inline_comment_prefixes=("#",))
    cp.optionxform = str
    cp.read(path)
    return float(cp["NURBS"]["FEED"])


def check_window(rows, e0, e1, offline, recorded, offset, vmax, amax, jmax, T, worst_ratio, fail, action=None,
                 override=(None, 0.0)):
    """One engagement (periods e0..e1): its setpoints against the offline plan, the drive
    following them, no step, the catch-up (or, after `action`, the stop and what follows).
    `override`: where the override came (curve, u) and the feed cap it set.
    Returns (what it saw, catch-up periods, catch-up mm)."""
    active = [k for k in range(e0, e1 + 1) if rows[k]["active"]]
    if not active or active[0] == e0:
        fail(f"engagement at {e0}: no setpoint, or one in the engaging period")
        return ("", 0, 0.0)
    with open(offline) as f:
        plan = list(csv.DictReader(f))
    axes = [c for c in "xyz" if c in plan[0]]
    ours = [rows[k] for k in active]
    same = 0
    for r, p in zip(ours, plan):
        if max(abs(r["ours"][i] - float(p[c])) for i, c in enumerate(axes)) > 1e-9:
            break
        same += 1
    override_text = ""
    if action == "override":
        (at_curve, at_u), cap = override
        # The first setpoint at or past where the knob was turned.
        k0 = next((k for k, r in enumerate(ours) if (r["curve"], r["u"]) >= (at_curve, at_u)), len(ours))
        above = [k for k, r in enumerate(ours) if r["feed"] > cap * (1 + 1e-6)]
        settled = above[-1] + 1 if above else 0
        if same < k0 or same == len(ours):
            fail(f"{offline}: {same} setpoints as planned, the override came at {k0}: "
                 "the plan changed before the override, or not at all")
        if len(ours) <= len(plan):
            fail(f"{offline}: {len(ours)} setpoints at 10 %, {len(plan)} planned at 100 %: not slower")
        if settled >= len(ours) - 1:
            fail(f"{offline}: the feed never came under the override's {cap:g} mm/s")
        # Where the override pin (halui.feed-override.value, non-realtime) changed.
        k1 = next((k for k, r in enumerate(ours) if k >= k0 and r["override"] < 0.5), len(ours))
        if same < k1:
            fail(f"{offline}: the plan changed at setpoint {same}, before the override pin did ({k1})")
        override_text = (f", override 10 % at setpoint {k0}, on the pin at {k1} "
                         f"({(k1 - k0) * T * 1e3:.1f} ms later): the new plan from setpoint {same} "
                         f"({(same - k1) * T * 1e3:.1f} ms after the pin, {(same - k0) * T * 1e3:.1f} ms after "
                         f"the knob), the feed under {cap:g} mm/s from setpoint {settled} to the end")
    if action == "pause":
        if same < int(0.25 / T) or same == len(ours):
            fail(f"{offline}: {same} setpoints as planned, {len(ours)} in all: not a hold after 0.25 s")
    elif action and action != "override":
        if same < int(0.25 / T) or len(ours) >= len(plan):
            fail(f"{offline}: {same} setpoints as planned, {len(ours)} in all (plan {len(plan)}): "
                 f"not a stop after 0.25 s or more of the plan")
    elif action != "override" and (same != len(plan) or len(ours) != len(plan)):
        fail(f"{offline}: {len(ours)} setpoints, the first {same} of them as the offline plan's {len(plan)}")
    write_recorded_csv(recorded, [dict(zip("xyz", r["ours"]), u=r["u"], feed=r["feed"], curve=r["curve"])
                                  for r in ours], axes, T)

    # The drive follows our position while engaged (on the axes the path drives).
    follow = max(abs(rows[k]["drive"][i] - offset[i] - rows[k]["ours"][i])
                 for k in range(e0, e1 + 1) for i in range(len(axes)))
    if follow > 1e-9:
        fail(f"{offline}: engaged, the drive command is off our position by {follow:.3e} mm")

    # No step: finite differences of the drive command around and through the hand-over (after
    # an E-stop only up to it, and the position).
    lo, hi = max(e0 - 2, 3), min(e1 + 3, len(rows) - 1)
    if action == "estop":
        hi = e1
        moved = max(abs(rows[k]["drive"][i] - rows[k - 1]["drive"][i]) / T for k in range(e1, len(rows))
                    for i in range(len(vmax)))
        still = max(abs(rows[k]["drive"][i] - rows[e1 + 1]["drive"][i]) for k in range(e1 + 1, len(rows))
                    for i in range(len(vmax)))
        if moved > max(vmax) * (1 + 1e-6) or still > 1e-9:
            fail(f"E-stop: the drive command stepped ({moved:.6g} mm/s) or moved after it ({still:.3e} mm)")
    for k in range(lo, hi + 1):
        for i in range(len(vmax)):
            d = [rows[k - m]["drive"][i] for m in range(4)]
            v = (d[0] - d[1]) / T
            acc = (d[0] - 2 * d[1] + d[2]) / T**2
            jerk = (d[0] - 3 * d[1] + 3 * d[2] - d[3]) / T**3
            for n, (x, lim) in enumerate(((v, vmax[i]), (acc, amax[i]), (jerk, jmax[i]))):
                worst_ratio[n] = max(worst_ratio[n], abs(x) / lim)
                if abs(x) > lim * (1 + 1e-6):
                    fail(f"period {k}, joint {i}: drive {['velocity', 'acceleration', 'jerk'][n]} "
                         f"{x:.6g} exceeds {lim:g}")
    if action == "estop":
        return (f"{len(ours)} setpoints, the first {same} as planned, then the {action}", 0, 0.0)
    # The catch-up move: from the path's last setpoint to the release, the drive stands still
    # while motion's command goes to the path's end (after an abort, to where the path stopped).
    catch_up = range(active[-1] + 1, e1 + 1)
    still = max((abs(rows[k]["drive"][i] - rows[active[-1]]["drive"][i]) for k in catch_up for i in range(len(vmax))),
                default=0.0)
    moved = max(abs(rows[e1]["pos_cmd"][i] - rows[active[-1]]["pos_cmd"][i]) for i in range(len(vmax)))
    arrived = max(abs(rows[e1]["pos_cmd"][i] - rows[active[-1]]["ours"][i]) for i in range(len(axes)))
    if still > 1e-9:
        fail(f"{offline}: the drive moved by {still:.3e} mm during the catch-up move")
    if arrived > 1e-6:
        fail(f"{offline}: released with motion {arrived:.3e} mm from the path's end")
    what = {"pause": f"the first {same} as planned, held, resumed to the end",
            "override": f"the first {same} as planned{override_text}",
            "abort": f"the first {same} as planned, then the abort's stop"}.get(action, "= offline plan")
    return (f"{len(ours)} setpoints {what}, catch-up {moved:.3f} mm in {len(catch_up)} periods "
            "with the drive still", len(catch_up), moved)


def report(errors):
    print("FAIL:\n  " + "\n  ".join(errors))
    sys.exit(1)


if __name__ == "__main__":
    main()
