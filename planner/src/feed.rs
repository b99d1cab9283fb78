//! What `nurbs-planner` sends, prepared from a plan: ring slots in groups that end at a stop
//! within the axis limits, and for path blocks the arena data their stops need. Compiled into
//! the `nurbs-planner` binary and into the tests (never into the realtime module's library: it
//! needs the planner crate).
//!
//! Segment records (the Erwinski planner, streamed): each record the planner hands out is
//! final, and the last one of each run carries its stop, the next segment re-planned to rest
//! and checked by the planner itself ([`FinalRecord`]). A run and its stop make a group
//! ([`Grouper`]): the module takes a group only whole, so it stops only where a checked stop
//! is. Path blocks (VPOp): the planner runs the module's stop from every block end and checks
//! it by finite differences ([`choose_block_stops`]); a block whose stop it cannot bring within
//! the limits joins the next block's group.

use std::cell::{OnceCell, RefCell};
use std::collections::{HashMap, VecDeque};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::time::Instant;

use crate::cut::{cut_into, CutFrom, CutPlace, ElementTables, CUT_RAMPS};
use crate::hold_stops::{HoldStops, RecordStops};
use crate::say;
use crate::shared_path::SharedPath;
use crate::writer::{GeometryWriter, Release, WriteError};
use nurbs_hal::channel::{
    Channel, Join, Slot, StopPoint, AT_RECORD_END, SEGMENT_SLOTS, SPLICE_ACCEPTED, SPLICE_DONE, SPLICE_REQUESTED,
};
use nurbs_hal::slot::{PathBlock, Record, SegmentSlot, BLOCK_SAMPLES, FLAG_LAST};
use nurbs_motion::geometry::{ArcLengthTable, Nurbs, Toolpath};
use nurbs_motion::planner::axial::FiniteDifferences;
use nurbs_motion::planner::erwinski::PlanStart;
use nurbs_motion::planner::reach::{self, ReachOptions, ReachPlan};
use nurbs_motion::planner::simulate::SimState;
use nurbs_motion::planner::verify::SLACK;
use nurbs_motion::planner::vpop::{brake_points, plan_tip, JointPath, PathPoint, SearchOptions, VpopPlan};
use nurbs_motion::planner::{FinalRecord, Limits, MovingStart, PathCurves, PlanOptions, Planner, SLOW_DOWN_SHARES};
use nurbs_rtcore::block_stop::block_stop;
use nurbs_rtcore::interpolator::{Interpolator, Step};
use nurbs_rtcore::{CachedCurve, SegmentRecord, SpanCache, StopRun};

/// Where a plan from the module's stop point starts: there, or where the machine stands at
/// the end of an element (not the last), at the start of the next one (the module accepts
/// either).
pub fn plan_start(curves: &mut PathCurves, stop: &StopPoint) -> PlanStart {
    PlanStart::at(curves, stop.curve as usize, stop.u, stop.s)
}

/// Segment records that go into the ring together: a run of final records whose last one has
/// a stop (or ends the path).
#[derive(Clone, Debug, Default)]
pub struct SegmentGroup {
    pub slots: Vec<SegmentSlot>,
    /// The stop's records after its first (in the last slot), as arena values: they go into the
    /// arena before the group into the ring ([`SegmentSlot::chain_offset`]).
    pub chain: Vec<f64>,
    /// Motion time of the records (s).
    pub time: f64,
    /// The curves this group is the first to need (it and its stop), in path order from
    /// `first_curve`: they go into the geometry stream before the group into the ring.
    pub curves: Vec<Nurbs>,
    pub first_curve: u32,
    /// Per slot, the checked stops inside its record ([`crate::hold_stops`]): they go into the
    /// arena before the group into the ring ([`SegmentSlot::hold_stops_offset`]).
    pub hold_stops: Vec<RecordStops>,
    /// Where the group leaves the motion (what a plan at another feed override continues
    /// from); `None` where it ends the path.
    pub end: Option<Box<GroupEnd>>,
    /// The motion's state before the group's first record (where a plan at another feed
    /// override that cuts into one of its records replays them from: [`crate::cut`]).
    pub begin: Option<Box<SimState>>,
    /// The first group of a plan that cuts into a running record: where.
    pub cut: Option<CutPlace>,
}

/// The end of a group of a streamed plan: its last record, the planner's state after it, and
/// the feed override the plan was made with.
#[derive(Clone, Copy, Debug)]
pub struct GroupEnd {
    pub record: SegmentRecord,
    pub state: SimState,
    pub feed_override: f64,
}

impl GroupEnd {
    /// Where a plan continuing after the group starts: the last record's end
    /// ([`PlanStart::at`]).
    fn start(&self, curves: &mut PathCurves) -> PlanStart {
        let r = &self.record;
        PlanStart::at(curves, r.curve(), r.u_end, r.s_start + r.length)
    }

    /// The motion state there, as the planner continues it.
    fn moving(&self, brake_share: f64) -> MovingStart {
        MovingStart {
            feed: self.record.profile().table().end().v.max(0.0),
            state: self.state,
            seq: self.record.seq.wrapping_add(1),
            feed_override: self.feed_override,
            brake_share,
        }
    }
}

impl SegmentGroup {
    /// Highest curve the group and its stop run on.
    pub fn curve_needed(&self) -> u32 {
        self.slots.first().map_or(0, |s| s.curve_needed)
    }
}

/// Collects a streamed plan's final records into groups.
#[derive(Default)]
pub struct Grouper {
    run: Vec<FinalRecord>,
    hold_stops: Vec<RecordStops>,
    begin: Option<Box<SimState>>,
}

impl Grouper {
    /// Whether the next record begins a group.
    pub fn starts_group(&self) -> bool {
        self.run.is_empty()
    }

    /// Takes the next final record, with the stops checked inside it and, where it begins a
    /// group ([`Self::starts_group`]), the motion's state before it; returns the group it
    /// completes, if it does.
    pub fn push(&mut self, r: FinalRecord, hold_stops: RecordStops, begin: Option<SimState>) -> Option<SegmentGroup> {
        let ends = !r.stop.is_empty() || r.record.is_last();
        if self.run.is_empty() {
            self.begin = begin.map(Box::new);
        }
        self.run.push(r);
        self.hold_stops.push(hold_stops);
        if !ends {
            return None;
        }
        let run = std::mem::take(&mut self.run);
        let hold_stops = std::mem::take(&mut self.hold_stops);
        let n = run.len();
        let stop = run.last().map_or(&[][..], |r| r.stop.as_slice());
        let mut needed = stop.iter().map(|s| s.curve).max().unwrap_or(0);
        let chain: Vec<f64> = stop
            .iter()
            .skip(1)
            .flat_map(|r| r.to_words().map(f64::from_bits))
            .collect();
        let mut slots = vec![SegmentSlot::default(); n];
        for (k, r) in run.iter().enumerate().rev() {
            // A stored hold stop may run on into later elements.
            needed = needed.max(r.record.curve).max(hold_stops[k].last_curve.unwrap_or(0));
            slots[k] = SegmentSlot {
                record: r.record,
                stop: r.stop.first().copied().unwrap_or_default(),
                group_left: (n - k) as u32,
                has_stop: u32::from(!r.stop.is_empty()),
                curve_needed: needed,
                chain_offset: 0,
                chain_len: r.stop.len().saturating_sub(1) as u32,
                hold_stops_offset: 0,
                hold_stops_len: hold_stops[k].count as u32,
                reserved: 0,
            };
        }
        let time = run.iter().map(|r| r.record.profile().total_time()).sum();
        Some(SegmentGroup {
            slots,
            chain,
            time,
            curves: Vec::new(),
            first_curve: 0,
            hold_stops,
            end: None,
            begin: self.begin.take(),
            cut: None,
        })
    }
}

/// Highest curve a final record and its stop run on.
fn curve_needed(r: &FinalRecord) -> u32 {
    r.stop.iter().map(|s| s.curve).fold(r.record.curve, u32::max)
}

/// What [`stream_plan`] hands out, in order.
#[derive(Clone, Debug)]
pub enum PlanEvent {
    /// The next group of final records.
    Group(SegmentGroup),
    /// The plan is complete (a line for the log); `error`: the file could not be read to its
    /// end, and the plan ends at rest before the element that failed.
    Done {
        line: String,
        error: Option<String>,
    },
    Failed(String),
}

/// Where a streamed plan starts.
#[derive(Clone, Debug)]
pub enum StreamStart {
    /// At rest: the path start (`None`) or the module's stop point.
    Rest(Option<StopPoint>),
    /// After a group already sent, at another feed override (the motion goes on); the curves
    /// from `send_from` on are still to be sent.
    After { end: Box<GroupEnd>, send_from: usize },
    /// Cutting into a record sent, at another feed override ([`crate::cut`]); the curves from
    /// `send_from` on are still to be sent.
    Cut { from: Box<CutFrom>, send_from: usize },
}

/// Runs the Erwinski planner as a stream ([`PlanOptions::stream`]) over `curves` (read as it
/// plans) at `feed_override`, from `start`, and hands each group of final records, with the
/// curves it is the first to need, to `emit` as soon as it is
/// complete; stops early when `emit` returns false (nobody listens any more). A plan after a
/// group whose motion is faster than the new caps ramps down to them; where that ramp does
/// not pass, gentler ones are tried ([`SLOW_DOWN_SHARES`], each from `open()`, a fresh read of
/// the path).
pub fn stream_plan(
    open: &dyn Fn() -> Result<PathCurves, String>,
    limits: &Limits,
    start: StreamStart,
    feed_override: f64,
    emit: &mut dyn FnMut(PlanEvent) -> bool,
) {
    // (ramp share, which of the cut's ramps) of each try; a cut tries them all at one
    // candidate, then (where only the plans after them were refused) at the next ones.
    let tries: Vec<(f64, usize)> = match start {
        StreamStart::Rest(_) => vec![(SLOW_DOWN_SHARES[0], 0)],
        StreamStart::After { .. } => SLOW_DOWN_SHARES.iter().map(|&share| (share, 0)).collect(),
        StreamStart::Cut { .. } => (0..CUT_RAMPS).map(|k| (SLOW_DOWN_SHARES[0], k)).collect(),
    };
    let rounds = if matches!(start, StreamStart::Cut { .. }) {
        CUT_CANDIDATES
    } else {
        1
    };
    let (mut refusals, mut skip) = (Vec::new(), 0);
    let mut tables = ElementTables::default();
    for round in 0..rounds {
        let mut next_skip = usize::MAX;
        for (k, &(share, ramp)) in tries.iter().enumerate() {
            let curves = match open() {
                Ok(c) => c,
                Err(e) => {
                    emit(PlanEvent::Failed(e));
                    return;
                }
            };
            let last_try = round + 1 == rounds && k + 1 == tries.len();
            match stream_plan_once(
                curves,
                limits,
                &start,
                (feed_override, share, (ramp, skip)),
                (last_try, &mut tables),
                emit,
            ) {
                Ok(()) => return,
                Err((e, cut_at)) => {
                    refusals.push(e);
                    next_skip = next_skip.min(cut_at.map_or(usize::MAX, |c| c + 1));
                }
            }
        }
        if next_skip == usize::MAX {
            break;
        }
        skip = next_skip;
    }
    emit(PlanEvent::Failed(refusals.join("; ")));
}

/// Candidates a cut tries where the plans after its ramps are refused ([`stream_plan`]).
const CUT_CANDIDATES: usize = 4;

