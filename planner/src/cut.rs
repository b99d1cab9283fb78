//! A plan at another feed override that cuts into a record the module is running.
//!
//! A join at a group's end waits for that end, up to a second away on a long line. A cut comes
//! within milliseconds anywhere the record has a checked hold stop ([`crate::hold_stops`]): at
//! such a sample the new plan's first record starts from the sample's very feed and tangential
//! acceleration with a jerk-limited change of feed ([`ramp_record`]) to a feed with zero
//! acceleration, and the Erwinski plan at the new override continues from there as from a
//! record end ([`MovingStart`]). The planner runs the old plan's records up to that sample on a
//! replica of the module's interpolator, so the ramp starts from exactly the module's state,
//! and checks the ramp by finite differences continuing the motion's samples; the plan after it
//! is checked the same way, continuing the ramp's. Should the new plan not be in the ring by
//! the sample, the module takes the hold stop there instead (an underrun).

use crate::hold_stops::{tangential_limits, INSIDE, STOP_SCALES};
use nurbs_motion::geometry::ArcLengthTable;
use nurbs_motion::planner::erwinski::PlanStart;
use nurbs_motion::planner::simulate::SimState;
use nurbs_motion::planner::verify::SLACK;
use nurbs_motion::planner::{Limits, PathCurves};
use nurbs_rtcore::block_stop::{ramp_record, StopStart};
use nurbs_rtcore::interpolator::{Sample, Step};
use nurbs_rtcore::SegmentRecord;

/// Where a cut may come, as the streamer knows it: the records of the group it comes in and
/// their checked hold stops ahead of the module.
#[derive(Clone, Debug)]
pub struct CutFrom {
    /// The motion's state before the first of `records` (the module's, sample for sample).
    pub begin: SimState,
    /// The old plan's records from there (a group).
    pub records: Vec<SegmentRecord>,
    /// The samples a cut may come after, in order: (index in `records`, motion sample), each
    /// with a checked hold stop inside that record (the stop the module takes should the new
    /// plan come late).
    pub candidates: Vec<(usize, u64)>,
    /// The feed override of the old plan.
    pub feed_override: f64,
}

/// Where a cut comes: the record cut into (index in [`CutFrom::records`]), the motion sample
/// after which, and the motion time of that record left after it (the module drops it).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CutPlace {
    pub record: usize,
    pub at_sample: u64,
    pub dropped_time: f64,
}

/// A cut, checked: where it comes, the new plan's first record and where the plan after it
/// starts.
#[derive(Clone, Debug)]
pub struct Cut {
    pub place: CutPlace,
    /// Which of [`CutFrom::candidates`] it cuts at.
    pub candidate: usize,
    /// The change of feed from the sample cut at, and its start acceleration.
    pub ramp: SegmentRecord,
    pub accel_start: f64,
    /// The motion's state after the sample cut at, and after the ramp.
    pub before: SimState,
    pub after: SimState,
    /// Where the plan after the ramp starts, and its feed there.
    pub start: PlanStart,
    pub feed: f64,
}

/// The arc-length tables of the elements a re-plan's cuts ramp on, built once for all its
/// tries: a long fitted element's took 0.3-0.65 ms, and one re-plan into a smoothed dense
/// program built 9-45 of them (up to 29 ms) for a handful of elements.
#[derive(Default)]
pub struct ElementTables(Vec<(usize, ArcLengthTable)>);

impl ElementTables {
    fn of(&mut self, curves: &PathCurves, c: usize) -> &ArcLengthTable {
        let k = match self.0.iter().position(|(i, _)| *i == c) {
            Some(k) => k,
            None => {
                self.0.push((c, ArcLengthTable::new(&curves.element(c).curve)));
                self.0.len() - 1
            }
        };
        &self.0[k].1
    }
}

/// Ramps a cut may try, in order ([`cut_into`]): the plan after one may be refused where the
/// next passes (from a lower feed it can still slow down for what lies ahead).
pub const CUT_RAMPS: usize = 3;

