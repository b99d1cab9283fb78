use super::corners::{describe, open, prepare, refuse_deviation, summary_fields, RoundCorners, Rounding};
use super::machine::{is_five_axis, MachineArgs};
use super::plot::{write_png, PlotSample, Profile};
use super::{LimitArgs, PlannerKind};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::axial::{FiniteDifferences, MAX_AXES};
use nurbs_motion::planner::corner::{Deviation, ProgramPolyline};
use nurbs_motion::planner::flf::CriticalPoint;
use nurbs_motion::planner::simulate::{run_segment, setpoints_with, Interpolation, SimState};
use nurbs_motion::planner::{FinalRecord, PathCurves, PlanOptions, PlanReport, Planner};
use nurbs_rtcore::interpolator::Sample;
use std::io::Write;
use std::path::Path;

pub struct PlanArgs<'a> {
    pub toolpath: &'a Path,
    pub limits: &'a LimitArgs,
    pub out: &'a Path,
    pub summary: Option<&'a Path>,
    pub planner: PlannerKind,
    pub stream: bool,
    pub interp: Interpolation,
    pub plot: Option<&'a Path>,
    pub round_corners: Option<RoundCorners>,
    pub machine: &'a MachineArgs,
}

/// Adds the fields of `extra` (corner rounding, machine) to a summary object.
fn with_fields(mut summary: serde_json::Value, extra: serde_json::Value) -> serde_json::Value {
    if let (Some(s), serde_json::Value::Object(e)) = (summary.as_object_mut(), extra) {
        s.extend(e);
    }
    summary
}

/// The summary keys both planners write: toolpath, planner, limits and the peaks of the first
/// `axes` axes that `check` measured, with the worst ratio to a limit.
fn summary_common(
    args: &PlanArgs,
    planner: &str,
    limits: &nurbs_motion::planner::Limits,
    check: &FiniteDifferences,
    axes: usize,
) -> serde_json::Value {
    let pk = &check.peaks;
    serde_json::json!({
        "toolpath": args.toolpath.display().to_string(),
        "planner": planner,
        "limits": {
            "feed": limits.feed, "velocity": limits.velocity, "acceleration": limits.acceleration,
            "jerk": limits.jerk, "chord_tolerance": limits.chord_tolerance, "period": limits.period,
        },
        "max_axial_velocity": &pk.vel[..axes],
        "max_axial_acceleration": &pk.acc[..axes],
        "max_axial_jerk": &pk.jerk[..axes],
        "worst_ratio_to_limit": check.worst_ratio(limits),
    })
}

