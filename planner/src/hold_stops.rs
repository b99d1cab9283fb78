//! Checked stops inside segment records, so that a hold or abort need not wait for the end of
//! the group.
//!
//! A group's stop is the only stop a record of the Erwinski plan carries, and a group may last
//! up to a second (a single long line is one record). So the planner also checks stops inside
//! the records, every [`HOLD_STOP_SPACING`] samples of the motion: it runs the module's own
//! interpolator over the records in the order the module runs them (a replica, sample for
//! sample the machine's), and at each such sample the stop that
//! [`nurbs_rtcore::block_stop::stop_record`] builds from it (an S-curve to rest along the element
//! from the sample's feed and tangential acceleration) is simulated through the same
//! interpolator and checked by finite differences against the axis limits, continuing the
//! motion's samples and holding at rest after it, as every stop of the plan is. The deceleration
//! and jerk start just inside what the axes allow along the tangent there and are lowered
//! until the stop passes ([`STOP_SCALES`]; on a curve the centripetal terms leave less). Where
//! none passes (near sharp curvature the plan rides an axis limit, and any change of its
//! tangential profile exceeds it; on short elements the S-curve leaves the element), VPOp's
//! per-period deceleration (Beudaert, Lavernhe, Tournier 2012) from the last three samples is
//! tried: it chooses each period's step within every axis' limits and may cross element joins;
//! its positions are stored with the stop and checked the same way, through the module's own
//! curve evaluator ([`StoredStop`]). A stop that does not pass is not offered: the hold waits
//! for the next one (or the group's end). The module, holding, switches to the first offered
//! stop at or after the hold's edge, at exactly that sample.

use std::cell::RefCell;
use std::collections::HashMap;

use nurbs_hal::channel::ARENA_VALUES;
use nurbs_hal::slot::MAX_HOLD_STOPS;
use nurbs_motion::geometry::{ArcLengthTable, Toolpath};
use nurbs_motion::planner::axial::FiniteDifferences;
use nurbs_motion::planner::simulate::SimState;
use nurbs_motion::planner::verify::SLACK;
use nurbs_motion::planner::vpop::{self, CurvatureTables, JointPath, PathPoint, SearchOptions};
use nurbs_motion::planner::{Limits, PathCurves};
use nurbs_rtcore::block_stop::{step_fits, stop_record, StopStart};
use nurbs_rtcore::interpolator::{Interpolator, Sample, Step};
use nurbs_rtcore::scurve::stop_from;
use nurbs_rtcore::{SegmentRecord, StopRun};

/// Samples of motion between two checked hold stops: the longest a hold waits (5 ms at the
/// 0.25 ms servo period), if the stop there passes.
pub const HOLD_STOP_SPACING: u64 = 20;

/// Stops tried at a sample, in turn: (deceleration, jerk) as shares of the tangential limits
/// there. The first steps are small: near sharp curvature the centripetal terms take a few
/// percent of an axis' jerk, and a much softer stop keeps the feed up for longer, into more
/// curvature.
pub(crate) const STOP_SCALES: [(f64, f64); 9] = [
    (1.0, 1.0),
    (1.0, 0.94),
    (0.95, 0.9),
    (0.9, 0.8),
    (0.8, 0.65),
    (0.7, 0.5),
    (0.6, 0.36),
    (0.45, 0.2),
    (0.3, 0.1),
];

/// The first try aims this far inside the tangential limits: at the limits themselves the
/// rounding of a third difference of positions far from the origin (1e-6 relative at 1 m and
/// 0.25 ms) decides the check.
pub(crate) const INSIDE: f64 = 1.0 - 1e-3;

/// A stop stored across element ends runs on at most this many elements after its own.
const ACROSS_ELEMENTS: usize = 64;

/// Below this feed (mm/s) the motion is as good as at rest: no stop is offered there.
const MOVING: f64 = 1e-6;

/// A stored stop's path looks this many times the braking distance ahead (at the tangential
/// limits, from the sample's feed) and at most [`STORED_ELEMENTS`] elements: VPOp's own
/// deceleration is softer where the curvature asks, and it must come to rest within the
/// elements it is given.
const STORED_REACH: f64 = 4.0;
const STORED_ELEMENTS: usize = 64;

/// Values of stored stops one record carries at most (a sixty-fourth of the arena): a long
/// record near sharp curvature stores no more beyond that.
const MAX_STORED_VALUES: usize = ARENA_VALUES / 64;

