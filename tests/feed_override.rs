//! A feed override change is a re-plan from the end of a record already handed out, at that
//! record's end feed and with the interpolator state after it, at the new override: the
//! records before the join and the re-planned ones after it, sampled at the servo period as
//! the module plays them, pass the finite-difference check across the join, and the motion
//! comes down to the new feed right after it.

mod common;

use common::{example, trident_vpop};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::erwinski::PlanStart;
use nurbs_motion::planner::presets::named;
use nurbs_motion::planner::simulate::{run_segment, SimState};
use nurbs_motion::planner::verify::{Row, Verifier, SLACK};
use nurbs_motion::planner::{FinalRecord, Limits, MovingStart, PathCurves, PlanOptions, Planner, SLOW_DOWN_SHARES};
use nurbs_rtcore::SegmentRecord;

/// A streamed plan's records, each with the state after it.
fn streamed(tp: &Toolpath, limits: &Limits, feed_override: f64) -> Vec<(FinalRecord, SimState)> {
    let options = PlanOptions {
        stream: true,
        feed_override,
        ..PlanOptions::default()
    };
    let mut planner = Planner::new(tp, limits, &options).unwrap();
    let mut out = Vec::new();
    while let Some(next) = planner.next_final() {
        let r = next.unwrap();
        out.push((r, planner.state_after_last().expect("the state after the record")));
    }
    out
}

/// What the check of one join found.
struct Joined {
    /// Share of the nominal limits the ramp down was planned with.
    brake_share: f64,
    /// Feed at the join, and the time from the join until the sampled feed stays at or below
    /// the new cap (s).
    feed_at_join: f64,
    settle_time: f64,
    motion_time: f64,
}

/// Plays `before` then the re-plan from its end at `feed_override` through the interpolator,
/// verifies every sample (axial limits by finite differences across the join, feed, chord,
/// distance to the curve) and measures how soon the feed comes down to the new cap.
fn join_and_verify(tp: &Toolpath, limits: &Limits, before: &[(FinalRecord, SimState)], feed_override: f64) -> Joined {
    let (last, state) = before.last().unwrap();
    let feed_at_join = last.record.profile().table().end().v.max(0.0);
    // The gentler ramps only where the steeper ones are refused.
    let mut refusals = Vec::new();
    let mut replanned = None;
    for brake_share in SLOW_DOWN_SHARES {
        let options = PlanOptions {
            stream: true,
            feed_override,
            start: Some(PlanStart::at(
                &mut PathCurves::new(tp),
                last.record.curve(),
                last.record.u_end,
                last.record.s_start + last.record.length,
            )),
            moving: Some(MovingStart {
                feed: feed_at_join,
                state: *state,
                seq: last.record.seq + 1,
                feed_override: 1.0,
                brake_share,
            }),
            ..PlanOptions::default()
        };
        let mut planner = Planner::new(tp, limits, &options).unwrap_or_else(|e| panic!("{e}"));
        match planner.by_ref().collect::<Result<Vec<SegmentRecord>, _>>() {
            Ok(records) => {
                replanned = Some((brake_share, records));
                break;
            }
            Err(e) => refusals.push(e.to_string()),
        }
    }
    let Some((brake_share, after)) = replanned else {
        panic!(
            "re-plan at override {feed_override} from {feed_at_join} mm/s after record {}: {refusals:?}",
            last.record.seq
        )
    };
    let records: Vec<SegmentRecord> = before.iter().map(|(r, _)| r.record).chain(after).collect();
    assert!(
        records.windows(2).all(|w| w[1].seq == w[0].seq + 1),
        "record numbers run on"
    );
    // The check's feed limit is the higher of the two plans'.
    let tip = tp.tip_dim();
    let check = Limits {
        feed: limits.feed * feed_override.max(1.0),
        ..limits.for_axes(tip).unwrap()
    };
    let whole = PathCurves::new(tp);
    let mut curves = PathCurves::new(tp);
    let mut verifier = Verifier::new(&mut curves, &check);
    let mut sim = SimState::start(tip, limits.period);
    let (mut rows, mut last_q): (usize, Option<Vec<f64>>) = (0, None);
    let join_row = {
        let mut n = 0usize;
        let mut s = SimState::start(tip, limits.period);
        for (r, _) in before {
            assert!(run_segment(&whole, &check, &mut s, r.record, &mut |_| n += 1));
        }
        n
    };
    let cap = limits.feed * feed_override;
    let mut last_above = join_row;
    for r in records {
        let ok = run_segment(&whole, &check, &mut sim, r, &mut |s| {
            let q = s.point[..tip].to_vec();
            if let Some(p) = &last_q {
                let feed = q.iter().zip(p).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt() / limits.period;
                if rows > join_row && feed > cap * (1.0 + SLACK) {
                    last_above = rows;
                }
            }
            verifier.push(&Row {
                t: rows as f64 * limits.period,
                curve: s.curve,
                u: s.u,
                q: q.clone(),
            });
            last_q = Some(q);
            rows += 1;
        });
        assert!(ok, "the interpolator refused record {}", r.seq);
    }
    let report = verifier.finish();
    assert!(
        report.violations.is_empty(),
        "override {feed_override} after record {}: {:?}",
        last.record.seq,
        report.violations
    );
    Joined {
        brake_share,
        feed_at_join,
        settle_time: (last_above - join_row) as f64 * limits.period,
        motion_time: rows.saturating_sub(1) as f64 * limits.period,
    }
}

