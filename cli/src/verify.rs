use super::corners::{describe, open, prepare, Prepared, RoundCorners};
use super::machine::{is_five_axis, MachineArgs};
use super::LimitArgs;
use nurbs_motion::planner::corner::Deviation;
use nurbs_motion::planner::corner::ProgramPolyline;
use nurbs_motion::planner::verify::{verify, Row, Verifier};
use nurbs_motion::planner::PathCurves;
use std::path::Path;

/// The rows of a setpoint CSV written by `plan` (columns t,u,x,y[,z] then optional extras; an
/// `element` column selects the path element, 0 otherwise), read one line at a time.
pub struct RowReader {
    path: std::path::PathBuf,
    lines: std::io::Lines<std::io::BufReader<std::fs::File>>,
    line: usize,
    t: usize,
    u: usize,
    axes: Vec<usize>,
    element: Option<usize>,
}

impl RowReader {
    pub fn open(path: &Path, tip: usize) -> Result<Self, String> {
        use std::io::BufRead;
        let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut lines = std::io::BufReader::new(file).lines();
        let header: Vec<String> = lines
            .next()
            .ok_or_else(|| format!("{}: empty file", path.display()))?
            .map_err(|e| format!("{}: {e}", path.display()))?
            .split(',')
            .map(|h| h.trim().to_owned())
            .collect();
        let col = |name: &str| header.iter().position(|h| h == name);
        let (Some(t), Some(u)) = (col("t"), col("u")) else {
            return Err(format!("{}: header must start with t,u,x,y", path.display()));
        };
        let axes: Vec<usize> = ["x", "y", "z"][..tip]
            .iter()
            .map(|n| col(n).ok_or_else(|| format!("{}: no column {n}", path.display())))
            .collect::<Result<_, _>>()?;
        Ok(RowReader {
            path: path.to_owned(),
            lines,
            line: 1,
            t,
            u,
            axes,
            element: col("element"),
        })
    }
}

impl Iterator for RowReader {
    type Item = Result<Row, String>;
    fn next(&mut self) -> Option<Self::Item> {
        loop {
            self.line += 1;
            let line = match self.lines.next()? {
                Ok(line) => line,
                Err(e) => return Some(Err(format!("{}: {e}", self.path.display()))),
            };
            if line.trim().is_empty() {
                continue;
            }
            let f: Vec<&str> = line.split(',').collect();
            let num = |c: usize| -> Result<f64, String> {
                f.get(c)
                    .and_then(|v| v.trim().parse::<f64>().ok())
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        format!(
                            "{}:{}: column {} is not a number",
                            self.path.display(),
                            self.line,
                            c + 1
                        )
                    })
            };
            let row = (|| {
                Ok(Row {
                    t: num(self.t)?,
                    u: num(self.u)?,
                    curve: match self.element {
                        Some(c) => num(c)? as usize,
                        None => 0,
                    },
                    q: self.axes.iter().map(|&c| num(c)).collect::<Result<_, String>>()?,
                })
            })();
            return Some(row);
        }
    }
}

/// Every row of a setpoint CSV ([`RowReader`]).
pub fn read_rows(path: &Path, tip: usize) -> Result<Vec<Row>, String> {
    RowReader::open(path, tip)?.collect()
}

/// Columns `names` of a CSV with a header, as numbers.
fn read_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<f64>>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').map(str::trim).collect();
    let cols: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .ok_or_else(|| format!("{}: no column {n}", path.display()))
        })
        .collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for (i, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        out.push(
            cols.iter()
                .map(|&c| {
                    f.get(c)
                        .and_then(|v| v.trim().parse::<f64>().ok())
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| format!("{}:{}: column {} is not a number", path.display(), i + 2, c + 1))
                })
                .collect::<Result<Vec<f64>, String>>()?,
        );
    }
    Ok(out)
}