/// The checked stops inside one record, as the arena carries them
/// ([`nurbs_hal::slot::SegmentSlot::hold_stops_offset`]): `count` triples in sample order, then
/// the stored sequences the stored ones point to.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecordStops {
    pub values: Vec<f64>,
    pub count: usize,
    /// Highest path element a stored sequence runs on: the group carrying the record needs it
    /// published and checked before it starts.
    pub last_curve: Option<u32>,
}

impl RecordStops {
    /// Motion sample indices of the stops, in order.
    pub fn samples(&self) -> impl Iterator<Item = u64> + '_ {
        self.values[..3 * self.count].chunks_exact(3).map(|t| t[0] as u64)
    }

    /// How many of them are stored sequences.
    pub fn stored(&self) -> usize {
        self.values[..3 * self.count]
            .chunks_exact(3)
            .filter(|t| t[1] < 0.0)
            .count()
    }

    /// The S-curve stops alone.
    pub fn without_stored(&self) -> RecordStops {
        let values: Vec<f64> = self.values[..3 * self.count]
            .chunks_exact(3)
            .filter(|t| t[1] > 0.0)
            .flatten()
            .copied()
            .collect();
        RecordStops {
            count: values.len() / 3,
            values,
            last_curve: None,
        }
    }
}

/// A record's stops as they are found: the triples, the stored sequences after them.
#[derive(Default)]
struct StopsBuilder {
    triples: Vec<f64>,
    stored: Vec<f64>,
    last_curve: Option<u32>,
}

impl StopsBuilder {
    /// Adds stored stop `stop` from motion sample `n`.
    fn store(&mut self, n: u64, stop: StoredStop) {
        // Its offset counts from the first triple: fixed once all are in.
        self.triples
            .extend([n as f64, -(stop.positions as f64), self.stored.len() as f64]);
        self.stored.extend(stop.values);
        self.last_curve = self.last_curve.max(Some(stop.last_curve as u32));
    }

    /// The arena values: the triples with the stored sequences' offsets counted from the first
    /// triple, then the sequences.
    fn finish(self) -> RecordStops {
        let StopsBuilder {
            mut triples,
            stored,
            last_curve,
        } = self;
        let count = triples.len() / 3;
        for t in triples.chunks_exact_mut(3).filter(|t| t[1] < 0.0) {
            t[2] += (3 * count) as f64;
        }
        triples.extend(stored);
        RecordStops {
            values: triples,
            count,
            last_curve,
        }
    }
}

/// How a stop inside an element fared.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Verdict {
    Passes,
    /// It needs more than what is left of its element (and is within the limits until then).
    LeavesElement,
    Fails,
}

/// Walks arc length along consecutive elements from a curve parameter, one stop sample after the
/// other: where each lies (element, curve parameter).
struct ArcWalk {
    curve: usize,
    u: f64,
    /// Arc length walked so far, and what is left of the current element.
    travelled: f64,
    left: f64,
    /// The last element the walk may enter.
    last: usize,
}

impl ArcWalk {
    /// From `u` on element `curve`, `left` of arc length from there to the element's end.
    fn new(curve: usize, u: f64, left: f64, elements: usize) -> Self {
        ArcWalk {
            curve,
            u,
            travelled: 0.0,
            left,
            last: curve + elements,
        }
    }

    /// The point `along` (arc length from the start, at least the last one's) ahead; `None`
    /// past the elements the walk may enter or the path's end.
    fn to(&mut self, along: f64, curves: &PathCurves, lengths: &ElementLengths, tip: usize) -> Option<(usize, f64)> {
        let mut need = along - self.travelled;
        self.travelled = along.max(self.travelled);
        while need > self.left {
            if self.curve >= self.last {
                return None;
            }
            need -= self.left;
            self.curve += 1;
            self.u = curves.get(self.curve)?.curve.view().u_min();
            self.left = lengths.of(self.curve, curves)?;
        }
        if need > 0.0 {
            // Newton on the arc length from the last point (a step of one period: the
            // five-point rule is exact to rounding there).
            let element = &curves.get(self.curve)?.curve;
            let view = element.view();
            let hi = view.u_max();
            let mut x = (self.u + need / view.speed(self.u, tip).max(f64::MIN_POSITIVE)).min(hi);
            for _ in 0..4 {
                let error = arc_between(element, self.u, x, tip) - need;
                let speed = view.speed(x, tip);
                if speed.is_nan() || speed <= 0.0 || error.abs() <= 1e-12 * (1.0 + need) {
                    break;
                }
                x = (x - error / speed).clamp(self.u, hi);
            }
            self.u = x;
            self.left -= need;
        }
        Some((self.curve, self.u))
    }
}

