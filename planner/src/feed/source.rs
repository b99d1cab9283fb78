//! Where a motion's groups of slots come from ([`Source`]): a streamed Erwinski plan and its
//! re-plans at another feed override ([`Replanner`]), or a whole plan's path blocks; and when a
//! motion may start ([`far_enough_ahead`]).

use super::*;

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
    /// Path blocks in groups: a whole plan's (VPOp), or a streamed plan's (the reachability
    /// planner, in a thread of its own that reads the path as it plans).
    Blocks {
        events: Option<Receiver<BlockEvent>>,
        queue: VecDeque<BlockGroup>,
        /// Motion time of the groups in `queue` (s).
        queued: f64,
        /// The plan has ended; its motion time.
        total: Option<f64>,
        /// The plan ended before the file did (it could not be read further).
        error: Option<String>,
        /// The path a streamed plan reads (released behind the module).
        path: Option<SharedPath>,
        /// The servo period the plan was made for (s).
        period: f64,
    },
}

/// Slots that go into the ring together, with the curve they need up to.
pub struct Group {
    pub(super) slots: Vec<Slot>,
    pub(super) times: Vec<f64>,
    pub(super) curve_needed: u32,
    /// Path blocks: the arena data of the stop after the last block, still to be written (its
    /// offsets go into the last slot).
    pub(super) block_stop: Option<BlockStopData>,
    /// Segment records: the stop chain of the last slot, still to be written to the arena.
    pub(super) chain: Option<Vec<f64>>,
    /// Segment records: per slot, the checked stops inside it, and how many slots have theirs
    /// written to the arena.
    pub(super) hold_stops: Vec<RecordStops>,
    pub(super) hold_stops_written: usize,
    /// Segment records: where the group leaves the motion.
    pub(super) end: Option<Box<GroupEnd>>,
    /// Segment records: what a cut into them needs ([`RingGroup`]).
    pub(super) cut_data: Option<RingGroup>,
}

/// The arena data of the stop after a block group: its stored sequence, or the stop points of
/// its tangential stop (each emptied once written).
pub(super) struct BlockStopData {
    pub(super) stored: Option<Vec<f64>>,
    pub(super) points: Option<Vec<f64>>,
}

/// A group of segment records in the ring (or running), as a plan at another feed override
/// that cuts into one of them needs it ([`crate::cut`]).
#[derive(Clone)]
pub(super) struct RingGroup {
    /// Slot number of its first record.
    pub(super) first: u64,
    pub(super) records: Vec<SegmentRecord>,
    /// The motion's state before its first record.
    pub(super) begin: Box<SimState>,
    /// Per record, the motion samples with a checked hold stop (where a cut may come).
    pub(super) hold_samples: Vec<Vec<u64>>,
    /// The feed override of its plan.
    pub(super) feed_override: f64,
}

impl RingGroup {
    /// Slot number after its last record.
    pub(super) fn end(&self) -> u64 {
        self.first + self.records.len() as u64
    }
}

/// Plans a streamed motion again at another feed override, in a thread of its own, from the
/// end of the last group sent: the module runs into the new plan's groups as it ran into the
/// old ones, and the old ones not yet sent are dropped.
pub struct Replanner {
    pub(super) path: SharedPath,
    pub(super) limits: Limits,
    /// Where the motion started (a new plan from there while nothing has been sent).
    pub(super) from: Option<StopPoint>,
    /// The override of the plan being sent, and the last one asked for (a re-plan refused is
    /// not tried again until it changes).
    pub(super) feed_override: f64,
    pub(super) asked: f64,
    pub(super) pending: Option<Pending>,
    /// The override a cut was refused for, and the first slot of the group it was refused in:
    /// a re-plan at that override cuts only into later groups (else it joins at a group end).
    pub(super) cut_refused: Option<(f64, u64)>,
    /// How far ahead of the module it joins (s of motion): at least [`JOIN_LEAD`] and what the
    /// last re-plan took to be ready ([`Self::lead`]), doubled each time the re-plan came too
    /// late.
    pub(super) lead: f64,
    /// How long the last re-plan took from its start until it was ready to join (s); before
    /// the first, how long the first plan took to plan [`FIRST_LEAD_PLANNED`] of motion.
    pub(super) ready_after: Option<f64>,
    /// When the override the next re-plan is for was asked for, where earlier re-plans at it
    /// came too late.
    pub(super) retry_since: Option<Instant>,
}

/// A re-plan in progress: its events, the groups it has handed out, and how many slots had
/// been sent when it began (it continues their last group; it is stale once more went out).
pub(super) struct Pending {
    pub(super) events: Receiver<PlanEvent>,
    pub(super) groups: VecDeque<SegmentGroup>,
    pub(super) queued: f64,
    pub(super) total: Option<f64>,
    pub(super) error: Option<String>,
    pub(super) pushed: u64,
    pub(super) feed_override: f64,
    /// When it began, and when the override was asked for (earlier where re-plans before it
    /// came too late).
    pub(super) began: Instant,
    pub(super) since: Instant,
    /// Where it joins: in or after the slot of this number, through the module's
    /// [`nurbs_hal::channel::Splice`] (after motion sample `.1`, a cut into the record, or at
    /// its end, [`AT_RECORD_END`], a group end still queued), or `None`: at the end of the
    /// slots sent.
    pub(super) join: Option<(u64, u64)>,
    /// A cut: the slot number of the first record of the group it comes in, until the re-plan
    /// says where in it ([`SegmentGroup::cut`]; `join` holds the first candidate till then).
    pub(super) cut_group: Option<u64>,
    /// The join has been asked of the module (nothing is sent until it answers).
    pub(super) requested: bool,
    /// When its first group came, and that group's motion time (its pace counts from there).
    pub(super) first_group: Option<(Instant, f64)>,
}

