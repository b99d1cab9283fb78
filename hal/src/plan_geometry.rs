//! Planner side of the geometry: what `nurbs-planner` publishes besides the curves, and the
//! check behind it. Compiled into the `nurbs-planner` binary and into the tests (never into
//! the realtime module's library: it needs the planner crate).
//!
//! The module's underrun stop starts at a segment boundary and is deterministic (the same
//! [`underrun_stop`] and interpolator on the same geometry and period), so the planner can run
//! it offline from every boundary and pick, per boundary, the largest stop deceleration and jerk
//! whose stop stays within the axis limits by finite differences (the `nurbs-plan verify`
//! check). That choice goes to the module with each record ([`RecordStop`] in the record's
//! slot), so records can be handed out while the stops of later ones are still being checked
//! ([`StopChooser`]).

use std::cell::{OnceCell, RefCell};
use std::collections::{HashMap, VecDeque};

use nurbs_hal::channel::{RecordStop, Slot, StopPoint, GEOMETRY_VALUES};
use nurbs_hal::module::{block_stop, underrun_stop};
use nurbs_hal::record::{PathBlock, SegmentRecord, BLOCK_SAMPLES, CURVE_SHIFT, FLAG_LAST};
use nurbs_hal::user::GeometryBuilder;
use nurbs_motion::geometry::{ArcLengthTable, Toolpath};
use nurbs_motion::planner::axial::FiniteDifferences;
use nurbs_motion::planner::erwinski::PlanStart;
use nurbs_motion::planner::flf::CriticalPoint;
use nurbs_motion::planner::verify::SLACK;
use nurbs_motion::planner::vpop::{brake_points, plan_tip, JointPath, PathPoint, SearchOptions, VpopPlan};
use nurbs_motion::planner::{plan, Limits, PathCurves, Plan, PlanOptions, Planner};
use nurbs_rtcore::executor::{Interpolator, Step};
use nurbs_rtcore::{CachedCurve, SpanCache, StopRun};

/// Stop deceleration and jerk tried at each boundary, as fractions of the smallest axis
/// acceleration and jerk, largest first: 1, 0.85, 0.85^2, ... (30 steps, down to 0.009).
pub fn fractions(max_fraction: f64) -> Vec<f64> {
    (0..30).map(|k| max_fraction * 0.85f64.powi(k)).collect()
}

/// The `(s, feed cap)` points of curve `c` the module's stop must respect: its critical points
/// (FLF minima, corners) at the planner's FLF margin, and the curve end at rest, in order of `s`.
pub fn curve_stop_points(
    toolpath: &Toolpath,
    c: usize,
    criticals: impl Iterator<Item = CriticalPoint>,
) -> Vec<(f64, f64)> {
    let margin = PlanOptions::default().flf_margin;
    let Some(e) = toolpath.elements.get(c) else {
        return Vec::new();
    };
    let table = ArcLengthTable::new(&e.curve);
    let mut stops: Vec<(f64, f64)> = criticals
        .map(|p| (table.length_to(&e.curve, p.u), margin * p.flf.max(0.0)))
        .collect();
    stops.push((table.total(), 0.0));
    stops.sort_by(|a, b| a.0.total_cmp(&b.0));
    stops
}

/// What a streamed plan ([`stream_plan`]) hands out, in order.
#[derive(Clone, Debug)]
pub enum PlanEvent {
    /// The stop points of a curve, once the planner has scanned it to its end (its critical
    /// points are final). Every curve's come before the path end.
    StopPoints(usize, Vec<(f64, f64)>),
    /// The next record, final.
    Record(SegmentRecord),
    /// The plan is complete (a line for the log).
    Done(String),
    Failed(String),
}