/// The first cut of `from`'s candidates at feed override `feed_override` with ramp number
/// `choice` (of [`CUT_RAMPS`]): the module's motion up to the sample, then a ramp that passes
/// the finite-difference check and stays on its element. Where the override goes down, the
/// ramps aim at the sample's feed scaled by the change, at half that, and at the feed reached
/// by only releasing the acceleration; where it goes up, at that release (the plan after it
/// speeds up), at half the sample's feed and at a fifth. Each with the tangential deceleration
/// and jerk the axes allow there, softened in turn ([`STOP_SCALES`]). Where the plan brakes
/// hard into sharp curvature no ramp passes: the next candidate is tried. Candidates before
/// number `skip` are not (the plans after their cuts were refused). `tables` keeps the
/// elements' arc-length tables from one try to the next.
pub fn cut_into(
    curves: &mut PathCurves,
    limits: &Limits,
    from: &CutFrom,
    feed_override: f64,
    (choice, skip): (usize, usize),
    tables: &mut ElementTables,
) -> Result<Cut, String> {
    if choice >= CUT_RAMPS {
        return Err("no more ramps to try".into());
    }
    for r in &from.records {
        if !curves.load(r.curve()) {
            return Err(format!("the path has no element {}", r.curve()));
        }
    }
    let (tip, dt) = (limits.velocity.len(), limits.period);
    let mut state = from.begin;
    let mut queue = from.records.iter().copied();
    let mut tried = 0;
    for (candidate, &(record, at_sample)) in from.candidates.iter().enumerate() {
        // The motion up to the candidate's sample.
        let sample = loop {
            match state.interp.step(curves, dt, &mut || queue.next()) {
                Step::Sample(s) => {
                    let n = state.samples as u64;
                    state.samples += 1;
                    state.check.push(&s.point[..tip], limits);
                    state.last_sample = Some(s);
                    if n >= at_sample {
                        break s;
                    }
                }
                _ => return Err(format!("motion sample {at_sample} is not in the records given")),
            }
        };
        let seq = from.records.get(record).map(|r| r.seq);
        if state.interp.record().map(|r| r.seq) != seq || state.samples as u64 != at_sample + 1 {
            return Err(format!("motion sample {at_sample} is not in record {seq:?}"));
        }
        if candidate < skip {
            continue;
        }
        tried += 1;
        if let Some(cut) = ramp_from(
            curves,
            limits,
            &state,
            &sample,
            feed_override / from.feed_override,
            choice,
            tables,
        ) {
            let place = CutPlace {
                record,
                at_sample,
                dropped_time: state.interp.time_left_in_segment(),
            };
            return Ok(Cut {
                place,
                candidate,
                ..cut
            });
        }
    }
    Err(format!(
        "no change of feed (ramp {choice}) passes the limits on its element from any of {tried} checked samples"
    ))
}

/// The first ramp of [`STOP_SCALES`] of choice `choice` ([`cut_into`]) from `sample` (the
/// motion's state `before`) for an override `ratio` times the old one.
fn ramp_from(
    curves: &PathCurves,
    limits: &Limits,
    before: &SimState,
    sample: &Sample,
    ratio: f64,
    choice: usize,
    tables: &mut ElementTables,
) -> Option<Cut> {
    let targets = if ratio < 1.0 {
        let scaled = sample.feed * ratio;
        [scaled, 0.5 * scaled, f64::INFINITY]
    } else {
        [f64::INFINITY, 0.5 * sample.feed, 0.2 * sample.feed]
    };
    let target = *targets.get(choice)?;
    let table = tables.of(curves, sample.curve);
    let length = table.total();
    let seq = before.interp.record()?.seq;
    let (accel, jerk) = tangential_limits(curves, limits, sample.curve, sample.u);
    STOP_SCALES.iter().find_map(|&(sa, sj)| {
        let tried = (target, accel * INSIDE * sa, jerk * INSIDE * sj);
        ramp(curves, limits, before, sample, seq, tried, (table, length))
    })
}

/// The ramp from `sample` (the motion's state `before`) towards `target` with deceleration
/// `accel` and jerk `jerk`, if it stays on its element (arc-length table `table`, length
/// `length`) and passes the finite-difference check; never faster than the feed the element may
/// run at, unless the sample was.
fn ramp(
    curves: &PathCurves,
    limits: &Limits,
    before: &SimState,
    sample: &Sample,
    seq: u32,
    (target, accel, jerk): (f64, f64, f64),
    (table, length): (&ArcLengthTable, f64),
) -> Option<Cut> {
    let (tip, dt) = (limits.velocity.len(), limits.period);
    let from = StopStart {
        seq: seq.wrapping_add(1),
        flags: 0,
        curve: u32::try_from(sample.curve).ok()?,
        u: sample.u,
        s: sample.s,
        feed: sample.feed,
        accel: sample.accel,
    };
    let (mut record, a0) = ramp_record(&from, target, accel, jerk);
    if record.check_from(a0).is_err() {
        return None;
    }
    let end = record.s_start + record.length;
    // Room for the rounding of the arc length at the element's end.
    if end >= length * (1.0 - 1e-9) - 1e-9 {
        return None;
    }
    let element = &curves.element(sample.curve).curve;
    record.u_end = table.parameter_at(element, end).max(record.u_start);
    let mut after = *before;
    let profile = record.profile().table_from(a0);
    if !after.interp.start_profile(curves, record, profile) {
        return None;
    }
    let cap = curves
        .programmed_feed(sample.curve)
        .map_or(limits.feed, |f| f.min(limits.feed));
    after.check.reset_peaks();
    loop {
        match after.interp.step(curves, dt, &mut || None) {
            Step::Sample(x) => {
                after.samples += 1;
                after.check.push(&x.point[..tip], limits);
                after.last_sample = Some(x);
                let too_fast = x.feed > cap && x.feed > sample.feed;
                if too_fast || x.curve != sample.curve || after.check.worst_ratio(limits) > 1.0 + SLACK {
                    return None;
                }
            }
            Step::Starved => break,
            Step::Finished | Step::BadRecord => return None,
        }
    }
    Some(Cut {
        place: CutPlace::default(),
        candidate: 0,
        ramp: record,
        accel_start: a0,
        before: *before,
        after,
        start: PlanStart {
            curve: sample.curve,
            u: record.u_end,
            s: end,
        },
        feed: profile.end().v.max(0.0),
    })
}
