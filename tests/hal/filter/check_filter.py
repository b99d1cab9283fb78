#!/usr/bin/python3
"""nurbs-filter offline (LinuxCNC's interpreter module, no machine running):

1. Our G-code reader against LinuxCNC's interpreter: every bundled G-code example through the
   filter gives one run holding all its feed moves; the plan of that run file (LinuxCNC's
   reading of the program) and the plan of the program itself (our reader) have the same
   setpoints, to 1e-9 mm (the NURBS block of trident.ngc goes to the run file as written).
2. What the filter makes of constructs a CAM program or a person writes: units, incremental
   moves, arcs, helices, other planes, inverse time, parameters, subroutines, loops, NURBS
   blocks with computed values, errors with the program's line, tool words without a machine
   (left out of the reading, kept in the program).

Usage: check_filter.py FILTER NURBS-PLAN EXAMPLES-DIR WORK-DIR
"""
import csv
import glob
import os
import re
import subprocess
import sys

FILTER, PLAN, EXAMPLES, WORK = sys.argv[1:5]
failures = []


def check(ok, what):
    print(("ok:   " if ok else "FAIL: ") + what)
    if not ok:
        failures.append(what)


def run_filter(name, text):
    """Filters program `text`; returns (returncode, output, report, run files' texts)."""
    folder = os.path.join(WORK, name)
    os.makedirs(folder, exist_ok=True)
    program = os.path.join(folder, f"{name}.ngc")
    with open(program, "w") as f:
        f.write(text)
    env = dict(os.environ, XDG_CACHE_HOME=os.path.join(folder, "cache"))
    env.pop("INI_FILE_NAME", None)
    p = subprocess.run([FILTER, program], capture_output=True, text=True, env=env)
    runs = sorted(glob.glob(os.path.join(folder, "cache", "nurbs-filter", "*", "run-*.ngc")),
                  key=lambda f: int(re.search(r"run-(\d+)", f).group(1)))
    return p.returncode, p.stdout, p.stderr, [open(r).read() for r in runs], runs


class Preview:
    """What a GUI's preview draws of a program: LinuxCNC's interpreter with #<_task> = 0."""

    def __init__(self):
        self.moves = []

    def __getattr__(self, name):
        return lambda *args: None

    def get_external_length_units(self):
        return 1.0

    def get_external_angular_units(self):
        return 1.0

    def get_axis_mask(self):
        return 7

    def get_block_delete(self):
        return 0

    def check_abort(self):
        return False

    def get_tool(self, index):
        return (index,) + (0.0,) * 12 + (0,)

    def next_line(self, state):
        pass

    def straight_traverse(self, *p):
        self.moves.append(("G0",) + tuple(round(v, 9) for v in p[:3]))

    def straight_feed(self, *p):
        self.moves.append(("G1",) + tuple(round(v, 9) for v in p[:3]))

    def arc_feed(self, *p):
        self.moves.append(("arc",) + tuple(round(v, 9) for v in p[:6]))


def preview(path):
    import gcode
    canon = Preview()
    canon.parameter_file = path + ".var"
    open(canon.parameter_file, "w").close()
    result, line = gcode.parse(path, canon, "G21", "")
    assert result <= gcode.MIN_ERROR, f"{path}:{line}: {gcode.strerror(result)}"
    return canon.moves


def preview_alike(name, text, output):
    """The filtered program previews as the program does (the GUI shows the programmed path)."""
    folder = os.path.join(WORK, name)
    original, filtered = os.path.join(folder, "original.ngc"), os.path.join(folder, "filtered.ngc")
    with open(original, "w") as f:
        f.write(text)
    with open(filtered, "w") as f:
        f.write(output)
    a, b = preview(original), preview(filtered)
    check(a == b and len(a) > 0, f"{name}: the filtered program previews as the program: {len(a)} / {len(b)} moves")


def moves(run_text):
    return [l for l in run_text.splitlines() if re.match(r"G[123] ", l)]


def plan_rows(path, out):
    """The plan of `path` at lab set 1, checked by `verify` (finite differences at the period)."""
    subprocess.run([PLAN, "plan", path, "--limits", "lab1", "--out", out], check=True, capture_output=True)
    v = subprocess.run([PLAN, "verify", out, path, "--limits", "lab1"], capture_output=True, text=True)
    check(v.returncode == 0, f"{os.path.basename(path)}: the plan verifies: {v.stdout.strip().splitlines()[-1:]}")
    with open(out) as f:
        return list(csv.DictReader(f))