/// One try of [`stream_plan`] (with ramp share `brake_share` after a group, the cut's ramp
/// `cut_ramp` from its candidate `skip` on): `Err` where the plan is refused before its first
/// group and another try may pass (`last_try`: none may), with the candidate a cut came at.
fn stream_plan_once(
    mut curves: PathCurves,
    limits: &Limits,
    start: &StreamStart,
    (feed_override, brake_share, (cut_ramp, skip)): (f64, f64, (usize, usize)),
    (last_try, tables): (bool, &mut ElementTables),
    emit: &mut dyn FnMut(PlanEvent) -> bool,
) -> Result<(), (String, Option<usize>)> {
    let (plan_from, moving, cut) = match start {
        StreamStart::Rest(from) => (from.map(|p| plan_start(&mut curves, &p)), None, None),
        StreamStart::After { end, .. } => (Some(end.start(&mut curves)), Some(end.moving(brake_share)), None),
        StreamStart::Cut { from, .. } => {
            // The ramp is the new plan's first record: within the limits it plans in (less the
            // hold reserve), as the plan after it.
            let cut = match cut_into(
                &mut curves,
                &limits.planned(),
                from,
                feed_override,
                (cut_ramp, skip),
                tables,
            ) {
                Ok(cut) => cut,
                Err(e) if last_try => {
                    emit(PlanEvent::Failed(format!(
                        "re-plan at feed override {feed_override}: {e}"
                    )));
                    return Ok(());
                }
                Err(e) => return Err((e, None)),
            };
            let moving = MovingStart {
                feed: cut.feed,
                state: cut.after,
                seq: cut.ramp.seq.wrapping_add(1),
                feed_override: from.feed_override,
                brake_share,
            };
            (Some(cut.start), Some(moving), Some(cut))
        }
    };
    // A plan from a point on the path never needs the path before it.
    curves.release_before(plan_from.map_or(0, |s| s.curve));
    let options = PlanOptions {
        stream: true,
        start: plan_from,
        moving,
        feed_override,
        ..PlanOptions::default()
    };
    let why = |e: String| match start {
        StreamStart::Rest(None) => e,
        StreamStart::Rest(Some(_)) => format!("re-plan from the stop point: {e}"),
        StreamStart::After { .. } | StreamStart::Cut { .. } => format!("re-plan at feed override {feed_override}: {e}"),
    };
    let mut planner = match Planner::with_curves(curves, limits, &options) {
        Ok(p) => p,
        Err(e) => {
            emit(PlanEvent::Failed(why(e.to_string())));
            return Ok(());
        }
    };
    let mut grouper = Grouper::default();
    // The highest element a stored hold stop so far runs on.
    let mut hold_needed = 0;
    let mut hold_stops = match (start, &cut) {
        (_, Some(cut)) => HoldStops::continuing(limits, &cut.before),
        (StreamStart::After { end, .. }, _) => HoldStops::continuing(limits, &end.state),
        _ => HoldStops::new(limits),
    };
    if let Some(cut) = &cut {
        // The ramp is the new plan's first record (its group goes on with the plan's).
        let begin = hold_stops.state();
        let inside = hold_stops.after_cut(&cut.ramp, cut.accel_start, planner.curves());
        hold_needed = inside.last_curve.unwrap_or(0);
        let ramp = FinalRecord {
            record: cut.ramp,
            stop: Vec::new(),
        };
        if grouper.push(ramp, inside, Some(begin)).is_some() {
            return Err(("a ramp without a stop ended a group".into(), Some(cut.candidate)));
        }
    }
    let mut cut_place = cut.as_ref().map(|c| c.place);
    let (mut groups, mut longest) = (0usize, 0.0f64);
    // The curves of the group being collected, from `first_curve` on: after a group, those not
    // sent yet; from rest, a new geometry stream from the plan's first curve.
    let mut next_curve = match start {
        StreamStart::After { send_from, .. } | StreamStart::Cut { send_from, .. } => *send_from,
        StreamStart::Rest(_) => plan_from.map_or(0, |s| s.curve),
    };
    let (mut first_curve, mut new_curves) = (next_curve as u32, Vec::new());
    while let Some(next) = planner.next_final() {
        match next {
            Ok(record) => {
                // The critical points are not sent: drop them as they come.
                drop(planner.take_critical_points());
                let begin = grouper.starts_group().then(|| hold_stops.state());
                let last = record.record;
                let inside = hold_stops.after(&record.record, !record.stop.is_empty(), planner.curves());
                // The record's curves are still held (its own until the next call, its stop's
                // and its stored hold stops' ahead of the planning front), and every curve
                // before them has been sent.
                hold_needed = hold_needed.max(inside.last_curve.unwrap_or(0));
                let needed = curve_needed(&record).max(hold_needed) as usize;
                while next_curve <= needed {
                    new_curves.push(planner.curves().element(next_curve).curve.clone());
                    next_curve += 1;
                }
                if let Some(mut group) = grouper.push(record, inside, begin) {
                    group.cut = cut_place.take();
                    groups += 1;
                    longest = longest.max(group.time);
                    group.first_curve = first_curve;
                    first_curve = next_curve as u32;
                    group.curves = std::mem::take(&mut new_curves);
                    group.end = (!last.is_last()).then(|| {
                        Box::new(GroupEnd {
                            record: last,
                            state: planner.state_after_last().expect("the state after a record handed out"),
                            feed_override,
                        })
                    });
                    if !emit(PlanEvent::Group(group)) {
                        return Ok(());
                    }
                }
            }
            // Refused before anything went out: a gentler ramp down may pass.
            Err(e) if groups == 0 && !last_try && moving.is_some() => {
                return Err((e.to_string(), cut.as_ref().map(|c| c.candidate)))
            }
            Err(e) => {
                emit(PlanEvent::Failed(why(e.to_string())));
                return Ok(());
            }
        }
    }
    let error = planner.curves().error().map(|e| {
        format!(
            "{e}: the plan ends at rest at the end of path element {} before it",
            planner.curves().len().saturating_sub(1)
        )
    });
    let report = planner.finish();
    let stops = match report.stops_made.as_slice() {
        [] => String::new(),
        made => format!(
            "; it stops at {} place(s) a whole-path plan would not (back-tracking reached records already sent), first at curve {} u = {}",
            made.len(),
            made[0].0,
            made[0].1
        ),
    };
    let what = match start {
        StreamStart::After { .. } => format!("streamed plan at feed override {feed_override} complete"),
        StreamStart::Cut { .. } => format!("streamed plan at feed override {feed_override} (cutting in) complete"),
        StreamStart::Rest(_) => "streamed plan complete".to_string(),
    };
    emit(PlanEvent::Done {
        line: format!(
            "{what}: {} segments in {groups} groups (longest {longest:.3} s of motion), motion {:.6} s, planned in {:.3} s, first record final after {:.3} ms{stops}",
            report.records,
            report.motion_time,
            report.plan_time,
            report.first_record_time * 1e3
        ),
        error,
    });
    Ok(())
}

/// The stop chosen after one record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopChoice {
    /// Stop jerk as a fraction of the smallest axis jerk.
    pub fraction: f64,
    /// Stop deceleration as a share of the same fraction of the smallest axis acceleration.
    pub accel_share: f64,
    pub accel: f64,
    pub jerk: f64,
    /// Worst ratio of an axial velocity, acceleration or jerk to its limit, from three samples
    /// before the stop to rest (<= 1: within the limits).
    pub ratio: f64,
    /// Path blocks only: the stop is the planner's own deceleration sequence of this many
    /// positions, stored with the geometry (0: the module's tangential stop).
    pub stored: usize,
}

impl StopChoice {
    /// The module's tangential stop with jerk `fraction` and deceleration `accel_share` of the
    /// tangential limits `(a_max, j_max)`, whose check gave `ratio`.
    fn tangential((fraction, accel_share): (f64, f64), (a_max, j_max): (f64, f64), ratio: f64) -> Self {
        StopChoice {
            fraction,
            accel_share,
            accel: fraction * accel_share * a_max,
            jerk: fraction * j_max,
            ratio,
            stored: 0,
        }
    }
}

/// Stop deceleration and jerk tried at each block end, as fractions of the tangential limits,
/// largest first: 1, 0.85, 0.85^2, ... (30 steps, down to 0.009).
pub fn fractions(max_fraction: f64) -> Vec<f64> {
    (0..30).map(|k| max_fraction * 0.85f64.powi(k)).collect()
}

/// Refuses toolpaths the module cannot run as VPOp plans: it drives the tool tip only, so a
/// path with a tool-axis (top) curve would need the machine's joint kinematics in the module.
pub fn check_tip_path(toolpath: &Toolpath) -> Result<(), String> {
    if toolpath.elements.iter().any(|e| e.curve.dim() > e.curve.tip_dim()) {
        return Err(
            "this is a 5-axis toolpath (tool tip and tool axis): the realtime module drives the \
                    tool tip only, so VPOp plans of 5-axis paths (joint positions of the machine) cannot \
                    run through it; plan 2-/3-axis tool-tip paths"
                .into(),
        );
    }
    Ok(())
}

/// Arc length of path points in the module's measure: per element from its curve start
/// (Gauss-Legendre, the measure of the stop points), except on the element of the anchor (a
/// stop point, or the last sample before a stored stop), where it is shifted so that the
/// anchor's `u` has exactly its `s`, the arc length the module holds there.
struct ArcLengths<'a> {
    toolpath: &'a Toolpath,
    /// Each element's table, built when first needed (a 1,000-line G1 program has 2,000).
    tables: Vec<OnceCell<ArcLengthTable>>,
    /// Path length before each element, as far as asked for (summed in path order).
    before: RefCell<Vec<f64>>,
    /// The anchor's element, arc length, and Gauss-Legendre length to its parameter.
    anchor: Option<(usize, f64, f64)>,
    /// Lengths of elements to parameters asked for lately, by element and the parameter's
    /// bits (the newer and the older of two generations of at most `LENGTHS_KEPT` each): the
    /// stored stops of nearby block ends share many points (the same planned positions, often
    /// the same deceleration), and each length is an adaptive quadrature of some hundred curve
    /// evaluations.
    lengths: RefCell<[HashMap<(usize, u64), f64>; 2]>,
}

/// Lengths each generation of [`ArcLengths`]'s memory keeps (some 2 MB).
const LENGTHS_KEPT: usize = 1 << 16;

impl<'a> ArcLengths<'a> {
    fn new(toolpath: &'a Toolpath) -> Self {
        ArcLengths {
            toolpath,
            tables: toolpath.elements.iter().map(|_| OnceCell::new()).collect(),
            before: RefCell::new(vec![0.0]),
            anchor: None,
            lengths: RefCell::new([HashMap::new(), HashMap::new()]),
        }
    }

    fn table(&self, e: usize) -> &ArcLengthTable {
        self.tables[e].get_or_init(|| ArcLengthTable::new(&self.toolpath.elements[e].curve))
    }

    /// Path length before element `e`.
    fn before(&self, e: usize) -> f64 {
        let mut before = self.before.borrow_mut();
        while before.len() <= e {
            let k = before.len() - 1;
            let next = before[k] + self.table(k).total();
            before.push(next);
        }
        before[e]
    }

    /// From now on, element `e` is measured so that `u` has arc length `s`.
    fn set_anchor(&mut self, e: usize, u: f64, s: f64) {
        self.anchor = (e < self.tables.len()).then(|| (e, s, self.length_to(e, u)));
    }

    /// Length of element `e` from its start to parameter `u`.
    fn length_to(&self, e: usize, u: f64) -> f64 {
        let key = (e, u.to_bits());
        let mut lengths = self.lengths.borrow_mut();
        if let Some(&length) = lengths[0].get(&key).or_else(|| lengths[1].get(&key)) {
            return length;
        }
        let length = self.table(e).length_to(&self.toolpath.elements[e].curve, u);
        if lengths[0].len() >= LENGTHS_KEPT {
            lengths[1] = std::mem::take(&mut lengths[0]);
        }
        lengths[0].insert(key, length);
        length
    }

    /// Arc length of `p` in the measure of element `e` (negative before it).
    fn s(&self, p: &PathPoint, e: usize) -> f64 {
        let own = self.length_to(p.element, p.u);
        if p.element == e {
            match self.anchor {
                // Exactly the anchor's arc length at its parameter (the difference is 0 there).
                Some((a, s, length)) if a == e => s + (own - length),
                _ => own,
            }
        } else {
            // An earlier element: minus the path length from `p` to the start of `e`.
            (self.before(p.element) + own) - self.before(e)
        }
    }
}