/// Runs the Erwinski planner as a stream ([`PlanOptions::stream`]) over `toolpath`, from its
/// start or from rest at the module's stop point `from`, and hands each record to `emit` as
/// soon as it is final, and each curve's stop points as soon as the scan has passed the curve's
/// end; stops early when `emit` returns false (nobody listens any more).
pub fn stream_plan(
    toolpath: &Toolpath,
    limits: &Limits,
    from: Option<&StopPoint>,
    emit: &mut dyn FnMut(PlanEvent) -> bool,
) {
    let options = PlanOptions {
        stream: true,
        start: from.map(|p| PlanStart {
            curve: p.curve as usize,
            u: p.u,
            s: p.s,
        }),
        ..PlanOptions::default()
    };
    let mut planner = match Planner::new(toolpath, limits, &options) {
        Ok(p) => p,
        Err(e) => {
            emit(PlanEvent::Failed(e.to_string()));
            return;
        }
    };
    let (mut curves_sent, mut next_critical) = (0, 0);
    loop {
        let next = planner.next_record();
        let scanned = match next {
            None => toolpath.elements.len(),
            Some(_) => planner.scanned_elements(),
        };
        // Critical points come in path order: those of each newly scanned curve in a run.
        while curves_sent < scanned {
            let criticals = planner.critical_points();
            let first = next_critical;
            while criticals.get(next_critical).is_some_and(|(c, _)| *c <= curves_sent) {
                next_critical += 1;
            }
            let on_curve = criticals[first..next_critical]
                .iter()
                .filter(|(c, _)| *c == curves_sent)
                .map(|(_, p)| *p);
            let points = curve_stop_points(toolpath, curves_sent, on_curve);
            if !emit(PlanEvent::StopPoints(curves_sent, points)) {
                return;
            }
            curves_sent += 1;
        }
        match next {
            Some(Ok(record)) => {
                if !emit(PlanEvent::Record(record)) {
                    return;
                }
            }
            Some(Err(e)) => {
                emit(PlanEvent::Failed(match from {
                    None => e.to_string(),
                    Some(_) => format!("re-plan from the stop point: {e}"),
                }));
                return;
            }
            None => break,
        }
    }
    let plan = planner.finish();
    emit(PlanEvent::Done(format!(
        "streamed plan complete: {} segments, motion {:.6} s, planned in {:.3} s, first record final after {:.3} ms",
        plan.records.len(),
        plan.motion_time,
        plan.plan_time,
        plan.first_record_time * 1e3
    )));
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

/// Chooses the stop after each segment record, one record at a time in plan order, so that
/// `nurbs-planner` can hand records out while it still checks later ones.
///
/// Each record is run through the interpolator (the samples the module will output), then,
/// from its last sample, the module's stop with each jerk fraction in `fractions` (largest
/// first) and deceleration shares 1, 1/2, 1/4, 1/10 of it, until one stays within the limits
/// by finite differences; the least violating one where none does. Where none does (e.g. a
/// boundary at an element join, where the module's stop would have to end on its curve at
/// once), a stop sequence that goes on along the path ([`planned_then_brake`]) is checked the
/// same way and stored if it does better. That sequence follows the plan's next samples, so
/// such a record is ready only once the records after it reach a state that brakes to rest
/// (or the plan ends); the records behind it wait, in order.
pub struct StopChooser<'t> {
    curves: PathCurves<'t>,
    path: JointPath<'t>,
    limits: Limits,
    fractions: Vec<f64>,
    arcs: ArcLengths<'t>,
    interp: Interpolator,
    fd: FiniteDifferences,
    /// Every sample so far: curve, parameter, arc length.
    samples: Vec<(usize, f64, f64)>,
    /// Records not handed out yet, in plan order.
    pending: VecDeque<Pending>,
    /// Per curve, its stop points as flat `(s, feed cap)` pairs once known, and where they are
    /// in the arena once a record on the curve has gone out (offset, pairs).
    points: Vec<Option<Vec<f64>>>,
    placed: Vec<Option<(u32, u32)>>,
    /// A whole plan's critical points, in path order: the stop points of a curve are made from
    /// them when a record on it first comes (a streamed plan sets them instead).
    criticals: Option<(&'t Toolpath, Vec<(usize, CriticalPoint)>)>,
    /// No more records come.
    finished: bool,
    /// What the searches for stored stops found so far.
    brakes: BrakeMemo,
}

/// A record whose stop is chosen, or being chosen.
struct Pending {
    record: SegmentRecord,
    choice: StopChoice,
    /// No tangential stop within the limits: a stored sequence is still to be tried.
    failing: Option<Failing>,
}

/// The state at the end of a record with no tangential stop within the limits.
#[derive(Clone, Copy)]
struct Failing {
    /// Samples up to the record's end.
    end: usize,
    fd: FiniteDifferences,
    interp: Interpolator,
    last: SegmentRecord,
    /// The record ends at its curve's end at speed: no tangential stop has room there.
    no_room: bool,
    /// Sample from which the search for a state that brakes to rest goes on.
    resume_at: usize,
}

impl<'t> StopChooser<'t> {
    pub fn new(toolpath: &'t Toolpath, limits: &Limits, max_fraction: f64) -> Result<Self, String> {
        if !(max_fraction > 0.0 && max_fraction <= 1.0) {
            return Err(format!("stop fraction {max_fraction} must be in (0, 1]"));
        }
        Ok(StopChooser {
            curves: PathCurves::new(toolpath),
            path: JointPath::tip(toolpath),
            limits: limits.clone(),
            fractions: fractions(max_fraction),
            arcs: ArcLengths::new(toolpath),
            interp: Interpolator::new(),
            fd: FiniteDifferences::new(limits.velocity.len(), limits.period),
            samples: Vec::new(),
            pending: VecDeque::new(),
            points: vec![None; toolpath.elements.len()],
            placed: vec![None; toolpath.elements.len()],
            criticals: None,
            finished: false,
            brakes: BrakeMemo::default(),
        })
    }

    /// The stop points of every curve come from `criticals` (a whole plan's, in path order),
    /// each made when a record on the curve first comes.
    pub fn with_critical_points(mut self, toolpath: &'t Toolpath, criticals: Vec<(usize, CriticalPoint)>) -> Self {
        self.criticals = Some((toolpath, criticals));
        self
    }

    /// Makes the stop points of `curve` from the plan's critical points, if not yet known.
    fn ensure_stop_points(&mut self, curve: usize) {
        if self.points.get(curve).is_none_or(Option::is_some) {
            return;
        }
        if let Some((toolpath, criticals)) = &self.criticals {
            let first = criticals.partition_point(|(c, _)| *c < curve);
            let end = criticals.partition_point(|(c, _)| *c <= curve);
            let points = curve_stop_points(toolpath, curve, criticals[first..end].iter().map(|(_, p)| *p));
            self.set_stop_points(curve, &points);
        }
    }

    /// The stop points of `curve` ([`curve_stop_points`]): needed before a record on it is pushed.
    pub fn set_stop_points(&mut self, curve: usize, points: &[(f64, f64)]) {
        if let Some(slot) = self.points.get_mut(curve) {
            *slot = Some(points.iter().flat_map(|&(s, cap)| [s, cap]).collect());
        }
    }

    /// Whether the stop points of `curve` are known (or can be made).
    pub fn has_stop_points(&self, curve: usize) -> bool {
        self.criticals.is_some() || self.points.get(curve).is_some_and(Option::is_some)
    }

    fn points_of(&self, curve: usize) -> &[f64] {
        self.points.get(curve).and_then(Option::as_deref).unwrap_or(&[])
    }

    /// The module's stop after `last` with `trial` = (jerk fraction, deceleration share), run
    /// by the interpolator from `interp` and checked by finite differences continuing `fd`;
    /// abandoned as soon as it is worse than `bound` (it cannot be the choice then).
    fn tangential(
        &self,
        (interp, fd, last): (Interpolator, FiniteDifferences, &SegmentRecord),
        (fraction, accel_share): (f64, f64),
        bound: f64,
    ) -> StopChoice {
        let limits = &self.limits;
        let untried = StopChoice::tangential((fraction, accel_share), (limits.min_accel(), limits.min_jerk()), 0.0);
        let mut stop = Some(underrun_stop(
            self.points_of(last.curve()),
            last,
            untried.accel,
            untried.jerk,
        ));
        let mut i = interp;
        let ratio = stop_ratio(limits, fd, bound, &mut || {
            i.step(&self.curves, limits.period, &mut || stop.take())
        });
        StopChoice { ratio, ..untried }
    }

    /// Takes the next record of the plan (the stop points of its curve set before).
    pub fn push(&mut self, record: &SegmentRecord) {
        self.ensure_stop_points(record.curve());
        let tip = self.limits.velocity.len();
        let mut next = Some(*record);
        while let Step::Sample(s) = self.interp.step(&self.curves, self.limits.period, &mut || next.take()) {
            self.fd.push(&s.point[..tip], &self.limits);
            self.samples.push((s.curve, s.u, s.s));
        }
        // The full stop with no trial: what the module falls back to (reported as exceeding)
        // if the interpolator refused the record (a plan's records never are).
        let mut choice = StopChoice::tangential(
            (1.0, 1.0),
            (self.limits.min_accel(), self.limits.min_jerk()),
            f64::INFINITY,
        );
        let Some(last) = self.interp.record().copied().filter(|r| r.seq == record.seq) else {
            self.pending.push_back(Pending {
                record: *record,
                choice,
                failing: None,
            });
            return;
        };
        let state = (self.interp, self.fd, &last);
        // A record that ends at its curve's end at speed leaves the tangential stop no room (it
        // runs on its own curve): the stored sequence, and one tangential trial only if there
        // is none (such a trial grinds at the curve end).
        let no_room = !last.is_last()
            && last.curve() < self.curves.len()
            && last.u_end >= self.curves.view(last.curve()).u_max()
            && last.profile().table().end().v > 0.0;
        if !no_room {
            let mut best: Option<StopChoice> = None;
            for trial in self.fractions.iter().flat_map(|&f| SHARES.map(|share| (f, share))) {
                let bound = best.map_or(f64::INFINITY, |b| b.ratio.max(1.0));
                let c = self.tangential(state, trial, bound);
                if best.is_none_or(|b| c.ratio < b.ratio) {
                    best = Some(c);
                }
                if c.ratio <= 1.0 {
                    best = Some(c);
                    break;
                }
            }
            choice = best.unwrap_or(choice);
        }
        let failing = (choice.ratio > 1.0 && !last.is_last()).then_some(Failing {
            end: self.samples.len(),
            fd: self.fd,
            interp: self.interp,
            last,
            no_room,
            resume_at: 0,
        });
        self.pending.push_back(Pending {
            record: *record,
            choice,
            failing,
        });
    }

    /// No more records come: every pending record can be decided.
    pub fn finish(&mut self) {
        self.finished = true;
    }

    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// The next record in plan order whose stop is decided, with that stop and the choice
    /// behind it; `Ok(None)` while it still waits for the records after it (or none is
    /// pending). A stored sequence goes to `arena` (returns its offset, or `None` when full:
    /// then the tangential stop stays), and so do the stop points of a curve when its first
    /// record goes out (an error if they do not fit: the module needs them).
    pub fn pop_ready(
        &mut self,
        arena: &mut dyn FnMut(&[f64]) -> Option<u32>,
    ) -> Result<Option<(SegmentRecord, RecordStop, StopChoice)>, String> {
        let Some(front) = self.pending.front() else {
            return Ok(None);
        };
        let mut choice = front.choice;
        let curve = front.record.curve();
        let (points_offset, points_len) = match self.placed.get(curve).copied().flatten() {
            Some(placed) => placed,
            None => {
                let points = self.points_of(curve);
                let offset = arena(points).ok_or("the channel's geometry arena is full")?;
                let placed = (offset, (points.len() / 2) as u32);
                if let Some(slot) = self.placed.get_mut(curve) {
                    *slot = Some(placed);
                }
                placed
            }
        };
        let mut stop = RecordStop {
            accel: choice.accel,
            jerk: choice.jerk,
            stored_len: 0,
            stored_offset: 0,
            points_offset,
            points_len,
        };
        if let Some(f) = front.failing {
            let samples = &self.samples;
            let path = &self.path;
            let point = |i: usize| samples.get(i).and_then(|&(e, u, _)| path.eval_at(e, u));
            let outcome = match f.end.checked_sub(1).and_then(point) {
                Some(from) => stored_stop(
                    path,
                    &self.curves,
                    &self.limits,
                    (f.fd, &point, samples.len()),
                    (f.end, from, f.resume_at),
                    choice,
                    &mut self.brakes,
                ),
                None => Ok(None),
            };
            let stored = match outcome {
                Err(resume_at) if !self.finished => {
                    if let Some(Pending { failing: Some(f), .. }) = self.pending.front_mut() {
                        f.resume_at = resume_at;
                    }
                    return Ok(None);
                }
                Err(_) => None, // the plan ends first
                Ok(stored) => stored,
            };
            let placed = stored.and_then(|stored| {
                // In the measure of the interpolator's samples (the records').
                self.arcs
                    .set_anchor(stored.from.element, stored.from.u, self.samples[f.end - 1].2);
                let offset = arena(&stop_runs(&self.arcs, stored.from, &stored.points))?;
                Some((stored, offset))
            });
            match placed {
                Some((stored, offset)) => {
                    choice = stored.choice;
                    stop.stored_offset = offset;
                    stop.stored_len = stored.points.len() as u32;
                }
                None if f.no_room => {
                    choice = self.tangential((f.interp, f.fd, &f.last), (1.0, 1.0), f64::INFINITY);
                    (stop.accel, stop.jerk) = (choice.accel, choice.jerk);
                }
                None => {}
            }
        }
        Ok(self.pending.pop_front().map(|p| (p.record, stop, choice)))
    }
}

/// The records of a plan as ring slots, each with its checked stop, produced one at a time
/// ([`StopChooser`]); or path blocks whose stops are all chosen already.
pub enum Records<'t> {
    Segments {
        /// Records to check, in plan order (a streamed plan adds them as they come).
        records: VecDeque<SegmentRecord>,
        chooser: Box<StopChooser<'t>>,
        /// No more records come.
        complete: bool,
    },
    Ready(VecDeque<(Slot, f64, StopChoice)>),
}