/// 5-axis setpoints (`--planner vpop` on a two-curve toolpath): joint limits in joint order
/// by finite differences; the tool tip columns against the curve (distance, chord error, feed,
/// end points) and against the forward kinematics of the joints on `machine` (tool tip and
/// tool axis).
fn run_five_axis(
    setpoints: &Path,
    prepared: &Prepared,
    mut program: ProgramPolyline,
    limits: &LimitArgs,
    machine: nurbs_motion::kinematics::TableTilting,
) -> Result<bool, Box<dyn std::error::Error>> {
    let names = machine.joint_names();
    use nurbs_motion::planner::axial::FiniteDifferences;
    use nurbs_motion::planner::verify::SLACK;
    use nurbs_rtcore::interpolator::CurveSet;
    let toolpath = &prepared.toolpath;
    let joint_limits = limits.limits(5)?;
    let joints = read_columns(setpoints, &names)?;
    let tips = read_columns(setpoints, &["tip_x", "tip_y", "tip_z"])?;
    let base = read_rows(setpoints, 0)?;
    let mut curves = PathCurves::new(toolpath);
    let mut fd = FiniteDifferences::new(5, joint_limits.period);
    let (mut fk_error, mut axis_error): (f64, f64) = (0.0, 0.0);
    for ((q, t), row) in joints.iter().zip(&tips).zip(&base) {
        fd.push(q, &joint_limits);
        let (tip, axis) = machine.forward(q);
        for i in 0..3 {
            fk_error = fk_error.max((tip[i] - t[i]).abs());
        }
        // The orientation too: the tool axis of the joints against the programmed one (top
        // minus tip curve); a missing element is reported by the tip check below.
        if let Some(curve) = curves.curve(row.curve) {
            let p = curve.point(row.u);
            let d = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            for i in 0..3 {
                axis_error = axis_error.max((axis[i] - d[i] / n).abs());
            }
        }
    }
    fd.finish(&joint_limits);
    let mut violations = Vec::new();
    for i in 0..5 {
        for (what, peak, limit) in [
            ("velocity", fd.peaks.vel[i], joint_limits.velocity[i]),
            ("acceleration", fd.peaks.acc[i], joint_limits.acceleration[i]),
            ("jerk", fd.peaks.jerk[i], joint_limits.jerk[i]),
        ] {
            if peak > limit * (1.0 + SLACK) {
                violations.push(format!("axis {}: {what} {peak:.6} exceeds limit {limit}", names[i]));
            }
        }
    }
    if fk_error > 1e-6 {
        violations.push(format!(
            "tool tip columns are {fk_error:.3e} mm off the joints' tool tip (the same --machine and geometry flags as plan?)"
        ));
    }
    if axis_error > 1e-6 {
        violations.push(format!(
            "the joints' tool axis is {axis_error:.3e} off the programmed tool axis (same --machine as plan?)"
        ));
    }
    let tip_limits = nurbs_motion::planner::Limits {
        velocity: vec![f64::MAX; 3],
        acceleration: vec![f64::MAX; 3],
        jerk: vec![f64::MAX; 3],
        ..joint_limits.clone()
    };
    let rows: Vec<Row> = base
        .iter()
        .zip(&tips)
        .map(|(r, t)| Row {
            q: t.clone(),
            ..r.clone()
        })
        .collect();
    let report = verify(&mut curves, &tip_limits, &rows);
    violations.extend(report.violations);
    let deviation = check_program_deviation(
        &mut program,
        tips.iter().map(Vec::as_slice),
        joint_limits.chord_tolerance,
        &mut violations,
    );
    println!(
        "{} setpoints ({:.6} s), joints {}: max |v| {:?}, |a| {:?}, |jerk| {:?}; tool tip: max feed {:.6}; chord error {:.3e} mm; off-curve {:.3e} mm",
        report.rows,
        report.rows.saturating_sub(1) as f64 * joint_limits.period,
        names.join(" "),
        &fd.peaks.vel[..5],
        &fd.peaks.acc[..5],
        &fd.peaks.jerk[..5],
        report.max_feed,
        report.max_chord_error,
        report.max_distance_to_curve,
    );
    if let Some(line) = describe(prepared.rounding, deviation, joint_limits.chord_tolerance) {
        println!("{line}");
    }
    print_programmed_feed(report.max_programmed_feed_ratio);
    for v in &violations {
        println!("VIOLATION: {v}");
    }
    if violations.is_empty() {
        println!("OK: no violation");
    }
    Ok(violations.is_empty())
}

