//! VPOp planner: every plan is checked with the project's verifier (finite
//! differences at the servo period, relative slack 1e-6, at rest before the first and after the
//! last row; feed; chord error; distance to the curve; end points).

mod common;

use common::{example, lab1, table1, tip_vpop, trident_vpop};
use nurbs_motion::geometry::{ElementKind, Nurbs, Toolpath};
use nurbs_motion::planner::verify::{verify, Report, Row};
use nurbs_motion::planner::vpop::{
    plan_tip, run_streamed, JointPath, PathPoint, Release, SearchOptions, VpopPlan, BRAKES,
};
use nurbs_motion::planner::{Limits, PathCurves};

fn rows(plan: &VpopPlan, tip: usize) -> Vec<Row> {
    plan.points
        .iter()
        .enumerate()
        .map(|(j, p)| Row {
            t: j as f64 * plan.limits.period,
            curve: p.element,
            u: p.u,
            q: p.tip[..tip].to_vec(),
        })
        .collect()
}

fn check(tp: &Toolpath, plan: &VpopPlan) -> Report {
    let report = verify(&mut PathCurves::new(tp), &plan.limits, &rows(plan, tp.tip_dim()));
    assert!(report.violations.is_empty(), "violations: {:?}", report.violations);
    report
}

#[test]
fn trident_vpop_limits() {
    let tp = example("trident.json");
    let plan = plan_tip(&tp, &trident_vpop(), SearchOptions::default()).unwrap();
    let r = check(&tp, &plan);
    eprintln!(
        "trident VPOp limits: {:.3} s, planned in {:.1} ms, {:?}, peaks jerk {:?}",
        plan.motion_time,
        plan.plan_time * 1e3,
        plan.stats,
        &r.peaks.jerk[..2]
    );
    // Physical lower bound 1.650 s, best known 1.668 s, paper 2.3 s, the goal 1.75 s
    // (measured 1.680 s).
    assert!(plan.motion_time >= 1.650, "{}", plan.motion_time);
    assert!(plan.motion_time <= 1.75, "{}", plan.motion_time);
    // The plan uses the jerk limit: checked against 1 % less it must fail.
    let mut tighter = plan.limits.clone();
    tighter.jerk = tighter.jerk.iter().map(|j| 0.99 * j).collect();
    let r = verify(&mut PathCurves::new(&tp), &tighter, &rows(&plan, 2));
    assert!(!r.violations.is_empty());
}

/// The trident at its limits with the first braking setting alone and no search back-off (VPOp
/// before it tried several): a verified plan, but 0.27 s slower, because every state that this
/// one deceleration sequence does not bring to rest counts as unsafe.
#[test]
fn one_braking_setting_brakes_earlier() {
    let tp = example("trident.json");
    let options = SearchOptions {
        brakes: &BRAKES[..1],
        search_backoff: 0.0,
        ..SearchOptions::default()
    };
    let one = plan_tip(&tp, &trident_vpop(), options).unwrap();
    check(&tp, &one);
    let all = plan_tip(&tp, &trident_vpop(), SearchOptions::default()).unwrap();
    eprintln!(
        "trident VPOp limits: {:.3} s with one braking setting, {:.3} s with {}",
        one.motion_time,
        all.motion_time,
        BRAKES.len()
    );
    assert!(
        one.motion_time > all.motion_time + 0.2,
        "{} vs {}",
        one.motion_time,
        all.motion_time
    );
}

/// The deceleration settings that release with the jerk the axes have left after the curvature
/// terms (the last five of `BRAKES`) save states near sharp turns that the first five do not,
/// so the plan brakes later: on the trident at lab set 1, 0.7708 s with the first five and
/// 0.7460 s with all ten (measured); both verified.
#[test]
fn releasing_with_the_jerk_left_brakes_later() {
    let tp = example("trident.json");
    let whole = SearchOptions {
        brakes: &BRAKES[..5],
        ..SearchOptions::default()
    };
    assert!(BRAKES[..5].iter().all(|b| b.release == Release::Whole));
    let five = plan_tip(&tp, &lab1(2), whole).unwrap();
    check(&tp, &five);
    let all = plan_tip(&tp, &lab1(2), SearchOptions::default()).unwrap();
    check(&tp, &all);
    eprintln!(
        "trident lab set 1: {:.4} s releasing with the whole jerk, {:.4} s also with the jerk left",
        five.motion_time, all.motion_time
    );
    assert!(
        all.motion_time < 0.98 * five.motion_time,
        "{} vs {}",
        all.motion_time,
        five.motion_time
    );
}