/// Figure title: file, planner, limits and motion time.
fn plot_title(args: &PlanArgs, planner: &str, limits: &nurbs_motion::planner::Limits, motion_time: f64) -> String {
    let name = args.toolpath.file_name().map_or_else(
        || args.toolpath.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let list = |v: &[f64]| {
        if v.iter().all(|x| *x == v[0]) {
            format!("{}", v[0])
        } else {
            v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join("/")
        }
    };
    format!(
        "{name}, {planner}: F {} mm/s, A {} mm/s², J {} mm/s³, chord {} mm, T {} ms; motion {:.4} s",
        limits.feed,
        list(&limits.acceleration),
        list(&limits.jerk),
        limits.chord_tolerance,
        limits.period * 1e3,
        motion_time
    )
}

pub fn run(args: PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    if args.planner == PlannerKind::Reach {
        if args.interp != Interpolation::Rk2pc {
            return Err(
                "--interp is for the erwinski planner (the reach planner plans the positions themselves)".into(),
            );
        }
        args.machine
            .refuse("the reach planner plans the tool tip; joint planning on a machine is --planner vpop")?;
        return run_reach(args);
    }
    if args.planner == PlannerKind::Vpop {
        if args.interp != Interpolation::Rk2pc {
            return Err("--interp is for the erwinski planner (VPOp plans the positions themselves)".into());
        }
        return run_vpop(args);
    }
    if args.machine.given().is_some() {
        // Refused either way; read whole to say why.
        let whole = prepare(args.toolpath, args.round_corners, args.limits)?;
        args.machine.refuse_unless_five_axis(&whole.toolpath, args.toolpath)?;
        args.machine.refuse(
            "the erwinski planner plans the tool tip of a 5-axis toolpath; joint planning on a machine is --planner vpop",
        )?;
    }
    run_erwinski(&args)
}

/// What an Erwinski plan came to, for the report, the summary and the plot.
struct ErwinskiRun {
    report: PlanReport,
    out: Written,
    motion_time: f64,
    elements: usize,
    groups: Groups,
    rounding: Option<Rounding>,
    critical_points: Vec<(usize, CriticalPoint)>,
    tip: usize,
}

fn run_erwinski(args: &PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    let options = PlanOptions {
        stream: args.stream,
        ..PlanOptions::default()
    };
    // RK2-PC setpoints are written as each record comes, from a path read as it is planned (a
    // program of any length in memory that follows the look-ahead); the comparison methods and
    // the plot need the whole path and every record.
    let keep = args.plot.is_some() || args.interp != Interpolation::Rk2pc;
    let mut stream = open(args.toolpath, args.round_corners, args.limits)?;
    let mut program = stream.program()?;
    let whole = match keep {
        true => Some(prepare(args.toolpath, args.round_corners, args.limits)?),
        false => None,
    };
    let curves = match &whole {
        Some(w) => PathCurves::new(&w.toolpath),
        None => PathCurves::streamed(stream.take_elements())?,
    };
    let tip = curves.tip_dim();
    let limits = args.limits.limits(tip)?;
    let mut sink = SetpointSink::create(args.out, &AXIS_NAMES[..tip], &limits, Some(&mut program), !keep)?;
    let mut planner = Planner::with_curves(curves, &limits, &options)?;
    let mut state = SimState::start(tip, limits.period);
    let (mut records, mut critical_points, mut groups) = (Vec::new(), Vec::new(), Groups::default());
    let (mut handed_out, mut handed_out_time) = (0usize, 0.0f64);
    let mut progress = Progress::new();
    while let Some(next) = planner.next_final() {
        let f = next.map_err(|e| match args.stream {
            // A streamed plan hands records out before it ends: on the machine they would be running.
            true => {
                let plural = if handed_out == 1 { "" } else { "s" };
                format!("{e} ({handed_out} record{plural} had been handed out: {handed_out_time:.3} s of motion)")
            }
            false => e.to_string(),
        })?;
        handed_out += 1;
        handed_out_time += f.record.profile().total_time();
        groups.push(&f);
        progress.report(handed_out_time, handed_out, f.record.curve + 1, planner.curves().len());
        let found = planner.take_critical_points();
        if args.plot.is_some() {
            critical_points.extend(found);
        } else {
            groups.critical_points += found.len();
        }
        if keep {
            records.push(f.record);
        } else {
            let sink = &mut sink;
            let mut error = None;
            run_segment(planner.curves(), &limits, &mut state, f.record, &mut |s| {
                if let Err(e) = sink.push(s) {
                    error.get_or_insert(e);
                }
            });
            error.map_or(Ok(()), Err)?;
        }
    }
    groups.critical_points += planner.take_critical_points().len() + critical_points.len();
    let elements = planner.curves().len();
    // A file that fails part way: the plan ends at rest before the element that failed.
    let read_error = planner.curves().error().cloned();
    let report = planner.finish();
    if let Some(w) = &whole {
        for s in setpoints_with(&w.toolpath, &report.limits, &records, args.interp) {
            sink.push(&s)?;
        }
    }
    let out = sink.finish()?;
    let run = ErwinskiRun {
        motion_time: out.rows.saturating_sub(1) as f64 * report.limits.period,
        report,
        out,
        elements,
        groups,
        rounding: whole.as_ref().map_or_else(|| stream.rounding(), |w| w.rounding),
        critical_points,
        tip,
    };
    run.print(args);
    if let Some(e) = read_error {
        return Err(format!(
            "{e}\nthe plan ends at rest at the end of path element {} before it ({} setpoints written to {})",
            run.elements.saturating_sub(1),
            run.out.rows,
            args.out.display()
        )
        .into());
    }
    if let Some(path) = args.summary {
        run.write_summary(args, path)?;
    }
    if let (Some(path), Some(w)) = (args.plot, &whole) {
        run.write_plot(args, path, &w.toolpath)?;
    }
    Ok(refuse_deviation(
        run.out.deviation,
        run.report.limits.chord_tolerance,
        args.out,
    )?)
}

impl ErwinskiRun {
    /// The plan's figures on stderr.
    fn print(&self, args: &PlanArgs) {
        let (report, groups) = (&self.report, &self.groups);
        eprintln!(
            "planned {} segments, {} critical points: motion {:.6} s ({} setpoints), planning {:.3} ms{}",
            report.records,
            groups.critical_points,
            self.motion_time,
            self.out.rows,
            report.plan_time * 1e3,
            if args.stream {
                format!(
                    " (first segment final after {:.3} ms; {} groups, the longest {:.3} s of motion)",
                    report.first_record_time * 1e3,
                    groups.count,
                    groups.longest
                )
            } else {
                String::new()
            }
        );
        if let Some(line) = describe(self.rounding, self.out.deviation, report.limits.chord_tolerance) {
            eprintln!("{line}");
        }
        for (curve, u) in &report.stops_made {
            eprintln!(
                "the streamed plan comes to rest at curve {curve} u = {u}: back-tracking reached records already handed out"
            );
        }
    }

    /// `--summary`: the plan's figures as JSON.
    fn write_summary(&self, args: &PlanArgs, path: &Path) -> Result<(), Box<dyn std::error::Error>> {
        let (report, groups) = (&self.report, &self.groups);
        let summary = with_fields(
            summary_common(args, "erwinski", &report.limits, &self.out.check, self.tip),
            serde_json::json!({
                "motion_time_s": self.motion_time,
                "profile_time_s": report.motion_time,
                "plan_time_s": report.plan_time,
                "first_segment_time_s": report.first_record_time,
                "interpolation": format!("{:?}", args.interp).to_lowercase(),
                "streamed": args.stream,
                "segments": report.records,
                "elements": self.elements,
                "critical_points": groups.critical_points,
                "setpoints": self.out.rows,
                "groups": groups.count,
                "longest_group_s": groups.longest,
                "stops_made": report.stops_made.len(),
            }),
        );
        let summary = with_fields(summary, summary_fields(self.rounding, self.out.deviation));
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
        Ok(())
    }

    /// `--plot`: the profile as a PNG.
    fn write_plot(&self, args: &PlanArgs, path: &Path, toolpath: &Toolpath) -> Result<(), Box<dyn std::error::Error>> {
        let tip = self.tip;
        let points: Vec<PlotSample> = self
            .out
            .samples
            .iter()
            .map(|s| {
                let mut q = [0.0; MAX_AXES];
                q[..tip].copy_from_slice(&s.point[..tip]);
                PlotSample {
                    curve: s.curve,
                    u: s.u,
                    feed: s.feed,
                    q,
                }
            })
            .collect();
        let limits = &self.report.limits;
        let profile = Profile {
            toolpath,
            limits,
            axes: &AXIS_NAMES[..tip],
            rotary_from: tip,
            samples: &points,
            flf: true,
            critical_points: &self.critical_points,
            title: plot_title(args, "erwinski planner", limits, self.motion_time),
        };
        write_png(path, &profile)?;
        eprintln!("plot written to {}", path.display());
        Ok(())
    }
}

/// The names of the tool tip's axes, in order.
const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// A long plan says how far it has got, every [`PROGRESS_EVERY`].
struct Progress {
    began: std::time::Instant,
    next_report: std::time::Duration,
}

impl Progress {
    fn new() -> Self {
        Progress {
            began: std::time::Instant::now(),
            next_report: PROGRESS_EVERY,
        }
    }

    fn report(&mut self, motion: f64, records: usize, element: u32, elements_read: usize) {
        if self.began.elapsed() >= self.next_report {
            self.next_report += PROGRESS_EVERY;
            eprintln!(
                "planning: {motion:.1} s of motion in {records} records after {:.0} s, at path element {element} of {elements_read} read",
                self.began.elapsed().as_secs_f64(),
            );
        }
    }
}

/// How often a long plan reports its progress on stderr.
const PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_secs(10);

/// Groups of final records (the records between two stops, [`FinalRecord`]): how many, and
/// the longest in motion time (how long a hold may wait for a stop).
#[derive(Default)]
struct Groups {
    count: usize,
    longest: f64,
    running: f64,
    critical_points: usize,
}

impl Groups {
    fn push(&mut self, f: &FinalRecord) {
        self.running += f.record.profile().total_time();
        if !f.stop.is_empty() || f.record.is_last() {
            self.count += 1;
            self.longest = self.longest.max(self.running);
            self.running = 0.0;
        }
    }
}

/// Where setpoints go: the CSV, the finite-difference check, the distance to the programmed
/// polyline, and (when asked) a copy of every sample.
struct SetpointSink<'a> {
    out: std::io::BufWriter<std::fs::File>,
    limits: &'a nurbs_motion::planner::Limits,
    axes: usize,
    check: FiniteDifferences,
    program: Option<(&'a mut ProgramPolyline, Deviation)>,
    rows: usize,
    samples: Option<Vec<Sample>>,
}

/// What a [`SetpointSink`] took.
struct Written {
    rows: usize,
    check: FiniteDifferences,
    deviation: Option<f64>,
    samples: Vec<Sample>,
}

impl<'a> SetpointSink<'a> {
    fn create(
        path: &Path,
        names: &[&str],
        limits: &'a nurbs_motion::planner::Limits,
        program: Option<&'a mut ProgramPolyline>,
        streaming: bool,
    ) -> Result<Self, Box<dyn std::error::Error>> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(out, "t,u,{},feed,element", names.join(","))?;
        Ok(SetpointSink {
            out,
            limits,
            axes: names.len(),
            check: FiniteDifferences::new(names.len(), limits.period),
            program: program.map(|p| (p, Deviation::default())),
            rows: 0,
            samples: (!streaming).then(Vec::new),
        })
    }

    fn push(&mut self, s: &Sample) -> std::io::Result<()> {
        let q = &s.point[..self.axes];
        // `{:?}` prints the shortest string that parses back to the same f64.
        write!(self.out, "{:?},{:?}", self.rows as f64 * self.limits.period, s.u)?;
        for c in q {
            write!(self.out, ",{c:?}")?;
        }
        writeln!(self.out, ",{:?},{}", s.feed, s.curve)?;
        self.check.push(q, self.limits);
        if let Some((polyline, d)) = &mut self.program {
            d.push(polyline, q);
        }
        if let Some(all) = &mut self.samples {
            all.push(*s);
        }
        self.rows += 1;
        Ok(())
    }

    fn finish(mut self) -> std::io::Result<Written> {
        self.check.finish(self.limits);
        self.out.flush()?;
        Ok(Written {
            rows: self.rows,
            check: self.check,
            deviation: self.program.and_then(|(p, d)| d.finish(p)),
            samples: self.samples.unwrap_or_default(),
        })
    }
}

