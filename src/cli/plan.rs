use super::{LimitArgs, PlannerKind};
use crate::planner::axial::FiniteDifferences;
use crate::planner::simulate::setpoints;
use crate::planner::{plan, PathCurves, PlanOptions};
use crate::readers::read_toolpath;
use std::io::Write;
use std::path::Path;

pub struct PlanArgs<'a> {
    pub toolpath: &'a Path,
    pub limits: &'a LimitArgs,
    pub out: &'a Path,
    pub summary: Option<&'a Path>,
    pub planner: PlannerKind,
}

pub fn run(args: PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    if args.planner == PlannerKind::Vpop {
        return run_vpop(args);
    }
    let toolpath = read_toolpath(args.toolpath)?;
    let limits = args.limits.limits(toolpath.tip_dim())?;
    let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {})?;
    let curves = PathCurves::new(&toolpath);
    let samples = setpoints(&curves, &plan.limits, &plan.records);
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
        "planned {} segments, {} critical points: motion {:.6} s ({} setpoints), planning {:.3} ms",
        plan.records.len(),
        plan.critical_points.len(),
        motion_time,
        samples.len(),
        plan.plan_time * 1e3
    );
    if let Some(path) = args.summary {
        let pk = &check.peaks;
        let summary = serde_json::json!({
            "toolpath": args.toolpath.display().to_string(),
            "motion_time_s": motion_time,
            "profile_time_s": plan.motion_time,
            "plan_time_s": plan.plan_time,
            "first_segment_s": plan.first_record_time,
            "segments": plan.records.len(),
            "critical_points": plan.critical_points.len(),
            "setpoints": samples.len(),
            "limits": {
                "feed": plan.limits.feed, "velocity": plan.limits.velocity, "acceleration": plan.limits.acceleration,
                "jerk": plan.limits.jerk, "chord_tolerance": plan.limits.chord_tolerance, "period": plan.limits.period,
            },
            "max_axial_velocity": &pk.vel[..tip],
            "max_axial_acceleration": &pk.acc[..tip],
            "max_axial_jerk": &pk.jerk[..tip],
            "worst_ratio_to_limit": check.worst_ratio(&plan.limits),
        });
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
    }
    Ok(())
}

/// `--planner vpop`: the tool-tip path planned by constraint intersection at the servo period
/// (same CSV columns and summary keys as the default planner).
fn run_vpop(args: PlanArgs) -> Result<(), Box<dyn std::error::Error>> {
    use crate::planner::vpop::{plan_five_axis, plan_tip, SearchOptions};
    let toolpath = read_toolpath(args.toolpath)?;
    let tip = toolpath.tip_dim();
    // A top curve on every element: 5-axis on the XYZAC machine, limits in joint order.
    let five = toolpath.elements.iter().all(|e| e.curve.dim() == 6);
    let plan = if five {
        let limits = args.limits.limits(5)?;
        plan_five_axis(
            &toolpath,
            crate::kinematics::Xyzac::default(),
            &limits,
            SearchOptions::default(),
        )?
    } else {
        plan_tip(&toolpath, &args.limits.limits(tip)?, SearchOptions::default())?
    };
    let axes = plan.axes;
    let mut out = std::io::BufWriter::new(std::fs::File::create(args.out)?);
    if five {
        writeln!(out, "t,u,x,y,z,a,c,tip_x,tip_y,tip_z,feed,element")?;
    } else {
        writeln!(out, "t,u,{},feed,element", ["x", "y", "z"][..tip].join(","))?;
    }
    let mut check = FiniteDifferences::new(axes, plan.limits.period);
    let mut prev: Option<[f64; 3]> = None;
    for (j, p) in plan.points.iter().enumerate() {
        let feed = prev.map_or(0.0, |a| {
            crate::planner::vpop::constraints::tip_distance(&p.tip, &a, tip) / plan.limits.period
        });
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
    if let Some(path) = args.summary {
        let pk = &check.peaks;
        let summary = serde_json::json!({
            "toolpath": args.toolpath.display().to_string(),
            "planner": "vpop",
            "motion_time_s": plan.motion_time,
            "plan_time_s": plan.plan_time,
            "setpoints": plan.points.len(),
            "dead_ends": plan.stats.dead_ends,
            "deceleration_checks": plan.stats.brakes,
            "limits": {
                "feed": plan.limits.feed, "velocity": plan.limits.velocity, "acceleration": plan.limits.acceleration,
                "jerk": plan.limits.jerk, "chord_tolerance": plan.limits.chord_tolerance, "period": plan.limits.period,
            },
            "axes": if five { "x,y,z,a,c" } else { "tool tip" },
            "max_axial_velocity": &pk.vel[..axes],
            "max_axial_acceleration": &pk.acc[..axes],
            "max_axial_jerk": &pk.jerk[..axes],
            "worst_ratio_to_limit": check.worst_ratio(&plan.limits),
        });
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)?;
    }
    Ok(())
}
