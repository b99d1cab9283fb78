//! A hold that acts at once: raised at random samples of the bundled curves, a G1 program and a
//! long straight line, the module leaves the plan at the next checked stop inside the record
//! (`nurbs_planner::hold_stops`, every 20 samples where one passes) or, failing one, at the
//! group's end. Every stop stays within the axis limits (the project's check over the whole
//! sampled run, at rest after it); the latency from the edge to the first sample that leaves
//! the plan is collected and its distribution printed, and next to it the latency until the
//! tool decelerates: the first sample from which its feed falls at every sample to rest, where
//! that comes before the plan is left (a hold while the plan itself brakes into
//! sharp curvature at the jerk limit follows that braking to the next stop). `HOLD_INSTANTS`
//! (default 12 per path) selects a longer run, `HOLD_RESERVE` plans every path with that hold
//! reserve (`--hold-reserve`); docs/testing.md records one of 1,000.

mod common;

use common::test_paths::{g1_zigzag, line};
use common::*;
use nurbs_hal::mock;
use nurbs_planner::hold_stops::HOLD_STOP_SPACING;

/// Holds at sample `at`: the samples up to rest (with the machine holding after), and the
/// latency in samples from the edge to the first sample that is not the plan's (`None` if
/// the motion ended at C(1) first: a hold in the last group without a stop inside it).
fn hold_at(job: &Job, at: usize) -> (Vec<Out>, Option<usize>) {
    hold_by(job, at, &|on| set_bit("nurbs_interp.hold", on))
}

/// [`hold_at`] with the hold raised and released by `raise`.
fn hold_by(job: &Job, at: usize, raise: &dyn Fn(bool)) -> (Vec<Out>, Option<usize>) {
    let l = load();
    let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    let mut got: Vec<Out> = Vec::new();
    for _ in 0..job.samples.len() + 20_000 {
        s.fill().unwrap();
        if got.len() >= at {
            raise(true);
        }
        assert!(!period(), "the update path allocated");
        if bit("nurbs_interp.active") {
            got.push(out());
        }
        if bit("nurbs_interp.held") || bit("nurbs_interp.done") || bit("nurbs_interp.fault") {
            break;
        }
    }
    assert!(
        !bit("nurbs_interp.fault"),
        "fault {}",
        u32_pin("nurbs_interp.fault-code")
    );
    let left = got
        .iter()
        .zip(&job.samples)
        .position(|(o, e)| o.q[0] != e.point[0] || o.q[1] != e.point[1]);
    let latency = if bit("nurbs_interp.done") {
        assert!(left.is_none());
        None
    } else {
        Some(left.unwrap_or(got.len()).saturating_sub(at))
    };
    raise(false);
    drop(l);
    hold_position(&mut got);
    (got, latency)
}

/// Samples from the edge at `at` until the tool decelerates to rest in `got` (a hold that
/// left the plan `latency` samples after the edge): the first sample from which the module's
/// feed falls at every sample until it is at rest, if that comes before the plan was left; else
/// the latency itself.
fn braking_latency(got: &[Out], at: usize, latency: usize) -> usize {
    let rest = (at..got.len()).find(|&k| got[k].feed <= 0.0).unwrap_or(got.len());
    // The last sample before rest whose feed did not fall: the deceleration starts there.
    let from = (at.max(1)..rest)
        .rev()
        .find(|&k| got[k].feed >= got[k - 1].feed)
        .unwrap_or(at);
    from.saturating_sub(at).min(latency)
}

/// Median, 90 %, 99 % and worst of sorted latencies (samples), and how many are within one
/// hold-stop spacing.
fn distribution(sorted: &[usize]) -> String {
    let q = |p: f64| quantile(sorted, p);
    let spacing = HOLD_STOP_SPACING as usize + 1;
    format!(
        "median {}, 90 % {}, 99 % {}, worst {}; within {spacing} samples: {} of them",
        q(0.5),
        q(0.9),
        q(0.99),
        sorted.last().copied().unwrap_or(0),
        sorted.iter().filter(|&&l| l <= spacing).count()
    )
}