impl Replanner {
    /// How far ahead of the module the next re-plan joins: the lead, and at least what the last
    /// re-plan took to be ready, with a quarter more and the module's time to answer (a re-plan
    /// that comes too late plans again from further on, which takes twice as long).
    pub(super) fn lead(&self) -> f64 {
        let learned = self.ready_after.map_or(0.0, |t| 1.25 * t + SPLICE_LAST_CALL);
        self.lead.max(learned).min(JOIN_LEAD_MAX)
    }
}

/// Runs [`stream_plan`] in a thread of its own; its events, at most [`EVENTS_AHEAD`] waiting.
pub(super) fn spawn_plan(
    path: SharedPath,
    limits: Limits,
    start: StreamStart,
    feed_override: f64,
) -> Receiver<PlanEvent> {
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
pub(super) const OVERRIDE_STEP: f64 = 1e-3;

/// While a re-plan at another feed override that joins at the end of the slots sent is on its
/// way, the old plan's next group waits unless the ring holds less motion than this (s): the
/// re-plan then joins after it instead.
pub(super) const REPLAN_LOW_WATER: f64 = 0.05;

/// A re-plan at another feed override joins at least this far (s of motion) ahead of the
/// module, and as far as the last re-plan took to be ready ([`Replanner::lead`]): at the first
/// checked hold stop there (a cut into the record), else at the first group end with that much
/// motion queued before it. Where it comes too late, the lead doubles, up to
/// [`JOIN_LEAD_MAX`]. Below 30 ms most first cuts into the butterfly and a G1 zigzag came too
/// late (their re-plans are ready in 15-35 ms), and a late one costs a second try further
/// ahead (60-100 ms after the change).
pub(super) const JOIN_LEAD: f64 = 0.03;
pub(super) const JOIN_LEAD_MAX: f64 = 0.32;

/// ... and asks the module only while at least this much is (s).
pub(super) const SPLICE_LAST_CALL: f64 = 0.005;

/// Motion (s) a re-plan must plan before it is ready to join, as first estimated: at the leads
/// it joins with (30-60 ms) the motion before the join makes up the rest of [`START_AHEAD`].
/// Its first plan's time to plan this much is the first re-plan's expected time.
pub(super) const FIRST_LEAD_PLANNED: f64 = 0.5 * START_AHEAD;

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
    pub(super) fn period(&self) -> f64 {
        match self {
            Source::Segments { period, .. } => *period,
            Source::Blocks { period, .. } => *period,
        }
    }

    /// A whole plan's blocks ([`block_plan`]).
    pub fn blocks(plan: BlockPlan) -> Source {
        let total = plan.time();
        Source::Blocks {
            events: None,
            queue: plan.groups.into(),
            queued: total,
            total: Some(total),
            error: None,
            path: None,
            period: plan.period,
        }
    }

    /// The reachability plan of `path` (from its start, or from rest at the stop point `from`)
    /// as a stream of block groups ([`spawn_reach_blocks`]); the streamer releases the path
    /// behind the module.
    pub fn streamed_blocks(path: SharedPath, limits: Limits, from: Option<StopPoint>, max_fraction: f64) -> Source {
        let period = limits.period;
        let events = spawn_reach_blocks(path.clone(), limits, from, max_fraction);
        Source::Blocks {
            events: Some(events),
            queue: VecDeque::new(),
            queued: 0.0,
            total: None,
            error: None,
            path: Some(path),
            period,
        }
    }

    /// Motion time planned so far.
    pub(super) fn planned(&self) -> f64 {
        match self {
            Source::Segments { total: Some(t), .. } | Source::Blocks { total: Some(t), .. } => *t,
            Source::Segments { .. } | Source::Blocks { .. } => 0.0,
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
/// The same for a streamed plan's path blocks, whose stored stops make a second of motion
/// weigh some 2 MB (LinuxCNC's `3D_Chips.ngc`: 880 arena values per 4 ms block).
pub const BLOCKS_QUEUED_AHEAD: f64 = 4.0;
/// While a re-plan at another feed override is on its way, the plan it is to replace is not
/// read further once this much of its motion (s) waits to be sent: its thread then waits (its
/// channel full), and the re-plan has the processor (on two cores, a plan still running ahead
/// near a program's start, its scan helper and the re-plan shared them, and the re-plan took
/// twice as long).
pub(super) const REPLAN_PAUSE: f64 = 1.0;

/// Events the planner thread may hand out before the streamer takes them.
pub(super) const EVENTS_AHEAD: usize = 4;