/// A straight line from rest to rest: ends exactly at the end point, and takes at least the
/// time of a one-axis jerk-limited move over that distance (the tangential limits here equal the
/// X axis limits, the Y axis does not move).
#[test]
fn straight_line_rest_to_rest() {
    let curve = Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[vec![0.0, 0.0], vec![30.0, 0.0]], None).unwrap();
    let tp = Toolpath::single(ElementKind::Polyline, curve);
    let limits = Limits::uniform(2, 100.0, 1000.0, 10000.0, 0.01, 0.001);
    let plan = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    let r = check(&tp, &plan);
    // Continuous time-optimal rest-to-rest move: cruise at F, accel phases F/A + A/J.
    let (f, a, j) = (100.0, 1000.0, 10000.0);
    let t_opt = 30.0 / f + f / a + a / j;
    eprintln!(
        "line: {:.4} s vs continuous optimum {:.4} s, peak feed {}",
        plan.motion_time, t_opt, r.max_feed
    );
    assert!(plan.motion_time >= t_opt - 2.0 * limits.period);
    assert!(plan.motion_time <= 1.1 * t_opt, "{} vs {t_opt}", plan.motion_time);
    assert!(r.max_feed > 0.99 * f);
}

/// VPOp streams: its points go out as soon as no back-tracking can reach them, so a run holds
/// the points of its look-ahead (the braking distance ahead), not of the motion: on a long line
/// and on the butterfly (lab set 1) at most 0.25 s of motion, against the thousands of periods
/// of the whole motion. The points handed out are the plan (verified), and an error of the
/// receiver ends the run at once with its message.
#[test]
fn points_go_out_as_they_become_final() {
    let curve = Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[vec![0.0, 0.0], vec![300.0, 0.0]], None).unwrap();
    let line = Toolpath::single(ElementKind::Polyline, curve);
    let cases = [
        (
            "300 mm line",
            line,
            Limits::uniform(2, 100.0, 1000.0, 10000.0, 0.01, 0.00025),
        ),
        ("butterfly", example("butterfly.json"), lab1(2)),
    ];
    for (name, tp, limits) in &cases {
        let path = JointPath::tip(tp);
        let mut points: Vec<PathPoint> = Vec::new();
        let run = run_streamed(&path, limits, SearchOptions::default(), &mut |p| {
            points.push(*p);
            Ok(())
        })
        .unwrap();
        let held = run.stats.most_held;
        eprintln!(
            "{name}: {} points, at most {held} held at once, first handed out after {:.2} ms",
            run.points,
            run.first_points_time * 1e3
        );
        assert_eq!(points.len(), run.points);
        assert!(run.points > 10_000, "{name}: {}", run.points);
        assert!(held as f64 * limits.period <= 0.25, "{name}: {held} points held");
        check(tp, &run.with_points(points));
        let mut taken = 0;
        let refused = run_streamed(&path, limits, SearchOptions::default(), &mut |_| {
            taken += 1;
            if taken > 100 {
                Err("the receiver is gone".into())
            } else {
                Ok(())
            }
        });
        assert!(refused.is_err_and(|e| e.to_string().contains("the receiver is gone")));
        assert_eq!(taken, 101);
    }
}