#[test]
fn a_hold_leaves_the_plan_within_a_few_milliseconds_within_the_limits() {
    let _guard = lock_module();
    let per_path: usize = std::env::var("HOLD_INSTANTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(12);
    let jobs = [
        ("trident", job("trident.json")),
        ("butterfly", job("butterfly.json")),
        ("star_g1", job("star_g1.ngc")),
        ("G1 zigzag", job_of(g1_zigzag(150))),
        (
            "dense G1 rounded (600 lines)",
            job_rounded(&dense_g1(600, &std::env::temp_dir())),
        ),
        ("2000 mm line", job_of(line(2000.0))),
        ("dense G1 (2000 lines)", job_at(&dense_g1(2000, &std::env::temp_dir()))),
    ];
    let mut instants = Instants::new(0x2545_f491_4f6c_dd1d);
    let mut all = Vec::new();
    for (name, job) in &jobs {
        let n = job.samples.len();
        let (mut latencies, mut braking) = (Vec::new(), Vec::new());
        let mut ended = 0;
        for _ in 0..per_path {
            let at = instants.next(n - 2);
            let (got, latency) = hold_at(job, at);
            assert_eq!(
                violations(job, &got, false),
                Vec::<String>::new(),
                "{name}: hold at sample {at}"
            );
            match latency {
                Some(l) => {
                    latencies.push(l);
                    braking.push(braking_latency(&got, at, l));
                }
                None => ended += 1,
            }
        }
        latencies.sort_unstable();
        braking.sort_unstable();
        println!(
            "{name}: {per_path} holds, samples of {:.2} ms; {ended} in the last group ended at C(1)",
            PERIOD * 1e3
        );
        println!("  leaves the plan after {}", distribution(&latencies));
        println!("  decelerates to rest after {}", distribution(&braking));
        all.extend(latencies);
    }
    // On the dense program most stops inside records would leave their 0.02 mm element; the
    // planner offers stops at record ends inside its settled runs instead, a group each.
    let dense = &jobs[4].1;
    let mean_group = dense.groups.iter().map(|g| g.time).sum::<f64>() / dense.groups.len() as f64;
    println!(
        "dense G1: {} groups, {:.1} ms of motion each on average",
        dense.groups.len(),
        mean_group * 1e3
    );
    assert!(mean_group < 0.05, "dense G1: groups of {mean_group} s on average");
    // On the long line every hold takes a stop inside its single record.
    let line_job = &jobs[5].1;
    let (_, latency) = hold_at(line_job, line_job.samples.len() / 3);
    assert!(
        latency.is_some_and(|l| l <= HOLD_STOP_SPACING as usize + 1),
        "the long line's hold waited {latency:?} samples"
    );
    all.sort_unstable();
    println!(
        "all paths: {} holds, median {} samples, worst {}",
        all.len(),
        all.get(all.len() / 2).copied().unwrap_or(0),
        all.last().copied().unwrap_or(0)
    );
}

/// A feed override of 0 (the operator's knob at 0 %) is a hold: the same stop, sample for
/// sample, as `hold` raised at the same sample; 1 releases it. Unconnected, the pin reads 1:
/// the motion runs.
#[test]
fn a_feed_override_of_zero_holds_as_hold_does() {
    let _guard = lock_module();
    let job = job_of(line(2000.0));
    let at = job.samples.len() / 3;
    let (held, latency) = hold_at(&job, at);
    let set_override = |v: f64| assert!(mock::set_pin("nurbs_interp.feed-override", mock::Value::Float(v)));
    let (by_override, by_override_latency) = hold_by(&job, at, &|on| set_override(if on { 0.0 } else { 1.0 }));
    assert!(latency.is_some());
    assert_eq!(by_override_latency, latency);
    assert_eq!(by_override.len(), held.len());
    assert!(by_override
        .iter()
        .zip(&held)
        .all(|(a, b)| a.q.map(f64::to_bits) == b.q.map(f64::to_bits)));
    // Unconnected (as loaded), the pin reads 1.
    let _l = load();
    assert_eq!(mock::pin("nurbs_interp.feed-override"), Some(mock::Value::Float(1.0)));
}

/// Near sharp curvature no S-curve stop passes at some samples (the trident at lab set 1: the
/// plan rides an axis limit there); the planner stores VPOp's deceleration from such a sample
/// instead. A hold raised there leaves the plan at that very sample, the module outputs exactly
/// the stored positions (the planner checked them through the module's own evaluator), comes to
/// rest at the last one and publishes it; released, the plan from there runs to C(1); the whole
/// run stays within the axis limits.
#[test]
fn a_hold_takes_the_stored_deceleration_where_no_s_curve_stop_passes() {
    let _guard = lock_module();
    let job = job("trident.json");
    let stored = job
        .groups
        .iter()
        .flat_map(|g| &g.hold_stops)
        .map(|h| h.stored())
        .sum::<usize>();
    assert!(stored > 10, "{stored} stored stops on the trident");
    let (at, len) = hold_at_stored_stop(&job, &|_| true);
    println!("trident: {stored} stored stops; the hold at sample {at} ran the stored {len} positions to rest, and the resumed plan to C(1)");
}

/// On a dense G1 program every S-curve stop leaves its 0.02 mm element (and the corner splines
/// between the lines are shorter than a period's step): the planner stores the same stop
/// across the element ends instead, so that nearly every sample a stop is offered at has one.
/// A hold at one that passes over a whole element within one period runs it as stored.
#[test]
fn on_dense_g1_the_stops_run_across_short_elements() {
    let _guard = lock_module();
    let job = job_rounded(&dense_g1(300, &std::env::temp_dir()));
    let stops = offered_stops(&job);
    let candidates = job.samples.len() as u64 / HOLD_STOP_SPACING;
    let offered = stops.iter().filter(|&&n| n % HOLD_STOP_SPACING == 0).count() as u64;
    assert!(
        offered * 10 >= candidates * 9,
        "stops at {offered} of {candidates} samples a stop is offered at"
    );
    let skips = |positions: &[(usize, f64)]| positions.windows(2).any(|w| w[1].0 > w[0].0 + 1);
    let (at, len) = hold_at_stored_stop(&job, &skips);
    println!(
        "dense G1 (300 lines): stops at {offered} of {candidates} samples offered; the hold at sample {at} ran the stored {len} positions (past an element within one step) to rest"
    );
}

/// On a G1 program with rounded corners a stop is offered at every candidate sample: where no
/// S-curve stop passes (near the corners), VPOp's stored deceleration does, tried at every such
/// candidate. The stops inside records lie at most one spacing apart, but where a group ends
/// between two candidates (its last sample is a candidate of its own) by a sample or two. A hold
/// at the first stored one runs its positions exactly, within the limits, and resumes to C(1).
#[test]
fn on_g1_corners_every_candidate_has_a_stop() {
    let _guard = lock_module();
    let job = job_of(g1_zigzag(40));
    let stops = offered_stops(&job);
    let stored: usize = job.groups.iter().flat_map(|g| &g.hold_stops).map(|h| h.stored()).sum();
    let widest = stops.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(u64::MAX);
    assert!(stored > 0, "no stored stop on the zigzag's corners");
    assert!(
        widest <= HOLD_STOP_SPACING + 2,
        "stops {widest} samples apart somewhere ({} stops, {stored} stored)",
        stops.len()
    );
    let (at, len) = hold_at_stored_stop(&job, &|_| true);
    println!(
        "G1 zigzag (40 lines): {} stops, {stored} stored, at most {widest} samples apart; the hold at sample {at} ran the stored {len} positions to rest",
        stops.len()
    );
}

/// The motion samples the planner offers a stop inside the records at, in order.
/// With a hold reserve (`--hold-reserve`: the plan leaves a share of every axis' jerk unused,
/// the stops keep the full limits) the trident and the butterfly have a stop at every candidate
/// sample, where without one some candidates have none on the way into their sharpest
/// curvature (the plan rides an axis' jerk limit there; measured 40 samples on the trident, 120
/// on the butterfly; checked here as the control);
/// holds raised where that stretch lies on the path stay within the limits and leave the plan
/// within a spacing, and the whole plan passes the finite-difference check. Prints both motion
/// times (the price: some 4-5 % more).
#[test]
fn with_a_hold_reserve_every_candidate_has_a_stop() {
    let _guard = lock_module();
    let widest_gap = |job: &Job| {
        let mut stops = offered_stops(job);
        stops.sort_unstable();
        stops
            .windows(2)
            .map(|w| (w[1] - w[0], w[0]))
            .max()
            .unwrap_or((u64::MAX, 0))
    };
    for name in ["trident.json", "butterfly.json"] {
        let toolpath = prepared(&examples().join(name));
        let lab = lab1(toolpath.tip_dim());
        let plain = job_within(toolpath.clone(), lab.clone());
        let (gap, gap_at) = widest_gap(&plain);
        assert!(
            gap > HOLD_STOP_SPACING + 2,
            "{name}: without a reserve the stops are at most {gap} samples apart"
        );
        let job = job_within(
            toolpath,
            nurbs_motion::planner::Limits {
                hold_reserve: HOLD_RESERVE,
                ..lab
            },
        );
        let (widest, _) = widest_gap(&job);
        let motion = |j: &Job| j.samples.len() as f64 * j.limits.period;
        println!(
            "{name}: stops at most {gap} samples apart, motion {:.4} s; with hold reserve {HOLD_RESERVE}: at most {widest} apart, motion {:.4} s (+{:.1} %)",
            motion(&plain),
            motion(&job),
            100.0 * (motion(&job) / motion(&plain) - 1.0)
        );
        assert!(
            widest <= HOLD_STOP_SPACING + 2,
            "{name}: stops {widest} samples apart somewhere"
        );
        let whole: Vec<Out> = job
            .samples
            .iter()
            .map(|x| Out {
                q: [x.point[0], x.point[1], x.point[2]],
                feed: x.feed,
                u: x.u,
                curve: x.curve,
            })
            .collect();
        assert_eq!(violations(&job, &whole, true), Vec::<String>::new(), "{name}: the plan");
        // Holds where the stretch without a stop lies on the path (its place in the plan
        // without the reserve, found again by curve and parameter in the slower plan).
        let place = &plain.samples[gap_at as usize];
        let at = job
            .samples
            .iter()
            .position(|x| (x.curve, x.u) >= (place.curve, place.u))
            .expect("the stretch lies on the path");
        for at in [at, at + 30, at + 60] {
            let (got, latency) = hold_at(&job, at);
            assert_eq!(
                violations(&job, &got, false),
                Vec::<String>::new(),
                "{name}: hold at sample {at}"
            );
            assert!(
                latency.is_some_and(|l| l <= HOLD_STOP_SPACING as usize + 2),
                "{name}: the hold at sample {at} left the plan after {latency:?} samples"
            );
        }
    }
}

/// The hold reserve of [`with_a_hold_reserve_every_candidate_has_a_stop`]. Measured: 0.05 leaves
/// the trident 80 samples without a stop, 0.1 the butterfly 60; 0.11 to 0.17 close both, with
/// 3-6 % more motion time (0.13: 4.8 % and 4.4 %).
const HOLD_RESERVE: f64 = 0.13;

fn offered_stops(job: &Job) -> Vec<u64> {
    job.groups
        .iter()
        .flat_map(|g| &g.hold_stops)
        .flat_map(|h| h.samples().collect::<Vec<_>>())
        .collect()
}

/// A stored stop's positions: (element, curve parameter) each.
type Positions = Vec<(usize, f64)>;

/// Which stored stop a test takes, by its positions.
type Pick = dyn Fn(&[(usize, f64)]) -> bool;

/// The first stored stop whose positions `pick` takes, as the arena carries it: its sample and
/// positions.
fn stored_stop(job: &Job, pick: &Pick) -> (usize, Positions) {
    use nurbs_rtcore::StopRun;
    job.groups
        .iter()
        .flat_map(|g| &g.hold_stops)
        .flat_map(|h| {
            h.values[..3 * h.count].chunks_exact(3).filter(|t| t[1] < 0.0).map(|t| {
                let (count, mut k) = (-t[1] as usize, t[2] as usize);
                let mut positions = Vec::new();
                while positions.len() < count {
                    let run = StopRun::from_values(&h.values[k..]).expect("a run header");
                    k += StopRun::VALUES;
                    positions.extend(
                        h.values[k..k + 2 * run.count]
                            .chunks_exact(2)
                            .map(|p| (run.curve, p[0])),
                    );
                    k += 2 * run.count;
                }
                (t[0] as usize, positions)
            })
        })
        .find(|(_, positions)| pick(positions))
        .expect("a stored stop")
}

/// Holds at the first stored stop `pick` takes: the module leaves the plan at its sample, outputs
/// exactly its positions, rests at the last and publishes it; released, the plan from there runs
/// to C(1); the whole run within the axis limits. Its sample and length.
fn hold_at_stored_stop(job: &Job, pick: &Pick) -> (usize, usize) {
    use nurbs_motion::planner::PathCurves;
    use nurbs_rtcore::interpolator::Interpolator;
    let (at, positions) = stored_stop(job, pick);
    let curves = PathCurves::new(&job.toolpath);
    let mut eval = Interpolator::new();
    let expected: Vec<[f64; 3]> = positions
        .iter()
        .map(|&(c, u)| {
            let p = eval.point_at(&curves, c, u).unwrap();
            [p[0], p[1], p[2]]
        })
        .collect();
    let l = load();
    let mut streamer = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    let mut got: Vec<Out> = Vec::new();
    while !bit("nurbs_interp.held") && got.len() < job.samples.len() + 20_000 {
        streamer.fill().unwrap();
        set_bit("nurbs_interp.hold", got.len() >= at);
        assert!(!period(), "the update path allocated");
        assert!(
            !bit("nurbs_interp.fault"),
            "fault {}",
            u32_pin("nurbs_interp.fault-code")
        );
        if bit("nurbs_interp.active") {
            got.push(out());
        }
    }
    let held = stop_point(l.channel).expect("the stop point published");
    drop(streamer);
    // Released, it goes on from where it stands: the plan from the stop point to C(1).
    for _ in 0..5 {
        period(); // the module empties the ring of the stopped motion
    }
    let from = nurbs_planner::feed::plan_start(&mut PathCurves::new(&job.toolpath), &held);
    let rest = nurbs_planner::feed::plan_groups(&job.toolpath, &job.limits, Some(&held)).unwrap();
    let mut streamer = nurbs_planner::feed::Streamer::new(
        l.channel,
        job.toolpath.tip_dim(),
        nurbs_planner::feed::Source::groups(rest, job.limits.period),
        from.curve,
        f64::INFINITY,
        std::time::Instant::now(),
    )
    .unwrap();
    run(&mut streamer, 200, &mut |_| {}, &mut |_| false);
    set_bit("nurbs_interp.hold", false);
    let resumed = run_to_rest(&mut streamer, job.samples.len() + 20_000);
    assert!(
        bit("nurbs_interp.done") && !bit("nurbs_interp.fault"),
        "resumed to C(1)"
    );
    drop(streamer);
    drop(l);
    let latency = got
        .iter()
        .zip(&job.samples)
        .position(|(o, e)| o.q[0] != e.point[0] || o.q[1] != e.point[1]);
    assert_eq!(
        latency,
        Some(at + 1),
        "the hold at sample {at} left the plan at {latency:?}"
    );
    assert_eq!(
        got[at].q,
        [
            job.samples[at].point[0],
            job.samples[at].point[1],
            job.samples[at].point[2]
        ]
    );
    let stop: Vec<[f64; 3]> = got[at + 1..at + 1 + expected.len()].iter().map(|o| o.q).collect();
    assert_eq!(stop, expected, "the module's stop is the stored sequence");
    let (last_curve, last_u) = *positions.last().unwrap();
    assert_eq!((held.curve as usize, held.u), (last_curve, last_u));
    hold_position(&mut got);
    got.extend(resumed);
    assert_eq!(violations(job, &got, true), Vec::<String>::new());
    (at, expected.len())
}

/// On straight elements the planner accepts a hold stop from its profile alone
/// (`HoldStops::passes_on_line`); simulated through the interpolator and checked by finite
/// differences instead, every one of them passes, with the same deceleration and jerk, on a
/// long line and on G1 programs (lines between rounded corners). The profile is the stricter
/// judge: it refuses a stop whose feed peaks above the cap between two samples, which the
/// samples do not show (where the plan accelerates at the limits along a line up to the cap);
/// such a sample gets a stored stop instead, or none. At most 1 % of the stops differ so.
#[test]
fn stops_on_lines_accepted_by_their_profile_pass_the_simulation() {
    use nurbs_motion::planner::PathCurves;
    use nurbs_planner::hold_stops::{HoldStops, RecordStops};
    for (name, job) in [
        ("2000 mm line", job_of(line(2000.0))),
        ("star_g1", job("star_g1.ngc")),
        ("G1 zigzag", job_of(g1_zigzag(40))),
    ] {
        let curves = PathCurves::new(&job.toolpath);
        let mut shortcut = HoldStops::new(&job.limits);
        let mut simulated = HoldStops::new(&job.limits).simulating_lines();
        let (mut stops, mut refused) = (0, 0);
        for slot in job.groups.iter().flat_map(|g| &g.slots) {
            let ends_group = slot.has_stop == 1;
            let a = shortcut.after(&slot.record, ends_group, &curves).without_stored();
            let b = simulated.after(&slot.record, ends_group, &curves).without_stored();
            let triples = |r: &RecordStops| r.values.chunks_exact(3).map(|t| (t[0], t[1], t[2])).collect::<Vec<_>>();
            let (a, b) = (triples(&a), triples(&b));
            for t in &a {
                assert!(
                    b.contains(t),
                    "{name}: record {}: stop {t:?} not in {b:?}",
                    slot.record.seq
                );
            }
            stops += b.len();
            refused += b.len() - a.len();
        }
        assert!(stops > 10, "{name}: {stops} stops");
        assert!(
            refused * 100 <= stops,
            "{name}: {refused} of {stops} stops refused by the profile alone"
        );
        println!("{name}: {stops} S-curve stops simulated, {refused} of them refused by the profile alone");
    }
}
