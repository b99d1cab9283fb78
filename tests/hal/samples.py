"""What the check_*.py scripts share: reading the offline plan and the recorder's samples,
the consecutive-sample check, the length of the stretch that follows the plan, and writing the
recorded setpoints as a CSV for `nurbs-plan verify`; the options and loading every check starts
with."""
import argparse
import csv


def parse_args(*extra):
    """The options of every check (--expected, --samples, --period, --tol, --recorded-csv) plus
    `extra` as (flag, keyword arguments) pairs."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--expected", required=True, help="nurbs-plan plan --out CSV")
    ap.add_argument("--samples", required=True, help="nurbs-hal-record output")
    ap.add_argument("--period", type=float, required=True)
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--recorded-csv", required=True, help="where to write the samples as a CSV")
    for flag, kwargs in extra:
        ap.add_argument(flag, **kwargs)
    return ap.parse_args()


def load_run(a):
    """The offline plan's rows and axes, the samples, and the errors found so far (a skipped
    period)."""
    rows, axes = read_plan(a.expected)
    samples = read_samples(a.samples)
    gap = sample_gap(samples)
    return rows, axes, samples, [gap] if gap else []


def read_plan(path):
    """Rows of a `nurbs-plan plan --out` CSV and its axis columns."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    axes = [c for c in ("x", "y", "z") if rows and c in rows[0]]
    return rows, axes


def read_samples(path):
    """Samples written by nurbs-hal-record (one line per recorded period)."""
    samples = []
    with open(path) as f:
        for line in f:
            v = line.split()
            samples.append({
                "n": int(v[0]), "x": float(v[1]), "y": float(v[2]), "z": float(v[3]),
                "u": float(v[4]), "feed": float(v[5]), "curve": int(v[6]), "underruns": int(v[7]),
                "fault_code": int(v[8]), "done": v[9] == "1", "fault": v[10] == "1",
                "underrun": v[11] == "1",
                # Where the session samples it: motion time queued ahead (s).
                "buffered": float(v[12]) if len(v) > 12 else None,
            })
    return samples


def sample_gap(samples):
    """An error message if the sampler skipped a period, else None."""
    for i in range(1, len(samples)):
        if samples[i]["n"] != samples[i - 1]["n"] + 1:
            return f"sample numbers jump at {i}: {samples[i - 1]['n']} -> {samples[i]['n']}"
    return None


def planned_prefix(samples, rows, axes, tol):
    """How many leading samples equal the offline plan (to tol mm)."""
    planned = 0
    for s, r in zip(samples, rows):
        if max(abs(s[c] - float(r[c])) for c in axes) > tol:
            break
        planned += 1
    return planned


def write_recorded_csv(path, samples, axes, period):
    """The samples in the setpoint CSV format of `nurbs-plan plan` (full precision)."""
    with open(path, "w") as f:
        f.write("t,u," + ",".join(axes) + ",feed,element\n")
        for j, s in enumerate(samples):
            f.write(f"{j * period!r},{s['u']!r}," + ",".join(repr(s[c]) for c in axes)
                    + f",{s['feed']!r},{s['curve']}\n")
