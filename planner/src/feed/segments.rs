//! Segment records (the Erwinski planner, streamed): the plan's final records in groups that
//! end at a checked stop ([`Grouper`]), planned in a thread of its own ([`stream_plan`]) or
//! whole ([`plan_groups`]).

use super::*;

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
pub(super) fn curve_needed(r: &FinalRecord) -> u32 {
    r.stop.iter().map(|s| s.curve).fold(r.record.curve, u32::max)
}

/// What [`stream_plan`] hands out, in order.
#[derive(Clone, Debug)]
pub enum PlanEvent<G = SegmentGroup> {
    /// The next group (of final records, or of path blocks: [`BlockEvent`]).
    Group(G),
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
pub(super) const CUT_CANDIDATES: usize = 4;

/// One try of [`stream_plan`] (with ramp share `brake_share` after a group, the cut's ramp
/// `cut_ramp` from its candidate `skip` on): `Err` where the plan is refused before its first
/// group and another try may pass (`last_try`: none may), with the candidate a cut came at.
pub(super) fn stream_plan_once(
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
