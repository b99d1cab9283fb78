//! VPOp plans (whole) and reachability plans (streamed in windows) as path blocks through the
//! realtime module on the mock HAL: exact positions, the stop at block group ends (the module's tangential stop or a stored sequence) within the
//! axis limits, resume, and malformed blocks.

mod common;

use std::time::Instant;

use common::test_paths::{g1_zigzag, line, rounded_polyline};
use common::*;
use nurbs_hal::channel::{PathBlock, Slot, StopPoint};
use nurbs_hal::module::FaultCode;
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::reach::{self, window::WindowOptions, ReachOptions, ReachPlan};
use nurbs_motion::planner::vpop::VpopPlan;
use nurbs_motion::planner::{Limits, PathCurves};
use nurbs_planner::feed::{block_plan, plan_start, reach_block_plan, vpop_plan, BlockPlan, Source, Streamer};
use nurbs_planner::shared_path::SharedPath;

struct BlockJob {
    job: Job,
    plan: VpopPlan,
}

/// The VPOp plan of `toolpath` at lab set 1 and its blocks; no block ends a group with a stop
/// outside the limits.
fn block_job(toolpath: Toolpath) -> BlockJob {
    let limits = lab1(toolpath.tip_dim()).for_axes(toolpath.tip_dim()).unwrap();
    let plan = vpop_plan(&toolpath, &limits, None).unwrap();
    let blocks = blocks_of(&toolpath, &plan, None);
    let (ends, stored, worst) = blocks.stops;
    println!(
        "{} blocks, {ends} group ends with a stop ({stored} stored), worst {worst:.9}",
        blocks.blocks().count()
    );
    assert!(worst <= 1.0 + 1e-6);
    BlockJob {
        job: Job {
            toolpath,
            limits,
            groups: Vec::new(),
            samples: Vec::new(),
        },
        plan,
    }
}

fn blocks_of(toolpath: &Toolpath, plan: &VpopPlan, from: Option<&StopPoint>) -> BlockPlan {
    block_plan(toolpath, (&plan.points, &plan.limits), from, 1.0).unwrap()
}

fn block_streamer<'a>(l: &'a Loaded, bj: &'a BlockJob, blocks: BlockPlan, first: usize) -> Streamer<'a> {
    Streamer::new(
        l.channel,
        bj.job.toolpath.tip_dim(),
        Source::blocks(blocks),
        first,
        f64::INFINITY,
        Instant::now(),
    )
    .unwrap()
}

/// One sample per planned period at VPOp's parameter and (to 1e-9 mm) position.
fn assert_positions(got: &[Out], plan: &VpopPlan) {
    assert_eq!(got.len(), plan.points.len(), "one sample per planned period");
    for (k, (g, p)) in got.iter().zip(&plan.points).enumerate() {
        assert_eq!((g.u, g.curve), (p.u, p.element), "sample {k}: parameter");
        let d = (g.q[0] - p.tip[0]).hypot(g.q[1] - p.tip[1]);
        assert!(d <= 1e-9, "sample {k}: {d:e} mm from the VPOp position");
    }
}

/// The trident and a rounded polyline (blocks start anew at every element): the module plays
/// VPOp's positions across every join, the run verifies, and no period allocates.
#[test]
fn vpop_blocks_run_exactly_the_planned_positions() {
    let _guard = lock_module();
    for toolpath in [job("trident.json").toolpath, rounded_polyline()] {
        let bj = block_job(toolpath);
        let l = load();
        let mut s = block_streamer(&l, &bj, blocks_of(&bj.job.toolpath, &bj.plan, None), 0);
        let got = run_to_rest(&mut s, bj.plan.points.len() + 50);
        assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault"));
        assert_positions(&got, &bj.plan);
        assert_eq!(violations(&bj.job, &got, true), Vec::<String>::new());
        assert_eq!(float("nurbs_interp.buffered"), 0.0);
    }
}

/// The bundled curve `name`, lab set 1, and its reachability plan in look-ahead windows (the
/// positions `nurbs-planner --planner reach` streams).
fn windowed_reach(name: &str) -> (Toolpath, Limits, ReachPlan) {
    windowed_reach_of(job(name).toolpath)
}

/// [`windowed_reach`] of any tool-tip path.
fn windowed_reach_of(toolpath: Toolpath) -> (Toolpath, Limits, ReachPlan) {
    let tip = toolpath.tip_dim();
    let limits = lab1(tip).for_axes(tip).unwrap();
    let options = ReachOptions {
        window: Some(WindowOptions::default()),
        ..ReachOptions::default()
    };
    let plan = reach::plan_tip(&toolpath, &limits, &options, None).unwrap();
    (toolpath, limits, plan)
}