/// Arc length of a whole element (its arc-length table's).
fn element_length(curve: &nurbs_motion::geometry::Nurbs) -> f64 {
    ArcLengthTable::new(curve).total()
}

/// Arc lengths of whole elements, each integrated once: the stops of consecutive candidates
/// cross the same elements ahead, and integrating them afresh for each took a sixth of a
/// re-plan's time on a dense G1 program (the wait before a feed override takes effect).
#[derive(Default)]
struct ElementLengths(RefCell<HashMap<usize, f64>>);

impl ElementLengths {
    /// Element `e`'s arc length (`None`: no such element).
    fn of(&self, e: usize, curves: &PathCurves) -> Option<f64> {
        if let Some(&l) = self.0.borrow().get(&e) {
            return Some(l);
        }
        let l = element_length(&curves.get(e)?.curve);
        let mut kept = self.0.borrow_mut();
        if kept.len() >= 4 * ACROSS_ELEMENTS {
            // Those behind the stops being checked now.
            kept.retain(|&k, _| k + ACROSS_ELEMENTS > e);
        }
        kept.insert(e, l);
        Some(l)
    }
}

/// A stored stop (VPOp's deceleration, or an S-curve stop across element ends) from a sample,
/// as arena values ([`StopRun`]s, each
/// position as (u, s) in its element's measure), and the highest element it runs on.
struct StoredStop {
    values: Vec<f64>,
    positions: usize,
    last_curve: usize,
}

/// The replica of the module's motion and the stops checked along it.
pub struct HoldStops {
    replica: Interpolator,
    /// Finite differences of the motion so far (the history a stop continues).
    fd: FiniteDifferences,
    /// Index of the motion's next sample.
    samples: u64,
    limits: Limits,
    /// Arc length of the element the last stop was checked on.
    element_length: Option<ElementLength>,
    /// Arc-length table of the element the last stored S-curve started on.
    arc_table: Option<(usize, ArcLengthTable)>,
    /// The motion's last sample.
    last: Option<Sample>,
    /// Accept stops on straight elements by their profile alone ([`Self::passes_on_line`]);
    /// off, every stop is simulated (to show that both agree).
    line_shortcut: bool,
    /// The motion's last three samples (oldest first) and how many of them are real: a stored
    /// stop starts from their finite differences.
    recent: [Option<Sample>; 3],
    /// Curvature tables of the elements VPOp's decelerations ran on (built once each).
    curvature_tables: CurvatureTables,
    /// Arc lengths of the elements stops were checked on or stored across.
    lengths: ElementLengths,
}

impl HoldStops {
    /// Simulates every stop, on straight elements too (the check that the shortcut agrees).
    pub fn simulating_lines(self) -> HoldStops {
        HoldStops {
            line_shortcut: false,
            ..self
        }
    }

    pub fn new(limits: &Limits) -> HoldStops {
        HoldStops {
            replica: Interpolator::new(),
            fd: FiniteDifferences::new(limits.velocity.len(), limits.period),
            samples: 0,
            limits: limits.clone(),
            element_length: None,
            arc_table: None,
            last: None,
            line_shortcut: true,
            recent: [None; 3],
            curvature_tables: CurvatureTables::default(),
            lengths: ElementLengths::default(),
        }
    }

    /// Continues a motion whose planner stands at `state` (a plan at another feed override,
    /// after a group already sent): the replica, its history and its sample count are the
    /// planner's there, as the module's are.
    pub fn continuing(limits: &Limits, state: &SimState) -> HoldStops {
        HoldStops {
            replica: state.interp,
            fd: state.check,
            samples: state.samples as u64,
            last: state.last_sample,
            recent: [None, None, state.last_sample],
            ..HoldStops::new(limits)
        }
    }

    /// The motion's state after the records run so far, as the planner's [`SimState`] (the
    /// module's, sample for sample).
    pub fn state(&self) -> SimState {
        SimState {
            interp: self.replica,
            check: self.fd,
            samples: self.samples as usize,
            last_sample: self.last,
        }
    }

    /// [`Self::after`] for a record that cuts into the motion at its last sample: started there
    /// with tangential acceleration `accel_start` ([`nurbs_rtcore::block_stop::ramp_record`]).
    pub fn after_cut(&mut self, record: &SegmentRecord, accel_start: f64, curves: &PathCurves) -> RecordStops {
        let table = record.profile().table_from(accel_start);
        if !self.replica.start_profile(curves, *record, table) {
            return RecordStops::default();
        }
        self.run(record, None, false, curves)
    }