/// What [`Records::next`] did. (Returned by value once per record: boxing the slot would
/// allocate for each.)
#[allow(clippy::large_enum_variant)]
pub enum Next {
    /// A slot ready for the ring, its motion time (s) and its stop choice.
    Slot(Slot, f64, StopChoice),
    /// Some work towards the next slot (call again).
    Working,
    /// Nothing to do until a streamed plan hands out more (its next record, or the stop points
    /// of the curve of the next record).
    Waiting,
    /// Every slot has been handed out.
    Done,
}

impl Records<'_> {
    /// The next slot, or one record's worth of stop checks towards it. `arena`: where stored
    /// stop sequences and stop points go (behind the published geometry).
    pub fn next(&mut self, arena: &mut dyn FnMut(&[f64]) -> Option<u32>) -> Result<Next, String> {
        Ok(match self {
            Records::Ready(slots) => match slots.pop_front() {
                Some((slot, time, choice)) => Next::Slot(slot, time, choice),
                None => Next::Done,
            },
            Records::Segments {
                records,
                chooser,
                complete,
            } => {
                if let Some((record, stop, choice)) = chooser.pop_ready(arena)? {
                    let time = record.profile().total_time();
                    return Ok(Next::Slot(Slot::segment(&record, &stop), time, choice));
                }
                if let Some(record) = records.front().copied() {
                    if !chooser.has_stop_points(record.curve()) {
                        return Ok(Next::Waiting);
                    }
                    records.pop_front();
                    chooser.push(&record);
                    Next::Working
                } else if !*complete {
                    Next::Waiting
                } else if !chooser.is_finished() {
                    chooser.finish();
                    Next::Working
                } else {
                    Next::Done
                }
            }
        })
    }

    /// Whether every record has come (a streamed plan has ended).
    pub fn is_complete(&self) -> bool {
        match self {
            Records::Segments { complete, .. } => *complete,
            Records::Ready(_) => true,
        }
    }

    /// Takes an event of a streamed plan: a record or a curve's stop points go to the checks,
    /// the end marks the records complete (returns its log line), a failure is an error.
    pub fn take(&mut self, event: PlanEvent) -> Result<Option<String>, String> {
        let Records::Segments {
            records,
            chooser,
            complete,
        } = self
        else {
            return Err("a streamed plan's event for path blocks".into());
        };
        match event {
            PlanEvent::StopPoints(curve, points) => chooser.set_stop_points(curve, &points),
            PlanEvent::Record(record) => records.push_back(record),
            PlanEvent::Done(line) => {
                *complete = true;
                return Ok(Some(line));
            }
            PlanEvent::Failed(e) => return Err(e),
        }
        Ok(None)
    }
}