/// The reachability planner streamed as `nurbs-planner --planner reach` runs it (in look-ahead
/// windows, in its own thread, the blocks decided as the points come): the module plays the
/// positions `nurbs-plan plan --planner reach --stream` plans, one per period, within the
/// limits, with a checked stop at every group end, and stops within the limits where it holds.
#[test]
fn reach_blocks_stream_the_windowed_plan() {
    let _guard = lock_module();
    let mut windows = 0;
    for name in ["trident.json", "butterfly.json"] {
        let (toolpath, limits, plan) = windowed_reach(name);
        let tip = toolpath.tip_dim();
        windows += plan.stats.windows;
        let l = load();
        let source = Source::streamed_blocks(SharedPath::whole(&toolpath), limits.clone(), None, 1.0);
        let (got, s) = paced_source_run(&l, tip, source, 1.0, plan.points.len() + 40_000, &mut |_, _| {});
        assert!(
            bit("nurbs_interp.done") && !bit("nurbs_interp.fault"),
            "{name}: ran to its end"
        );
        assert!(!bit("nurbs_interp.underrun"), "{name}: the plan kept ahead");
        assert_eq!(got.len(), plan.points.len(), "{name}: one sample per planned period");
        for (k, (g, p)) in got.iter().zip(&plan.points).enumerate() {
            assert_eq!((g.u, g.curve), (p.u, p.element), "{name} sample {k}: parameter");
        }
        let job = Job {
            toolpath,
            limits,
            groups: Vec::new(),
            samples: Vec::new(),
        };
        assert_eq!(violations(&job, &got, true), Vec::<String>::new(), "{name}");
        println!("{name}: {} samples, longest group {:.4} s", got.len(), s.longest_group);
    }
    assert!(windows >= 2, "some stretch planned in windows");
}

/// Only the groups up to block `cut` arrive: the module stops after the group end at or
/// before it, within the limits, at rest; VPOp re-plans from the stop point and the resume
/// command runs it to C(1), the whole run within the limits.
fn underrun_and_resume(bj: &BlockJob, cut: usize) {
    let l = load();
    let mut blocks = blocks_of(&bj.job.toolpath, &bj.plan, None);
    // The groups that end at or before block `cut`.
    let mut end = 0;
    let kept = blocks
        .groups
        .iter()
        .take_while(|g| {
            end += g.blocks.len();
            end <= cut + 1
        })
        .count();
    blocks.groups.truncate(kept);
    let mut s = block_streamer(&l, bj, blocks, 0);
    let mut got = run_to_rest(&mut s, bj.plan.points.len() + 20_000);
    let stop = stop_point(l.channel).expect("no stop point");
    assert!(bit("nurbs_interp.underrun") && !bit("nurbs_interp.fault"));
    assert_eq!(
        violations(&bj.job, &got, false),
        Vec::<String>::new(),
        "stop after block {cut}"
    );
    for _ in 0..5 {
        period();
    }
    let plan = vpop_plan(&bj.job.toolpath, &bj.job.limits, Some(&stop)).unwrap();
    let rest = blocks_of(&bj.job.toolpath, &plan, Some(&stop));
    let first = plan_start(&mut PathCurves::new(&bj.job.toolpath), &stop).curve;
    drop(s);
    let mut s = block_streamer(&l, bj, rest, first);
    set_bit("nurbs_interp.resume", true);
    hold_position(&mut got);
    got.extend(run_to_rest(&mut s, bj.plan.points.len() + 20_000));
    set_bit("nurbs_interp.resume", false);
    assert!(
        bit("nurbs_interp.done") && !bit("nurbs_interp.fault"),
        "block {cut}: resumed to the end"
    );
    assert_eq!(violations(&bj.job, &got, true), Vec::<String>::new(), "block {cut}");
}