# 1. Our reader and LinuxCNC's interpreter on the bundled programs.
for example in sorted(glob.glob(os.path.join(EXAMPLES, "*.ngc"))):
    name = os.path.basename(example)[:-4]
    rc, out, report, runs, files = run_filter("example-" + name, open(example).read())
    preview_alike("example-" + name, open(example).read(), out)
    if rc != 0 or len(runs) != 1:
        check(False, f"{name}: one run expected, got rc {rc}, {len(runs)} run(s): {report.strip()}")
        continue
    ours = plan_rows(example, os.path.join(WORK, f"ours-{name}.csv"))
    theirs = plan_rows(files[0], os.path.join(WORK, f"theirs-{name}.csv"))
    axes = [a for a in "xyz" if a in ours[0] and a in theirs[0]]
    worst = max((abs(float(a[c]) - float(b[c])) for a, b in zip(ours, theirs) for c in axes), default=0.0)
    left = [l for l in report.splitlines() if "left to LinuxCNC" in l]
    check(len(ours) == len(theirs) and worst <= 1e-9 and all("rapid from an unknown position" in l for l in left),
          f"{name}: our reader and LinuxCNC's interpreter plan alike: {len(ours)} / {len(theirs)} setpoints, "
          f"largest difference {worst:.3e} mm")

# 2. Constructs.
sub_loop = open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "machine", "programs", "sub_loop.ngc")).read()
rc, out, report, runs, _ = run_filter("sub_loop", sub_loop)
check(rc == 0 and len(runs) == 2 and "move left to LinuxCNC's planner (inside an o-word block" in report,
      f"a subroutine's moves stay LinuxCNC's, the top-level runs around it are cut: {len(runs)} run(s)")
preview_alike("sub_loop", sub_loop, out)
rc, out, report, runs, _ = run_filter("inch_incremental", """G20 G90 G17
G0 X0 Y0 Z0.1
G91
G1 X1 F10
G1 Y1
G90
M2
""")
check(rc == 0 and len(runs) == 1 and moves(runs[0]) == ["G1 X25.4 Y0.0 Z2.54 F254.0", "G1 X25.4 Y25.4 Z2.54"],
      f"G20 and G91: the run in absolute millimetres: {moves(runs[0]) if runs else runs}")
check("  G1 F10.0" in out, "G20: the feed comes back in inches per minute after the run")

rc, out, report, runs, _ = run_filter("arcs", """G21 G90 G17
G0 X0 Y0 Z0
G1 X10 F600
G3 X10 Y10 I0 J5
G2 X10 Y10 I0 J-5 P2
G3 X0 Y0 Z-1 I-5 J-5 (a helix)
G18
G2 X5 Z-1 I2.5 K0
G17
G1 X1
M2
""")
check(rc == 0 and len(runs) == 2, f"arcs: a helix and an XZ arc end runs: {len(runs)} run(s)")
if len(runs) == 2:
    check(moves(runs[0]) == ["G1 X10.0 Y0.0 Z0.0 F600.0", "G3 X10.0 Y10.0 I0.0 J5.0", "G2 X10.0 Y10.0 I0.0 J-5.0 P2"],
          f"arcs: G2/G3 with centres relative to the start and turns: {moves(runs[0])}")
check(":6: move left to LinuxCNC's planner (helix)" in report, "arcs: the helix is LinuxCNC's, said with its line")
check(":8: move left to LinuxCNC's planner (arc outside the XY plane)" in report,
      "arcs: the XZ arc is LinuxCNC's, said with its line")

rc, out, report, runs, _ = run_filter("modes_and_words", """G21 G90
G0 X0 Y0 Z0
G1 X1 F100
#1 = 2
G1 X#1 Y[#1 * 2]
G93 G1 X3 F2
G1 X3.5 F2
G94 G1 X4 F100
M3 S1000 G1 X5
G1 X6
M2
""")
check(rc == 0 and [moves(r) for r in runs] == [["G1 X1.0 Y0.0 Z0.0 F100.0"], ["G1 X2.0 Y4.0 Z0.0 F100.0"],
                                               ["G1 X6.0 Y4.0 Z0.0 F100.0"]],
      f"a parameter set, G93, an M-code split runs; parameters and expressions are evaluated: {[moves(r) for r in runs]}")
check("inverse-time" in report, "G93: said why the move is LinuxCNC's")