/// The geometry `nurbs-planner` publishes for `plan` (the curves with their stop points; the
/// stored stop sequences behind them) and every record as a slot with its checked stop (jerk
/// fractions up to `max_fraction`), all at once; also returns the choices. (The tests' and
/// the benchmark's form of what `nurbs-planner` streams.)
#[allow(dead_code)]
pub fn geometry(
    toolpath: &Toolpath,
    plan: &Plan,
    max_fraction: f64,
) -> Result<(GeometryBuilder, Vec<Slot>, Vec<StopChoice>), String> {
    let mut g = curves_geometry(toolpath)?;
    let mut records = Records::Segments {
        records: plan.records.iter().copied().collect(),
        chooser: Box::new(segment_chooser(toolpath, plan, max_fraction)?),
        complete: true,
    };
    let mut stored: Vec<f64> = Vec::new();
    let mut slots = Vec::with_capacity(plan.records.len());
    let mut choices = Vec::with_capacity(plan.records.len());
    {
        let base = g.values().len();
        let mut arena = |values: &[f64]| -> Option<u32> {
            let offset = base + stored.len();
            if offset + values.len() > GEOMETRY_VALUES {
                return None;
            }
            stored.extend_from_slice(values);
            u32::try_from(offset).ok()
        };
        loop {
            match records.next(&mut arena)? {
                Next::Slot(slot, _, choice) => {
                    slots.push(slot);
                    choices.push(choice);
                }
                Next::Working | Next::Waiting => {}
                Next::Done => break,
            }
        }
    }
    g.add_values(&stored)?;
    Ok((g, slots, choices))
}