/// Packs the points of a VPOp plan into path blocks: runs of at most [`BLOCK_SAMPLES`] points
/// on one element (a new block at every element change), each with the arc lengths of its
/// points and of the two points before it, the last flagged. `anchor`: the stop point a
/// re-plan starts from (its arc length is kept exactly). Stop limits are left at zero
/// ([`choose_block_stops`] sets them).
fn pack_blocks(arcs: &ArcLengths, points: &[PathPoint]) -> Vec<PathBlock> {
    let mut blocks: Vec<PathBlock> = Vec::new();
    let mut i = 0;
    while i < points.len() {
        let e = points[i].element;
        let before = |k: usize| arcs.s(&points[i.saturating_sub(k)], e);
        let mut b = PathBlock {
            seq: blocks.len() as u32,
            curve: e as u32,
            s_before: [before(2), before(1)],
            ..PathBlock::default()
        };
        let mut n = 0;
        while n < BLOCK_SAMPLES && i < points.len() && points[i].element == e {
            b.u[n] = points[i].u;
            b.s[n] = arcs.s(&points[i], e);
            n += 1;
            i += 1;
        }
        b.count = n as u32;
        blocks.push(b);
    }
    if let Some(last) = blocks.last_mut() {
        last.flags |= FLAG_LAST;
    }
    blocks
}

/// A stop sequence chosen after a block: its positions (path points, from the period after
/// `from`) and the choice it makes.
#[derive(Clone, Debug)]
pub struct StoredStop {
    pub from: PathPoint,
    pub points: Vec<PathPoint>,
    pub choice: StopChoice,
}

/// Runs the blocks as the module does (each sample the curve point at its parameter) and, at
/// every block end, VPOp's own deceleration sequence from there ([`brake_points`], after the
/// plan's next positions where the block end's state has none), checked as the module plays
/// it by finite differences continuing the motion; it is stored with the geometry. Where it
/// does not pass (or cannot be stored: the last block), the module's tangential stop
/// ([`block_stop`]) with jerk fractions of the tangential limits there and deceleration shares
/// 1, 1/2, 1/4, 1/10 of each, looking for the largest fraction with a share that stays within
/// the axis limits by finite differences, as [`StopChooser`] does for segment records, then
/// bisecting towards the next larger fraction (the tangential limits hold for the direction at
/// the block end only, so the largest stop that passes is often just below them); that search
/// starts at the fraction that passed at the last block end that had one
/// ([`StopSearch::starting_at`]; the first searches from the largest). Stores the limits in
/// each block (the least violating ones where none passes) and returns the choices.
///
/// The sequence first, because it is the cheaper to find and check: VPOp's plan checks most
/// of its states safe to brake from, with the same sequences. Measured (`cargo bench -p
/// nurbs-planner --features linuxcnc --bench start -- "vpop start"`, lab set 1), the trident's
/// 192 block ends and the butterfly's 848: 0.35 s and 2.0 s with the tangential stop first
/// (128 and 784 stored), against 0.24 s and 1.3 s with the sequence first (all stored; the
/// arena they take, 20 % and 3 % more values, is the price).
pub fn choose_block_stops(
    toolpath: &Toolpath,
    limits: &Limits,
    blocks: &mut [PathBlock],
    stop_points: &[Vec<f64>],
    fractions: &[f64],
    points: &[PathPoint],
) -> (Vec<StopChoice>, Vec<Option<StoredStop>>) {
    let curves = PathCurves::new(toolpath);
    let path = JointPath::tip(toolpath);
    let mut sequences = Vec::with_capacity(blocks.len());
    let mut end = 0;
    let tip = limits.velocity.len();
    let dt = limits.period;
    let mut fd = FiniteDifferences::new(tip, dt);
    let mut choices = Vec::with_capacity(blocks.len());
    // Whether a search has run (the next starts from `last_passed`, the fraction index of the
    // last tangential stop that passed).
    let mut searched = false;
    let mut last_passed = 0;
    let mut brakes = BrakeMemo::default();
    // The module's evaluation of a block's points (see `Interpolator::point_at`).
    let mut spans = SpanCache::new();
    for b in blocks.iter_mut() {
        let view = curves.view(b.curve());
        let curve = &mut CachedCurve::new(view, &mut spans);
        for &u in &b.u[..b.len()] {
            fd.push(&curve.point(u)[..tip], limits);
        }
        end += b.len();
        let curve_points = stop_points.get(b.curve()).map_or(&[][..], Vec::as_slice);
        // Tangential limits at the block end: what the axes allow along the path direction
        // there (each axis limit over its share of the unit tangent; at least the smallest axis
        // limit). The fractions scale them down where the path turns during the stop.
        let (a_max, j_max) = tangential_limits(&curves, limits, b);
        // The module's stop with these limits, checked by finite differences; abandoned as soon
        // as it is worse than `bound` (it cannot be the choice then).
        let simulate = |fraction: f64, accel_share: f64, bound: f64| -> StopChoice {
            let untried = StopChoice::tangential((fraction, accel_share), (a_max, j_max), 0.0);
            let mut trial = *b;
            trial.stop_accel = untried.accel;
            trial.stop_jerk = untried.jerk;
            let (stop, a0) = block_stop(curve_points, &trial, dt);
            let mut interp = Interpolator::new();
            let started = interp.start_profile(&curves, stop, stop.profile().table_from(a0));
            let mut step = || {
                if started {
                    interp.step(&curves, dt, &mut || None)
                } else {
                    Step::Finished
                }
            };
            let ratio = stop_ratio(limits, fd, bound, &mut step);
            StopChoice { ratio, ..untried }
        };
        let mut search = StopSearch {
            simulate: &simulate,
            fractions,
            best: None,
        };
        let point = |i: usize| points.get(i).copied();
        let can_store = !b.is_last() && end >= 1;
        // VPOp's own deceleration first (the plan's states mostly brake at once: one sequence
        // and its check), the module's tangential stop where it does not pass.
        let stored = can_store
            .then(|| {
                let from = (end, points[end - 1], 0);
                stored_stop(&path, &curves, limits, (fd, &point, points.len()), from, &mut brakes)
            })
            .and_then(Result::ok)
            .flatten()
            .filter(|s| s.ratio <= 1.0 + SLACK)
            .map(|s| StoredStop {
                // The block keeps the tangential limits there (the module's stop, were it to
                // need one) and the stored sequence's ratio.
                choice: StopChoice {
                    stored: s.points.len(),
                    ..StopChoice::tangential((1.0, 1.0), (a_max, j_max), s.ratio)
                },
                from: s.from,
                points: s.points,
            });
        let (best, sequence) = match stored {
            Some(stored) => (Some(stored.choice), Some(stored)),
            None => {
                // From the last fraction that passed: 4 ms later the state is nearly the same.
                let found = if searched {
                    search.starting_at(last_passed)
                } else {
                    search.exhaustive()
                };
                searched = true;
                if let Some((k, _)) = found {
                    last_passed = k;
                }
                let best = match found {
                    Some((k, share)) => Some(search.refine(k, share)),
                    None => search.best,
                };
                (best, None)
            }
        };
        sequences.push(sequence);
        if let Some(c) = best {
            b.stop_accel = c.accel;
            b.stop_jerk = c.jerk;
            choices.push(c);
        }
    }
    (choices, sequences)
}

/// Deceleration shares of the module's stop tried at each jerk fraction, largest first (for
/// segment records and path blocks alike).
const SHARES: [f64; 4] = [1.0, 0.5, 0.25, 0.1];

/// The search for a block end's stop: `simulate(fraction, share, bound)` checks one (see
/// [`choose_block_stops`]); the least violating stop tried so far is kept.
struct StopSearch<'s> {
    simulate: &'s dyn Fn(f64, f64, f64) -> StopChoice,
    fractions: &'s [f64],
    best: Option<StopChoice>,
}

impl StopSearch<'_> {
    /// Whether the stop with `fractions[k]` and `SHARES[share]` stays within the limits.
    fn passes(&mut self, k: usize, share: usize) -> bool {
        let bound = self.best.map_or(f64::INFINITY, |c| c.ratio.max(1.0 + SLACK));
        let c = (self.simulate)(self.fractions[k], SHARES[share], bound);
        if self.best.is_none_or(|b| c.ratio < b.ratio) {
            self.best = Some(c);
        }
        c.ratio <= 1.0 + SLACK
    }

    /// The first (fraction, share) that passes, largest fraction first, then largest share,
    /// trying each in turn.
    fn exhaustive(&mut self) -> Option<(usize, usize)> {
        (0..self.fractions.len()).find_map(|k| self.first_share(k).map(|share| (k, share)))
    }

    /// The largest share that passes with `fractions[k]` (a gentler deceleration is a longer
    /// stop, which can reach a tighter bend: it may fail where a steeper one passes).
    fn first_share(&mut self, k: usize) -> Option<usize> {
        (0..SHARES.len()).find(|&share| self.passes(k, share))
    }

    /// The (fraction, share) of [`Self::exhaustive`], searched from fraction index `warm`, taking a
    /// fraction that passes to pass at every smaller one too: upwards from `warm` while the
    /// fractions pass, else downwards from it, and only if none passes there, the larger ones.
    fn starting_at(&mut self, warm: usize) -> Option<(usize, usize)> {
        let warm = warm.min(self.fractions.len() - 1);
        if let Some(share) = self.first_share(warm) {
            let mut found = (warm, share);
            for k in (0..warm).rev() {
                match self.first_share(k) {
                    Some(share) => found = (k, share),
                    None => break,
                }
            }
            return Some(found);
        }
        let n = self.fractions.len();
        (warm + 1..n)
            .chain(0..warm)
            .find_map(|k| self.first_share(k).map(|share| (k, share)))
    }

    /// The stop of fraction index `k` and `share`, which passes, refined towards the next
    /// larger fraction (bisection, 5 steps: the tangential limits hold for the direction at
    /// the block end only, so the largest stop that passes is often just below them).
    fn refine(&mut self, k: usize, share: usize) -> StopChoice {
        let mut good = (self.simulate)(self.fractions[k], SHARES[share], 1.0 + SLACK);
        if k > 0 {
            let mut bad = self.fractions[k - 1];
            for _ in 0..5 {
                let mid = 0.5 * (good.fraction + bad);
                let c = (self.simulate)(mid, SHARES[share], 1.0 + SLACK);
                if c.ratio <= 1.0 + SLACK {
                    good = c;
                } else {
                    bad = mid;
                }
            }
        }
        good
    }
}