/// `--planner vpop`: the tool-tip path planned by constraint intersection at the servo period
/// (same CSV columns and summary keys as the default planner). The setpoints are written as
/// VPOp hands them out (final: no back-tracking reaches them), and a tool-tip path is read as
/// it is planned (a program of any length in memory that follows the look-ahead; the plan is
/// the same as from the whole path, so `--stream` changes nothing here). A 5-axis path (its C
/// angle is unwrapped along the whole path), machine flags and the plot read it whole.
fn run_vpop(args: PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    use nurbs_motion::planner::vpop::{run_streamed, JointPath, SearchOptions};
    let mut stream = open(args.toolpath, args.round_corners, args.limits)?;
    let program = stream.program()?;
    let streamed = match args.plot.is_none() && args.machine.given().is_none() {
        true => Some(JointPath::streamed(stream.take_elements())?).filter(|p| !p.has_top_curve()),
        false => None,
    };
    let (path, five, whole) = match streamed {
        Some(path) => (path, false, None),
        None => {
            let whole = prepare(args.toolpath, args.round_corners, args.limits)?;
            let toolpath = &whole.toolpath;
            args.machine.refuse_unless_five_axis(toolpath, args.toolpath)?;
            // A top curve on every element: 5-axis on the machine (XYZAC unless --machine says otherwise).
            let (path, five) = match is_five_axis(toolpath) {
                true => (JointPath::five_axis(toolpath, args.machine.kinematics())?, true),
                false => (JointPath::tip(toolpath), false),
            };
            (path, five, Some(whole))
        }
    };
    let tip = path.tip_dim();
    // Limits in joint order.
    let limits = if five {
        args.limits.limits(5)?
    } else {
        args.limits.limits(tip)?
    };
    let axes = path.axes();
    let limits = limits.for_axes(axes)?;
    if limits.hold_reserve > 0.0 {
        eprintln!("{}", nurbs_motion::planner::vpop::HOLD_RESERVE_IGNORED);
    }
    let columns = if five {
        format!(
            "{},tip_x,tip_y,tip_z",
            args.machine.kinematics().joint_names().join(",")
        )
    } else {
        ["x", "y", "z"][..tip].join(",")
    };
    let mut writer = PointWriter::create(args.out, &columns, program, &limits, (tip, five), args.plot.is_some())?;
    // A failed write ends the plan; its error is the one to report.
    let planned = run_streamed(&path, &limits, SearchOptions::default(), &mut |p| writer.emit(p));
    writer.write_error()?;
    let plan = planned?;
    let (check, deviation, points, rows) = writer.finish()?;
    eprintln!(
        "VPOp: motion {:.6} s ({} setpoints), planning {:.3} ms (first setpoints final after {:.3} ms), {} dead ends, {} deceleration checks",
        plan.motion_time,
        plan.points,
        plan.plan_time * 1e3,
        plan.first_points_time * 1e3,
        plan.stats.dead_ends,
        plan.stats.brakes
    );
    let rounding = whole.as_ref().map_or_else(|| stream.rounding(), |w| w.rounding);
    let (elements, most_elements_held) = (path.end() as usize, path.most_elements_held());
    if let Some(line) = describe(rounding, deviation, plan.limits.chord_tolerance) {
        eprintln!("{line}");
    }
    if let Some(e) = path.read_error() {
        return Err(format!(
            "{e}\nthe plan ends at rest at the end of the path element before it ({rows} setpoints written to {})",
            args.out.display()
        )
        .into());
    }
    if let Some(path) = args.summary {
        let summary = with_fields(
            summary_common(&args, "vpop", &plan.limits, &check, axes),
            serde_json::json!({
                "motion_time_s": plan.motion_time,
                "plan_time_s": plan.plan_time,
                "setpoints": plan.points,
                "first_points_time_s": plan.first_points_time,
                "dead_ends": plan.stats.dead_ends,
                "deceleration_checks": plan.stats.brakes,
                "most_points_held": plan.stats.most_held,
                "elements": elements,
                "most_elements_held": most_elements_held,
                "axes": if five { args.machine.kinematics().joint_names().join(",") } else { "tool tip".into() },
            }),
        );
        let mut summary = with_fields(summary, summary_fields(rounding, deviation));
        if five {
            summary = with_fields(summary, args.machine.summary_fields());
        }
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
    }
    if let (Some(path), Some(whole)) = (args.plot, &whole) {
        let joints = args.machine.kinematics().joint_names();
        let names: &[&str] = if five { &joints } else { &AXIS_NAMES[..tip] };
        let profile = Profile {
            toolpath: &whole.toolpath,
            limits: &plan.limits,
            axes: names,
            rotary_from: if five { 3 } else { axes },
            samples: &points,
            // The FLF is a tool-tip construction: on the 5-axis machine the limits are joint limits.
            flf: !five,
            critical_points: &[],
            title: plot_title(&args, "VPOp planner", &plan.limits, plan.motion_time),
        };
        write_png(path, &profile)?;
        eprintln!("plot written to {}", path.display());
    }
    Ok(refuse_deviation(deviation, plan.limits.chord_tolerance, args.out)?)
}