    /// Runs `record` (the motion's next) on the replica and returns the stops checked inside it.
    /// Where it ends a group (`ends_group`), its last sample is a candidate too: the group's own
    /// stop is the next segment re-planned to rest at its end, which on a long segment runs on
    /// along the plan (a hold 18 samples before the end of such a group on `star_g1` followed
    /// the plan for 430 ms, accelerating from 4 to 100 mm/s, before it braked).
    pub fn after(&mut self, record: &SegmentRecord, ends_group: bool, curves: &PathCurves) -> RecordStops {
        self.run(record, Some(*record), ends_group, curves)
    }

    /// Runs the replica until it needs a record after `pending` (`record`, or `None` where it is
    /// loaded already), checking stops inside `record`.
    fn run(
        &mut self,
        record: &SegmentRecord,
        mut pending: Option<SegmentRecord>,
        ends_group: bool,
        curves: &PathCurves,
    ) -> RecordStops {
        let (tip, dt) = (self.limits.velocity.len(), self.limits.period);
        let mut stops = StopsBuilder::default();
        let mut last = None;
        while let Step::Sample(s) = self.replica.step(curves, dt, &mut || pending.take()) {
            let n = self.samples;
            self.samples += 1;
            self.last = Some(s);
            self.recent = [self.recent[1], self.recent[2], Some(s)];
            self.fd.push(&s.point[..tip], &self.limits);
            if n.is_multiple_of(HOLD_STOP_SPACING) {
                self.offer(n, &s, record, curves, &mut stops);
            }
            last = Some((n, s));
        }
        // The replica stands at the record's last sample (a starved step changes nothing).
        if let Some((n, s)) = last.filter(|(n, _)| ends_group && !n.is_multiple_of(HOLD_STOP_SPACING)) {
            self.offer(n, &s, record, curves, &mut stops);
        }
        stops.finish()
    }

    /// Checks a stop from sample `n` (`s`, the replica standing there) and adds it to `stops`
    /// if one passes: the S-curve, else the same stored across element ends, else VPOp's
    /// deceleration (each candidate tries all: a hold waits at most one spacing wherever one
    /// passes).
    fn offer(&mut self, n: u64, s: &Sample, record: &SegmentRecord, curves: &PathCurves, stops: &mut StopsBuilder) {
        // A record takes at most MAX_HOLD_STOPS (minutes of motion): a hold in the rest of such
        // a record waits for its group's end.
        if stops.triples.len() >= 3 * MAX_HOLD_STOPS as usize || s.feed <= MOVING {
            return;
        }
        let leaving = match self.check(s, record, curves) {
            Ok((accel, jerk)) => {
                stops.triples.extend([n as f64, accel, jerk]);
                return;
            }
            Err(leaving) => leaving,
        };
        if stops.stored.len() >= MAX_STORED_VALUES {
            return;
        }
        // On short elements: the same stop, stored, across the element ends.
        let rest = if leaving.is_empty() {
            None
        } else {
            self.rest_of_element(s, curves)
        };
        let across = match rest {
            Some(rest) => leaving
                .iter()
                .find_map(|&(accel, jerk)| self.scurve_across(s, record, (accel, jerk), rest, curves)),
            _ => None,
        };
        if let Some(stop) = across.or_else(|| self.stored_stop(s, curves)) {
            stops.store(n, stop);
        }
    }

    /// The deceleration and jerk of a stop from sample `s` that stays on its element and within
    /// the axis limits, if one of [`STOP_SCALES`] does; else, where all that fail do so only by
    /// leaving the element, their deceleration and (landed) jerk.
    fn check(
        &mut self,
        s: &Sample,
        record: &SegmentRecord,
        curves: &PathCurves,
    ) -> Result<(f64, f64), Vec<(f64, f64)>> {
        let dt = self.limits.period;
        let Some(length) = self.element_length(s.curve, curves) else {
            return Err(Vec::new());
        };
        let (mut leaving, mut exceeded) = (Vec::new(), false);
        let tangential = tangential_limits(curves, &self.limits, s.curve, s.u);
        let (accel0, jerk0) = (tangential.0 * INSIDE, tangential.1 * INSIDE);
        let from = stop_start(record, s);
        let line = self.line_shortcut && curves.get(s.curve).is_some_and(|e| is_line(&e.curve));
        for (sa, sj) in STOP_SCALES {
            let (accel, jerk) = (accel0 * sa, jerk0 * sj);
            if let Some(landed) = landing_jerk(&from, accel, jerk, dt) {
                let passed = if line {
                    self.passes_on_line(&from, (accel, landed), tangential, &length, curves)
                } else {
                    self.passes(&from, accel, landed, &length, curves)
                };
                self.element_length = Some(length);
                match passed {
                    Verdict::Passes => return Ok((accel, landed)),
                    Verdict::LeavesElement => leaving.push((accel, landed)),
                    Verdict::Fails => exceeded = true,
                }
            }
        }
        // Where one exceeds the limits inside the element, the limits decide rather than the
        // element's length: no stored version (each simulates a whole stop) is offered.
        Err(if exceeded { Vec::new() } else { leaving })
    }

