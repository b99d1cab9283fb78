//! Segment records (the Erwinski planner's streamed plan) through the realtime module on the
//! mock HAL: exact playback, the stop at every group end (underrun, hold, abort) within the axis
//! limits, resume, and faults.

mod common;

use std::time::Instant;

use common::test_paths::{dense_arc, g1_zigzag};
use common::*;
use nurbs_cli::corners::{prepare, RoundCorners};
use nurbs_hal::channel::Slot;
use nurbs_hal::mock;
use nurbs_hal::module::FaultCode;
use nurbs_hal::slot::{SegmentSlot, KIND_BLOCK};
use nurbs_hal::sys;
use nurbs_motion::planner::simulate::setpoints;
use nurbs_motion::planner::PathCurves;
use nurbs_planner::feed::{plan_groups, Source, Streamer};
use nurbs_planner::shared_path::SharedPath;
use nurbs_planner::writer::GeometryWriter;

#[test]
fn module_creates_its_pins_and_function() {
    let _guard = lock_module();
    let l = load();
    let names = mock::pin_names();
    for pin in [
        "enable",
        "pos-cmd-x",
        "pos-cmd-y",
        "pos-cmd-z",
        "feed",
        "u",
        "curve",
        "active",
        "done",
        "fault",
        "fault-code",
        "underrun",
        "underruns",
        "records",
        "seq",
        "buffered",
        "hold",
        "abort",
        "resume",
        "resume-ready",
        "held",
    ] {
        assert!(
            names.contains(&format!("nurbs_interp.{pin}")),
            "missing {pin}: {names:?}"
        );
    }
    assert_eq!(mock::pin_dir("nurbs_interp.enable"), Some(sys::HAL_IN));
    assert_eq!(mock::pin_dir("nurbs_interp.pos-cmd-x"), Some(sys::HAL_OUT));
    assert!(mock::funct("nurbs_interp.update").is_some());
    drop(l);
    assert!(mock::funct("nurbs_interp.update").is_none());
    assert_eq!(mock::component_ready("nurbs_interp"), None);
}