/// Underruns at the fastest block ends of the trident and of the rounded polyline (there the
/// stops are stored sequences that may cross a join).
#[test]
fn an_underrun_at_a_block_end_stops_within_the_limits_and_resumes() {
    let _guard = lock_module();
    for toolpath in [job("trident.json").toolpath, rounded_polyline()] {
        let bj = block_job(toolpath);
        let blocks = blocks_of(&bj.job.toolpath, &bj.plan, None);
        let all: Vec<_> = blocks.blocks().copied().collect();
        let feed = |k: usize| nurbs_rtcore::block_stop::block_end_state(&all[k], PERIOD).1;
        // Each group's last block, and whether its stop is a stored sequence.
        let mut k = 0;
        let group_ends: Vec<(usize, bool)> = blocks
            .groups
            .iter()
            .map(|g| {
                k += g.blocks.len();
                (k - 1, g.stored.is_some())
            })
            .filter(|&(k, _)| k >= 2 && k + 2 < all.len())
            .collect();
        let mut ends: Vec<usize> = group_ends.iter().map(|&(k, _)| k).collect();
        ends.sort_by(|&a, &b| feed(b).total_cmp(&feed(a)));
        let stored = ends
            .iter()
            .copied()
            .find(|k| group_ends.iter().any(|&(e, stored)| e == *k && stored));
        for cut in ends.iter().copied().take(2).chain(stored) {
            underrun_and_resume(&bj, cut);
        }
    }
}

/// Hold mid-path: the module plays on to the end of the group it is in and stops there; the
/// re-plan from the stop point runs on release.
#[test]
fn hold_stops_at_the_group_end_and_resumes() {
    let _guard = lock_module();
    let bj = block_job(job("trident.json").toolpath);
    let l = load();
    let mut s = block_streamer(&l, &bj, blocks_of(&bj.job.toolpath, &bj.plan, None), 0);
    let hold_at = bj.plan.points.len() / 2;
    let mut got = run(
        &mut s,
        bj.plan.points.len() + 20_000,
        &mut |k| {
            if k == hold_at {
                set_bit("nurbs_interp.hold", true)
            }
        },
        &mut |_| bit("nurbs_interp.held"),
    );
    let stop = stop_point(l.channel).expect("a hold stop point");
    assert_eq!(stop.cause, 2);
    assert_eq!(violations(&bj.job, &got, false), Vec::<String>::new());
    for _ in 0..5 {
        period();
    }
    let plan = vpop_plan(&bj.job.toolpath, &bj.job.limits, Some(&stop)).unwrap();
    let first = plan_start(&mut PathCurves::new(&bj.job.toolpath), &stop).curve;
    drop(s);
    let mut s = block_streamer(&l, &bj, blocks_of(&bj.job.toolpath, &plan, Some(&stop)), first);
    run(&mut s, 100, &mut |_| {}, &mut |_| false);
    assert!(bit("nurbs_interp.resume-ready"));
    set_bit("nurbs_interp.hold", false);
    hold_position(&mut got);
    got.extend(run_to_rest(&mut s, bj.plan.points.len() + 20_000));
    assert!(bit("nurbs_interp.done"));
    assert_eq!(violations(&bj.job, &got, true), Vec::<String>::new());
}

/// Malformed blocks fault with the position held: NaN, a parameter outside the curve or going
/// back, arc lengths going back or not continuing the previous block, a sequence gap, no
/// samples, group fields that do not fit.
#[test]
fn bad_blocks_are_refused_with_the_position_held() {
    let _guard = lock_module();
    let bj = block_job(job("trident.json").toolpath);
    type Tamper = fn(&mut PathBlock);
    let cases: [(&str, Tamper, FaultCode); 8] = [
        ("NaN", |b| b.u[3] = f64::NAN, FaultCode::Record),
        (
            "u beyond the curve",
            |b| b.u[b.count as usize - 1] = 2.0,
            FaultCode::BlockPath,
        ),
        ("u back", |b| b.u[3] = b.u[0] - 1e-3, FaultCode::Record),
        ("s back", |b| b.s[3] = b.s[0] - 1.0, FaultCode::Record),
        ("not continuing", |b| b.s_before[0] -= 0.5, FaultCode::BlockPath),
        ("sequence", |b| b.seq += 1, FaultCode::Sequence),
        ("no samples", |b| b.count = 0, FaultCode::Record),
        ("group", |b| b.group_left = 0, FaultCode::Record),
    ];
    for (name, tamper, code) in cases {
        let l = load();
        let mut blocks = blocks_of(&bj.job.toolpath, &bj.plan, None);
        // The last block of a group half-way along the path.
        let g = blocks.groups.len() / 2;
        tamper(blocks.groups[g].blocks.last_mut().unwrap());
        let mut s = block_streamer(&l, &bj, blocks, 0);
        run(&mut s, bj.plan.points.len() + 100, &mut |_| {}, &mut |_| {
            bit("nurbs_interp.fault")
        });
        assert_eq!(u32_pin("nurbs_interp.fault-code"), code as u32, "{name}");
        let held = out().q;
        for _ in 0..50 {
            period();
            assert!(!bit("nurbs_interp.active"), "{name}: moved after the fault");
        }
        assert_eq!(out().q, held);
    }
    // A segment slot in a block motion.
    let l = load();
    let mut s = block_streamer(&l, &bj, blocks_of(&bj.job.toolpath, &bj.plan, None), 0);
    run(&mut s, 50, &mut |_| {}, &mut |_| false);
    let mut queue: Vec<Slot> = Vec::new();
    while let Ok(Some(slot)) = l.channel.segments.consumer().pop() {
        queue.push(slot);
    }
    queue[0].kind = nurbs_hal::slot::KIND_SEGMENT;
    for q in &queue {
        l.channel.segments.producer().push(q).unwrap();
    }
    for _ in 0..bj.plan.points.len() {
        period();
        if bit("nurbs_interp.fault") {
            break;
        }
    }
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::RecordKind as u32);
}