/// The stop after the first `end` of the planned positions `point(0..count)` (VPOp's, or the
/// interpolator's samples of segment records): VPOp's deceleration sequence from there, or,
/// where that does not reach rest (VPOp checks its deceleration only where it has to, so not
/// every planned state has one), the plan's own next positions up to the first state whose
/// deceleration sequence does. Every step is a planned or a braking step, so all pass VPOp's
/// constraints; the sequence may cross element joins (only onwards). The search for that state
/// starts at position `resume_at` (or at the stop's start); `Err(resume_at)` if the `count`
/// positions known end first (call again from there with more, or the plan ends there).
fn planned_then_brake(
    path: &JointPath,
    limits: &Limits,
    (point, count): (&dyn Fn(usize) -> Option<PathPoint>, usize),
    (end, resume_at): (usize, usize),
    memo: &mut BrakeMemo,
) -> Result<Vec<PathPoint>, usize> {
    // The deceleration is chosen within the limits themselves, as VPOp's plan is: the module
    // plays its positions from its own (de Boor) evaluation of the curve, which differs from
    // VPOp's power basis by rounding, and the check of the played positions allows that
    // ([`SLACK`]). A margin inside the limits would make the plan's own states, which ride
    // them, unsafe to brake from: with 1e-5 the search walked on along the plan for a state
    // that brakes, and the stops took 2.5 times as long to find.
    let first = resume_at.max(end.max(1) - 1);
    let mut i = first;
    while i < count.saturating_sub(1) {
        // What an earlier search (from an earlier end) found out about position i.
        if memo.failed.contains(&i) {
            i = memo.failed.end;
            continue;
        }
        let brake = match &memo.found {
            Some((at, brake)) if *at == i => Some(brake.clone()),
            _ => {
                let last = [point(i.saturating_sub(2)), point(i.saturating_sub(1)), point(i)];
                match last {
                    [Some(a), Some(b), Some(c)] => brake_points(path, limits, SearchOptions::default(), [a, b, c])
                        .ok()
                        .flatten(),
                    _ => None,
                }
            }
        };
        if let Some(brake) = brake {
            let Some(planned) = (end..=i).map(point).collect::<Option<Vec<PathPoint>>>() else {
                // Not a failure of position i: nothing to remember from this search.
                return Err(first.max(count.saturating_sub(1)));
            };
            memo.remember(first..i, Some((i, brake.clone())));
            return Ok(planned.into_iter().chain(brake).collect());
        }
        i += 1;
    }
    memo.remember(first..i.max(first), None);
    Err(first.max(count.saturating_sub(1)))
}

/// What the searches of [`planned_then_brake`] found out, kept for the next one (the block or
/// record ends come in path order, 4 ms apart, and a search from one end often runs past the
/// next): the positions in `failed` have no deceleration to rest, `found` has one. The results
/// are the same as without it (each position's deceleration depends on it alone).
#[derive(Default)]
struct BrakeMemo {
    failed: std::ops::Range<usize>,
    found: Option<(usize, Vec<PathPoint>)>,
}

impl BrakeMemo {
    /// A search tried `failed` in vain (positions where no deceleration was tried count too:
    /// they are missing or not on the path) and ended at `found`, if anywhere.
    fn remember(&mut self, failed: std::ops::Range<usize>, found: Option<(usize, Vec<PathPoint>)>) {
        // Join the failures when the new run starts inside or right after the old one.
        self.failed = if self.failed.contains(&failed.start) || self.failed.end == failed.start {
            self.failed.start..self.failed.end.max(failed.end)
        } else {
            failed
        };
        if found.is_some() {
            self.found = found;
        }
    }
}

/// [`planned_then_brake`] after the first `end` of the `count` planned positions known
/// (searching from `resume_at`), checked as the module runs it (each position the curve point
/// at its `u`) by finite differences continuing `fd` (the motion up to `from`, the last
/// position before the stop): its positions and worst ratio to an axis limit, `None` where it
/// would step back over an element; `Err` as from [`planned_then_brake`].
fn stored_stop(
    path: &JointPath,
    curves: &PathCurves,
    limits: &Limits,
    (fd, point, count): (FiniteDifferences, &dyn Fn(usize) -> Option<PathPoint>, usize),
    (end, from, resume_at): (usize, PathPoint, usize),
    memo: &mut BrakeMemo,
) -> Result<Option<CheckedStop>, usize> {
    let points = planned_then_brake(path, limits, (point, count), (end, resume_at), memo)?;
    // Elements only onwards, one at a time (the module checks each step).
    let onwards = points.iter().try_fold(from.element, |e, p| {
        (p.element == e || p.element == e + 1).then_some(p.element)
    });
    if points.is_empty() || onwards.is_none() {
        return Ok(None);
    }
    let tip = limits.velocity.len();
    let mut f = fd;
    f.reset_peaks();
    let mut spans = SpanCache::new();
    for p in &points {
        let point = CachedCurve::new(curves.view(p.element), &mut spans).point(p.u);
        f.push(&point[..tip], limits);
    }
    f.finish(limits);
    Ok(Some(CheckedStop {
        from,
        points,
        ratio: f.worst_ratio(limits),
    }))
}

/// A stored stop sequence as [`stored_stop`] checked it.
struct CheckedStop {
    from: PathPoint,
    points: Vec<PathPoint>,
    ratio: f64,
}

/// The arena values of the stored stop `points` that follow `from`: a [`StopRun`] per element,
/// each position as `(u, s)` in its element's measure.
fn stop_runs(arcs: &ArcLengths, from: PathPoint, points: &[PathPoint]) -> Vec<f64> {
    let mut values = Vec::with_capacity(2 * points.len() + StopRun::VALUES);
    let mut before = from;
    for run in points.chunk_by(|a, b| a.element == b.element) {
        let e = run[0].element;
        let header = StopRun {
            curve: e,
            count: run.len(),
            s_before: arcs.s(&before, e),
        };
        values.extend(header.to_values());
        values.extend(run.iter().flat_map(|p| [p.u, arcs.s(p, e)]));
        before = run[run.len() - 1];
    }
    values
}

/// Worst ratio to an axis limit of a stop whose samples `step` yields, by finite differences
/// continuing `fd` (the motion before it) and at rest after it; abandoned (a value above
/// `bound`) as soon as it is worse than `bound`, as it cannot be the choice then.
fn stop_ratio(limits: &Limits, fd: FiniteDifferences, bound: f64, step: &mut dyn FnMut() -> Step) -> f64 {
    let tip = limits.velocity.len();
    let mut f = fd;
    f.reset_peaks();
    while let Step::Sample(s) = step() {
        f.push(&s.point[..tip], limits);
        let ratio = f.worst_ratio(limits);
        if ratio > bound {
            return ratio;
        }
    }
    f.finish(limits);
    f.worst_ratio(limits)
}

/// Tangential deceleration and jerk the axes allow at the end of `b`: min over the axes of the
/// limit over the axis' share of the unit tangent.
fn tangential_limits(curves: &PathCurves, limits: &Limits, b: &PathBlock) -> (f64, f64) {
    crate::hold_stops::tangential_limits(curves, limits, b.curve(), b.u[b.len().saturating_sub(1)])
}