/// The stop chooser for the records of `plan`, with the stop points of every curve from the
/// plan's critical points ([`curve_stop_points`]).
pub fn segment_chooser<'t>(toolpath: &'t Toolpath, plan: &Plan, max_fraction: f64) -> Result<StopChooser<'t>, String> {
    let chooser = StopChooser::new(toolpath, &plan.limits, max_fraction)?;
    Ok(chooser.with_critical_points(toolpath, plan.critical_points.clone()))
}

/// The curves of `toolpath`: what is published before the records (stop points and stored stop
/// sequences are appended behind it).
pub fn curves_geometry(toolpath: &Toolpath) -> Result<GeometryBuilder, String> {
    let mut g = GeometryBuilder::new(toolpath.tip_dim());
    for e in &toolpath.elements {
        let c = &e.curve;
        g.add_curve(c.degree(), c.dim(), c.knots(), c.points(), c.weights())?;
    }
    Ok(g)
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
    if toolpath.elements.len() > 1 << (32 - CURVE_SHIFT) {
        return Err("too many path elements".into());
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
            flags: (e as u32) << CURVE_SHIFT,
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

/// A stop sequence chosen after a record or block: its positions (path points, from the period
/// after `from`), the choice it makes, and the tangential choice it replaces (kept if the
/// sequence does not fit the channel).
#[derive(Clone, Debug)]
pub struct StoredStop {
    pub from: PathPoint,
    pub points: Vec<PathPoint>,
    pub choice: StopChoice,
    pub tangential: StopChoice,
}

/// Runs the blocks as the module does (each sample the curve point at its parameter) and, at
/// every block end, the module's stop ([`block_stop`]) with jerk fractions of the tangential
/// limits there and deceleration shares 1, 1/2, 1/4, 1/10 of each, looking for the largest
/// fraction with a share that stays within the axis limits by finite differences, as
/// [`StopChooser`] does for segment records, then bisects towards the next larger fraction (the
/// tangential limits hold for the direction at the block end only, so the largest stop that
/// passes is often just below them). The search starts at the fraction that passed at the last
/// block end that had one ([`StopSearch::starting_at`]; the first searches from the largest).
/// Where none passes, VPOp's own deceleration sequence from the block end ([`brake_points`])
/// is checked the same way and taken if it does better (it is stored with the geometry;
/// returned with the tangential choice it replaces). Within a run of such block ends the
/// sequence is tried first, and taken if it passes while the tangential stops at that last
/// fraction and at the smallest one still fail. Stores the limits in each block (the least
/// violating ones where none passes) and returns the choices.
///
/// Measured (`vpop_start_cost`, lab set 1): 0.66 s for the trident's 229 block ends and 4.8 s
/// for the butterfly's 955, against 1.5 and 16.9 s when every fraction was tried from the
/// largest at every block end; 82 and 664 stored stops instead of 68 and 603 (the arena they
/// take is the price: 4,308 instead of 4,145 on the 100 random polylines of
/// `random_polylines_have_a_stop_within_the_limits_at_every_boundary`).
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
    // last tangential stop that passed), and whether the last block end's stop is stored.
    let mut searched = false;
    let mut last_passed = 0;
    let mut in_stored_run = false;
    let mut brakes = BrakeMemo::default();
    // The module's evaluation of a block's points (see `Interpolator::point_at`).
    let mut spans = SpanCache::new();
    for b in blocks.iter_mut() {
        let view = *curves.view(b.curve());
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
        let store = |tangential: StopChoice, brakes: &mut BrakeMemo| {
            let from = (end, points[end - 1], 0);
            stored_stop(
                &path,
                &curves,
                limits,
                (fd, &point, points.len()),
                from,
                tangential,
                brakes,
            )
            .ok()
            .flatten()
        };
        // In a run of block ends with no tangential stop within the limits (a tight turn), the
        // stored sequence first: if it passes and the tangential stops at the last fraction
        // that passed and at the smallest still do not, it is the choice, with the least
        // violating tangential stop tried as its fallback (searching every fraction at each of
        // them was most of the cost).
        let mut chosen = None;
        if in_stored_run && can_store {
            let untried = StopChoice::tangential((1.0, 1.0), (a_max, j_max), f64::INFINITY);
            if let Some(mut stored) = store(untried, &mut brakes) {
                let gentlest = fractions.len() - 1;
                if stored.choice.ratio <= 1.0 + SLACK
                    && search.first_share(last_passed).is_none()
                    && search.first_share(gentlest).is_none()
                {
                    let fallback = search.best.unwrap_or(untried);
                    stored.choice = StopChoice {
                        ratio: stored.choice.ratio,
                        stored: stored.points.len(),
                        ..fallback
                    };
                    stored.tangential = fallback;
                    chosen = Some((stored.choice, Some(stored)));
                }
            }
        }
        let (best, sequence) = match chosen {
            Some((choice, stored)) => (Some(choice), stored),
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
                let mut best = match found {
                    Some((k, share)) => Some(search.refine(k, share)),
                    None => search.best,
                };
                // No tangential stop within the limits (near a tight turn, where VPOp balances
                // the tangential jerk against the curvature terms): VPOp's own deceleration
                // sequence.
                let mut sequence = None;
                if let (Some(tangential), true) = (best, can_store) {
                    if tangential.ratio > 1.0 + SLACK {
                        sequence = store(tangential, &mut brakes);
                        best = sequence.as_ref().map(|s| s.choice).or(best);
                    }
                }
                (best, sequence)
            }
        };
        in_stored_run = sequence.is_some();
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
    // VPOp's constraints use its own (power-basis) evaluation of the curve; the module plays the
    // positions from its own (de Boor): the deceleration aims a hair inside the limits so that
    // the finite differences of the played positions stay within them.
    let scale = |v: &[f64]| v.iter().map(|x| x * (1.0 - BRAKE_MARGIN)).collect::<Vec<f64>>();
    let inside = Limits {
        velocity: scale(&limits.velocity),
        acceleration: scale(&limits.acceleration),
        jerk: scale(&limits.jerk),
        ..limits.clone()
    };
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
                    [Some(a), Some(b), Some(c)] => brake_points(path, &inside, SearchOptions::default(), [a, b, c])
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

/// Relative margin of the stored decelerations to the axis limits.
const BRAKE_MARGIN: f64 = 1e-5;

/// [`planned_then_brake`] after the first `end` of the `count` planned positions known
/// (searching from `resume_at`), checked as the module runs it (each position the curve point
/// at its `u`) by finite differences continuing `fd` (the motion up to `from`, the last
/// position before the stop): `Some` if it does better than `tangential`, the best tangential
/// stop there; `Err` as from [`planned_then_brake`].
fn stored_stop(
    path: &JointPath,
    curves: &PathCurves,
    limits: &Limits,
    (fd, point, count): (FiniteDifferences, &dyn Fn(usize) -> Option<PathPoint>, usize),
    (end, from, resume_at): (usize, PathPoint, usize),
    tangential: StopChoice,
    memo: &mut BrakeMemo,
) -> Result<Option<StoredStop>, usize> {
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
        let point = CachedCurve::new(*curves.view(p.element), &mut spans).point(p.u);
        f.push(&point[..tip], limits);
    }
    f.finish(limits);
    let ratio = f.worst_ratio(limits);
    Ok((ratio < tangential.ratio).then_some(StoredStop {
        from,
        choice: StopChoice {
            ratio,
            stored: points.len(),
            ..tangential
        },
        points,
        tangential,
    }))
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
    let tip = limits.velocity.len();
    let u = b.u[b.len().saturating_sub(1)];
    let d = curves.view(b.curve()).derivatives(u, 1)[1];
    let norm = d[..tip].iter().map(|x| x * x).sum::<f64>().sqrt();
    let (mut a, mut j) = (f64::INFINITY, f64::INFINITY);
    for ((di, ai), ji) in d.iter().zip(&limits.acceleration).zip(&limits.jerk).take(tip) {
        let share = if norm > 0.0 { (di / norm).abs() } else { 1.0 };
        if share > 0.0 {
            a = a.min(ai / share);
            j = j.min(ji / share);
        }
    }
    (a.max(limits.min_accel()), j.max(limits.min_jerk()))
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

/// What `nurbs-planner --planner vpop` publishes for a VPOp plan: the curves (with their ends
/// as stop points) and the blocks with their checked stops.
pub fn block_geometry(
    toolpath: &Toolpath,
    plan: &VpopPlan,
    anchor: Option<&StopPoint>,
    max_fraction: f64,
) -> Result<(GeometryBuilder, Vec<PathBlock>, Vec<StopChoice>), String> {
    check_tip_path(toolpath)?;
    let mut arcs = ArcLengths::new(toolpath);
    if let Some(a) = anchor {
        arcs.set_anchor(a.curve as usize, a.u, a.s);
    }
    let mut blocks = pack_blocks(&arcs, &plan.points);
    if !(max_fraction > 0.0 && max_fraction <= 1.0) {
        return Err(format!("stop fraction {max_fraction} must be in (0, 1]"));
    }
    let mut g = curves_geometry(toolpath)?;
    // Each curve's stop points, in the arena once; every block refers to its curve's.
    let points: Vec<Vec<f64>> = block_stop_points(toolpath, &blocks, plan.limits.period)
        .iter()
        .map(|list| list.iter().flat_map(|&(s, cap)| [s, cap]).collect())
        .collect();
    let mut placed = Vec::with_capacity(points.len());
    for list in &points {
        placed.push((g.add_values(list)?, (list.len() / 2) as u32));
    }
    for b in &mut blocks {
        (b.points_offset, b.points_len) = placed.get(b.curve()).copied().unwrap_or((0, 0));
    }
    let (mut choices, sequences) = {
        let fractions = fractions(max_fraction);
        choose_block_stops(toolpath, &plan.limits, &mut blocks, &points, &fractions, &plan.points)
    };
    // The stored stop sequences as runs per element ([`StopRun`]), in the blocks' arc-length
    // measure. Where the arena is full, the tangential stop (and its check result) stays.
    for ((b, c), sequence) in blocks.iter_mut().zip(&mut choices).zip(sequences) {
        let Some(stored) = sequence else {
            continue;
        };
        let values = stop_runs(&arcs, stored.from, &stored.points);
        match g.add_values(&values) {
            Ok(offset) => {
                b.stop_offset = offset;
                b.stop_len = stored.points.len() as u32;
            }
            Err(_) => *c = stored.tangential,
        }
    }
    Ok((g, blocks, choices))
}

/// The VPOp plan of `toolpath` (tool tip), from its start or from rest at the stop point `from`.
pub fn vpop_plan(toolpath: &Toolpath, limits: &Limits, from: Option<&StopPoint>) -> Result<VpopPlan, String> {
    check_tip_path(toolpath)?;
    let options = SearchOptions {
        start: from.map(|p| (p.curve as usize, p.u)),
        ..SearchOptions::default()
    };
    plan_tip(toolpath, limits, options).map_err(|e| match from {
        None => e.to_string(),
        Some(_) => format!("re-plan from the stop point: {e}"),
    })
}

/// Which planner `nurbs-planner` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlannerKind {
    Erwinski,
    Vpop,
}

/// A planned motion ready for the channel: its geometry (to publish first) and its records,
/// which come as ring slots with their checked stops.
pub struct Motion<'t> {
    pub geometry: GeometryBuilder,
    pub records: Records<'t>,
    /// Motion time of all its records (s).
    pub motion_time: f64,
    /// One line for the log.
    pub summary: String,
}