/// `--planner reach`: the tool-tip path planned by third-order reachability over arc-length
/// stations (same CSV columns and summary keys as the other planners). The path is read as it
/// is planned; every setpoint is written once its stretch (rest to rest) passed the
/// finite-difference check.
fn run_reach(args: PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    use nurbs_motion::planner::reach::{run, window::WindowOptions, Begin, Planned, ReachOptions};
    let mut stream = open(args.toolpath, args.round_corners, args.limits)?;
    let program = stream.program()?;
    let mut curves = PathCurves::streamed(stream.take_elements())?;
    let tip = curves.tip_dim();
    let limits = args.limits.limits(tip)?.for_axes(tip)?;
    let columns = ["x", "y", "z"][..tip].join(",");
    let mut writer = PointWriter::create(args.out, &columns, program, &limits, (tip, false), args.plot.is_some())?;
    let options = ReachOptions {
        window: args.stream.then(WindowOptions::default),
        ..ReachOptions::default()
    };
    let planned = run(&mut curves, &limits, &options, &Begin::Rest(None), &mut |p| match p {
        Planned::Point(p) => writer.emit(p),
        Planned::Stop(..) => Ok(()),
    });
    writer.write_error()?;
    let (limits, stats, plan_time) = planned?;
    let (check, deviation, points, rows) = writer.finish()?;
    let motion_time = rows.saturating_sub(1) as f64 * limits.period;
    eprintln!(
        "reach: motion {motion_time:.6} s ({rows} setpoints), planning {:.3} ms (first setpoints after {:.3} ms), {} stretches, {} stations, {} passes, {} re-plans{}",
        plan_time * 1e3,
        stats.first_points_time * 1e3,
        stats.stretches,
        stats.stations,
        stats.passes,
        stats.repairs,
        if stats.windows > 0 {
            format!(", {} windows ({} restarts from rest)", stats.windows, stats.restarts)
        } else {
            String::new()
        }
    );
    let rounding = stream.rounding();
    if let Some(line) = describe(rounding, deviation, limits.chord_tolerance) {
        eprintln!("{line}");
    }
    if let Some(path) = args.summary {
        let summary = with_fields(
            summary_common(&args, "reach", &limits, &check, tip),
            serde_json::json!({
                "motion_time_s": motion_time,
                "plan_time_s": plan_time,
                "setpoints": rows,
                "first_points_time_s": stats.first_points_time,
                "stretches": stats.stretches,
                "stations": stats.stations,
                "passes": stats.passes,
                "replans": stats.repairs,
                "elements": curves.len(),
                "windows": stats.windows,
                "window_restarts": stats.restarts,
                "axes": "tool tip",
            }),
        );
        let summary = with_fields(summary, summary_fields(rounding, deviation));
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
    }
    if let Some(path) = args.plot {
        let whole = prepare(args.toolpath, args.round_corners, args.limits)?;
        let profile = Profile {
            toolpath: &whole.toolpath,
            limits: &limits,
            axes: &AXIS_NAMES[..tip],
            rotary_from: tip,
            samples: &points,
            flf: true,
            critical_points: &[],
            title: plot_title(&args, "reachability planner", &limits, motion_time),
        };
        write_png(path, &profile)?;
        eprintln!("plot written to {}", path.display());
    }
    Ok(refuse_deviation(deviation, limits.chord_tolerance, args.out)?)
}