/// Per curve, the points the module's stop after a path block must respect: where the VPOp plan
/// itself passes slowest (every local minimum of its feed, as a cap of that feed: the path
/// needs it there, e.g. at a sharp turn) and the curve end, at rest. The stop is compressed to
/// pass them no faster; the simulation check decides whether that stays within the limits.
pub fn block_stop_points(toolpath: &Toolpath, blocks: &[PathBlock], period: f64) -> Vec<Vec<(f64, f64)>> {
    let mut stops: Vec<Vec<(f64, f64)>> = toolpath
        .elements
        .iter()
        .map(|e| vec![(ArcLengthTable::new(&e.curve).total(), 0.0)])
        .collect();
    // (curve, s, feed) of every sample, the feed over the step into it.
    let samples: Vec<(usize, f64, f64)> = blocks
        .iter()
        .flat_map(|b| (0..b.len()).map(move |k| (b.curve(), b.s[k], (b.s[k] - b.s_history(k + 1)) / period)))
        .collect();
    for w in samples.windows(3) {
        let (c, s, f) = w[1];
        if f > 0.0 && f < w[0].2 && f <= w[2].2 {
            if let Some(list) = stops.get_mut(c) {
                list.push((s, f));
            }
        }
    }
    for list in &mut stops {
        list.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    stops
}

/// A VPOp plan ready for the channel: its blocks in groups (a block whose stop the planner
/// could not bring within the limits joins the next block's group), and the arena data their
/// stops need, which the streamer writes before the block goes out and whose offsets it
/// fills in: per block its stored stop sequence ([`StopRun`]s), per curve its stop points.
#[derive(Clone)]
pub struct BlockPlan {
    pub blocks: Vec<PathBlock>,
    /// The stored stop sequence after each block, as arena values (a group's last block only).
    pub stored: Vec<Option<Vec<f64>>>,
    /// Per curve, its stop points as `(s, feed cap)` pairs.
    pub points: Vec<Vec<f64>>,
    /// The stop choice of each block.
    pub choices: Vec<StopChoice>,
    /// Motion time of one block sample (s).
    pub period: f64,
    /// The path's curves, for the geometry stream.
    pub curves: Vec<Nurbs>,
}

impl BlockPlan {
    /// Motion time of block `k`.
    pub fn time(&self, k: usize) -> f64 {
        self.blocks.get(k).map_or(0.0, |b| b.len() as f64 * self.period)
    }

    /// Block ends with a stop within the limits, stored sequences among them, and the worst
    /// ratio of those stops to an axis limit.
    pub fn stops(&self) -> (usize, usize, f64) {
        let ends = self.blocks.iter().filter(|b| b.group_left == 1 && !b.is_last()).count();
        let stored = self.stored.iter().filter(|s| s.is_some()).count();
        let worst = self
            .blocks
            .iter()
            .zip(&self.choices)
            .filter(|(b, _)| b.group_left == 1 && !b.is_last())
            .map(|(_, c)| c.ratio)
            .fold(0.0, f64::max);
        (ends, stored, worst)
    }
}

/// The blocks of a plan of one point per period (`points`, planned within `limits`: VPOp's or
/// the reachability planner's) with their checked stops (jerk fractions up to
/// `max_fraction`), in groups, and the data their stops need. `anchor`: the stop point a
/// re-plan starts from (its arc length is kept exactly).
pub fn block_plan(
    toolpath: &Toolpath,
    (points, limits): (&[PathPoint], &Limits),
    anchor: Option<&StopPoint>,
    max_fraction: f64,
) -> Result<BlockPlan, String> {
    check_tip_path(toolpath)?;
    if !(max_fraction > 0.0 && max_fraction <= 1.0) {
        return Err(format!("stop fraction {max_fraction} must be in (0, 1]"));
    }
    let mut arcs = ArcLengths::new(toolpath);
    if let Some(a) = anchor {
        let start = plan_start(&mut PathCurves::new(toolpath), a);
        arcs.set_anchor(start.curve, start.u, start.s);
    }
    let mut blocks = pack_blocks(&arcs, points);
    let stop_points: Vec<Vec<f64>> = block_stop_points(toolpath, &blocks, limits.period)
        .iter()
        .map(|list| list.iter().flat_map(|&(s, cap)| [s, cap]).collect())
        .collect();
    let (choices, sequences) = choose_block_stops(
        toolpath,
        limits,
        &mut blocks,
        &stop_points,
        &fractions(max_fraction),
        points,
    );
    // From the last block back: a block ends its group where its stop passed (or at the path
    // end); the group's curves reach as far as the stored stop at its end.
    let mut stored = vec![None; blocks.len()];
    let (mut group_left, mut needed) = (0u32, 0u32);
    for (k, (b, sequence)) in blocks.iter_mut().zip(sequences).enumerate().rev() {
        let passes = choices.get(k).is_some_and(|c| c.ratio <= 1.0 + SLACK);
        if passes || b.is_last() {
            group_left = 1;
            needed = b.curve;
            if let Some(seq) = sequence.filter(|_| passes) {
                needed = needed.max(seq.points.last().map_or(0, |p| p.element as u32));
                stored[k] = Some(stop_runs(&arcs, seq.from, &seq.points));
                b.stop_len = seq.points.len() as u32;
            }
        } else {
            group_left += 1;
            needed = needed.max(b.curve);
        }
        b.group_left = group_left;
        b.curve_needed = needed;
    }
    Ok(BlockPlan {
        blocks,
        stored,
        points: stop_points,
        choices,
        period: limits.period,
        curves: toolpath.elements.iter().map(|e| e.curve.clone()).collect(),
    })
}

/// The VPOp plan of `toolpath` (tool tip), from its start or from rest at the stop point `from`.
pub fn vpop_plan(toolpath: &Toolpath, limits: &Limits, from: Option<&StopPoint>) -> Result<VpopPlan, String> {
    check_tip_path(toolpath)?;
    let options = SearchOptions {
        start: from.map(|p| {
            let start = plan_start(&mut PathCurves::new(toolpath), p);
            (start.curve, start.u)
        }),
        ..SearchOptions::default()
    };
    plan_tip(toolpath, limits, options).map_err(|e| match from {
        None => e.to_string(),
        Some(_) => format!("re-plan from the stop point: {e}"),
    })
}

/// The reachability plan of `toolpath` (tool tip), from its start or from rest at the stop
/// point `from`.
pub fn reach_plan(toolpath: &Toolpath, limits: &Limits, from: Option<&StopPoint>) -> Result<ReachPlan, String> {
    check_tip_path(toolpath)?;
    let start = from.map(|p| {
        let start = plan_start(&mut PathCurves::new(toolpath), p);
        (start.curve, start.u)
    });
    reach::plan_tip(toolpath, limits, &ReachOptions::default(), start).map_err(|e| match from {
        None => e.to_string(),
        Some(_) => format!("re-plan from the stop point: {e}"),
    })
}

/// Whether a motion of `total` seconds (infinite while unknown) can start with its first
/// `ready` seconds planned, planning at `rate` seconds of motion per second: the plan must stay
/// `margin` ahead of the motion to its end, counted at half the measured rate (the planner
/// shares the machine with the module and everything else, and later parts may cost more).
/// Where planning is faster than the motion that is `margin`; where slower, enough more that
/// the motion does not catch up with it (an underrun stop on the way).
pub fn far_enough_ahead(ready: f64, total: f64, rate: f64, margin: f64) -> bool {
    if ready >= total {
        return true;
    }
    if ready < margin {
        return false;
    }
    let rate = 0.5 * rate;
    if rate >= 1.0 {
        return true;
    }
    rate > 0.0 && ready >= margin + (total - ready) * (1.0 - rate) / rate
}

/// Where a motion's groups of slots come from.
pub enum Source {
    /// A streamed Erwinski plan running in its own thread, and the groups it has handed out
    /// that wait to be sent.
    Segments {
        events: Option<Receiver<PlanEvent>>,
        queue: VecDeque<SegmentGroup>,
        /// Motion time of the groups in `queue` (s).
        queued: f64,
        /// The plan has ended; its motion time.
        total: Option<f64>,
        /// The plan ended before the file did (it could not be read further).
        error: Option<String>,
        /// How the plan is made again at another feed override (`None`: groups planned
        /// already, which keep theirs).
        replanner: Option<Box<Replanner>>,
        /// The servo period the plan was made for (s).
        period: f64,
    },
    /// A VPOp plan with its checked stops, sent block group by block group.
    Blocks {
        plan: BlockPlan,
        next: usize,
        /// Where each curve's stop points lie in the arena, once written.
        points: HashMap<usize, (u32, u32)>,
    },
}

/// Slots that go into the ring together, with the curve they need up to.
pub struct Group {
    slots: Vec<Slot>,
    times: Vec<f64>,
    curve_needed: u32,
    /// Path blocks: the blocks' indices in the plan, and how many of them have their arena
    /// data written (and their slots made with its offsets).
    blocks: Vec<usize>,
    written: usize,
    /// Segment records: the stop chain of the last slot, still to be written to the arena.
    chain: Option<Vec<f64>>,
    /// Segment records: per slot, the checked stops inside it, and how many slots have theirs
    /// written to the arena.
    hold_stops: Vec<RecordStops>,
    hold_stops_written: usize,
    /// Segment records: where the group leaves the motion.
    end: Option<Box<GroupEnd>>,
    /// Segment records: what a cut into them needs ([`RingGroup`]).
    cut_data: Option<RingGroup>,
}

/// A group of segment records in the ring (or running), as a plan at another feed override
/// that cuts into one of them needs it ([`crate::cut`]).
#[derive(Clone)]
struct RingGroup {
    /// Slot number of its first record.
    first: u64,
    records: Vec<SegmentRecord>,
    /// The motion's state before its first record.
    begin: Box<SimState>,
    /// Per record, the motion samples with a checked hold stop (where a cut may come).
    hold_samples: Vec<Vec<u64>>,
    /// The feed override of its plan.
    feed_override: f64,
}

impl RingGroup {
    /// Slot number after its last record.
    fn end(&self) -> u64 {
        self.first + self.records.len() as u64
    }
}

/// Plans a streamed motion again at another feed override, in a thread of its own, from the
/// end of the last group sent: the module runs into the new plan's groups as it ran into the
/// old ones, and the old ones not yet sent are dropped.
pub struct Replanner {
    path: SharedPath,
    limits: Limits,
    /// Where the motion started (a new plan from there while nothing has been sent).
    from: Option<StopPoint>,
    /// The override of the plan being sent, and the last one asked for (a re-plan refused is
    /// not tried again until it changes).
    feed_override: f64,
    asked: f64,
    pending: Option<Pending>,
    /// The override a cut was refused for, and the first slot of the group it was refused in:
    /// a re-plan at that override cuts only into later groups (else it joins at a group end).
    cut_refused: Option<(f64, u64)>,
    /// How far ahead of the module it joins (s of motion): at least [`JOIN_LEAD`] and what the
    /// last re-plan took to be ready ([`Self::lead`]), doubled each time the re-plan came too
    /// late.
    lead: f64,
    /// How long the last re-plan took from its start until it was ready to join (s); before
    /// the first, how long the first plan took to plan [`FIRST_LEAD_PLANNED`] of motion.
    ready_after: Option<f64>,
    /// When the override the next re-plan is for was asked for, where earlier re-plans at it
    /// came too late.
    retry_since: Option<Instant>,
}

/// A re-plan in progress: its events, the groups it has handed out, and how many slots had
/// been sent when it began (it continues their last group; it is stale once more went out).
struct Pending {
    events: Receiver<PlanEvent>,
    groups: VecDeque<SegmentGroup>,
    queued: f64,
    total: Option<f64>,
    error: Option<String>,
    pushed: u64,
    feed_override: f64,
    /// When it began, and when the override was asked for (earlier where re-plans before it
    /// came too late).
    began: Instant,
    since: Instant,
    /// Where it joins: in or after the slot of this number, through the module's
    /// [`nurbs_hal::channel::Splice`] (after motion sample `.1`, a cut into the record, or at
    /// its end, [`AT_RECORD_END`], a group end still queued), or `None`: at the end of the
    /// slots sent.
    join: Option<(u64, u64)>,
    /// A cut: the slot number of the first record of the group it comes in, until the re-plan
    /// says where in it ([`SegmentGroup::cut`]; `join` holds the first candidate till then).
    cut_group: Option<u64>,
    /// The join has been asked of the module (nothing is sent until it answers).
    requested: bool,
    /// When its first group came, and that group's motion time (its pace counts from there).
    first_group: Option<(Instant, f64)>,
}

impl Replanner {
    /// How far ahead of the module the next re-plan joins: the lead, and at least what the last
    /// re-plan took to be ready, with a quarter more and the module's time to answer (a re-plan
    /// that comes too late plans again from further on, which takes twice as long).
    fn lead(&self) -> f64 {
        let learned = self.ready_after.map_or(0.0, |t| 1.25 * t + SPLICE_LAST_CALL);
        self.lead.max(learned).min(JOIN_LEAD_MAX)
    }
}

/// Runs [`stream_plan`] in a thread of its own; its events, at most [`EVENTS_AHEAD`] waiting.
fn spawn_plan(path: SharedPath, limits: Limits, start: StreamStart, feed_override: f64) -> Receiver<PlanEvent> {
    let (sender, receiver) = mpsc::sync_channel(EVENTS_AHEAD);
    std::thread::spawn(move || {
        stream_plan(&|| path.open(), &limits, start, feed_override, &mut |e| {
            sender.send(e).is_ok()
        })
    });
    receiver
}

/// A feed override change smaller than this (relative) is not worth a re-plan (`halui`
/// reports the knob in steps of 1 % or more).
const OVERRIDE_STEP: f64 = 1e-3;

/// While a re-plan at another feed override that joins at the end of the slots sent is on its
/// way, the old plan's next group waits unless the ring holds less motion than this (s): the
/// re-plan then joins after it instead.
const REPLAN_LOW_WATER: f64 = 0.05;

/// A re-plan at another feed override joins at least this far (s of motion) ahead of the
/// module, and as far as the last re-plan took to be ready ([`Replanner::lead`]): at the first
/// checked hold stop there (a cut into the record), else at the first group end with that much
/// motion queued before it. Where it comes too late, the lead doubles, up to
/// [`JOIN_LEAD_MAX`]. Below 30 ms most first cuts into the butterfly and a G1 zigzag came too
/// late (their re-plans are ready in 15-35 ms), and a late one costs a second try further
/// ahead (60-100 ms after the change).
const JOIN_LEAD: f64 = 0.03;
const JOIN_LEAD_MAX: f64 = 0.32;

/// ... and asks the module only while at least this much is (s).
const SPLICE_LAST_CALL: f64 = 0.005;

/// Motion (s) a re-plan must plan before it is ready to join, as first estimated: at the leads
/// it joins with (30-60 ms) the motion before the join makes up the rest of [`START_AHEAD`].
/// Its first plan's time to plan this much is the first re-plan's expected time.
const FIRST_LEAD_PLANNED: f64 = 0.5 * START_AHEAD;

impl Source {
    /// The Erwinski plan of `path` (from its start, or from rest at the stop point `from`) at
    /// `feed_override` as a stream, planned in a thread of its own that reads the path as it
    /// plans and waits while [`QUEUED_AHEAD`] seconds of motion wait to be sent; planned again
    /// when the override changes ([`Streamer::set_feed_override`]). The streamer releases the
    /// path behind the module ([`SharedPath::release_before`]).
    pub fn streamed(path: SharedPath, limits: Limits, from: Option<StopPoint>, feed_override: f64) -> Source {
        let events = spawn_plan(path.clone(), limits.clone(), StreamStart::Rest(from), feed_override);
        Source::Segments {
            events: Some(events),
            queue: VecDeque::new(),
            queued: 0.0,
            total: None,
            error: None,
            period: limits.period,
            replanner: Some(Box::new(Replanner {
                path,
                limits,
                from,
                feed_override,
                asked: feed_override,
                pending: None,
                cut_refused: None,
                lead: JOIN_LEAD,
                ready_after: None,
                retry_since: None,
            })),
        }
    }

    /// Groups planned already (a whole streamed plan: [`plan_groups`]) for the servo period
    /// `period` (s).
    pub fn groups(groups: Vec<SegmentGroup>, period: f64) -> Source {
        let total = groups.iter().map(|g| g.time).sum();
        Source::Segments {
            events: None,
            queue: groups.into(),
            queued: total,
            total: Some(total),
            error: None,
            replanner: None,
            period,
        }
    }

    /// The servo period the plan was made for (s).
    fn period(&self) -> f64 {
        match self {
            Source::Segments { period, .. } => *period,
            Source::Blocks { plan, .. } => plan.period,
        }
    }

    /// A VPOp plan's blocks.
    pub fn blocks(plan: BlockPlan) -> Source {
        Source::Blocks {
            plan,
            next: 0,
            points: HashMap::new(),
        }
    }

    /// Motion time planned so far.
    fn planned(&self) -> f64 {
        match self {
            Source::Segments { total: Some(t), .. } => *t,
            Source::Segments { .. } => 0.0,
            Source::Blocks { plan, .. } => plan.blocks.iter().map(|b| b.len() as f64 * plan.period).sum(),
        }
    }
}

/// Motion time (s) planned before the motion starts, where the planner's pace lets the queue
/// grow from there to the margin as the motion runs (the start rule asks for twice the
/// motion's pace): the machine moves within milliseconds of the start, whatever the program's
/// length. At that pace the next group may be twice as long before it could come late; on a
/// dense G1 program (groups of 0.1-0.5 s, planned at 8-12 times the motion's pace) the first two
/// groups make 0.13 s.
pub const START_AHEAD: f64 = 0.1;

/// Motion time (s) of the groups a streamed plan hands out ahead of the ring: the planner
/// thread waits beyond it, so that memory follows the look-ahead, not the program's length.
pub const QUEUED_AHEAD: f64 = 20.0;
/// While a re-plan at another feed override is on its way, the plan it is to replace is not
/// read further once this much of its motion (s) waits to be sent: its thread then waits (its
/// channel full), and the re-plan has the processor (on two cores, a plan still running ahead
/// near a program's start, its scan helper and the re-plan shared them, and the re-plan took
/// twice as long).
const REPLAN_PAUSE: f64 = 1.0;

/// Events the planner thread may hand out before the streamer takes them.
const EVENTS_AHEAD: usize = 4;

/// The whole streamed plan of `toolpath` as groups, planned here (tests, benches).
pub fn plan_groups(
    toolpath: &Toolpath,
    limits: &Limits,
    from: Option<&StopPoint>,
) -> Result<Vec<SegmentGroup>, String> {
    let mut groups = Vec::new();
    let mut failed = None;
    let open = || Ok(PathCurves::new(toolpath));
    stream_plan(&open, limits, StreamStart::Rest(from.copied()), 1.0, &mut |e| {
        match e {
            PlanEvent::Group(g) => groups.push(g),
            PlanEvent::Done { error, .. } => failed = error,
            PlanEvent::Failed(e) => failed = Some(e),
        }
        true
    });
    failed.map_or(Ok(groups), Err)
}

/// Streams one motion into the channel: its curves into the geometry stream, its groups of
/// slots into the ring within the time margin.
pub struct Streamer<'a> {
    channel: &'a Channel,
    writer: GeometryWriter<'a>,
    /// Curves the groups taken so far need that wait for the geometry stream, from the
    /// writer's next curve on; the index the next curve queued will have.
    curves: VecDeque<Nurbs>,
    next_queued: u32,
    source: Source,
    /// The next group to go out (its curves published as far as there was room).
    current: Option<Group>,
    /// Motion time of the slots pushed and not yet taken by the module, oldest first, and
    /// their sum; slots pushed in all, and the motion time they make.
    in_ring: VecDeque<(u64, f64)>,
    buffered: f64,
    /// The ring's count of this stream's first slot (slot `k` has count `ring_base + k`).
    ring_base: u32,
    /// Slots (numbers) that end a group still in the ring or running, with where they leave
    /// the motion: where a re-plan at another feed override may join.
    group_ends: VecDeque<(u64, Box<GroupEnd>)>,
    /// The segment groups still in the ring or running: where such a re-plan may cut in.
    ring_groups: VecDeque<RingGroup>,
    pub pushed: u64,
    pub pushed_time: f64,
    /// Motion time planned (received from the planner), in how many groups, and when
    /// planning began.
    planned: f64,
    groups_planned: usize,
    began: Instant,
    margin: f64,
    /// Records may go into the ring (the start rule has held once).
    started: bool,
    /// Longest group sent (s of motion: how long a hold may take to begin).
    pub longest_group: f64,
    /// Plans at another feed override run into: at a group end in the ring (the module
    /// dropping the old plan's slots after it), and at the end of the slots sent.
    pub joins_in_ring: u32,
    pub joins_at_end: u32,
    /// ... and cutting into a record the module runs or has queued ([`crate::cut`]).
    pub cuts: u32,
    /// Where the last group sent leaves the motion (`None` before the first, and after the
    /// path's last).
    last_end: Option<Box<GroupEnd>>,
}

