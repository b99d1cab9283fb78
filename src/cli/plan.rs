use super::corners::{prepare, RoundCorners};
use super::machine::{is_five_axis, MachineArgs};
use super::plot::{write_png, PlotSample, Profile};
use super::{LimitArgs, PlannerKind};
use crate::planner::axial::{FiniteDifferences, MAX_AXES};
use crate::planner::simulate::{setpoints_with, Interpolation};
use crate::planner::{plan, PlanOptions};
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
    pub round_corners: RoundCorners,
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
    limits: &crate::planner::Limits,
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
fn plot_title(args: &PlanArgs, planner: &str, limits: &crate::planner::Limits, motion_time: f64) -> String {
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
    if args.planner == PlannerKind::Vpop {
        if args.stream {
            return Err("--stream is for the erwinski planner (VPOp plans the whole path)".into());
        }
        if args.interp != Interpolation::Rk2pc {
            return Err("--interp is for the erwinski planner (VPOp plans the positions themselves)".into());
        }
        return run_vpop(args);
    }
    let prepared = prepare(args.toolpath, args.round_corners, args.limits.chord_tol)?;
    let toolpath = &prepared.toolpath;
    args.machine.refuse_unless_five_axis(toolpath, args.toolpath)?;
    args.machine.refuse(
        "the erwinski planner plans the tool tip of a 5-axis toolpath; joint planning on a machine is --planner vpop",
    )?;
    let limits = args.limits.limits(toolpath.tip_dim())?;
    let options = PlanOptions {
        stream: args.stream,
        ..PlanOptions::default()
    };
    // A streamed plan hands records out before it ends: on the machine they would be running.
    let (mut handed_out, mut handed_out_time) = (0usize, 0.0f64);
    let plan = plan(toolpath, &limits, &options, &mut |r| {
        handed_out += 1;
        handed_out_time += r.profile().total_time();
    })
    .map_err(|e| match args.stream {
        true => {
            let plural = if handed_out == 1 { "" } else { "s" };
            format!("{e} ({handed_out} record{plural} had been handed out: {handed_out_time:.3} s of motion)")
        }
        false => e.to_string(),
    })?;
    let samples = setpoints_with(toolpath, &plan.limits, &plan.records, args.interp);
    let tip = toolpath.tip_dim();
    let names = ["x", "y", "z"];
    let mut out = std::io::BufWriter::new(std::fs::File::create(args.out)?);
    writeln!(out, "t,u,{},feed,element", names[..tip].join(","))?;
    let mut check = FiniteDifferences::new(tip, plan.limits.period);
    for (j, s) in samples.iter().enumerate() {
        // `{:?}` prints the shortest string that parses back to the same f64.
        write!(out, "{:?},{:?}", j as f64 * plan.limits.period, s.u)?;
        for c in &s.point[..tip] {
            write!(out, ",{c:?}")?;
        }
        writeln!(out, ",{:?},{}", s.feed, s.curve)?;
        check.push(&s.point[..tip], &plan.limits);
    }
    check.finish(&plan.limits);
    out.flush()?;
    let motion_time = (samples.len().saturating_sub(1)) as f64 * plan.limits.period;
    eprintln!(
        "planned {} segments, {} critical points: motion {:.6} s ({} setpoints), planning {:.3} ms{}",
        plan.records.len(),
        plan.critical_points.len(),
        motion_time,
        samples.len(),
        plan.plan_time * 1e3,
        if args.stream {
            format!(" (first segment final after {:.3} ms)", plan.first_record_time * 1e3)
        } else {
            String::new()
        }
    );
    let deviation = prepared.deviation_from_program(samples.iter().map(|s| &s.point[..tip]));
    if let Some(line) = prepared.describe(deviation, plan.limits.chord_tolerance) {
        eprintln!("{line}");
    }
    if let Some(path) = args.summary {
        let summary = with_fields(
            summary_common(&args, "erwinski", &plan.limits, &check, tip),
            serde_json::json!({
                "motion_time_s": motion_time,
                "profile_time_s": plan.motion_time,
                "plan_time_s": plan.plan_time,
                "first_segment_time_s": plan.first_record_time,
                "interpolation": format!("{:?}", args.interp).to_lowercase(),
                "streamed": args.stream,
                "segments": plan.records.len(),
                "critical_points": plan.critical_points.len(),
                "setpoints": samples.len(),
            }),
        );
        let summary = with_fields(summary, prepared.summary_fields(deviation));
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
    }
    if let Some(path) = args.plot {
        let points: Vec<PlotSample> = samples
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
        let profile = Profile {
            toolpath,
            limits: &plan.limits,
            axes: &names[..tip],
            rotary_from: tip,
            samples: &points,
            flf: true,
            critical_points: &plan.critical_points,
            title: plot_title(&args, "erwinski planner", &plan.limits, motion_time),
        };
        write_png(path, &profile)?;
        eprintln!("plot written to {}", path.display());
    }
    Ok(())
}