/// The setpoints of a VPOp or reachability plan as the planner hands them out: the CSV, their
/// finite differences, their distance to the programmed polyline and, for `--plot`, the
/// samples.
struct PointWriter<'a> {
    out: std::io::BufWriter<std::fs::File>,
    path: &'a Path,
    program: ProgramPolyline,
    limits: nurbs_motion::planner::Limits,
    check: FiniteDifferences,
    deviation: Deviation,
    prev: Option<[f64; 3]>,
    plot: Option<Vec<PlotSample>>,
    rows: usize,
    /// Tool-tip coordinates, and whether the joints of a 5-axis machine come first.
    tip: usize,
    five: bool,
    error: Option<String>,
}

impl<'a> PointWriter<'a> {
    /// The CSV at `path` with position columns `columns` between `t,u` and `feed,element`.
    fn create(
        path: &'a Path,
        columns: &str,
        program: ProgramPolyline,
        limits: &nurbs_motion::planner::Limits,
        (tip, five): (usize, bool),
        plot: bool,
    ) -> std::io::Result<Self> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(out, "t,u,{columns},feed,element")?;
        Ok(PointWriter {
            out,
            path,
            program,
            limits: limits.clone(),
            check: FiniteDifferences::new(limits.velocity.len(), limits.period),
            deviation: Deviation::default(),
            prev: None,
            plot: plot.then(Vec::new),
            rows: 0,
            tip,
            five,
            error: None,
        })
    }

    fn push(&mut self, p: &nurbs_motion::planner::vpop::PathPoint) -> std::io::Result<()> {
        use nurbs_motion::planner::vpop::constraints::tip_distance;
        let (tip, axes, period) = (self.tip, self.limits.velocity.len(), self.limits.period);
        let feed = self.prev.map_or(0.0, |a| tip_distance(&p.tip, &a, tip) / period);
        if let Some(samples) = &mut self.plot {
            let mut q = [0.0; MAX_AXES];
            q[..axes].copy_from_slice(&p.q[..axes]);
            samples.push(PlotSample {
                curve: p.element,
                u: p.u,
                feed,
                q,
            });
        }
        write!(self.out, "{:?},{:?}", self.rows as f64 * period, p.u)?;
        // A 5-axis machine's joints, then the tool tip.
        let (joints, tip_columns): (&[f64], &[f64]) = if self.five {
            (&p.q[..5], &p.tip)
        } else {
            (&[], &p.tip[..tip])
        };
        for c in joints.iter().chain(tip_columns) {
            write!(self.out, ",{c:?}")?;
        }
        writeln!(self.out, ",{feed:?},{}", p.element)?;
        self.check.push(&p.q[..axes], &self.limits);
        self.deviation.push(&mut self.program, &p.tip[..tip]);
        self.prev = Some(p.tip);
        self.rows += 1;
        Ok(())
    }

    /// [`Self::push`] for a planner's callback: a failed write ends the plan, and is kept as
    /// the error to report ([`Self::write_error`]).
    fn emit(&mut self, p: &nurbs_motion::planner::vpop::PathPoint) -> Result<(), String> {
        self.push(p).map_err(|e| {
            self.error = Some(format!("writing {}: {e}", self.path.display()));
            "the setpoints could not be written".to_string()
        })
    }

    fn write_error(&mut self) -> Result<(), String> {
        self.error.take().map_or(Ok(()), Err)
    }

    /// The finite differences, the largest distance to the program, the plot samples and the
    /// rows written.
    fn finish(mut self) -> std::io::Result<(FiniteDifferences, Option<f64>, Vec<PlotSample>, usize)> {
        self.check.finish(&self.limits);
        self.out.flush()?;
        let deviation = self.deviation.finish(&self.program);
        Ok((self.check, deviation, self.plot.unwrap_or_default(), self.rows))
    }
}