impl<'a> Streamer<'a> {
    /// Begins the geometry stream of a motion of a `tip`-axis path whose first curve is
    /// `first_curve` (the module must run no motion), to be filled from `source` keeping
    /// `margin` seconds queued. `began`: when its planning began (the start rule's pace).
    pub fn new(
        channel: &'a Channel,
        tip: usize,
        source: Source,
        first_curve: usize,
        margin: f64,
        began: Instant,
    ) -> Result<Self, String> {
        let first = u32::try_from(first_curve).map_err(|_| "path element index beyond 32 bits".to_string())?;
        let writer = GeometryWriter::begin(channel, first, tip, source.period())?;
        channel.set_planned_time(0.0);
        // No motion runs, so no join of an earlier stream is open.
        channel.splice.reset();
        Ok(Streamer {
            channel,
            writer,
            curves: VecDeque::new(),
            next_queued: first,
            planned: source.planned(),
            // (A source planned whole counts as paced: it has all its motion.)
            groups_planned: 0,
            source,
            current: None,
            in_ring: VecDeque::new(),
            ring_base: channel.segments.producer().pushed(),
            group_ends: VecDeque::new(),
            ring_groups: VecDeque::new(),
            buffered: 0.0,
            pushed: 0,
            pushed_time: 0.0,
            began,
            margin,
            started: false,
            longest_group: 0.0,
            joins_in_ring: 0,
            joins_at_end: 0,
            cuts: 0,
            last_end: None,
        })
    }