    /// Whether the stop from `from` with `accel` and `jerk` stays on its element (of arc length
    /// `length`) and, continuing the motion's samples and held at rest after it, within the axis
    /// limits.
    fn passes(&self, from: &StopStart, accel: f64, jerk: f64, length: &ElementLength, curves: &PathCurves) -> Verdict {
        let (tip, dt) = (self.limits.velocity.len(), self.limits.period);
        let (stop, a0) = stop_record(from, accel, jerk);
        // Room for rounding of the arc length at the element's end.
        let leaves = |length: f64| stop.s_start + stop.length >= length * (1.0 - 1e-9) - 1e-9;
        // Beyond the bound it leaves the exact length too (most stops on short elements).
        if length.bound.is_some_and(leaves) || leaves(length.exact(&self.lengths, curves)) {
            return Verdict::LeavesElement;
        }
        let mut sim = self.replica;
        if !sim.start_profile(curves, stop, stop.profile().table_from(a0)) {
            return Verdict::Fails;
        }
        // A stop that starts while the plan still accelerates speeds up first: never beyond the
        // feed the plan may run there.
        let cap = curves
            .programmed_feed(stop.curve())
            .map_or(self.limits.feed, |f| f.min(self.limits.feed));
        let mut f = self.fd;
        f.reset_peaks();
        while let Step::Sample(x) = sim.step(curves, dt, &mut || None) {
            f.push(&x.point[..tip], &self.limits);
            let too_fast = x.feed > cap && x.feed > from.feed;
            if x.curve != stop.curve() {
                return Verdict::LeavesElement;
            }
            if too_fast || f.worst_ratio(&self.limits) > 1.0 + SLACK {
                return Verdict::Fails;
            }
        }
        f.finish(&self.limits);
        if f.worst_ratio(&self.limits) <= 1.0 + SLACK {
            Verdict::Passes
        } else {
            Verdict::Fails
        }
    }

    /// [`Self::passes`] on a straight element, from the stop's profile alone: on a line every
    /// axis moves in proportion to the arc length, so a stop whose tangential deceleration and
    /// jerk stay within `tangential` (the axes' limits along the line) and whose feed stays
    /// within the axes' velocities keeps every axis within its limits, and so do the finite
    /// differences of its samples (a third difference is the jerk averaged over three periods
    /// with a non-negative kernel of unit mass, and the motion is continuous in acceleration
    /// from the plan into the stop and from the stop, landing just after a sample, to rest).
    /// What it checks beyond that: the stop stays on the element, and never runs faster than
    /// the feed the plan may run there (unless it started faster).
    fn passes_on_line(
        &self,
        from: &StopStart,
        (accel, jerk): (f64, f64),
        tangential: (f64, f64),
        length: &ElementLength,
        curves: &PathCurves,
    ) -> Verdict {
        let (stop, a0) = stop_record(from, accel, jerk);
        let leaves = |length: f64| stop.s_start + stop.length >= length * (1.0 - 1e-9) - 1e-9;
        if length.bound.is_some_and(leaves) || leaves(length.exact(&self.lengths, curves)) {
            return Verdict::LeavesElement;
        }
        let table = stop.profile().table_from(a0);
        // Within the tangential limits (the profile's jerks, and its acceleration at every phase
        // boundary: it is linear in between), at rest at the end.
        let (max_accel, max_jerk) = tangential;
        let jerks_ok = stop.jerks.iter().all(|j| j.abs() <= max_jerk);
        let accels_ok = table.states.iter().all(|st| st.a.abs() <= max_accel.max(a0.abs()));
        // The feed peaks where the acceleration crosses zero (a stop that starts accelerating).
        let peak = if a0 > 0.0 && stop.jerks[0] < 0.0 {
            table.state_at(a0 / -stop.jerks[0]).v
        } else {
            from.feed
        };
        let cap = curves
            .programmed_feed(stop.curve())
            .map_or(self.limits.feed, |f| f.min(self.limits.feed));
        let d = curves.view(stop.curve()).derivatives(from.u, 1)[1];
        let tip = self.limits.velocity.len();
        let norm = d[..tip].iter().map(|x| x * x).sum::<f64>().sqrt();
        let velocity_ok = norm > 0.0
            && d[..tip]
                .iter()
                .zip(&self.limits.velocity)
                .all(|(di, vmax)| peak * (di / norm).abs() <= *vmax);
        let at_rest = table.end().v.abs() <= 1e-9 * (1.0 + from.feed);
        if jerks_ok && accels_ok && velocity_ok && at_rest && (peak <= cap || peak <= from.feed) {
            Verdict::Passes
        } else {
            Verdict::Fails
        }
    }