/// Holds at random samples of the blocks `nurbs-planner --planner reach` streams (the
/// reachability plan in windows, with the stops it offers: every block end has one stored):
/// every stop within the limits, at rest; how soon the motion leaves the plan (the first sample
/// that is not the plan's) and brakes (the first sample after which, at every sample until it
/// leaves the plan or rests, the feed or its rate of change falls), printed as distributions;
/// every hold brakes within 5 ms. `HOLD_INSTANTS` (default 12 per path) selects a longer run;
/// docs/testing.md records one.
#[test]
fn reach_blocks_hold_within_the_limits() {
    let _guard = lock_module();
    let per_path: usize = std::env::var("HOLD_INSTANTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(12);
    let mut instants = Instants::new(0x9e37_79b9_7f4a_7c15);
    let paths = [
        ("trident", job("trident.json").toolpath),
        ("butterfly", job("butterfly.json").toolpath),
        ("star_g1", job("star_g1.ngc").toolpath),
        ("G1 zigzag", g1_zigzag(150)),
        (
            "dense G1 (2000 lines)",
            job_at(&dense_g1(2000, &std::env::temp_dir())).toolpath,
        ),
        ("2000 mm line", line(2000.0)),
    ];
    for (name, toolpath) in paths {
        let (toolpath, limits, plan) = windowed_reach_of(toolpath);
        let tip = toolpath.tip_dim();
        // The blocks `nurbs-planner --planner reach` streams, with the stops the plan offers.
        let (blocks, line) = reach_block_plan(&SharedPath::whole(&toolpath), &limits, 1.0).unwrap();
        println!("{name}: {line}");
        let played: Vec<f64> = blocks.blocks().flat_map(|b| b.u[..b.len()].to_vec()).collect();
        let planned: Vec<f64> = plan.points.iter().map(|p| p.u).collect();
        assert_eq!(played, planned, "{name}: the blocks hold the windowed plan");
        let (ends, stored, worst) = blocks.stops;
        let blocks_count = blocks.blocks().count();
        assert!(
            stored == ends && ends + 1 == blocks_count && worst <= 1.0 + 1e-6,
            "{name}: a stored stop within the limits at every block end but the last ({stored} stored, {ends} ends, {blocks_count} blocks)"
        );
        let job = Job {
            toolpath,
            limits,
            groups: Vec::new(),
            samples: Vec::new(),
        };
        let (mut leaves, mut brakes) = (Vec::new(), Vec::new());
        for _ in 0..per_path {
            let at = instants.next(plan.points.len() - 2);
            let l = load();
            let source = Source::blocks(blocks.clone());
            let mut s = Streamer::new(l.channel, tip, source, 0, f64::INFINITY, Instant::now()).unwrap();
            let mut got: Vec<Out> = Vec::new();
            for _ in 0..plan.points.len() + 20_000 {
                s.fill().unwrap();
                if got.len() >= at {
                    set_bit("nurbs_interp.hold", true);
                }
                assert!(!period(), "the update path allocated");
                if bit("nurbs_interp.active") {
                    got.push(out());
                }
                if bit("nurbs_interp.held") || bit("nurbs_interp.done") || bit("nurbs_interp.fault") {
                    break;
                }
            }
            set_bit("nurbs_interp.hold", false);
            assert!(!bit("nurbs_interp.fault"), "{name}: hold at {at}: fault");
            let held = bit("nurbs_interp.held");
            drop(s);
            drop(l);
            if !held {
                continue; // the motion ended first (a hold in its last group)
            }
            hold_position(&mut got);
            assert_eq!(
                violations(&job, &got, false),
                Vec::<String>::new(),
                "{name}: hold at {at}"
            );
            let left = got
                .iter()
                .zip(&plan.points)
                .position(|(o, p)| o.u != p.u || o.curve != p.element)
                .unwrap_or(got.len());
            let leave = left.saturating_sub(at);
            // The motion brakes from the first sample after which, at every sample until it
            // leaves the plan for its stop (or rests), the feed falls or its rate of change does (a
            // jerk-limited stop from an accelerating state first brings the acceleration down;
            // where the plan already brakes there, the hold needs nothing sooner).
            let rest = (at..got.len()).find(|&k| got[k].feed <= 0.0).unwrap_or(got.len());
            let rate = |k: usize| got[k].feed - got[k - 1].feed;
            let from = (at.max(2)..left.min(rest))
                .rev()
                .find(|&k| rate(k) >= 0.0 && rate(k) - rate(k - 1) >= 0.0)
                .map_or(at, |k| k + 1);
            leaves.push(leave);
            brakes.push(from.saturating_sub(at));
            if from.saturating_sub(at) > 20 {
                let mut k = 0usize;
                for g in &blocks.groups {
                    let n: usize = g.blocks.iter().map(|b| b.len()).sum();
                    if k + n + 40 > at && k < at + 40 {
                        let first_diff = g.stored.as_ref().map(|v| v.len());
                        eprintln!(
                            "DBG {name} at {at}: group {k}..{} blocks {} curves {:?} stored {:?} choice {:?}",
                            k + n,
                            g.blocks.len(),
                            g.blocks.iter().map(|b| (b.curve, b.len())).collect::<Vec<_>>(),
                            first_diff,
                            g.choices.last().map(|c| (c.ratio, c.stored))
                        );
                    }
                    k += n;
                }
            }
        }
        leaves.sort_unstable();
        brakes.sort_unstable();
        let ms = |k: usize| k as f64 * PERIOD * 1e3;
        let show = |v: &[usize]| {
            format!(
                "median {:.2} ms, 99 % {:.2} ms, worst {:.2} ms; within 5 ms: {} of {}",
                ms(quantile(v, 0.5)),
                ms(quantile(v, 0.99)),
                ms(v.last().copied().unwrap_or(0)),
                v.iter().filter(|&&k| ms(k) <= 5.0).count(),
                v.len()
            )
        };
        println!(
            "{name}: {} holds: leaves the plan after {}",
            leaves.len(),
            show(&leaves)
        );
        println!("{name}: brakes after {}", show(&brakes));
        assert!(!leaves.is_empty(), "{name}: some hold stopped the motion");
        let worst = brakes.last().copied().unwrap_or(0);
        assert!(ms(worst) <= 5.0, "{name}: a hold braked only after {:.2} ms", ms(worst));
    }
}

#[derive(clap::Parser)]
struct ProgramLimits {
    #[command(flatten)]
    limits: nurbs_cli::limits::LimitArgs,
}

/// What the reachability planner's blocks with their stops cost on a program of one's own, as
/// `nurbs-planner --planner reach` makes them but without the module's pace:
/// `REACH_PROGRAM=chips.ngc REACH_FLAGS="--feed 100 --accel 5000 --jerk 5e4 --chord-tol 0.01
/// --period 0.00025" cargo test --release -p nurbs-planner --features linuxcnc --test blocks
/// reach_blocks_of_a_program -- --ignored --nocapture` (docs/integration.md records one); every
/// block end's stop is checked within the limits as the module plays it.
#[test]
#[ignore]
fn reach_blocks_of_a_program() {
    use clap::Parser;
    let program = std::env::var("REACH_PROGRAM").expect("REACH_PROGRAM: the program to plan");
    let flags = std::env::var("REACH_FLAGS").unwrap_or_default();
    let args = ProgramLimits::parse_from(std::iter::once("limits").chain(flags.split_whitespace()));
    let mut stream = nurbs_cli::corners::open(std::path::Path::new(&program), None, &args.limits).unwrap();
    let shared = SharedPath::new(stream.take_elements());
    let tip = shared.open().unwrap().tip_dim();
    let limits = args.limits.limits(tip).unwrap();
    let (plan, line) = reach_block_plan(&shared, &limits, 1.0).unwrap();
    println!("{program}: {line}");
    let (ends, stored, worst) = plan.stops;
    assert!(ends > 0 && stored <= ends && worst <= 1.0 + 1e-6, "{program}: {line}");
}