/// A program read as it is planned: 2,400 line elements in a row (a 1000 mm line cut into
/// 0.5 mm pieces, then 400 pieces turning a little at every join, each join a tangent break
/// the plan stops on as it comes) give the same plan, bit for bit, streamed as read whole, and
/// the streamed path holds a few hundred elements at a time.
#[test]
fn a_streamed_path_plans_as_the_whole_path() {
    use nurbs_motion::geometry::PathElement;
    let mut vertices: Vec<[f64; 2]> = (0..=2000).map(|k| [0.5 * k as f64, 0.0]).collect();
    vertices.extend((1..=400).map(|k| {
        let a = 0.002 * k as f64;
        [1000.0 + 50.0 * a.sin(), 50.0 * (1.0 - a.cos())]
    }));
    let elements: Vec<PathElement> = vertices
        .windows(2)
        .map(|w| {
            let curve = Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[w[0].to_vec(), w[1].to_vec()], None).unwrap();
            PathElement {
                kind: ElementKind::Polyline,
                curve,
                feed: None,
                source_line: None,
            }
        })
        .collect();
    let tp = Toolpath { elements };
    let limits = Limits::uniform(2, 200.0, 2000.0, 20000.0, 0.01, 0.001);
    let whole = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    let source = tp.elements.clone().into_iter().map(Ok);
    let path = JointPath::streamed(Box::new(source)).unwrap();
    let mut points = Vec::new();
    let run = run_streamed(&path, &limits, SearchOptions::default(), &mut |p| {
        points.push(*p);
        Ok(())
    })
    .unwrap();
    let held = path.most_elements_held();
    eprintln!(
        "{} elements, {} points, at most {held} elements held at once",
        tp.elements.len(),
        run.points
    );
    assert_eq!(points, whole.points);
    assert!(held < tp.elements.len() / 4, "{held} elements held");
    check(&tp, &whole);
}

/// A polyline with two corners and a reversal, as one degree-1 curve, at a coarse 5.6 ms period
/// with a high jerk limit (a case the property test found refused): VPOp stops exactly on every
/// corner (a sample on the vertex, then at rest there) and the plan passes the checker.
#[test]
fn tangent_breaks_are_exact_stops() {
    let vertices = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 12.0], [10.0, 12.0]];
    let cps: Vec<Vec<f64>> = vertices.iter().map(|v| v.to_vec()).collect();
    let curve = Nurbs::new(1, vec![0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0], &cps, None).unwrap();
    let tp = Toolpath::single(ElementKind::Polyline, curve);
    let limits = Limits::uniform(2, 100.0, 3360.0, 8.37e6, 0.0119, 0.0056);
    let plan = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    check(&tp, &plan);
    for v in &vertices[1..4] {
        let at = plan
            .points
            .iter()
            .position(|p| (p.tip[0] - v[0]).abs() < 1e-9 && (p.tip[1] - v[1]).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no sample on the corner {v:?}"));
        let rest = &plan.points[at..at + 3];
        assert!(rest.iter().all(|p| p.w == rest[0].w), "not at rest on {v:?}");
    }
    eprintln!("corners: {:.4} s", plan.motion_time);
}

/// Butterfly, Erwinski lab set 1 (dt 0.25 ms, about 15 000 periods): measured 3.817 s of
/// motion (best known 3.163 s, lower bound 2.404 s), planned in about 7 s on this 2-core machine
/// (release build).
#[test]
fn butterfly_lab_set_1() {
    let tp = example("butterfly.json");
    let limits = lab1(2);
    let plan = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    check(&tp, &plan);
    eprintln!(
        "butterfly lab set 1: {:.4} s, planned in {:.1} ms, {:?}",
        plan.motion_time,
        plan.plan_time * 1e3,
        plan.stats
    );
    assert!(plan.motion_time >= 2.404);
    assert!(plan.motion_time <= 3.9, "{}", plan.motion_time);
}