    /// VPOp's deceleration from sample `s` (the last of the motion's three recent samples), if
    /// it comes to rest on the elements read and passes as every stored stop must
    /// ([`Self::checked_stored`]).
    fn stored_stop(&mut self, s: &Sample, curves: &PathCurves) -> Option<StoredStop> {
        let recent: Vec<Sample> = self.recent.iter().flatten().copied().collect();
        if recent.len() < 3 {
            return None;
        }
        // The elements from the oldest sample's on, as far as the braking distance reaches.
        let first = recent[0].curve;
        let (a, j) = tangential_limits(curves, &self.limits, s.curve, s.u);
        let braking = stop_from(s.feed, s.accel, a, j).table_from(s.accel).end().s;
        if self.ends_path_before(s, braking, curves) {
            return None;
        }
        let mut elements = Vec::new();
        let mut ahead = 0.0;
        while elements.len() < STORED_ELEMENTS {
            let Some(e) = curves.get(first + elements.len()) else {
                break;
            };
            if first + elements.len() > s.curve {
                ahead += e.curve.polygon_length().unwrap_or(f64::INFINITY);
            }
            elements.push(e.clone());
            if ahead >= STORED_REACH * braking {
                break;
            }
        }
        let path_part = Toolpath { elements };
        let path = JointPath::tip_reusing(path_part, first, std::mem::take(&mut self.curvature_tables));
        let point = |x: &Sample| path.eval_at(x.curve - first, x.u);
        let last: [PathPoint; 3] = [point(&recent[0])?, point(&recent[1])?, point(&recent[2])?];
        let points = vpop::brake_points(&path, &self.limits, SearchOptions::default(), last)
            .ok()
            .flatten();
        self.curvature_tables = path.into_curvature_tables();
        let mut positions = points?.into_iter().map(|p| Some((first + p.element, p.u)));
        self.checked_stored(s, &mut positions, curves)
    }

    /// Whether sample `s` is on the path's last element, a straight line, where the shortest
    /// jerk-limited stop along it at the axes' own limits (`braking`: on a line the tangential
    /// limits are exactly theirs) would end no further than [`END_MARGIN`] before the path's
    /// end: the plan's own final braking, which a hold follows to the end. A stored stop there
    /// could gain no more than that margin, and VPOp's search for one fails nearly always, slowly
    /// (on a 2000 mm line re-planned at another feed override it was tried at every candidate
    /// of the final braking and took four fifths of the re-plan's time).
    fn ends_path_before(&mut self, s: &Sample, braking: f64, curves: &PathCurves) -> bool {
        let last = curves.is_complete() && s.curve + 1 == curves.len();
        if !last || !curves.get(s.curve).is_some_and(|e| is_line(&e.curve)) {
            return false;
        }
        let margin = END_MARGIN.0 * braking + END_MARGIN.1 * s.feed * self.limits.period;
        self.rest_of_element(s, curves)
            .is_some_and(|rest| rest < braking + margin)
    }

    /// Arc length from sample `s` to its element's end (the element's table kept for the next
    /// samples on it).
    fn rest_of_element(&mut self, s: &Sample, curves: &PathCurves) -> Option<f64> {
        let curve = &curves.get(s.curve)?.curve;
        if self.arc_table.as_ref().is_none_or(|(e, _)| *e != s.curve) {
            self.arc_table = Some((s.curve, ArcLengthTable::new(curve)));
        }
        let (_, table) = self.arc_table.as_ref()?;
        Some(table.total() - table.length_to(curve, s.u))
    }