/// Plans `toolpath` (from its start, or from rest at the module's stop point `from`) with
/// `planner` and prepares what goes into the channel: segment records get their stops checked
/// one by one as they are handed out ([`Records::next`]), path blocks all at once. One way for
/// both record kinds.
pub fn motion<'t>(
    toolpath: &'t Toolpath,
    limits: &Limits,
    planner: PlannerKind,
    from: Option<&StopPoint>,
    max_fraction: f64,
) -> Result<Motion<'t>, String> {
    match planner {
        PlannerKind::Erwinski => {
            let plan = match from {
                None => plan(toolpath, limits, &PlanOptions::default(), &mut |_| {}).map_err(|e| e.to_string())?,
                Some(p) => plan_from_stop(toolpath, limits, p)?,
            };
            let summary = format!(
                "{} segments, motion {:.6} s, planned in {:.3} s",
                plan.records.len(),
                plan.motion_time,
                plan.plan_time
            );
            let chooser = segment_chooser(toolpath, &plan, max_fraction)?;
            Ok(Motion {
                geometry: curves_geometry(toolpath)?,
                motion_time: plan.records.iter().map(|r| r.profile().total_time()).sum(),
                records: Records::Segments {
                    records: plan.records.into(),
                    chooser: Box::new(chooser),
                    complete: true,
                },
                summary,
            })
        }
        PlannerKind::Vpop => {
            let plan = vpop_plan(toolpath, limits, from)?;
            let (geometry, blocks, stops) = block_geometry(toolpath, &plan, from, max_fraction)?;
            let summary = format!(
                "VPOp: {} periods in {} path blocks, motion {:.6} s, planned in {:.3} s",
                plan.points.len(),
                blocks.len(),
                plan.motion_time,
                plan.plan_time
            );
            let period = plan.limits.period;
            Ok(Motion {
                geometry,
                motion_time: blocks.iter().map(|b| b.len() as f64 * period).sum(),
                records: Records::Ready(
                    blocks
                        .iter()
                        .zip(stops)
                        .map(|(b, c)| (Slot::block(b), b.len() as f64 * period, c))
                        .collect(),
                ),
                summary,
            })
        }
    }
}