rc, out, report, runs, _ = run_filter("rapids", """G21 G90
G0 X0 Y0 Z5
G1 Z0 F100
(a comment between moves)

G1 X10
G0 Z5
G53 G0 X20
G1 Z0
G0 Z5
M2
""")
check(rc == 0 and [moves(r) for r in runs] == [["G1 X0.0 Y0.0 Z0.0 F100.0", "G1 X10.0 Y0.0 Z0.0", "G1 X10.0 Y0.0 Z5.0 F60000000.0",
                                                "G1 X20.0 Y0.0 Z5.0", "G1 X20.0 Y0.0 Z0.0 F100.0", "G1 X20.0 Y0.0 Z5.0 F60000000.0"]]
      and "  G0 F100.0" in out and "(rapid from an unknown position)" in report,
      f"rapids (G53 too) join the run at the rapid rate, comments and empty lines do not end it, the first "
      f"rapid (from nowhere known) is LinuxCNC's: {[moves(r) for r in runs]}")

rc, out, report, runs, _ = run_filter("g43_and_modal_arcs", """G21 G90
G0 X0 Y0 Z10
G43 Z5 H1
G1 Z0 F100
G2 X10 Y0 I5 J0
X0 Y0 I-5 J0 M8
G0 Z10
M2
""")
check(rc == 0 and [moves(r) for r in runs][:1] == [["G1 X0.0 Y0.0 Z5.0 F60000000.0", "G1 X0.0 Y0.0 Z0.0 F100.0"]]
      and "  G43 H1\n  o<nurbs_run> call [1]" in out and "(an arc the next line continues in its mode)" in report,
      f"a G43 H line starts a run (the machine applies G43 H first); an arc the next line continues in G2 stays LinuxCNC's: {[moves(r) for r in runs]}")

rc, out, report, runs, _ = run_filter("known_axes", """G21 G90
G53 G0 Z0
G0 X10 Y10
G1 Z-1 F100
G1 X20
M2
""")
rc2, out2, report2, runs2, _ = run_filter("two_d", "G21 G90\nG0 X0 Y0\nG1 X5 F100\nG1 Y5\nM2\n")
check(rc == 0 and [moves(r) for r in runs] == [["G1 X10.0 Y10.0 Z-1.0 F100.0", "G1 X20.0 Y10.0 Z-1.0"]]
      and ":3: move left to LinuxCNC's planner (rapid from an unknown position)" in report
      and rc2 == 0 and len(runs2) == 1 and "G0 X0.0 Y0.0\n" in runs2[0] and moves(runs2[0]) == ["G1 X5.0 Y0.0 F100.0", "G1 X5.0 Y5.0"],
      f"an axis is known once a line programs it: after G53 G0 Z0, X and Y are not; a program that never "
      f"names Z runs 2-D: {[moves(r) for r in runs]} {[moves(r) for r in runs2]}")

os.makedirs(os.path.join(WORK, "toolpath_file"), exist_ok=True)
trident = os.path.join(EXAMPLES, "trident.json")
with open(trident) as f, open(os.path.join(WORK, "toolpath_file", "part.json"), "w") as g:
    g.write(f.read())
rc, out, report, runs, files = run_filter("toolpath_file", """G21 G90
G0 X0 Y0 Z5
G1 X1 F100
(NURBS_TOOLPATH, part.json)
G1 X2
G0 X0 Y0 Z5
G1 X3
M2
""")
folder = os.path.dirname(files[0]) if files else ""
copied = os.path.join(folder, "run-3.json")
check(rc == 0 and [moves(r) for r in runs] == [["G1 X1.0 Y0.0 Z5.0 F100.0"], ["G1 X3.0 Y0.0 Z5.0 F100.0"]]
      and os.path.isfile(copied) and open(copied).read() == open(trident).read()
      and os.path.isfile(os.path.join(folder, "run-3.from-file"))
      and "(NURBS_TOOLPATH, part.json)\no<nurbs_filter_3> if [#<_task>]\n  o<nurbs_run> call [3]" in out
      and ":5: move left to LinuxCNC's planner (feed from an unknown position)" in report,
      f"(NURBS_TOOLPATH, file) runs the file there; after it the position is unknown until programmed: "
      f"{[moves(r) for r in runs]}, {report.strip()}")
rc, out, report, runs, _ = run_filter("toolpath_missing", "G21\n(NURBS_TOOLPATH, nowhere.json)\nM2\n")
check(rc != 0 and "toolpath_missing.ngc:2: toolpath nowhere.json is neither beside" in report,
      f"a toolpath file that is not there: {report.strip()}")

rc, out, report, runs, _ = run_filter("unknown_start", "G21 G90\nG1 X1 Y1 Z0 F100\nG1 X2\nM2\n")
check(rc == 0 and len(runs) == 1 and moves(runs[0]) == ["G1 X2.0 Y1.0 Z0.0 F100.0"],
      f"a feed from an unknown position stays LinuxCNC's; the next one is a run: {[moves(r) for r in runs]}")