    /// The stop of [`Self::check`] with deceleration `accel` and (landed) jerk `jerk` from sample
    /// `s`, which leaves its element (`rest_of_own` of arc length left of it): the same tangential
    /// profile sampled at the servo period, each sample's arc length walked along the elements
    /// ahead ([`ACROSS_ELEMENTS`] at most), checked and stored as every stored stop is
    /// ([`Self::checked_stored`]).
    fn scurve_across(
        &self,
        s: &Sample,
        record: &SegmentRecord,
        (accel, jerk): (f64, f64),
        rest_of_own: f64,
        curves: &PathCurves,
    ) -> Option<StoredStop> {
        let (tip, dt) = (self.limits.velocity.len(), self.limits.period);
        let from = stop_start(record, s);
        let (stop, a0) = stop_record(&from, accel, jerk);
        let table = stop.profile().table_from(a0);
        // Room for it on the elements ahead (none at the path's end), before any sample.
        let mut room = rest_of_own;
        let mut next = s.curve + 1;
        while room < table.length() {
            if next > s.curve + ACROSS_ELEMENTS {
                return None;
            }
            room += self.lengths.of(next, curves)?;
            next += 1;
        }
        let steps = (table.total_time() / dt).ceil() as usize;
        let mut walk = ArcWalk::new(s.curve, s.u, rest_of_own, ACROSS_ELEMENTS);
        let mut positions = (1..=steps).map(|k| {
            let along = table.state_at((k as f64 * dt).min(table.total_time())).s;
            walk.to(along, curves, &self.lengths, tip)
        });
        self.checked_stored(s, &mut positions, curves)
    }

    /// A stored stop from sample `s` through `positions` (element, curve parameter; `None`: no
    /// such stop), if it passes the check every stored stop passes, position by position: continuing the motion's finite differences, positions
    /// as the module's evaluator computes them, at rest after the last, never faster than the
    /// feed the plan may run, and each step as the module checks a stored step (onward on its
    /// element or into a later one, its chord within its arc length: [`step_fits`]).
    fn checked_stored(
        &self,
        s: &Sample,
        positions: &mut dyn Iterator<Item = Option<(usize, f64)>>,
        curves: &PathCurves,
    ) -> Option<StoredStop> {
        let (tip, dt) = (self.limits.velocity.len(), self.limits.period);
        // Checked as the module will run it.
        let cap = curves
            .programmed_feed(s.curve)
            .map_or(self.limits.feed, |f| f.min(self.limits.feed))
            .max(s.feed);
        let mut eval = self.replica;
        let mut f = self.fd;
        f.reset_peaks();
        let (mut curve, mut u, mut s_at, mut at) = (s.curve, s.u, s.s, s.point);
        let mut values = Vec::new();
        let mut run_header = None;
        let mut count = 0;
        for position in positions {
            let (c, pu) = position?;
            count += 1;
            let element = curves.get(c)?;
            let (lo, hi) = {
                let v = element.curve.view();
                (v.u_min(), v.u_max())
            };
            // Arc lengths step by step from the sample's own (in each element's measure), so
            // that the first step starts exactly where the motion stands.
            let (s_before, s_p) = if c == curve {
                if !(pu >= u && pu <= hi) {
                    return None;
                }
                (s_at, s_at + arc_between(&element.curve, u, pu, tip))
            } else {
                if c <= curve || !(pu >= lo && pu <= hi) {
                    return None;
                }
                // The step's start in the later element's measure (before its start): what is
                // left of the last element and the elements it passes (shorter than the step),
                // then the element's start to the position.
                let mut left = arc_between(&curves.get(curve)?.curve, u, curves.view(curve).u_max(), tip);
                for passed in curve + 1..c {
                    left += self.lengths.of(passed, curves)?;
                }
                let into = arc_between(&element.curve, lo, pu, tip);
                (-left, into)
            };
            let x = eval.point_at(curves, c, pu)?;
            // The module's distance between its output positions (z zero on a 2-D path).
            let axes = tip.min(3);
            let chord = (0..axes).map(|i| (x[i] - at[i]) * (x[i] - at[i])).sum::<f64>().sqrt();
            if !step_fits(chord, s_p - s_before) || chord > cap * dt * (1.0 + 1e-6) {
                return None;
            }
            f.push(&x[..tip], &self.limits);
            if f.worst_ratio(&self.limits) > 1.0 + SLACK {
                return None;
            }
            if c != curve || run_header.is_none() {
                run_header = Some(values.len());
                values.extend(
                    StopRun {
                        curve: c,
                        count: 0,
                        s_before,
                    }
                    .to_values(),
                );
            }
            values.extend([pu, s_p]);
            if let Some(h) = run_header {
                values[h + 1] += 1.0;
            }
            (curve, u, s_at, at) = (c, pu, s_p, x);
        }
        f.finish(&self.limits);
        (count > 0 && f.worst_ratio(&self.limits) <= 1.0 + SLACK).then_some(StoredStop {
            values,
            positions: count,
            last_curve: curve,
        })
    }