    /// The geometry stream's writer (to limit what it uses, in tests).
    pub fn writer(&mut self) -> &mut GeometryWriter<'a> {
        &mut self.writer
    }

    /// Slots the module has taken.
    fn taken(&self) -> u64 {
        self.pushed - self.channel.segments.len() as u64
    }

    /// Motion time queued in the ring.
    pub fn buffered(&mut self) -> f64 {
        let taken = self.taken();
        while self.in_ring.front().is_some_and(|&(k, _)| k < taken) {
            if let Some((_, t)) = self.in_ring.pop_front() {
                self.buffered -= t;
            }
        }
        while self.group_ends.front().is_some_and(|(k, _)| k + 1 < taken) {
            self.group_ends.pop_front();
        }
        while self.ring_groups.front().is_some_and(|g| g.end() < taken) {
            self.ring_groups.pop_front();
        }
        self.buffered.max(0.0)
    }

    /// Motion time queued in the ring up to slot `k` (its own included).
    fn queued_through(&mut self, k: u64) -> f64 {
        self.buffered();
        self.in_ring.iter().take_while(|&&(j, _)| j <= k).map(|&(_, t)| t).sum()
    }

    /// Where a re-plan at another feed override joins: the first group end in the ring with
    /// `lead` of motion queued before it (its slot number and end), or `None`: at the end of
    /// the slots sent.
    fn join_point(&mut self, lead: f64) -> Option<(u64, Box<GroupEnd>)> {
        let last = self.pushed.checked_sub(1)?;
        self.buffered();
        let (mut queued, mut slots) = (0.0, self.in_ring.iter().peekable());
        for (k, end) in &self.group_ends {
            if *k >= last {
                return None;
            }
            while let Some(&(_, t)) = slots.next_if(|(j, _)| j <= k) {
                queued += t;
            }
            if queued >= lead {
                return Some((*k, end.clone()));
            }
        }
        None
    }

    /// Where a re-plan at another feed override may cut in: the checked hold stops at least
    /// `lead` (s of motion) ahead of the module's last sample in the first group that has one
    /// (after the group whose first slot is `after`, if given), in records still to run or
    /// running (the group's first slot number and what the cut needs), or `None`.
    fn cut_point(&mut self, period: f64, lead: f64, after: Option<u64>) -> Option<(u64, Box<CutFrom>)> {
        let taken = self.taken();
        self.buffered();
        let target = self.channel.splice.samples() + (lead / period).ceil() as u64;
        let later = |g: &&RingGroup| after.is_none_or(|k| g.first > k);
        self.ring_groups.iter().filter(later).find_map(|g| {
            let candidates: Vec<(usize, u64)> = g
                .hold_samples
                .iter()
                .enumerate()
                .filter(|&(i, _)| g.first + i as u64 + 1 >= taken) // not run already
                .flat_map(|(i, samples)| samples.iter().filter(|&&n| n >= target).map(move |&n| (i, n)))
                .collect();
            let from = CutFrom {
                begin: *g.begin,
                records: g.records.clone(),
                candidates,
                feed_override: g.feed_override,
            };
            (!from.candidates.is_empty()).then(|| (g.first, Box::new(from)))
        })
    }

    /// Every slot has gone into the ring.
    pub fn done(&self) -> bool {
        self.current.is_none()
            && match &self.source {
                Source::Segments {
                    events, queue, total, ..
                } => events.is_none() && queue.is_empty() && total.is_some(),
                Source::Blocks { plan, next, .. } => *next >= plan.blocks.len(),
            }
    }

    /// Why the plan ended before the toolpath file did, once it has ended.
    pub fn plan_error(&self) -> Option<&str> {
        match &self.source {
            Source::Segments { error, .. } => error.as_deref(),
            Source::Blocks { .. } => None,
        }
    }

    /// Whether [`QUEUED_AHEAD`] seconds of motion wait to be sent (the planner waits for them).
    fn queue_full(&self) -> bool {
        matches!(&self.source, Source::Segments { queued, events: Some(_), .. } if *queued >= QUEUED_AHEAD)
    }

    /// Takes what the planner thread has handed out so far, up to [`QUEUED_AHEAD`].
    fn receive(&mut self) -> Result<(), String> {
        self.receive_replan();
        let Source::Segments {
            events,
            queue,
            queued,
            total,
            error,
            replanner,
            ..
        } = &mut self.source
        else {
            return Ok(());
        };
        let replanning = replanner.as_ref().is_some_and(|r| r.pending.is_some());
        while let Some(rx) = events {
            if *queued >= QUEUED_AHEAD || (replanning && *queued >= REPLAN_PAUSE) {
                break;
            }
            match rx.try_recv() {
                Ok(PlanEvent::Group(g)) => {
                    self.planned += g.time;
                    self.groups_planned += 1;
                    if let (true, Some(r)) = (self.planned >= FIRST_LEAD_PLANNED, replanner.as_deref_mut()) {
                        // What a re-plan of this path will take to be ready, until one has been:
                        // what its first plan took to plan as much as a re-plan must.
                        r.ready_after.get_or_insert(self.began.elapsed().as_secs_f64());
                    }
                    *queued += g.time;
                    queue.push_back(g);
                }
                Ok(PlanEvent::Done { line, error: failed }) => {
                    say!("nurbs-planner: {line}");
                    *total = Some(self.planned);
                    *events = None;
                    *error = failed;
                }
                Ok(PlanEvent::Failed(e)) => return Err(e),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    // A panic in the planning thread (its message kept by nurbs_motion::panics).
                    let why = nurbs_motion::panics::take_last();
                    return Err(format!(
                        "the planner thread ended before the plan did{}",
                        why.map_or(String::new(), |w| format!(": {w}"))
                    ));
                }
            }
        }
        Ok(())
    }

    /// Asks for the motion at feed override `feed_override` (the operator's, clamped to what
    /// the machine allows): a streamed plan is planned again at it from a cut into a record at
    /// a checked hold stop the join lead ahead (learned by the [`Replanner`]; [`crate::cut`]),
    /// else from the first group end in the ring with that much motion before it (the module
    /// drops the old plan's slots after it there: [`nurbs_hal::channel::Splice`]), else from
    /// the end of the last group sent (or from its start while nothing has been sent), and the
    /// motion runs into the new plan there. 0 (a hold, which the module carries out) and small
    /// changes keep the plan. Plans sent whole keep their override.
    pub fn set_feed_override(&mut self, feed_override: f64) {
        {
            let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
                return;
            };
            let close = |a: f64, b: f64| (a - b).abs() <= OVERRIDE_STEP * b;
            if feed_override.is_nan() || feed_override <= 0.0 || close(feed_override, r.asked) {
                return;
            }
            if r.pending.as_ref().is_some_and(|p| p.requested) {
                // The module is asked to join one already: this one follows once it has
                // answered.
                return;
            }
            r.asked = feed_override;
            if close(feed_override, r.feed_override) {
                // Back to the plan being sent: a re-plan on its way is not needed any more.
                r.pending = None;
                return;
            }
        }
        let (pushed, next_queued) = (self.pushed, self.next_queued);
        let last_end = self.last_end.clone();
        let (period, refused_in, lead) = match &self.source {
            Source::Segments { replanner: Some(r), .. } => (
                r.limits.period,
                r.cut_refused.filter(|&(o, _)| o == feed_override).map(|(_, g)| g),
                r.lead(),
            ),
            _ => return,
        };
        let cut = self.cut_point(period, lead, refused_in);
        let join = if cut.is_some() { None } else { self.join_point(lead) };
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let send_from = next_queued as usize;
        let cut_group = cut.is_some();
        let (start, from, place) = match (cut, &join, &last_end) {
            (Some((first, cut)), _, _) => {
                let (at_sample, seq) = (cut.candidates[0].1, cut.records[cut.candidates[0].0].seq);
                (
                    StreamStart::Cut { from: cut, send_from },
                    format!("motion sample {at_sample} (inside record {seq}) or a later one"),
                    Some((first, at_sample)),
                )
            }
            (None, Some((k, end)), _) => (
                StreamStart::After {
                    end: end.clone(),
                    send_from,
                },
                format!("the end of record {}", end.record.seq),
                Some((*k, AT_RECORD_END)),
            ),
            (None, None, Some(end)) => (
                StreamStart::After {
                    end: end.clone(),
                    send_from,
                },
                format!("the end of record {}", end.record.seq),
                None,
            ),
            // The path's last group has gone out: nothing left to plan.
            (None, None, None) if pushed > 0 => {
                say!("nurbs-planner: feed override {feed_override}: not taken, the path's last group has gone out and has no cut ahead of the module");
                return;
            }
            (None, None, None) => (StreamStart::Rest(r.from), "its start".to_string(), None),
        };
        say!("nurbs-planner: feed override {feed_override}: planning the rest of the motion again from {from}");
        r.pending = Some(Pending {
            events: spawn_plan(r.path.clone(), r.limits.clone(), start, feed_override),
            groups: VecDeque::new(),
            queued: 0.0,
            total: None,
            error: None,
            pushed,
            feed_override,
            began: Instant::now(),
            since: r.retry_since.take().unwrap_or_else(Instant::now),
            join: place,
            cut_group: cut_group.then_some(place.map_or(0, |(k, _)| k)),
            requested: false,
            first_group: None,
        });
    }

    /// Plans again at `feed_override` from a later place, a re-plan at it having failed to
    /// join (`since`: when the override was asked for, for the log).
    fn plan_again(&mut self, feed_override: f64, since: Instant) {
        if let Source::Segments { replanner: Some(r), .. } = &mut self.source {
            r.asked = r.feed_override;
            r.retry_since = Some(since);
        }
        self.set_feed_override(feed_override);
        if let Source::Segments { replanner: Some(r), .. } = &mut self.source {
            r.retry_since = None;
        }
    }

    /// Takes what a re-plan at another feed override has handed out; once it has a group, the
    /// motion runs into it: at a group end still queued once the module has accepted the join
    /// (asked while the module is [`SPLICE_LAST_CALL`] or more before it), or at the end of the
    /// slots sent if nothing was sent since it began. Otherwise it begins again from a later
    /// join. A re-plan that fails leaves the plan as it is.
    fn receive_replan(&mut self) {
        let pushed = self.pushed;
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let Some(p) = &mut r.pending else {
            return;
        };
        while p.queued < QUEUED_AHEAD && p.total.is_none() {
            match p.events.try_recv() {
                Ok(PlanEvent::Group(g)) => {
                    p.first_group.get_or_insert((Instant::now(), g.time));
                    p.queued += g.time;
                    p.groups.push_back(g);
                }
                Ok(PlanEvent::Done { line, error }) => {
                    say!("nurbs-planner: {line}");
                    p.total = Some(p.queued);
                    p.error = error;
                }
                Ok(PlanEvent::Failed(e)) if !p.requested && p.join.is_some_and(|(_, n)| n != AT_RECORD_END) => {
                    // No cut in that group: cut into a later one, or join at a group end.
                    say!(
                        "nurbs-planner: feed override {}: no cut into that group ({e}); trying a later one or a group end",
                        p.feed_override
                    );
                    let asked = p.feed_override;
                    // (The group it cuts into, or, where its groups came before it failed, the
                    // record it cut into: either way a later group is tried next.)
                    r.cut_refused = p.cut_group.or(p.join.map(|(k, _)| k)).map(|g| (asked, g));
                    let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                    self.plan_again(asked, since);
                    return;
                }
                Ok(PlanEvent::Failed(e)) if !p.requested => {
                    say!(
                        "nurbs-planner: feed override {} not taken, the motion goes on at {}: {e}",
                        p.feed_override,
                        r.feed_override
                    );
                    r.pending = None;
                    return;
                }
                Ok(PlanEvent::Failed(e)) => {
                    // Asked of the module already: the plan has failed after its first groups;
                    // it ends there, at rest at a checked stop, as an underrun.
                    say!(
                        "nurbs-planner: the re-plan at feed override {} failed: {e}",
                        p.feed_override
                    );
                    p.total = Some(p.queued);
                    p.error = Some(e);
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    p.total = Some(p.queued);
                    break;
                }
            }
        }
        if p.groups.is_empty() {
            if p.total.is_some() && !p.requested {
                r.pending = None;
            }
            return;
        }
        if let (Some(first), Some(place)) = (p.cut_group, p.groups.front().and_then(|g| g.cut)) {
            // Where in the group the cut comes.
            p.join = Some((first + place.record as u64, place.at_sample));
            p.cut_group = None;
        }
        if !p.requested {
            // The motion runs into the new plan only once it could start on it: as much motion
            // ahead of the module, the old plan's up to the join and the new one's planned, at
            // the pace, as a motion from rest waits for ([`START_AHEAD`]). The pace counts from
            // the first group on (its wait is the time to join, not the pace it keeps) once a
            // second one has come.
            let rate = match p.first_group {
                Some((at, time)) if p.groups.len() >= 2 => (p.queued - time) / at.elapsed().as_secs_f64().max(1e-9),
                _ => p.queued / p.began.elapsed().as_secs_f64().max(1e-9),
            };
            let (queued, total, join) = (p.queued, p.total, p.join);
            let before_join = match join {
                None => self.buffered(),
                Some((k, AT_RECORD_END)) => self.queued_through(k),
                Some((_, n)) => n.saturating_sub(self.channel.splice.samples()) as f64 * r.limits.period,
            };
            let total = total.map_or(f64::INFINITY, |t| t + before_join);
            if !far_enough_ahead(queued + before_join, total, rate, START_AHEAD) {
                return;
            }
            let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
                return;
            };
            let Some(p) = &mut r.pending else {
                return;
            };
            r.ready_after = Some(p.began.elapsed().as_secs_f64());
        }
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let Some(p) = &mut r.pending else {
            return;
        };
        if p.join.is_none() && p.pushed != pushed && p.pushed > 0 {
            // The old plan's next group went out meanwhile: the group end the re-plan starts
            // from is in the ring now, and the module may join there (dropping what went out
            // after it) if it is still far enough from it. Planning again after each group
            // that goes out would never catch up where a re-plan takes longer than a group.
            p.join = Some((p.pushed - 1, AT_RECORD_END));
        }
        let (join, requested, asked) = (p.join, p.requested, p.feed_override);
        match join {
            None if p.pushed != pushed => {
                // The old plan's first group went out meanwhile: plan again after it.
                let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                self.plan_again(asked, since);
                return;
            }
            None => {}
            Some((k, at_sample)) if !requested => {
                // The module must still be far enough from the join to answer in time.
                let join = Join {
                    after: self.ring_base.wrapping_add(k as u32),
                    drop_to: self.ring_base.wrapping_add(pushed as u32),
                    at_sample,
                };
                let period = r.limits.period;
                let ahead = if at_sample == AT_RECORD_END {
                    self.queued_through(k)
                } else {
                    at_sample.saturating_sub(self.channel.splice.samples()) as f64 * period
                };
                let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
                    return;
                };
                if ahead < SPLICE_LAST_CALL || !self.channel.splice.request(join) {
                    if ahead < SPLICE_LAST_CALL {
                        r.lead = (2.0 * r.lead).min(JOIN_LEAD_MAX);
                    }
                    let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                    self.plan_again(asked, since);
                    return;
                }
                if let Some(p) = &mut r.pending {
                    p.requested = true;
                }
                return;
            }
            Some(_) => match self.channel.splice.state() {
                SPLICE_ACCEPTED | SPLICE_DONE => {}
                SPLICE_REQUESTED => return,
                _ => {
                    // Missed (too late, or the motion stopped): plan again from a later join,
                    // further ahead.
                    r.lead = (2.0 * r.lead).min(JOIN_LEAD_MAX);
                    let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                    self.plan_again(asked, since);
                    return;
                }
            },
        }
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let Some(p) = r.pending.take() else {
            return;
        };
        r.feed_override = p.feed_override;
        r.lead = JOIN_LEAD;
        let still_asked = r.asked;
        match p.join {
            Some((_, AT_RECORD_END)) => self.joins_in_ring += 1,
            Some(_) => self.cuts += 1,
            None => self.joins_at_end += 1,
        }
        if let Some((k, at_sample)) = p.join {
            // The module drops the old plan's slots after the join: they are not queued motion;
            // nor is the rest of the record a cut comes in.
            let cut = at_sample != AT_RECORD_END;
            let kept = |j: u64| j < k || (j == k && !cut);
            let mut dropped: f64 = self.in_ring.iter().filter(|&&(j, _)| !kept(j)).map(|&(_, t)| t).sum();
            let rest = p.groups.front().and_then(|g| g.cut).map_or(0.0, |c| c.dropped_time);
            if let Some(entry) = self.in_ring.iter_mut().find(|(j, _)| *j == k).filter(|_| cut) {
                // Still queued: the part before the cut stays.
                entry.1 -= rest;
                dropped -= entry.1;
            } else {
                dropped += rest;
            }
            self.in_ring.retain(|&(j, _)| j <= k);
            self.group_ends.retain(|&(j, _)| kept(j));
            self.ring_groups.retain(|g| g.end() <= k || (g.end() == k + 1 && !cut));
            self.buffered -= dropped;
            self.pushed_time -= dropped;
            self.channel.set_planned_time(self.pushed_time);
        }
        say!(
            "nurbs-planner: feed override {}: the motion runs into the new plan after slot {} ({}), re-planned in {:.1} ms ({:.1} ms after the override was asked for)",
            p.feed_override,
            p.join.map_or(pushed, |(k, _)| k + 1),
            match p.join {
                Some((_, AT_RECORD_END)) => "a group end the module accepted".to_string(),
                Some((_, n)) => format!("cutting into the record before it after motion sample {n}"),
                None => "the end of the slots sent".to_string(),
            },
            p.began.elapsed().as_secs_f64() * 1e3,
            p.since.elapsed().as_secs_f64() * 1e3
        );
        let Source::Segments {
            events,
            queue,
            queued,
            total,
            error,
            ..
        } = &mut self.source
        else {
            return;
        };
        *events = (p.total.is_none()).then_some(p.events);
        *queue = p.groups;
        *queued = p.queued;
        *total = p.total.map(|t| self.pushed_time + t);
        *error = p.error;
        self.planned = self.pushed_time + p.queued;
        // The old plan's group waiting to go out is not part of the motion any more.
        self.current = None;
        if (still_asked - p.feed_override).abs() > OVERRIDE_STEP * p.feed_override {
            // The knob moved on while the module answered.
            if let Source::Segments { replanner: Some(r), .. } = &mut self.source {
                r.asked = r.feed_override;
            }
            self.set_feed_override(still_asked);
        }
    }

    /// The next group from the source, if one is ready; the curves it is the first to need
    /// join the queue of curves to publish.
    fn next_group(&mut self) -> Result<Option<Group>, String> {
        match &mut self.source {
            Source::Segments {
                queue,
                queued,
                replanner,
                ..
            } => {
                let Some(mut g) = queue.pop_front() else {
                    return Ok(None);
                };
                *queued -= g.time;
                let curve_needed = g.curve_needed();
                // A record's stored hold stops go into the arena with it in one piece: where
                // they would take more than an eighth of the arena the writer may use, the
                // record keeps its S-curve stops only.
                let most = self.writer.arena_capacity() / 8;
                for (slot, stops) in g.slots.iter_mut().zip(&mut g.hold_stops) {
                    if stops.values.len() > most {
                        *stops = stops.without_stored();
                        slot.hold_stops_len = stops.count as u32;
                    }
                }
                if !g.curves.is_empty() && g.first_curve > self.next_queued {
                    return Err(format!(
                        "a group brings curves from {}, but curve {} comes next",
                        g.first_curve, self.next_queued
                    ));
                }
                // A re-plan may bring curves again that an earlier plan's groups brought (the
                // same path): those are queued already.
                let known = (self.next_queued.saturating_sub(g.first_curve) as usize).min(g.curves.len());
                self.next_queued += (g.curves.len() - known) as u32;
                self.curves.extend(g.curves.into_iter().skip(known));
                let cut_data = g.begin.map(|begin| RingGroup {
                    first: 0, // set as it goes into the ring
                    records: g.slots.iter().map(|s| s.record).collect(),
                    begin,
                    hold_samples: g.hold_stops.iter().map(|stops| stops.samples().collect()).collect(),
                    feed_override: replanner.as_ref().map_or(1.0, |r| r.feed_override),
                });
                Ok(Some(Group {
                    curve_needed,
                    times: g.slots.iter().map(|s| s.record.profile().total_time()).collect(),
                    slots: g.slots.iter().map(Slot::segment).collect(),
                    blocks: Vec::new(),
                    written: 0,
                    chain: (!g.chain.is_empty()).then_some(g.chain),
                    hold_stops: g.hold_stops,
                    hold_stops_written: 0,
                    end: g.end,
                    cut_data,
                }))
            }
            Source::Blocks { plan, next, .. } => {
                let first = *next;
                if first >= plan.blocks.len() {
                    return Ok(None);
                }
                let n = (plan.blocks[first].group_left as usize).max(1);
                let range = first..(first + n).min(plan.blocks.len());
                *next = range.end;
                let needed = plan.blocks[first].curve_needed;
                while self.next_queued <= needed {
                    let c = plan
                        .curves
                        .get(self.next_queued as usize)
                        .ok_or_else(|| format!("a block needs curve {}, beyond the path", self.next_queued))?;
                    self.curves.push_back(c.clone());
                    self.next_queued += 1;
                }
                Ok(Some(Group {
                    curve_needed: needed,
                    times: range.clone().map(|k| plan.time(k)).collect(),
                    slots: range.clone().map(|k| Slot::block(&plan.blocks[k])).collect(),
                    blocks: range.collect(),
                    written: 0,
                    chain: None,
                    hold_stops: Vec::new(),
                    hold_stops_written: 0,
                    end: None,
                    cut_data: None,
                }))
            }
        }
    }

    /// Publishes the curves up to `needed`; false if there is no room for them yet.
    fn publish_curves(&mut self, needed: u32) -> Result<bool, String> {
        while self.writer.next_curve() <= needed {
            let c = self.writer.next_curve();
            let curve = self
                .curves
                .front()
                .ok_or_else(|| format!("a record needs curve {c}, beyond the path"))?;
            match self.writer.publish_curve(
                curve.degree(),
                curve.dim(),
                curve.knots(),
                curve.points(),
                curve.weights(),
            ) {
                Ok(()) => {
                    self.curves.pop_front();
                }
                Err(WriteError::Full) => return Ok(false),
                Err(WriteError::Refused(e)) => return Err(e),
            }
        }
        Ok(true)
    }

    /// Writes a segment group's stop chain into the arena and its offset into the last slot;
    /// false if there is no room yet.
    fn write_chain(&mut self, group: &mut Group) -> Result<bool, String> {
        let Some(values) = group.chain.take() else {
            return Ok(true);
        };
        // Needed until the module runs past the group's end.
        let last = group.slots.len() - 1;
        let written = self.put_for_slot(&values, group, last, |s, offset| s.chain_offset = offset)?;
        if !written {
            group.chain = Some(values);
        }
        Ok(written)
    }

    /// Writes the checked stops inside each record of a segment group into the arena and their
    /// offsets into the slots; false if there is no room yet (what is written stays written).
    fn write_hold_stops(&mut self, group: &mut Group) -> Result<bool, String> {
        while group.hold_stops_written < group.hold_stops.len() {
            let k = group.hold_stops_written;
            let values = std::mem::take(&mut group.hold_stops[k].values);
            // Needed while the module runs this record.
            if !values.is_empty() && !self.put_for_slot(&values, group, k, |s, offset| s.hold_stops_offset = offset)? {
                group.hold_stops[k].values = values;
                return Ok(false);
            }
            group.hold_stops_written += 1;
        }
        Ok(true)
    }

    /// Puts `values` into the arena, kept until the module has run slot `k` of `group`, and
    /// writes their offset into that slot with `set`; false if there is no room yet.
    fn put_for_slot(
        &mut self,
        values: &[f64],
        group: &mut Group,
        k: usize,
        set: impl FnOnce(&mut SegmentSlot, u32),
    ) -> Result<bool, String> {
        let offset = match self.writer.put(values, Release::Slot(self.pushed + k as u64)) {
            Ok(offset) => offset,
            Err(WriteError::Full) => return Ok(false),
            Err(WriteError::Refused(e)) => return Err(e),
        };
        if let Some(Record::Segment(mut s)) = group.slots[k].decode() {
            set(&mut s, offset);
            group.slots[k] = Slot::segment(&s);
        }
        Ok(true)
    }

    /// Path blocks: writes the arena data of the group's blocks (their curve's stop points,
    /// their stored stop) and fills in the offsets; false if there is no room yet.
    fn write_block_data(&mut self, group: &mut Group) -> Result<bool, String> {
        let Source::Blocks { plan, points, .. } = &mut self.source else {
            return Ok(true);
        };
        let first_push = self.pushed;
        while let Some(&k) = group.blocks.get(group.written) {
            let mut b = plan.blocks[k];
            let curve = b.curve();
            let placed = match points.get(&curve) {
                Some(&placed) => placed,
                None => {
                    let list = plan.points.get(curve).map_or(&[][..], Vec::as_slice);
                    match self.writer.put(list, Release::Curve(b.curve)) {
                        Ok(offset) => {
                            let placed = (offset, (list.len() / 2) as u32);
                            points.insert(curve, placed);
                            placed
                        }
                        Err(WriteError::Full) => return Ok(false),
                        Err(WriteError::Refused(e)) => return Err(e),
                    }
                }
            };
            (b.points_offset, b.points_len) = placed;
            if let Some(values) = &plan.stored[k] {
                // Needed until the module runs past the block's end.
                match self
                    .writer
                    .put(values, Release::Slot(first_push + group.written as u64))
                {
                    Ok(offset) => b.stop_offset = offset,
                    Err(WriteError::Full) => return Ok(false),
                    Err(WriteError::Refused(e)) => return Err(e),
                }
                plan.stored[k] = None;
            }
            group.slots[group.written] = Slot::block(&b);
            group.written += 1;
        }
        Ok(true)
    }

    /// Sends what it can: curves ahead, groups while the margin and the ring allow. Returns
    /// whether it did anything.
    pub fn fill(&mut self) -> Result<bool, String> {
        let mut progressed = false;
        loop {
            self.receive()?;
            self.writer.reclaim(self.taken());
            self.release_path();
            if self.current.is_none() {
                self.current = self.next_group()?;
                if self.current.is_none() {
                    return Ok(progressed);
                }
                progressed = true;
            }
            let Some(mut group) = self.current.take() else {
                return Ok(progressed);
            };
            if group.slots.len() > SEGMENT_SLOTS {
                return Err(format!(
                    "a group of {} records without a stop between them does not fit the ring of {SEGMENT_SLOTS}",
                    group.slots.len()
                ));
            }
            let ready = self.publish_curves(group.curve_needed)?
                && self.write_block_data(&mut group)?
                && self.write_chain(&mut group)?
                && self.write_hold_stops(&mut group)?;
            if !ready && self.writer.held_values() == 0 && self.channel.segments.is_empty() {
                return Err("a group's curves and stops do not fit the channel's arena".into());
            }
            let room = SEGMENT_SLOTS - self.channel.segments.len() >= group.slots.len();
            if !(ready && room && self.may_push() && !self.replan_waits()) {
                self.current = Some(group);
                return Ok(progressed);
            }
            for (slot, time) in group.slots.iter().zip(&group.times) {
                self.channel
                    .segments
                    .producer()
                    .push(slot)
                    .map_err(|e| format!("channel: {e:?}"))?;
                self.in_ring.push_back((self.pushed, *time));
                self.buffered += time;
                self.pushed += 1;
                self.pushed_time += time;
            }
            if let Some(end) = &group.end {
                self.group_ends.push_back((self.pushed - 1, end.clone()));
            }
            if let Some(mut g) = group.cut_data.take() {
                g.first = self.pushed - group.slots.len() as u64;
                self.ring_groups.push_back(g);
            }
            self.longest_group = self.longest_group.max(group.times.iter().sum());
            self.last_end = group.end;
            self.channel.set_planned_time(self.pushed_time);
            progressed = true;
        }
    }

    /// Lets the path shared by the plans forget what no plan can start at any more: the
    /// elements before the module's, and before the first record of the oldest group a cut
    /// may replay ([`Streamer::cut_point`]), less one (a plan from rest at the end of an
    /// element, or a replay from the end of the record before, looks at it).
    fn release_path(&mut self) {
        self.buffered();
        let module = self.writer.module_curve();
        let replayed = self
            .ring_groups
            .front()
            .and_then(|g| g.records.first())
            .map(|r| r.curve);
        let floor = replayed.map_or(module, |c| c.min(module)).saturating_sub(1);
        if let Source::Segments { replanner: Some(r), .. } = &self.source {
            r.path.release_before(floor as usize);
        }
    }

    /// Whether the old plan's next group waits for a re-plan at another feed override on its
    /// way (see [`REPLAN_LOW_WATER`]).
    fn replan_waits(&mut self) -> bool {
        let (to_ring_end, asked) = match &self.source {
            Source::Segments { replanner: Some(r), .. } => match &r.pending {
                Some(p) => (p.join.is_none(), p.requested),
                None => (false, false),
            },
            _ => (false, false),
        };
        // While the module is asked, nothing goes out: the new plan must land where it was
        // told to.
        asked || (to_ring_end && self.buffered() >= REPLAN_LOW_WATER)
    }

    /// Whether the start rule has held: records go into the ring.
    pub fn started(&self) -> bool {
        self.started
    }

    /// Whether the next group may go into the ring: within the margin once the motion has
    /// started; before, once the plan can stay ahead of the motion (a plan that fails by then
    /// moves nothing).
    fn may_push(&mut self) -> bool {
        if self.started {
            return self.buffered() < self.margin;
        }
        let total = match &self.source {
            Source::Segments { total, .. } => total.unwrap_or(f64::INFINITY),
            Source::Blocks { .. } => self.planned,
        };
        let rate = self.planned / self.began.elapsed().as_secs_f64().max(1e-9);
        // With the queue full the planner waits for the motion: it cannot get further ahead.
        // The pace counts once it spans two groups: a plan's first group can come far sooner
        // than its pace (a smoothed dense program's first after 31 ms, its fourth 140 ms after
        // the third, for 75 ms of motion). A re-plan's first group comes at its pace.
        let paced = self.groups_planned >= 2 || self.planned >= total;
        let ahead = START_AHEAD.min(self.margin);
        self.started = (paced && far_enough_ahead(self.planned, total, rate, ahead)) || self.queue_full();
        self.started
    }
}