/// A path of several elements (line, NURBS, line), the 5-axis open pocket (3 tip axes of a
/// 6-D curve) and G1 programs with their corners rounded, streamed as `nurbs-planner` streams
/// them: the module's position, feed, u and curve are the offline streamed setpoints bit for
/// bit, every element runs, the run passes the project's limit check, and no period allocates.
#[test]
fn the_module_plays_the_offline_streamed_setpoints_bit_for_bit() {
    let _guard = lock_module();
    let dir = std::env::temp_dir().join(format!("nurbs-planner-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ngc = dir.join("line-trident-line.ngc");
    std::fs::write(
        &ngc,
        "G21 G17 G90 G64\nG0 X0 Y0\nF60000\nG1 X10 Y0\nG5.2 X20 Y27 P1 L4\nX12 Y8 P1\nX10 Y20 P1\n\
         X8 Y8 P1\nX0 Y27 P1\nX10 Y0 P1\nG5.3\nG1 X0 Y0\nM2\n",
    )
    .unwrap();
    let jobs = [
        ("trident", job("trident.json")),
        ("butterfly", job("butterfly.json")),
        ("line-trident-line", job(ngc.to_str().unwrap())),
        ("open_pocket", job("open_pocket.json")),
        ("star_g1", job("star_g1.ngc")),
        ("G1 zigzag", job_of(g1_zigzag(150))),
    ];
    for (name, job) in jobs {
        let l = load();
        let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
        let got = run_to_rest(&mut s, job.samples.len() + 100);
        assert_exact(name, &got, &job.samples, job.toolpath.tip_dim());
        assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault") && !bit("nurbs_interp.underrun"));
        assert_eq!(u32_pin("nurbs_interp.records") as u64, s.pushed);
        assert_eq!(float("nurbs_interp.buffered"), 0.0);
        let curves: std::collections::BTreeSet<usize> = got.iter().map(|o| o.curve).collect();
        assert_eq!(curves.len(), job.toolpath.elements.len(), "{name}: every element runs");
        assert_eq!(violations(&job, &got, true), Vec::<String>::new(), "{name}");
        println!(
            "{name}: {} samples, {} groups, {} elements",
            got.len(),
            job.groups.len(),
            curves.len()
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The planner falls behind after group `g` (only the groups before it arrive): the module
/// stops at the end of group `g - 1` with its stop and publishes where it stands.
fn stop_after(job: &Job, g: usize) -> (Loaded, Vec<Out>, nurbs_hal::channel::StopPoint) {
    let l = load();
    let mut s = streamer(&l, &job.toolpath, job.groups[..g].to_vec(), 0);
    let got = run_to_rest(&mut s, job.samples.len() + 20_000);
    let stop = stop_point(l.channel).expect("no stop point published");
    (l, got, stop)
}

/// At every group end of the trident, of a rounded G1 program and at the butterfly's fastest:
/// an underrun stops on the path with the stop the planner made there, within the axis limits
/// (the project's check on the samples up to the stop and the held position after), at rest,
/// with the samples up to the group end those of the plan.
#[test]
fn an_underrun_at_any_group_end_stops_within_the_limits() {
    let _guard = lock_module();
    let butterfly = job("butterfly.json");
    let fastest = (1..butterfly.groups.len())
        .max_by(|&a, &b| {
            let end = |g: usize| {
                butterfly.groups[g - 1]
                    .slots
                    .last()
                    .unwrap()
                    .record
                    .profile()
                    .table()
                    .end()
                    .v
            };
            end(a).total_cmp(&end(b))
        })
        .unwrap();
    let cases = [
        ("trident", job("trident.json"), None),
        ("star_g1", job("star_g1.ngc"), None),
        ("butterfly", butterfly, Some(fastest)),
    ];
    let mut stops = 0;
    for (name, job, only) in cases {
        let ends: Vec<usize> = match only {
            Some(g) => vec![g],
            None => (1..job.groups.len()).collect(),
        };
        for g in ends {
            let (l, got, stop) = stop_after(&job, g);
            let planned: usize = job.groups[..g]
                .iter()
                .flat_map(|gr| &gr.slots)
                .map(|s| s.record.profile().total_time())
                .sum::<f64>()
                .div_euclid(PERIOD) as usize;
            let prefix = got
                .iter()
                .zip(&job.samples)
                .take_while(|(o, e)| o.q[0] == e.point[0] && o.q[1] == e.point[1])
                .count();
            assert!(
                prefix >= planned.saturating_sub(1),
                "{name} group {g}: {prefix} planned samples of {planned}"
            );
            assert_eq!(violations(&job, &got, false), Vec::<String>::new(), "{name} group {g}");
            let last = got.last().unwrap();
            let rest = job.limits.min_jerk() * PERIOD * PERIOD / 2.0;
            assert!(
                last.feed.abs() <= rest,
                "{name} group {g}: not at rest ({} mm/s)",
                last.feed
            );
            assert!(bit("nurbs_interp.underrun") && bit("nurbs_interp.held") && !bit("nurbs_interp.fault"));
            assert_eq!([stop.point[0], stop.point[1]], [last.q[0], last.q[1]]);
            assert_eq!(stop.cause, 1);
            // Held: no further sample, the position stays.
            for _ in 0..10 {
                assert!(!period());
                assert!(!bit("nurbs_interp.active"));
            }
            assert_eq!(out().q, last.q);
            drop(l);
            stops += 1;
        }
    }
    println!("{stops} underrun stops checked");
}

/// A dense G1 program (600 lines of 0.02 mm): no single segment can stop, so the planner's
/// stops are chains of segments (the rest of each in the arena). The module plays the plan
/// exactly, and an underrun at several chain group ends stops within the limits.
#[test]
fn stop_chains_on_a_dense_g1_program() {
    let _guard = lock_module();
    let job = job_of(dense_arc(600));
    let chains: Vec<usize> = (0..job.groups.len())
        .filter(|&g| job.groups[g].slots.last().is_some_and(|s| s.chain_len > 0))
        .collect();
    let longest = job.groups.iter().map(|g| g.time).fold(0.0, f64::max);
    println!(
        "{} groups, {} ending in a stop chain, the longest {longest:.3} s",
        job.groups.len(),
        chains.len()
    );
    assert!(chains.len() >= 3, "the dense program's stops should be chains");
    let l = load();
    let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    let got = run_to_rest(&mut s, job.samples.len() + 100);
    assert_eq!(
        (u32_pin("nurbs_interp.fault-code"), u32_pin("nurbs_interp.underruns")),
        (0, 0)
    );
    assert_exact("dense arc", &got, &job.samples, 2);
    drop(s);
    drop(l);
    for &g in chains.iter().step_by((chains.len() / 3).max(1)).take(3) {
        let (_l, got, _) = stop_after(&job, g + 1);
        assert_eq!(
            violations(&job, &got, false),
            Vec::<String>::new(),
            "chain after group {g}"
        );
        let rest = job.limits.min_jerk() * PERIOD * PERIOD / 2.0;
        assert!(got.last().unwrap().feed.abs() <= rest, "group {g}: not at rest");
        assert!(bit("nurbs_interp.held") && !bit("nurbs_interp.fault"));
    }
}

/// Underrun, resume: the planner re-plans the rest of the path from the stop point (a new
/// geometry stream from that element); nothing moves until the resume command, a command
/// without data is dropped; then the motion runs to C(1), and the whole sampled run (the stop's
/// samples followed directly by the resumed ones, as a sampler records them) passes the check.
#[test]
fn an_underrun_resumes_from_the_stop_point_on_command() {
    let _guard = lock_module();
    for (name, job) in [("trident", job("trident.json")), ("star_g1", job("star_g1.ngc"))] {
        let g = job.groups.len() / 2;
        let (l, mut got, stop) = stop_after(&job, g);
        let held = out().q;
        // A resume command without data does nothing.
        set_bit("nurbs_interp.resume", true);
        for _ in 0..50 {
            period();
        }
        set_bit("nurbs_interp.resume", false);
        assert!(!bit("nurbs_interp.active") && !bit("nurbs_interp.resume-ready"));
        for _ in 0..5 {
            period(); // the module empties the ring of the stopped motion
        }
        let from = nurbs_planner::feed::plan_start(&mut PathCurves::new(&job.toolpath), &stop);
        let rest = plan_groups(&job.toolpath, &job.limits, Some(&stop)).unwrap();
        let mut s = Streamer::new(
            l.channel,
            job.toolpath.tip_dim(),
            Source::groups(rest, job.limits.period),
            from.curve,
            f64::INFINITY,
            Instant::now(),
        )
        .unwrap();
        // Data but no command: the machine stays.
        let waiting = run(&mut s, 400, &mut |_| {}, &mut |_| false);
        assert!(waiting.is_empty());
        assert!(bit("nurbs_interp.resume-ready") && bit("nurbs_interp.underrun"));
        assert_eq!(out().q, held);
        set_bit("nurbs_interp.resume", true);
        let resumed = run_to_rest(&mut s, job.samples.len() + 20_000);
        set_bit("nurbs_interp.resume", false);
        assert!(bit("nurbs_interp.done"), "{name}: did not resume to the end");
        assert!(!bit("nurbs_interp.fault") && !bit("nurbs_interp.underrun"));
        assert!(stop_point(l.channel).is_none());
        // Where the machine stands (exactly, or within the module's resume tolerance where it
        // stands at an element's end and the plan starts on the next element).
        let gap = (0..3).map(|i| (resumed[0].q[i] - held[i]).abs()).fold(0.0, f64::max);
        assert!(
            gap <= nurbs_hal::module::RESUME_TOLERANCE,
            "{name}: the resumed motion starts {gap} mm from where the machine stands"
        );
        let end = job.samples.last().unwrap();
        let last = resumed.last().unwrap();
        assert_eq!(
            [last.q[0], last.q[1], last.feed],
            [end.point[0], end.point[1], 0.0],
            "{name}"
        );
        hold_position(&mut got);
        got.extend(resumed);
        assert_eq!(violations(&job, &got, true), Vec::<String>::new(), "{name}");
    }
}

/// After a stop, a plan that does not start where the machine stands (the whole path again,
/// from C(0)) is refused with a fault and the position is held.
#[test]
fn a_resume_from_elsewhere_is_refused() {
    let _guard = lock_module();
    let job = job("trident.json");
    let (l, _, _) = stop_after(&job, job.groups.len() / 2);
    let held = out().q;
    for _ in 0..5 {
        period();
    }
    let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    set_bit("nurbs_interp.resume", true);
    let got = run(&mut s, 100, &mut |_| {}, &mut |_| bit("nurbs_interp.fault"));
    assert!(got.is_empty());
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::ResumePoint as u32);
    assert_eq!(out().q, held);
}

/// Hold raised at many periods of the butterfly and of a G1 program: the module goes on to the
/// end of the group it is in, runs that group's stop, and comes to rest within the limits; the
/// running planner re-plans from there, and releasing the hold runs the rest to C(1), the whole
/// run within the limits. Abort stops the same way and discards the queue.
#[test]
fn hold_and_abort_stop_at_the_group_end_within_the_limits() {
    let _guard = lock_module();
    for (name, job) in [("butterfly", job("butterfly.json")), ("zigzag", job("zigzag_g1.ngc"))] {
        let n = job.samples.len();
        for hold_at in [n / 10, n / 3, n / 2, 3 * n / 4] {
            let l = load();
            let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
            let mut got = run(
                &mut s,
                n + 20_000,
                &mut |k| {
                    if k == hold_at {
                        set_bit("nurbs_interp.hold", true)
                    }
                },
                &mut |_| bit("nurbs_interp.held") || bit("nurbs_interp.done"),
            );
            if bit("nurbs_interp.done") {
                // Held during the last group: the motion ends at C(1).
                set_bit("nurbs_interp.hold", false);
                assert_exact(name, &got, &job.samples, 2);
                continue;
            }
            let stop = stop_point(l.channel).expect("a hold stop point");
            assert_eq!(stop.cause, 2);
            let at_rest = got.len();
            let latency = (at_rest - hold_at) as f64 * PERIOD;
            assert_eq!(
                violations(&job, &got, false),
                Vec::<String>::new(),
                "{name} hold at {hold_at}"
            );
            for _ in 0..5 {
                period();
            }
            let from = nurbs_planner::feed::plan_start(&mut PathCurves::new(&job.toolpath), &stop);
            let rest = plan_groups(&job.toolpath, &job.limits, Some(&stop)).unwrap();
            drop(s);
            let mut s = Streamer::new(
                l.channel,
                job.toolpath.tip_dim(),
                Source::groups(rest, job.limits.period),
                from.curve,
                f64::INFINITY,
                Instant::now(),
            )
            .unwrap();
            let waiting = run(&mut s, 100, &mut |_| {}, &mut |_| false);
            assert!(waiting.is_empty() && bit("nurbs_interp.resume-ready"));
            set_bit("nurbs_interp.hold", false);
            hold_position(&mut got);
            got.extend(run_to_rest(&mut s, n + 20_000));
            assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault"), "{name}");
            assert_eq!(
                violations(&job, &got, true),
                Vec::<String>::new(),
                "{name} hold at {hold_at}"
            );
            println!("{name}: hold at period {hold_at}: at rest after {latency:.3} s, resumed to C(1)");
        }
        // Abort: the same stop, then the queue is gone and nothing resumes.
        let l = load();
        let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
        let got = run(
            &mut s,
            n + 20_000,
            &mut |k| {
                if k == n / 3 {
                    set_bit("nurbs_interp.abort", true)
                }
            },
            &mut |_| bit("nurbs_interp.held"),
        );
        assert_eq!(violations(&job, &got, false), Vec::<String>::new(), "{name} abort");
        for _ in 0..5 {
            period();
        }
        assert!(l.channel.segments.is_empty() && stop_point(l.channel).is_none());
        set_bit("nurbs_interp.abort", false);
        for _ in 0..100 {
            period();
            assert!(!bit("nurbs_interp.active"));
        }
    }
}

/// The raw stream of a job: every curve published, nothing else.
fn raw_stream<'a>(l: &'a Loaded, job: &Job) -> GeometryWriter<'a> {
    let mut w = GeometryWriter::begin(l.channel, 0, job.toolpath.tip_dim(), PERIOD).unwrap();
    for e in &job.toolpath.elements {
        let c = &e.curve;
        w.publish_curve(c.degree(), c.dim(), c.knots(), c.points(), c.weights())
            .unwrap();
    }
    w
}

fn slots_of(job: &Job) -> Vec<SegmentSlot> {
    job.groups.iter().flat_map(|g| g.slots.clone()).collect()
}

/// The module takes a group only whole: with all but its last record queued nothing moves
/// (before the first record) or the motion stops at the group end before it (underrun); the
/// last record arriving lets it go on.
#[test]
fn a_group_is_taken_only_whole() {
    let _guard = lock_module();
    let job = job("zigzag_g1.ngc");
    let long = job.groups.iter().position(|g| g.slots.len() >= 3).unwrap();
    let slots = slots_of(&job);
    let first: usize = job.groups[..long].iter().map(|g| g.slots.len()).sum();
    let l = load();
    let _w = raw_stream(&l, &job);
    let push = |range: std::ops::Range<usize>| {
        for s in &slots[range] {
            l.channel.segments.producer().push(&Slot::segment(s)).unwrap();
        }
    };
    if long == 0 {
        push(0..job.groups[0].slots.len() - 1);
        for _ in 0..100 {
            period();
            assert!(!bit("nurbs_interp.active"), "started before its first group was whole");
        }
        return;
    }
    // Everything before the long group, and that group but for its last record.
    let group_end = first + job.groups[long].slots.len();
    push(0..group_end - 1);
    let mut got = Vec::new();
    for _ in 0..job.samples.len() + 20_000 {
        period();
        if bit("nurbs_interp.active") {
            got.push(out());
        }
        if bit("nurbs_interp.held") {
            break;
        }
    }
    assert!(bit("nurbs_interp.underrun"), "stopped before the incomplete group");
    assert_eq!(
        u32_pin("nurbs_interp.records") as usize,
        first,
        "took none of the incomplete group"
    );
    assert_eq!(violations(&job, &got, false), Vec::<String>::new());
}

/// Malformed slots fault with the position held: a sequence gap, a record that does not check,
/// a stop that is not a record ending at rest after it, group fields that do not fit, a path
/// block in a segment motion.
#[test]
fn malformed_slots_fault_and_hold() {
    let _guard = lock_module();
    let job = job("trident.json");
    let slots = slots_of(&job);
    let with_stop = slots.iter().position(|s| s.has_stop == 1).unwrap();
    type Tamper = fn(&mut SegmentSlot);
    let cases: [(&str, Tamper, FaultCode); 8] = [
        ("sequence", |s| s.record.seq += 1, FaultCode::Sequence),
        ("NaN", |s| s.record.durations[3] = f64::NAN, FaultCode::Record),
        ("length", |s| s.record.length *= 2.0, FaultCode::Record),
        ("curve beyond the group's", |s| s.record.curve = 7, FaultCode::Record),
        ("stop sequence", |s| s.stop.seq += 5, FaultCode::Record),
        ("stop not at rest", |s| s.stop.jerks = [0.0; 7], FaultCode::Record),
        ("inner stop", |s| s.group_left = 2, FaultCode::Record),
        ("no stop", |s| s.has_stop = 0, FaultCode::Record),
    ];
    for (name, tamper, code) in cases {
        let l = load();
        let _w = raw_stream(&l, &job);
        let mut bad = slots.clone();
        tamper(&mut bad[with_stop]);
        for s in &bad[..=with_stop] {
            l.channel.segments.producer().push(&Slot::segment(s)).unwrap();
        }
        for _ in 0..job.samples.len() {
            period();
            if bit("nurbs_interp.fault") {
                break;
            }
        }
        assert_eq!(u32_pin("nurbs_interp.fault-code"), code as u32, "{name}");
        let held = out().q;
        for s in &slots[with_stop + 1..] {
            let _ = l.channel.segments.producer().push(&Slot::segment(s));
        }
        for _ in 0..100 {
            period();
            assert!(!bit("nurbs_interp.active"), "{name}: moved after the fault");
        }
        assert_eq!(out().q, held, "{name}");
    }
    // A path block in a segment motion.
    let l = load();
    let _w = raw_stream(&l, &job);
    l.channel.segments.producer().push(&Slot::segment(&slots[0])).unwrap();
    let mut block = Slot::segment(&slots[1]);
    block.kind = KIND_BLOCK;
    l.channel.segments.producer().push(&block).unwrap();
    for _ in 0..job.samples.len() {
        period();
        if bit("nurbs_interp.fault") {
            break;
        }
    }
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::RecordKind as u32);
}

/// Malformed hold stops in the arena fault the module on a hold (never a loop without end in
/// the servo thread's search, never a step): a sample index that is not a number, a stored
/// sequence whose count is not whole or whose offset points into the triples, and one whose
/// positions are not numbers (found as it is played).
#[test]
fn malformed_hold_stops_fault_and_hold() {
    use nurbs_planner::writer::Release;
    let _guard = lock_module();
    let job = job("trident.json");
    let slots = slots_of(&job);
    let end = slots.iter().position(|s| s.has_stop == 1).unwrap();
    let cases: [(&str, Vec<f64>, FaultCode); 4] = [
        ("sample not a number", vec![f64::NAN, 1.0, 1.0], FaultCode::Record),
        ("count not whole", vec![20.0, -2.5, 3.0], FaultCode::Record),
        ("offset into the triples", vec![20.0, -5.0, 0.0], FaultCode::Record),
        (
            "positions not numbers",
            vec![20.0, -2.0, 3.0, 0.0, 2.0, 0.0, f64::NAN, f64::NAN, f64::NAN, f64::NAN],
            FaultCode::BlockPath,
        ),
    ];
    for (name, values, code) in cases {
        let l = load();
        let mut w = raw_stream(&l, &job);
        let offset = w.put(&values, Release::Slot(u64::MAX)).unwrap();
        let mut bad = slots.clone();
        bad[0].hold_stops_offset = offset;
        bad[0].hold_stops_len = 1;
        for s in &bad[..=end] {
            l.channel.segments.producer().push(&Slot::segment(s)).unwrap();
        }
        // Raised once the motion runs (a motion does not start under hold).
        for k in 0..job.samples.len() {
            set_bit("nurbs_interp.hold", k >= 5);
            period();
            if bit("nurbs_interp.fault") || bit("nurbs_interp.held") {
                break;
            }
        }
        set_bit("nurbs_interp.hold", false);
        assert_eq!(u32_pin("nurbs_interp.fault-code"), code as u32, "{name}");
        let held = out().q;
        for _ in 0..100 {
            period();
            assert!(!bit("nurbs_interp.active"), "{name}: moved after the fault");
        }
        assert_eq!(out().q, held, "{name}");
    }
}

/// The plan streamed from its own thread while the module runs (as `nurbs-planner` runs it):
/// the module starts once the start rule holds, runs with no underrun and equals the offline
/// streamed plan bit for bit.
#[test]
fn a_streamed_plan_runs_through_the_module_while_it_is_planned() {
    let _guard = lock_module();
    let job = job_of(g1_zigzag(60));
    let l = load();
    let path = SharedPath::whole(&job.toolpath);
    let source = Source::streamed(path.clone(), job.limits.clone(), None, 1.0);
    let began = Instant::now();
    let mut s = Streamer::new(l.channel, job.toolpath.tip_dim(), source, 0, 0.5, began).unwrap();
    // The module at 8 times the real pace (the planner is far faster than that here).
    let mut paced = Pace::new(began, 8.0);
    let mut pace = |_: usize| paced.wait();
    // The path the plans share is forgotten behind the module as it goes.
    let mut kept_behind = Vec::new();
    let got = run(&mut s, job.samples.len() + 200_000, &mut pace, &mut |_| {
        let (first, _) = path.kept();
        kept_behind.push((first, u32_pin("nurbs_interp.curve") as usize));
        bit("nurbs_interp.done") || bit("nurbs_interp.fault") || bit("nurbs_interp.held")
    });
    assert_exact("streamed zigzag", &got, &job.samples, 2);
    assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
    let elements = job.toolpath.elements.len();
    // Never past the module (a plan may start where it stands), trailing it by at most a few
    // elements (those of the oldest group a cut may replay), to the path's end.
    assert!(
        kept_behind.iter().all(|&(first, curve)| first <= curve),
        "released ahead of the module"
    );
    let lag = kept_behind.iter().map(|&(first, curve)| curve - first).max().unwrap();
    assert!(lag <= 8, "the path kept {lag} elements behind the module");
    assert!(
        kept_behind.last().unwrap().0 + 8 >= elements,
        "{:?} of {elements}",
        kept_behind.last()
    );
}

/// A new geometry stream starts a new motion after a motion that is done, stopped by an
/// underrun (and aborted), or aborted before it started: each runs the whole trident exactly.
#[test]
fn a_new_stream_starts_a_new_motion_after_done_underrun_or_abort() {
    let _guard = lock_module();
    let job = job("trident.json");
    let l = load();
    let whole = |l: &Loaded| {
        let mut s = streamer(l, &job.toolpath, job.groups.clone(), 0);
        let got = run_to_rest(&mut s, job.samples.len() + 100);
        assert_exact("trident", &got, &job.samples, 2);
    };
    whole(&l);
    // Done, then a new motion.
    whole(&l);
    // An underrun stop, aborted, then a new motion.
    {
        let mut s = streamer(&l, &job.toolpath, job.groups[..2].to_vec(), 0);
        run_to_rest(&mut s, job.samples.len());
        assert!(bit("nurbs_interp.held"));
    }
    set_bit("nurbs_interp.abort", true);
    period();
    set_bit("nurbs_interp.abort", false);
    period();
    whole(&l);
}

/// The butterfly's plan in the ring and the plan at feed override 0.5 that cuts into one of
/// its records ([`nurbs_planner::cut`]) at a checked hold stop two thirds into it: the old
/// plan's samples up to the cut, then the interpolator from that very sample through the new
/// plan's records (its ramp started with the sample's acceleration), to the path end.
fn cut_case(job: &Job) -> (usize, u64, Vec<SegmentSlot>, Vec<nurbs_rtcore::interpolator::Sample>) {
    use nurbs_planner::cut::CutFrom;
    use nurbs_planner::feed::{stream_plan, PlanEvent, StreamStart};
    use nurbs_rtcore::interpolator::{Interpolator, Step};
    let (g, i) = (1..job.groups.len())
        .find_map(|g| {
            let i = job.groups[g].hold_stops.iter().position(|h| h.count >= 6)?;
            Some((g, i))
        })
        .expect("a record with hold stops past the first group");
    let group = &job.groups[g];
    let k = job.groups[..g].iter().map(|g| g.slots.len()).sum::<usize>() + i;
    let samples: Vec<u64> = group.hold_stops[i].samples().collect();
    let at_sample = samples[2 * samples.len() / 3];
    let from = CutFrom {
        begin: **group.begin.as_ref().expect("the group's begin state"),
        records: group.slots[..=i].iter().map(|s| s.record).collect(),
        candidates: vec![(i, at_sample)],
        feed_override: 1.0,
    };
    let mut new_slots = Vec::new();
    let start = StreamStart::Cut {
        from: Box::new(from),
        send_from: job.toolpath.elements.len(),
    };
    let toolpath = job.toolpath.clone();
    stream_plan(&|| Ok(PathCurves::new(&toolpath)), &job.limits, start, 0.5, &mut |e| {
        match e {
            PlanEvent::Group(g) => new_slots.extend(g.slots),
            PlanEvent::Failed(e) => panic!("the cut's plan: {e}"),
            PlanEvent::Done { .. } => {}
        }
        true
    });
    let curves = PathCurves::new(&job.toolpath);
    let mut interp = Interpolator::new();
    let mut old = slots_of(job).into_iter().map(|s| s.record);
    let mut expected = Vec::new();
    while expected.len() as u64 <= at_sample {
        match interp.step(&curves, PERIOD, &mut || old.next()) {
            Step::Sample(s) => expected.push(s),
            other => panic!("the old plan before the cut: {other:?}"),
        }
    }
    let at = *expected.last().unwrap();
    let ramp = new_slots[0].record;
    assert_eq!(
        (ramp.curve(), ramp.u_start.to_bits(), ramp.feed_start.to_bits()),
        (at.curve, at.u.to_bits(), at.feed.to_bits()),
        "the ramp starts at the sample"
    );
    assert!(interp.start_profile(&curves, ramp, ramp.profile().table_from(at.accel)));
    let mut rest = new_slots[1..].iter().map(|s| s.record);
    loop {
        match interp.step(&curves, PERIOD, &mut || rest.next()) {
            Step::Sample(s) => expected.push(s),
            Step::Finished => break,
            other => panic!("the new plan: {other:?}"),
        }
    }
    (k, at_sample, new_slots, expected)
}

/// A plan at another feed override cutting into a record the module runs (asked through the
/// channel's [`nurbs_hal::channel::Splice`] with the motion sample): the module cuts in at
/// exactly that sample and its samples are the old plan's up to there and the new plan's from
/// there, bit for bit, within the limits, to the path end. And where the new plan is not in
/// the ring by that sample (its planner came late), the module misses the join and stops there
/// with the sample's checked hold stop, within the limits, as an underrun.
#[test]
fn the_module_cuts_a_new_plan_into_a_running_record_or_stops_at_the_cut() {
    use nurbs_hal::channel::{Join, SPLICE_ACCEPTED, SPLICE_DONE, SPLICE_MISSED};
    let _guard = lock_module();
    let job = job("butterfly.json");
    let (k, at_sample, new_slots, expected) = cut_case(&job);
    assert!(
        expected[..=at_sample as usize]
            .iter()
            .zip(&job.samples)
            .all(|(a, b)| a.point == b.point),
        "the replica up to the cut is the plan"
    );
    for late in [false, true] {
        let l = load();
        let ring = l.channel.segments.producer();
        let base = ring.pushed();
        // The old plan as the planner sends it (its hold stops in the arena), until the join
        // is asked.
        let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
        let mut got: Vec<Out> = Vec::new();
        let step = |got: &mut Vec<Out>| {
            assert!(!period(), "the update path allocated");
            if bit("nurbs_interp.active") {
                got.push(out());
            }
        };
        while (got.len() as u64) + 100 < at_sample {
            s.fill().unwrap();
            step(&mut got);
        }
        assert!(l.channel.splice.request(Join {
            after: base.wrapping_add(k as u32),
            drop_to: ring.pushed(),
            at_sample,
        }));
        step(&mut got);
        assert_eq!(l.channel.splice.state(), SPLICE_ACCEPTED);
        if !late {
            for s in &new_slots {
                ring.push(&Slot::segment(s)).unwrap();
            }
        }
        for _ in 0..expected.len() + 20_000 {
            step(&mut got);
            if bit("nurbs_interp.done") || bit("nurbs_interp.fault") || bit("nurbs_interp.held") {
                break;
            }
        }
        assert!(
            !bit("nurbs_interp.fault"),
            "fault {}",
            u32_pin("nurbs_interp.fault-code")
        );
        if late {
            assert_eq!(l.channel.splice.state(), SPLICE_MISSED);
            assert!(bit("nurbs_interp.held") && bit("nurbs_interp.underrun"));
            assert_exact(
                "butterfly up to the cut",
                &got[..=at_sample as usize],
                &job.samples[..=at_sample as usize],
                2,
            );
            assert!(got.len() > at_sample as usize + 1, "a stop after the cut");
            let mut held = got.clone();
            hold_position(&mut held);
            assert_eq!(violations(&job, &held, false), Vec::<String>::new());
            println!(
                "late: stopped {} samples after the cut",
                got.len() - at_sample as usize - 1
            );
        } else {
            assert!(bit("nurbs_interp.done"));
            assert_eq!(l.channel.splice.state(), SPLICE_DONE);
            assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
            assert_exact("butterfly cut at feed override 0.5", &got, &expected, 2);
            assert_eq!(violations(&job, &got, true), Vec::<String>::new());
            // From the ramp's end on, within the new override's feed.
            let ramp_end = at_sample as usize + (new_slots[0].record.profile().total_time() / PERIOD).ceil() as usize;
            let cap = 0.5 * job.limits.feed * (1.0 + 1e-9);
            let fastest = got[ramp_end + 1..].iter().map(|o| o.feed).fold(0.0, f64::max);
            assert!(fastest <= cap, "feed {fastest} after the ramp, over {cap}");
            println!(
                "cut after sample {at_sample} of {}: {} samples at 0.5",
                job.samples.len(),
                got.len()
            );
        }
    }
}

/// A feed override change while a streamed plan of the trident (at F250) runs through the
/// module (as `nurbs-planner` carries it out): the rest of the motion is planned again from a
/// group end still in the ring, and the module, asked, drops the old plan's records after it
/// and runs into the new plan there. The motion up to the join is the plan at the old override
/// bit for bit; every sample passes the finite-difference check (across the joins too); the
/// feed comes under the new cap after the ramp down and stays there; no underrun; the motion
/// ends at the path end. Then back up to 100 %.
#[test]
fn a_feed_override_change_is_planned_anew_and_the_module_runs_into_it() {
    let _guard = lock_module();
    let toolpath = prepare(
        &examples().join("trident.json"),
        Some(RoundCorners::Auto),
        &chord_tolerance(0.001),
    )
    .unwrap()
    .toolpath;
    let limits = nurbs_motion::planner::presets::named("table3-f250")
        .on(2)
        .for_axes(2)
        .unwrap();
    assert_eq!(limits.period, PERIOD);
    let unchanged = {
        let groups = plan_groups(&toolpath, &limits, None).unwrap();
        let records: Vec<_> = groups.iter().flat_map(|g| g.slots.iter().map(|s| s.record)).collect();
        setpoints(&PathCurves::new(&toolpath), &limits, &records)
    };
    let l = load();
    // Down to 20 % at 0.25 s of motion, back to 100 % at 0.75 s; the module at twice the real
    // pace at most.
    let low = 0.2;
    let changes = [(1000, low), (3000, 1.0)];
    let mut queued_at_change = Vec::new();
    let (got, s) = paced_run(&l, &toolpath, &limits, 2.0, 200_000, |s, samples| {
        if let Some(&(_, ov)) = changes.iter().find(|(at, _)| *at == samples) {
            if queued_at_change.len() < changes.len() && queued_at_change.last() != Some(&(samples, ov)) {
                s.set_feed_override(ov);
                queued_at_change.push((samples, ov));
                eprintln!("override {ov} at sample {samples}: {:.3} s queued", s.buffered());
            }
        }
    });
    assert!(
        bit("nurbs_interp.done"),
        "the motion ends at the path end: {} samples ({} planned at 100 %; {} slots sent, done {}, {:?}), fault {}, held {}, underruns {}",
        got.len(),
        unchanged.len(),
        s.pushed,
        s.done(),
        s.plan_error(),
        u32_pin("nurbs_interp.fault-code"),
        bit("nurbs_interp.held"),
        u32_pin("nurbs_interp.underruns")
    );
    assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
    // Every sample within the limits (the programmed feed at its highest override, 100 %).
    let checked = Job {
        toolpath: toolpath.clone(),
        limits: limits.clone(),
        groups: Vec::new(),
        samples: Vec::new(),
    };
    let found = violations(&checked, &got, true);
    assert!(found.is_empty(), "{found:?}");
    // Before the first join, the plan at 100 % bit for bit.
    let first_change = queued_at_change[0].0;
    let same = got
        .iter()
        .zip(&unchanged)
        .take_while(|(g, e)| g.q[0].to_bits() == e.point[0].to_bits() && g.q[1].to_bits() == e.point[1].to_bits())
        .count();
    assert!(
        same > first_change,
        "the motion changed before the override did ({same} samples the same)"
    );
    // After the change to 20 %, the feed is under the new cap from some point before the
    // change back, and stays there until then.
    let cap = low * limits.feed * (1.0 + 1e-6);
    let back = queued_at_change.get(1).map_or(got.len(), |c| c.0);
    let last_above = (first_change..back)
        .rev()
        .find(|&k| got[k].feed > cap)
        .unwrap_or(first_change);
    let latency = (last_above + 1 - first_change) as f64 * PERIOD;
    eprintln!(
        "feed under {low} of F {} mm/s {:.1} ms after the change (the motion {:.3} s, unchanged {:.3} s); {same} samples as planned at 100 %",
        limits.feed,
        latency * 1e3,
        got.len() as f64 * PERIOD,
        unchanged.len() as f64 * PERIOD
    );
    assert!(last_above + 1 < back, "the feed never came under the new cap");
    eprintln!(
        "joins: {} cutting into a record, {} at a group end in the ring, {} at the end of the slots sent",
        s.cuts, s.joins_in_ring, s.joins_at_end
    );
    assert!(s.cuts + s.joins_in_ring >= 1, "no join inside the ring");
    // Slower at 50 % for a while: the motion takes longer than the plan at 100 %.
    assert!(got.len() > unchanged.len());
}

/// The join of a plan at another feed override ([`nurbs_hal::channel::Splice`]), asked of the
/// module directly: a join after a record the module has finished is missed; one after a group
/// end still queued is accepted, and there the module drops the records queued after it and
/// runs on with what follows. With the same records pushed again as the "new plan", the motion
/// is the plan's bit for bit, and the join reports done.
#[test]
fn the_module_joins_a_new_plan_at_a_queued_group_end_and_drops_the_old_records() {
    use nurbs_hal::channel::{Join, AT_RECORD_END, SPLICE_ACCEPTED, SPLICE_DONE, SPLICE_MISSED};
    let _guard = lock_module();
    let job = job("butterfly.json");
    let slots = slots_of(&job);
    let ends: Vec<usize> = (0..slots.len()).filter(|&k| slots[k].group_left == 1).collect();
    assert!(ends.len() >= 4, "{} groups", ends.len());
    let l = load();
    let _w = raw_stream(&l, &job);
    let ring = l.channel.segments.producer();
    let base = ring.pushed();
    for s in &slots {
        ring.push(&Slot::segment(s)).unwrap();
    }
    let taken = || ring.taken().wrapping_sub(base) as usize;
    let mut got: Vec<Out> = Vec::new();
    let step = |got: &mut Vec<Out>| {
        assert!(!period(), "the update path allocated");
        if bit("nurbs_interp.active") {
            got.push(out());
        }
    };
    // Past the first group.
    while taken() <= ends[0] + 1 {
        step(&mut got);
    }
    let at_end = |k: usize| Join {
        after: base.wrapping_add(k as u32),
        drop_to: ring.pushed(),
        at_sample: AT_RECORD_END,
    };
    assert!(l.channel.splice.request(at_end(ends[0])));
    step(&mut got);
    assert_eq!(l.channel.splice.state(), SPLICE_MISSED, "a join behind the module");
    // A group end still queued: accepted; the records after it again, as the new plan.
    let join = *ends.iter().find(|&&k| k > taken()).unwrap();
    assert!(l.channel.splice.request(at_end(join)));
    step(&mut got);
    assert_eq!(l.channel.splice.state(), SPLICE_ACCEPTED);
    for s in &slots[join + 1..] {
        ring.push(&Slot::segment(s)).unwrap();
    }
    for _ in 0..job.samples.len() + 1000 {
        step(&mut got);
        if bit("nurbs_interp.done") || bit("nurbs_interp.fault") || bit("nurbs_interp.held") {
            break;
        }
    }
    assert!(bit("nurbs_interp.done"), "fault {}", u32_pin("nurbs_interp.fault-code"));
    assert_eq!(l.channel.splice.state(), SPLICE_DONE);
    assert_exact("butterfly joined", &got, &job.samples, 2);
    assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
}