    /// Arc length of element `e` (kept for the element the last check was on).
    fn element_length(&mut self, e: usize, curves: &PathCurves) -> Option<ElementLength> {
        match self.element_length {
            Some(l) if l.element == e => Some(l),
            _ => {
                let curve = &curves.get(e)?.curve;
                // Above the polygon's length by more than the table's rounding (1e-14 per piece).
                let bound = curve.polygon_length().map(|l| l * (1.0 + 1e-9) + 1e-12);
                Some(ElementLength { element: e, bound })
            }
        }
    }
}

/// The arc length of an element: an upper bound first (it decides most stops on short
/// elements: integrating the arc length of every element the motion passes was a sixth of the
/// planning time on dense G1 programs), the exact length ([`ElementLengths`]) where it must.
#[derive(Clone, Copy)]
struct ElementLength {
    element: usize,
    bound: Option<f64>,
}

impl ElementLength {
    fn exact(&self, lengths: &ElementLengths, curves: &PathCurves) -> f64 {
        lengths.of(self.element, curves).unwrap_or(0.0)
    }
}

/// The jerk at most `jerk` with which the stop from `from` (deceleration `accel`) ends just after
/// a sample, [`LANDING`] after it: the last sample of the stop is then at rest to within
/// nanometres, and holding there adds nothing to the finite differences (a stop ending between
/// two samples leaves the last one moving, and holding after it jerks). `None` if the search
/// does not land.
fn landing_jerk(from: &StopStart, accel: f64, jerk: f64, dt: f64) -> Option<f64> {
    let total = |j: f64| {
        let (stop, a0) = stop_record(from, accel, j);
        stop.profile().table_from(a0).total_time()
    };
    let t0 = total(jerk);
    let target = (t0 / dt).ceil() * dt + LANDING;
    if t0 > target - LANDING && t0 <= target {
        return Some(jerk);
    }
    // A lower jerk stops later; the search stays within a factor 4 of `jerk`.
    let (mut lo, mut hi) = (0.25 * jerk, jerk);
    if total(lo) < target {
        return None;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        let t = total(mid);
        if t >= target && t <= target + LANDING {
            return Some(mid);
        }
        if t >= target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    None
}

/// Where a stop from sample `s` inside `record` starts: its feed and tangential acceleration
/// there, as the module builds it when a hold takes that sample.
fn stop_start(record: &SegmentRecord, s: &Sample) -> StopStart {
    StopStart {
        seq: record.seq.wrapping_add(1),
        flags: 0,
        curve: s.curve as u32,
        u: s.u,
        s: s.s,
        feed: s.feed,
        accel: s.accel,
    }
}

/// True if `curve` is a straight line through its tool-tip coordinates at a pace uniform in its
/// parameter (degree 1, two control points, equal weights): its points are linear in the arc
/// length, and the interpolator's are too, to rounding.
fn is_line(curve: &nurbs_motion::geometry::Nurbs) -> bool {
    curve.degree() == 1 && curve.control_point_count() == 2 && curve.weights().windows(2).all(|w| w[0] == w[1])
}

/// Arc length of `curve`'s tool tip from parameter `a` to `b` (a short step: Gauss-Legendre
/// over the span, accurate to rounding for the steps of a stop).
fn arc_between(curve: &nurbs_motion::geometry::Nurbs, a: f64, b: f64, tip: usize) -> f64 {
    if b <= a {
        return 0.0;
    }
    let view = curve.view();
    let (h, m) = (0.5 * (b - a), 0.5 * (a + b));
    GAUSS5.iter().map(|(x, w)| w * view.speed(m + h * x, tip)).sum::<f64>() * h
}

/// Five-point Gauss-Legendre nodes and weights on [-1, 1].
const GAUSS5: [(f64, f64); 5] = [
    (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.0, 0.568_888_888_888_888_9),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.906_179_845_938_664, 0.236_926_885_056_189_1),
];

/// What a stop on a path's last line must gain over following the plan to the end for VPOp's
/// deceleration to be tried ([`HoldStops::ends_path_before`]): a share of the shortest stop's
/// length, and periods of the sample's feed.
const END_MARGIN: (f64, f64) = (1e-3, 4.0);

/// How long after its last sample a hold stop reaches rest (s).
const LANDING: f64 = 1e-9;

/// Tangential deceleration and jerk the axes allow at parameter `u` of element `e`: min over the
/// axes of the limit over the axis' share of the unit tangent.
pub fn tangential_limits(curves: &PathCurves, limits: &Limits, e: usize, u: f64) -> (f64, f64) {
    let tip = limits.velocity.len();
    limits.along(&curves.view(e).derivatives(u, 1)[1][..tip])
}