/// Open pocket (two curves) on the XYZAC machine with the paper's Table 1 limits (joint order
/// x, y, z, a, c; rotary in degrees): the joint setpoints pass the finite-difference check, and
/// the tool tip recovered by forward kinematics lies on the programmed curve (verifier: distance,
/// chord error, tool-tip feed, end points).
#[test]
fn open_pocket_five_axis_table_1() {
    use nurbs_motion::kinematics::TableTilting;
    use nurbs_motion::planner::axial::FiniteDifferences;
    use nurbs_motion::planner::verify::SLACK;
    use nurbs_motion::planner::vpop::plan_five_axis;
    let tp = example("open_pocket.json");
    let limits = table1();
    let machine = TableTilting::default();
    let plan = plan_five_axis(&tp, machine, &limits, SearchOptions::default()).unwrap();
    let mut fd = FiniteDifferences::new(5, limits.period);
    for p in &plan.points {
        fd.push(&p.q[..5], &limits);
        let (tip, _) = machine.forward(&p.q[..5]);
        for i in 0..3 {
            assert!((tip[i] - p.tip[i]).abs() < 1e-9, "{tip:?} vs {:?}", p.tip);
        }
    }
    fd.finish(&limits);
    for i in 0..5 {
        assert!(
            fd.peaks.vel[i] <= limits.velocity[i] * (1.0 + SLACK),
            "axis {i} v {}",
            fd.peaks.vel[i]
        );
        assert!(
            fd.peaks.acc[i] <= limits.acceleration[i] * (1.0 + SLACK),
            "axis {i} a {}",
            fd.peaks.acc[i]
        );
        assert!(
            fd.peaks.jerk[i] <= limits.jerk[i] * (1.0 + SLACK),
            "axis {i} j {}",
            fd.peaks.jerk[i]
        );
    }
    let tip_limits = Limits {
        velocity: vec![1e12; 3],
        acceleration: vec![1e12; 3],
        jerk: vec![1e12; 3],
        ..limits.clone()
    };
    let r = verify(&mut PathCurves::new(&tp), &tip_limits, &rows(&plan, 3));
    assert!(r.violations.is_empty(), "{:?}", r.violations);
    eprintln!(
        "open pocket 5-axis: {:.3} s, planned in {:.1} ms, joint peaks v {:?} a {:?} j {:?}",
        plan.motion_time,
        plan.plan_time * 1e3,
        &fd.peaks.vel[..5],
        &fd.peaks.acc[..5],
        &fd.peaks.jerk[..5]
    );
    // The tool-tip length at the programmed feed is a lower bound.
    assert!(plan.motion_time >= 98.168 / 83.333);
}