/// Largest distance of the tool tips to the programmed polyline (`None` when the program is
/// not one); a violation when it exceeds --chord-tol.
fn check_program_deviation<'a>(
    program: &mut ProgramPolyline,
    tips: impl IntoIterator<Item = &'a [f64]>,
    tolerance: f64,
    violations: &mut Vec<String>,
) -> Option<f64> {
    let deviation = program.max_distance(tips);
    report_deviation(deviation, tolerance, violations);
    deviation
}

/// A violation when the largest distance to the programmed polyline exceeds --chord-tol.
fn report_deviation(deviation: Option<f64>, tolerance: f64, violations: &mut Vec<String>) {
    if let Some(dev) = crate::corners::deviation_over(deviation, tolerance) {
        violations.push(format!(
            "a setpoint is {dev:.6} mm from the programmed polyline, more than --chord-tol {tolerance}"
        ));
    }
}

/// One line on the programmed feeds, when the toolpath has them.
fn print_programmed_feed(ratio: f64) {
    if ratio > 0.0 {
        println!("programmed feed (per element): feed up to {ratio:.6} of it");
    }
}

/// Whether the CSV's header has every column of `names`.
fn has_columns(path: &Path, names: &[&str]) -> Result<bool, String> {
    use std::io::BufRead;
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut header = String::new();
    std::io::BufReader::new(file)
        .read_line(&mut header)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let columns: Vec<&str> = header.trim().split(',').map(str::trim).collect();
    Ok(names.iter().all(|n| columns.contains(n)))
}

pub fn run(
    setpoints: &Path,
    toolpath: &Path,
    limits: &LimitArgs,
    round_corners: Option<RoundCorners>,
    machine: &MachineArgs,
) -> Result<bool, Box<dyn std::error::Error>> {
    let file = toolpath;
    if has_columns(setpoints, &["c", "tip_x"])? {
        let prepared = prepare(toolpath, round_corners, limits)?;
        machine.refuse_unless_five_axis(&prepared.toolpath, file)?;
        if !is_five_axis(&prepared.toolpath) {
            return Err(format!(
                "{}: joint setpoints (x,y,z,a|b,c) need a 5-axis toolpath, but {} has no top curve on every element",
                setpoints.display(),
                file.display()
            )
            .into());
        }
        let program = open(toolpath, round_corners, limits)?.program()?;
        return run_five_axis(setpoints, &prepared, program, limits, machine.kinematics());
    }
    machine.refuse(&format!(
        "{} holds tool-tip setpoints (no c, tip_x columns): no machine kinematics to check",
        setpoints.display()
    ))?;
    // A row at a time, the path read as the rows reach it: a setpoint file and a program of
    // any length in constant memory.
    let mut stream = open(toolpath, round_corners, limits)?;
    let mut program = stream.program()?;
    let mut curves = PathCurves::streamed(stream.take_elements())?;
    let tip = curves.tip_dim();
    let limits = limits.limits(tip)?;
    let mut verifier = Verifier::new(&mut curves, &limits);
    let mut deviation = Deviation::default();
    for row in RowReader::open(setpoints, tip)? {
        let row = row?;
        verifier.push(&row);
        deviation.push(&mut program, &row.q[..tip]);
    }
    let mut report = verifier.finish();
    if let Some(e) = curves.error() {
        report
            .violations
            .push(format!("the toolpath could not be read to its end: {e}"));
    }
    let deviation = deviation.finish(&program);
    report_deviation(deviation, limits.chord_tolerance, &mut report.violations);
    println!(
        "{} setpoints ({:.6} s): max |v| {:?}, |a| {:?}, |jerk| {:?}; max feed {:.6}; chord error {:.3e} mm; off-curve {:.3e} mm",
        report.rows,
        report.rows.saturating_sub(1) as f64 * limits.period,
        &report.peaks.vel[..tip],
        &report.peaks.acc[..tip],
        &report.peaks.jerk[..tip],
        report.max_feed,
        report.max_chord_error,
        report.max_distance_to_curve,
    );
    if let Some(line) = describe(stream.rounding(), deviation, limits.chord_tolerance) {
        println!("{line}");
    }
    print_programmed_feed(report.max_programmed_feed_ratio);
    for v in &report.violations {
        println!("VIOLATION: {v}");
    }
    if report.violations.is_empty() {
        println!("OK: no violation");
    }
    Ok(report.violations.is_empty())
}