/// `--planner vpop`: the tool-tip path planned by constraint intersection at the servo period
/// (same CSV columns and summary keys as the default planner).
fn run_vpop(args: PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    use crate::planner::vpop::{plan_five_axis, plan_tip, SearchOptions};
    let prepared = prepare(args.toolpath, args.round_corners, args.limits.chord_tol)?;
    let toolpath = &prepared.toolpath;
    let tip = toolpath.tip_dim();
    args.machine.refuse_unless_five_axis(toolpath, args.toolpath)?;
    // A top curve on every element: 5-axis on the machine (XYZAC unless --machine says otherwise), limits in joint order.
    let five = is_five_axis(toolpath);
    let plan = if five {
        let limits = args.limits.limits(5)?;
        plan_five_axis(toolpath, args.machine.kinematics(), &limits, SearchOptions::default())?
    } else {
        plan_tip(toolpath, &args.limits.limits(tip)?, SearchOptions::default())?
    };
    let axes = plan.axes;
    let mut out = std::io::BufWriter::new(std::fs::File::create(args.out)?);
    if five {
        let joints = args.machine.kinematics().joint_names().join(",");
        writeln!(out, "t,u,{joints},tip_x,tip_y,tip_z,feed,element")?;
    } else {
        writeln!(out, "t,u,{},feed,element", ["x", "y", "z"][..tip].join(","))?;
    }
    let mut check = FiniteDifferences::new(axes, plan.limits.period);
    let mut prev: Option<[f64; 3]> = None;
    let mut points = Vec::new();
    for (j, p) in plan.points.iter().enumerate() {
        let feed = prev.map_or(0.0, |a| {
            crate::planner::vpop::constraints::tip_distance(&p.tip, &a, tip) / plan.limits.period
        });
        if args.plot.is_some() {
            let mut q = [0.0; MAX_AXES];
            q[..axes].copy_from_slice(&p.q[..axes]);
            points.push(PlotSample {
                curve: p.element,
                u: p.u,
                feed,
                q,
            });
        }
        write!(out, "{:?},{:?}", j as f64 * plan.limits.period, p.u)?;
        if five {
            for c in p.q[..5].iter().chain(&p.tip) {
                write!(out, ",{c:?}")?;
            }
        } else {
            for c in &p.tip[..tip] {
                write!(out, ",{c:?}")?;
            }
        }
        writeln!(out, ",{feed:?},{}", p.element)?;
        check.push(&p.q[..axes], &plan.limits);
        prev = Some(p.tip);
    }
    check.finish(&plan.limits);
    out.flush()?;
    eprintln!(
        "VPOp: motion {:.6} s ({} setpoints), planning {:.3} ms, {} dead ends, {} deceleration checks",
        plan.motion_time,
        plan.points.len(),
        plan.plan_time * 1e3,
        plan.stats.dead_ends,
        plan.stats.brakes
    );
    let deviation = prepared.deviation_from_program(plan.points.iter().map(|p| &p.tip[..tip]));
    if let Some(line) = prepared.describe(deviation, plan.limits.chord_tolerance) {
        eprintln!("{line}");
    }
    if let Some(path) = args.summary {
        let summary = with_fields(
            summary_common(&args, "vpop", &plan.limits, &check, axes),
            serde_json::json!({
                "motion_time_s": plan.motion_time,
                "plan_time_s": plan.plan_time,
                "setpoints": plan.points.len(),
                "dead_ends": plan.stats.dead_ends,
                "deceleration_checks": plan.stats.brakes,
                "axes": if five { args.machine.kinematics().joint_names().join(",") } else { "tool tip".into() },
            }),
        );
        let mut summary = with_fields(summary, prepared.summary_fields(deviation));
        if five {
            summary = with_fields(summary, args.machine.summary_fields());
        }
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
    }
    if let Some(path) = args.plot {
        let joints = args.machine.kinematics().joint_names();
        let names: &[&str] = if five { &joints } else { &["x", "y", "z"][..tip] };
        let profile = Profile {
            toolpath,
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
    Ok(())
}