/// G1 path (fan_5axis, 25 points): corners rounded with five-point cubic B-splines inside the
/// contour tolerance (tip and top curve together), the tool tip planned as one motion with the
/// VPOp limits (3 axes).
#[test]
fn fan_5axis_tip_polyline_rounded() {
    use nurbs_motion::planner::corner::round_toolpath;
    let raw = example("fan_5axis.json");
    let eps = 0.02;
    let rounded = round_toolpath(&raw, eps).unwrap();
    assert!(rounded.corners >= 20, "{} corners", rounded.corners);
    assert!(rounded.max_deviation <= eps, "{}", rounded.max_deviation);
    // Uses the tolerance where the segments are long enough.
    assert!(rounded.max_deviation >= 0.9 * eps, "{}", rounded.max_deviation);
    let tp = rounded.toolpath;
    let limits = tip_vpop();
    assert_eq!(limits.chord_tolerance, eps);
    let plan = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    check(&tp, &plan);
    // Every setpoint is within the rounding deviation plus nothing else of the programmed
    // polyline (setpoints lie on the rounded path).
    let verts: Vec<[f64; 3]> = (0..raw.elements[0].curve.control_point_count())
        .map(|k| {
            let c = raw.elements[0].curve.control_point(k);
            [c[0], c[1], c[2]]
        })
        .collect();
    let seg = |x: &[f64; 3], a: &[f64; 3], b: &[f64; 3]| {
        let ab: Vec<f64> = (0..3).map(|i| b[i] - a[i]).collect();
        let ax: Vec<f64> = (0..3).map(|i| x[i] - a[i]).collect();
        let l2: f64 = ab.iter().map(|v| v * v).sum();
        let t = (ax.iter().zip(&ab).map(|(p, q)| p * q).sum::<f64>() / l2).clamp(0.0, 1.0);
        (0..3).map(|i| (ax[i] - t * ab[i]).powi(2)).sum::<f64>().sqrt()
    };
    let dev = plan
        .points
        .iter()
        .map(|p| {
            verts
                .windows(2)
                .map(|w| seg(&p.tip, &w[0], &w[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    eprintln!(
        "fan_5axis tip G1: {} corners, rounding deviation {:.5} mm, setpoint deviation {:.5} mm, {:.3} s, planned in {:.1} ms",
        rounded.corners,
        rounded.max_deviation,
        dev,
        plan.motion_time,
        plan.plan_time * 1e3
    );
    assert!(dev <= eps * (1.0 + 1e-9), "{dev}");
    // At least the length at the programmed feed.
    assert!(plan.motion_time >= 342.0 / 166.667);
}

/// VPOp on the random curves of the planner's property test (`random_curve`: degree 1-7, 2-D
/// and 3-D, weights 0.2-5, near-repeated control points, straight stretches, random limits):
/// every plan must pass the checker; a clear refusal is allowed for at most 2 % of the cases.
/// VPOp's cost grows with the number of periods times the length of its deceleration checks,
/// so cases over 20,000 periods at full feed are skipped. `PROPTEST_VPOP_CASES` (default 64),
/// `PROPTEST_RNG_SEED` (default 20261122) and `PROPTEST_FIRST_CASE` select the run.
#[test]
fn random_curves_never_violate() {
    let env = |name: &str, default: u64| std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default);
    let (cases, seed) = (env("PROPTEST_VPOP_CASES", 64), env("PROPTEST_RNG_SEED", 20261122));
    let first_case = env("PROPTEST_FIRST_CASE", 0);
    let (mut planned, mut refused, mut skipped) = (0usize, Vec::new(), 0usize);
    for (case, tp, limits) in common::random_cases(seed, first_case..cases) {
        let len = nurbs_motion::geometry::ArcLengthTable::new(&tp.elements[0].curve).total();
        if len / limits.feed / limits.period >= 2e4 {
            skipped += 1;
            continue;
        }
        match plan_tip(&tp, &limits, SearchOptions::default()) {
            Ok(plan) => {
                let report = verify(&mut PathCurves::new(&tp), &plan.limits, &rows(&plan, tp.tip_dim()));
                assert!(
                    report.violations.is_empty(),
                    "case {case} (seed {seed}): violations {:?}\n{tp:?}\n{limits:?}",
                    report.violations
                );
                planned += 1;
            }
            Err(e) => refused.push(format!("case {case}: {e}")),
        }
    }
    eprintln!(
        "VPOp random curves, seed {seed}: {planned} planned and verified, {} refused, {skipped} skipped",
        refused.len()
    );
    for r in &refused {
        eprintln!("  refused {r}");
    }
    assert!(refused.len() * 50 <= cases as usize, "too many refusals: {refused:?}");
}

/// A plan from rest at an arbitrary point of the path (the rest of the path after a stop): it
/// starts exactly at that element and parameter, stays within the limits by the finite-
/// difference check (at rest before its first sample) and ends at rest at the path end; a
/// start off the path is refused.
#[test]
fn starts_from_rest_at_any_point() {
    use nurbs_motion::planner::axial::FiniteDifferences;
    let tp = example("trident.json");
    let limits = lab1(2);
    for u0 in [0.0, 0.37, 0.9] {
        let options = SearchOptions {
            start: Some((0, u0)),
            ..SearchOptions::default()
        };
        let plan = plan_tip(&tp, &limits, options).unwrap();
        let first = plan.points[0];
        assert_eq!((first.element, first.u), (0, u0));
        let c = tp.elements[0].curve.point(u0);
        assert!((first.tip[0] - c[0]).abs() < 1e-12 && (first.tip[1] - c[1]).abs() < 1e-12);
        let mut fd = FiniteDifferences::new(2, plan.limits.period);
        for p in &plan.points {
            fd.push(&p.tip[..2], &plan.limits);
        }
        fd.finish(&plan.limits);
        let ratio = fd.worst_ratio(&plan.limits);
        assert!(ratio <= 1.0 + 1e-6, "u0 {u0}: worst ratio {ratio}");
        let last = plan.points.last().unwrap();
        assert_eq!((last.element, last.u), (0, 1.0));
        eprintln!("from u = {u0}: {} periods, worst ratio {ratio:.4}", plan.points.len());
    }
    let off = SearchOptions {
        start: Some((0, 1.5)),
        ..SearchOptions::default()
    };
    assert!(plan_tip(&tp, &limits, off).is_err());
    let off = SearchOptions {
        start: Some((3, 0.5)),
        ..SearchOptions::default()
    };
    assert!(plan_tip(&tp, &limits, off).is_err());
}