/// On the bundled curves, at group ends through the path (where the module may take a new
/// plan), overrides down to 10 % and up again: every joined motion passes the check, and a
/// lower override brings the feed under its cap within the braking time the nominal tangential
/// limits allow (plus the period the join may fall in).
#[test]
fn a_re_plan_from_a_record_end_at_a_new_override_is_within_the_limits() {
    let cases = [
        ("trident.json", named("lab1").on(2)),
        ("butterfly.json", named("lab1").on(2)),
        ("butterfly.json", named("table3-f250").on(2)),
        ("trident.json", trident_vpop()),
    ];
    let mut joins = 0;
    for (name, limits) in cases {
        let tp = example(name);
        let base = streamed(&tp, &limits, 1.0);
        let group_ends: Vec<usize> = (0..base.len() - 1).filter(|&k| !base[k].0.stop.is_empty()).collect();
        assert!(group_ends.len() >= 4, "{name}: {} group ends", group_ends.len());
        let (a, j) = {
            let l = limits.for_axes(2).unwrap();
            (l.min_accel(), l.min_jerk())
        };
        for pick in 1..=4 {
            let m = group_ends[pick * (group_ends.len() - 1) / 5];
            for feed_override in [0.1, 0.5, 0.9, 1.0] {
                let joined = join_and_verify(&tp, &limits, &base[..=m], feed_override);
                let v0 = joined.feed_at_join;
                let cap = limits.feed * feed_override;
                // Braking from v0 to the cap at the nominal limits, the share the planner plans
                // with, and the headroom it keeps under the cap.
                let dv = (v0 - cap).max(0.0);
                let nominal = if dv * j >= a * a {
                    dv / a + a / j
                } else {
                    2.0 * (dv / j).sqrt()
                };
                let share = joined.brake_share;
                let bound = nominal / share + 2.0 * limits.period;
                eprintln!(
                    "{name} F{}: after record {m} at {v0:.1} mm/s, override {feed_override}: under the cap after {:.1} ms (bound {:.1} ms at share {share}), motion {:.4} s",
                    limits.feed,
                    joined.settle_time * 1e3,
                    bound * 1e3,
                    joined.motion_time
                );
                assert!(
                    joined.settle_time <= bound,
                    "{name}: override {feed_override} after record {m}: the feed stays above the cap for {} s",
                    joined.settle_time
                );
                joins += 1;
            }
        }
    }
    assert_eq!(joins, 64);
}

/// Without a change of override the re-plan from a group end is the plan itself: the same
/// records bit for bit (a join leaves nothing behind).
#[test]
fn a_re_plan_at_the_same_override_continues_the_plan_unchanged() {
    let tp = example("butterfly.json");
    let limits = named("lab1").on(2);
    let base = streamed(&tp, &limits, 1.0);
    let group_ends: Vec<usize> = (0..base.len() - 1).filter(|&k| !base[k].0.stop.is_empty()).collect();
    let m = group_ends[group_ends.len() / 2];
    let (last, state) = &base[m];
    let options = PlanOptions {
        stream: true,
        start: Some(PlanStart::at(
            &mut PathCurves::new(&tp),
            last.record.curve(),
            last.record.u_end,
            last.record.s_start + last.record.length,
        )),
        moving: Some(MovingStart {
            feed: last.record.profile().table().end().v.max(0.0),
            state: *state,
            seq: last.record.seq + 1,
            feed_override: 1.0,
            brake_share: SLOW_DOWN_SHARES[0],
        }),
        ..PlanOptions::default()
    };
    let after: Vec<SegmentRecord> = Planner::new(&tp, &limits, &options)
        .unwrap()
        .map(|r| r.unwrap())
        .collect();
    let rest: Vec<SegmentRecord> = base[m + 1..].iter().map(|(r, _)| r.record).collect();
    assert_eq!(after.len(), rest.len());
    let same = after.iter().zip(&rest).filter(|(a, b)| a == b).count();
    assert_eq!(same, rest.len(), "records after the join differ");
}