# A laser post's second pass: the beam off, a rapid to where the first pass ended (it moves
# nothing), the beam on, the pass back. The zero-length rapid is no run of its own (our planner
# refuses a run that moves nothing), and every run plans.
laser = """G21 G90
G0 X0 Y0 Z0
M3 S100
G1 X5 Y1 F600
G1 X10 Y0
M5
G0 X10 Y0
G4 P0
M3 S100
G1 X5 Y1
G1 X0 Y0
M5
M2
"""
rc, out, report, runs, files = run_filter("zero_length_rapid", laser)
preview_alike("zero_length_rapid", laser, out)
check(rc == 0 and [moves(r) for r in runs] == [["G1 X5.0 Y1.0 Z0.0 F600.0", "G1 X10.0 Y0.0 Z0.0"],
                                               ["G1 X5.0 Y1.0 Z0.0 F600.0", "G1 X0.0 Y0.0 Z0.0"]],
      f"a rapid to where the tool stands is no run: {[moves(r) for r in runs]}")
for k, f in enumerate(files):
    plan_rows(f, os.path.join(WORK, f"zero_length_rapid-{k}.csv"))

rc, out, report, runs, _ = run_filter("computed_nurbs", """G21 G90
G0 X0 Y0 Z0
F600
#1 = 5
G5.2 X10 Y#1 P1 L3
X20 Y0 P1
G5.3
M2
""")
check(rc == 0 and not any("G5.2" in r for r in runs) and "NURBS block LinuxCNC computes" in report,
      f"a NURBS block with a parameter is LinuxCNC's (its line approximation): {report.strip()}")

rc, out, report, runs, _ = run_filter("bad_word", "G21\nG0 X0 Y0 Z0\nG1 X1 F100\nG1 X2 Q3\nM2\n")
check(rc != 0 and re.search(r"bad_word\.ngc:4: Q word", report), f"an interpreter error names the program's line: {report.strip()}")

rc, out, report, runs, _ = run_filter("tool_change", """G21
T#<_tool> M6 (tool words LinuxCNC's module cannot read without a machine)
G43 H1
G0 X0 Y0 Z5
G1 Z0 F100
G1 X1
M2
""")
check(rc == 0 and "tool words of 2 line(s)" in report and [moves(r) for r in runs] == [["G1 X0.0 Y0.0 Z0.0 F100.0", "G1 X1.0 Y0.0 Z0.0"]],
      f"tool words without a machine: read as for tools of length 0, said: {report.strip()}")
check("T#<_tool> M6" in out and "G43 H1" in out, "tool words without a machine: kept in the program LinuxCNC runs")

rc, out, report, runs, _ = run_filter("offsets_under_the_tool", """G21 G90
G10 L2 P1 X1 R30
G0 X0 Y0 Z0
G1 X1 F100
G10 L2 P1 X0 R0
G1 X2
G92 X0 Y0
G1 X1
M2
""")
# Each offset change keeps the tool where it stands on the machine: its program coordinates
# move (machine (1 + cos 30, sin 30) after X1 rotated; then G54 0: program = machine; G92).
check(rc == 0 and [moves(r) for r in runs] == [["G1 X1.0 Y0.0 Z0.0 F100.0"], ["G1 X2.0 Y0.5 Z0.0 F100.0"],
                                               ["G1 X1.0 Y0.0 Z0.0 F100.0"]]
      and "G0 X1.866025403784 Y0.5 Z0.0" in runs[1] and "G0 X0.0 Y0.0 Z0.0" in runs[2],
      f"G10 L2 (with R) and G92 under the tool: runs start where the tool stands: {[r.splitlines()[3] for r in runs]}")

rc, out, report, runs, files = run_filter("path_modes", """G20
G64 P0.002
G0 X0 Y0 Z0
G1 X1 F10
G61
G1 X2
G64
G0 Z1
G1 X3
M2
""")
args = [open(f[:-4] + ".args").read().split() for f in files]
check(rc == 0 and args == [["--chord-tol", "0.0508"], ["--round-corners", "off"], []],
      f"G64 P (in inches) sets the run's chord tolerance, G61 plans its corners as programmed, G64 the INI's: {args}")

p = subprocess.run([FILTER, os.path.join(WORK, "no-such.ngc")], capture_output=True, text=True)
check(p.returncode != 0 and "no-such.ngc" in p.stderr, f"a missing program: {p.stderr.strip()}")

print(f"{len(failures)} failure(s)")
sys.exit(1 if failures else 0)