/// A motion whose records come from a streamed plan ([`stream_plan`], run elsewhere; its
/// events go to [`Records::take`]): the curves to publish, and the checks waiting for records.
/// Its motion time is unknown until the plan is complete (infinite here).
pub fn streamed_motion<'t>(toolpath: &'t Toolpath, limits: &Limits, max_fraction: f64) -> Result<Motion<'t>, String> {
    let limits = limits.for_axes(toolpath.tip_dim()).map_err(|e| e.to_string())?;
    Ok(Motion {
        geometry: curves_geometry(toolpath)?,
        records: Records::Segments {
            records: VecDeque::new(),
            chooser: Box::new(StopChooser::new(toolpath, &limits, max_fraction)?),
            complete: false,
        },
        motion_time: f64::INFINITY,
        summary: "streamed plan: records go out as they are planned".into(),
    })
}

/// Whether a motion of `total` seconds can start with the stops of its first `checked` seconds
/// checked, the checks running at `rate` seconds of motion per second: they must stay `margin`
/// ahead of the motion to its end, counted at half the measured rate (the stop checks share the
/// machine with the module and everything else, and later records may cost more). Where the
/// checks are faster than the motion that is `margin`; where slower, enough more that the motion
/// does not catch up with them (an underrun stop on the way).
pub fn checked_far_enough(checked: f64, total: f64, rate: f64, margin: f64) -> bool {
    if checked >= total {
        return true;
    }
    if checked < margin {
        return false;
    }
    let rate = 0.5 * rate;
    if rate >= 1.0 {
        return true;
    }
    rate > 0.0 && checked >= margin + (total - checked) * (1.0 - rate) / rate
}

/// The plan of the rest of the path from where the module stopped after an underrun (at rest,
/// its first record starting at exactly the published element, parameter and arc length).
pub fn plan_from_stop(toolpath: &Toolpath, limits: &Limits, stop: &StopPoint) -> Result<Plan, String> {
    let options = PlanOptions {
        start: Some(PlanStart {
            curve: stop.curve as usize,
            u: stop.u,
            s: stop.s,
        }),
        ..PlanOptions::default()
    };
    plan(toolpath, limits, &options, &mut |_| {}).map_err(|e| format!("re-plan from the stop point: {e}"))
}
