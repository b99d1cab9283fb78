//! The realtime module `nurbs_interp`: `loadrt nurbs_interp`, then
//! `addf nurbs_interp.update servo-thread`.
//!
//! `rtapi_app_main` creates the component, its pins (all instance state lives in `hal_malloc`'d
//! memory, as in C components), the shared-memory [`Channel`] the planner writes to, and exports
//! `nurbs_interp.update`. [`Instance::update`] runs every servo period: it takes the curve
//! geometry once the planner has published it (validated with `CurveView`'s checks, a slice of
//! values per period), drives the
//! `nurbs_rtcore` [`Interpolator`] with the segment records it pops from the channel (S-curve
//! feed, RK2 predictor-corrector step of the curve parameter, NURBS evaluation) and writes the
//! output pins. It never allocates, locks, calls the OS or panics (no indexing that can fail);
//! failures are pins (fault, fault-code, underrun), not errors.
//!
//! Pins:
//!
//! | pin | type | dir | unit | meaning |
//! | --- | --- | --- | --- | --- |
//! | `nurbs_interp.enable` | bit | in | | run; when false nothing advances and the outputs hold (an immediate freeze: use `hold` to stop a moving machine) |
//! | `nurbs_interp.hold` | bit | in | | feed hold: at the next segment boundary, the planner-checked stop to rest on the path; released, the plan from the stop point runs (see below) |
//! | `nurbs_interp.abort` | bit | in | | stop as for hold, then discard the queue; the motion is over until a planner publishes a new geometry |
//! | `nurbs_interp.resume` | bit | in | | after an underrun stop: a rising edge starts the plan from the stop point once one is queued (`resume-ready`); an edge without it is ignored |
//! | `nurbs_interp.pos-cmd-x`, `-y`, `-z` | float | out | mm | axis position commands (`-z` is 0 on a 2-D path) |
//! | `nurbs_interp.feed` | float | out | mm/s | path feed at this sample |
//! | `nurbs_interp.u` | float | out | | curve parameter |
//! | `nurbs_interp.curve` | u32 | out | | index of the path element (curve) |
//! | `nurbs_interp.active` | bit | out | | a new sample was produced this period |
//! | `nurbs_interp.done` | bit | out | | the last segment has been completed (at rest at its end) |
//! | `nurbs_interp.fault` | bit | out | | malformed channel, geometry or record, or a resumed plan that does not start where the machine stands; latched, outputs hold |
//! | `nurbs_interp.fault-code` | u32 | out | | why ([`FaultCode`]) |
//! | `nurbs_interp.underrun` | bit | out | | the planner fell behind; the module stops or stopped on the path; set until the resumed motion starts (or an abort) |
//! | `nurbs_interp.held` | bit | out | | at rest on the path after a stop (hold, underrun or abort), not moving |
//! | `nurbs_interp.resume-ready` | bit | out | | stopped (hold or underrun) and a plan from the stop point is queued: releasing `hold` / a `resume` edge starts it |
//! | `nurbs_interp.underruns` | u32 | out | | underrun stops so far |
//! | `nurbs_interp.records` | u32 | out | | records taken so far |
//! | `nurbs_interp.seq` | u32 | out | | sequence number of the last record taken |
//! | `nurbs_interp.buffered` | float | out | s | motion time queued ahead of the current sample |
//!
//! Every stop is the same planner-checked stop. The records end at segment boundaries with zero
//! tangential acceleration; when the module must not (hold, abort) or cannot (underrun: the next
//! record is missing) take the next record, it appends a jerk-limited stop of its own (a
//! three-phase S-curve from the feed at the segment end to rest, [`underrun_stop`]) and runs it
//! through the same interpolator along the same curve: no jump, the feed ramps down to zero.
//! Its deceleration and jerk (or a stored stop sequence to play instead) come with the record
//! ([`RecordStop`] in its slot): the planner ran this very stop from every boundary, by finite differences on the
//! setpoints the module will produce, and chose limits under which it stays within the axis
//! limits (`plan_geometry.rs`); the stop is compressed in time where it would otherwise pass a
//! corner, critical point or the curve end faster than that point's feed cap. So hold, abort
//! and underrun stops are within the axis limits by the same check as the plan itself; the price
//! is that a hold or abort takes effect at the next segment boundary (measured on the butterfly
//! and the trident: at rest at most 0.30 s after the request), and a hold during the last
//! segment lets the motion end at C(1). Afterwards the module holds that position; records
//! arriving later are not run (they were planned from a feed the machine no longer has).
//!
//! Resume (after a hold or an underrun): at rest, the module publishes where it stands in the
//! channel ([`crate::channel::StopStatus`]: cause, element, parameter `u`, arc length `s`,
//! position, the last record's sequence number). A planner (the running `nurbs-planner`, or one
//! started afterwards) plans the rest of the path from rest at exactly that point
//! (`PlanOptions::start`) and publishes it as a new geometry with its own records (sequence
//! from 0). The module takes it but does not move until the command: for a hold,
//! `hold` false; for an underrun, a rising edge on `resume` (with records queued:
//! `resume-ready`; `hold` must be false). Then it runs the new plan with a fresh interpolator,
//! whose first setpoint is the stop point, at rest, as in the planner's own check. The first
//! record must start at rest at exactly the held element, `u` and `s`, and its first sample must
//! be the held position (within [`RESUME_TOLERANCE`]); otherwise nothing moves and the module
//! faults ([`FaultCode::ResumePoint`]). `abort` while stopped ends the stopped motion (and
//! withdraws the stop point): the next geometry is a new motion from its own first record.

use core::cell::Cell;
use core::ffi::{c_int, c_long, c_void, CStr};
use core::ptr::{self, addr_of_mut};
use core::sync::atomic::{AtomicI32, Ordering};

use nurbs_rtcore::executor::{CurveSet, Interpolator, Sample, Step};
use nurbs_rtcore::{CurveView, StopRun};

use nurbs_rtcore::scurve::{stop_from, SCurveTable};

use crate::channel::{
    stop_points, trusted_curve, validate_curves, validate_header, Channel, CurveDesc, CurvesChecked, CurvesCursor,
    GeometryHeader, GeometryRef, RecordStop, StopPoint, CHANNEL_KEY,
};
use crate::pins::Pin;
use crate::record::{PathBlock, Record, SegmentRecord, FLAG_LAST, KIND_BLOCK, PHASES};
use crate::sys;

/// Component name: must equal the module's file name (`loadrt` dlopens `NAME.so`).
pub const NAME: &CStr = c"nurbs_interp";

/// Component id and channel id, for `rtapi_app_exit` (set once in `rtapi_app_main`).
static COMP_ID: AtomicI32 = AtomicI32::new(-1);
static SHMEM_ID: AtomicI32 = AtomicI32::new(-1);

const EINVAL: c_int = 22;
const ENOMEM: c_int = 12;

/// Values of the `fault-code` pin.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultCode {
    None = 0,
    /// The channel header does not match this build, or its counters are inconsistent.
    Channel = 1,
    /// The published geometry does not validate.
    Geometry = 2,
    /// The geometry was re-published while a motion was running.
    GeometryChanged = 3,
    /// A record failed its structural check (non-finite, negative, inconsistent profile, or the
    /// limits of the stop it carries not finite and positive).
    Record = 4,
    /// A record's sequence number is not the next one (lost or repeated record).
    Sequence = 5,
    /// The interpolator refused a record (curve index without a curve).
    BadRecord = 6,
    /// After a stop, the first record of the resumed motion does not start at rest
    /// exactly where the machine stands (element, parameter, position): refused, position held.
    ResumePoint = 7,
    /// A record of the other kind (segment / path block) within one motion, or of no known
    /// kind: one motion is planned by one planner.
    RecordKind = 8,
    /// A path block's positions do not match its arc lengths or the curve (parameter outside
    /// the curve, chord longer than the arc, a step back, or not continuing the previous block).
    BlockPath = 9,
}

/// The component's pins, in HAL shared memory.
#[repr(C)]
pub struct Pins {
    pub enable: Pin<bool>,
    pub hold: Pin<bool>,
    pub abort: Pin<bool>,
    pub resume: Pin<bool>,
    pub pos_cmd_x: Pin<f64>,
    pub pos_cmd_y: Pin<f64>,
    pub pos_cmd_z: Pin<f64>,
    pub feed: Pin<f64>,
    pub u: Pin<f64>,
    pub curve: Pin<u32>,
    pub active: Pin<bool>,
    pub done: Pin<bool>,
    pub fault: Pin<bool>,
    pub fault_code: Pin<u32>,
    pub underrun: Pin<bool>,
    pub underruns: Pin<u32>,
    pub records: Pin<u32>,
    pub seq: Pin<u32>,
    pub buffered: Pin<f64>,
    pub resume_ready: Pin<bool>,
    pub held: Pin<bool>,
}

/// The accepted curve geometry: the channel's header, curve descriptors and arena, validated
/// once when published; each curve's view is made when it is needed (validated again: O(size
/// of the curve), once per change of curve thanks to a one-entry cache).
pub struct RtGeometry {
    /// Generation of the channel geometry (0: none).
    generation: u32,
    header: GeometryHeader,
    curves: &'static [CurveDesc],
    tip: usize,
    /// The geometry arena (curve data, stored stop sequences).
    values: &'static [f64],
    /// The last curve asked for.
    cache: Cell<Option<(usize, CurveView<'static>)>>,
}

impl RtGeometry {
    fn empty() -> RtGeometry {
        RtGeometry {
            generation: 0,
            header: GeometryHeader::default(),
            curves: &[],
            tip: 2,
            values: &[],
            cache: Cell::new(None),
        }
    }

    /// Curve `index`, if the geometry has it. O(1): the curves were checked when the geometry
    /// was accepted, and a rewrite (a new generation) is never used unchecked.
    fn valid(&self, index: usize) -> Option<CurveView<'static>> {
        if let Some((i, c)) = self.cache.get() {
            if i == index {
                return Some(c);
            }
        }
        let g = GeometryRef {
            header: self.header,
            curves: self.curves,
            values: self.values,
        };
        let c = trusted_curve(&g, index).ok()?;
        self.cache.set(Some((index, c)));
        Some(c)
    }

    fn is_valid(&self) -> bool {
        self.generation != 0
    }
}

impl CurveSet for RtGeometry {
    fn curve(&self, index: usize) -> Option<CurveView<'_>> {
        self.valid(index)
    }
    fn tip_axes(&self) -> usize {
        self.tip
    }
    fn generation(&self) -> u64 {
        u64::from(self.generation)
    }
}

/// Where the machine stands after a hold or underrun stop (what a resumed plan must start from).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Held {
    pub curve: usize,
    pub u: f64,
    pub s: f64,
    pub point: [f64; 3],
}

/// Checks of curve values (knots, coordinates and weights once, interior knots once more) the
/// module runs per period on a newly published geometry (a few microseconds), within a curve
/// if it is larger ([`validate_curves`]).
pub const VALIDATION_VALUES_PER_PERIOD: usize = 4096;

/// Largest distance (mm) between where the machine stands and a resumed motion's first sample.
/// Evaluated by the same code on the same geometry the two are bit-equal; this only absorbs a
/// re-published copy of the geometry that rounds differently.
pub const RESUME_TOLERANCE: f64 = 1e-9;

/// Everything the update function touches: pins, the channel and plain-data state.
#[repr(C)]
pub struct Instance {
    pub pins: Pins,
    channel: *const Channel,
    geometry: RtGeometry,
    /// A published geometry being validated: its generation and where the check stands.
    validating: Option<(u32, CurvesCursor)>,
    interp: Interpolator,
    /// Sequence number the next record must carry.
    next_seq: u32,
    /// The stop after the last segment record taken (it came with the record).
    record_stop: RecordStop,
    /// The stop points of the last record or block taken, validated (with the arena offset and
    /// length they came as: records on one curve share them, checked once).
    points: StopPoints,
    records: u32,
    underruns: u32,
    /// Motion time of the records taken so far (s).
    taken_time: f64,
    /// The planner fell behind and the module ran (or runs) its own stop.
    stopping: bool,
    /// ... and that stop is over: at rest.
    stopped: bool,
    /// Why the module stops or stopped (until the resumed motion starts).
    cause: StopCause,
    /// Abort completed: at rest, queue discarded, nothing more runs until a new geometry.
    aborted: bool,
    fault: FaultCode,
    /// Stops so far (the epoch of the published stop point).
    stops: u32,
    /// Stopped on the path: where the machine stands, until a resumed motion starts.
    held: Option<Held>,
    /// A new geometry (the plan from `held`) has been taken: it runs after the command.
    awaiting_resume: bool,
    /// The resume command came: the next record must start at `held`, checked on its first
    /// sample.
    resuming: bool,
    /// `resume` pin of the last period (rising-edge detection).
    resume_pin: bool,
    /// Which kind of record the current motion runs (set by its first record).
    mode: Mode,
    /// Servo period of the current update (s).
    period: f64,
    /// Path-block motion: the block being output.
    player: BlockPlayer,
}

/// The record kind of a motion.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Undecided = 0,
    Segments = 1,
    Blocks = 2,
}

/// Playback state of a path-block motion, and of a stored stop sequence (after a block or a
/// segment record; plain data).
#[derive(Clone, Copy, Debug)]
struct BlockPlayer {
    block: PathBlock,
    /// A block has been taken (the motion started).
    loaded: bool,
    /// Samples of `block` output so far.
    index: usize,
    /// The last sample of the last block has been output: at rest at the path end.
    finished: bool,
    /// A sample of this motion has been output (the fields below describe it).
    has_sample: bool,
    /// The last output sample: curve, parameter, arc length, the one before's arc length, point.
    curve: usize,
    u: f64,
    s: f64,
    s_before: f64,
    point: [f64; 3],
    /// Running a stored stop sequence: where it is read.
    stored: Option<StoredCursor>,
}

impl BlockPlayer {
    const IDLE: BlockPlayer = BlockPlayer {
        block: PathBlock {
            seq: 0,
            flags: 0,
            count: 0,
            stop_len: 0,
            stop_offset: 0,
            points_offset: 0,
            points_len: 0,
            reserved: 0,
            stop_accel: 0.0,
            stop_jerk: 0.0,
            s_before: [0.0; 2],
            u: [0.0; nurbs_rtcore::BLOCK_SAMPLES],
            s: [0.0; nurbs_rtcore::BLOCK_SAMPLES],
        },
        loaded: false,
        index: 0,
        finished: false,
        has_sample: false,
        curve: 0,
        u: 0.0,
        s: 0.0,
        s_before: 0.0,
        point: [0.0; 3],
        stored: None,
    };

    fn remaining(&self) -> usize {
        self.block.len().saturating_sub(self.index)
    }
}

/// Where a stored stop sequence ([`StopRun`]s in the arena) is being read.
#[derive(Clone, Copy, Debug)]
struct StoredCursor {
    /// The record or block it follows.
    seq: u32,
    /// Arena index of the next value to read (a run header when `run_left` is 0).
    next: usize,
    /// Positions of the sequence still to output.
    left: usize,
    /// Positions of the current run still to read.
    run_left: usize,
    /// The arc length before the run's first position, until that position is read.
    run_s_before: Option<f64>,
}

impl StoredCursor {
    fn new(seq: u32, offset: u32, len: u32) -> Self {
        StoredCursor {
            seq,
            next: offset as usize,
            left: len as usize,
            run_left: 0,
            run_s_before: None,
        }
    }
}

/// Validated stop points (`(s, feed cap)` pairs in the arena) and where they came from.
#[derive(Clone, Copy, Debug)]
struct StopPoints {
    key: Option<(u32, u32)>,
    pairs: &'static [f64],
}

impl StopPoints {
    const NONE: StopPoints = StopPoints { key: None, pairs: &[] };

    /// The `len` pairs at `offset` of `values`, checked unless they are the ones held already;
    /// `None` if they are not valid stop points ([`stop_points`]).
    fn take(&mut self, values: &'static [f64], offset: u32, len: u32) -> Option<()> {
        if self.key != Some((offset, len)) {
            let pairs = stop_points(values, offset, len)?;
            *self = StopPoints {
                key: Some((offset, len)),
                pairs,
            };
        }
        Some(())
    }
}

/// Why the module stops (or stopped) on the path.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopCause {
    None = 0,
    /// The next record was missing: resumes on a rising edge of `resume`.
    Underrun = 1,
    /// `hold`: resumes when `hold` is released.
    Hold = 2,
    /// `abort`: the motion is over once at rest.
    Abort = 3,
}

/// What the record source saw while the interpolator pulled records.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pull {
    Fine,
    Empty,
    Fault(FaultCode),
}

/// Phase times `(t1, t2)` of a stop from `v0` to rest with deceleration `accel` and jerk `jerk`:
/// jerk `-jerk` for `t1`, constant deceleration for `t2`, jerk `+jerk` for `t1`. The feed falls
/// point-symmetrically, so the stop covers `v0 (2 t1 + t2) / 2`.
fn stop_phases(v0: f64, accel: f64, jerk: f64) -> (f64, f64) {
    if v0 * jerk <= accel * accel {
        ((v0 / jerk).sqrt(), 0.0)
    } else {
        (accel / jerk, (v0 - accel * accel / jerk) / accel)
    }
}

/// Distance of the stop of [`stop_phases`].
pub fn stop_distance(v0: f64, accel: f64, jerk: f64) -> f64 {
    let (t1, t2) = stop_phases(v0, accel, jerk);
    v0 * (2.0 * t1 + t2) / 2.0
}

/// The jerk-limited stop appended after `last` when no next record comes: from the feed at the
/// end of `last` (zero tangential acceleration there) to rest along the same curve, with
/// deceleration `accel * k` and jerk `jerk * k^2`, i.e. the `(accel, jerk)` stop compressed in
/// time by `k >= 1`.
pub fn stop_record(last: &SegmentRecord, accel: f64, jerk: f64, k: f64) -> SegmentRecord {
    let v0 = last.profile().table().end().v.max(0.0);
    let j = jerk * k * k;
    let (t1, t2) = stop_phases(v0, accel * k, j);
    let (t1, t2, j) = if t1.is_finite() && t2.is_finite() && j.is_finite() && v0 > 0.0 {
        (t1, t2, j)
    } else {
        (0.0, 0.0, 0.0) // no feed, or no room: stop where we are
    };
    let mut durations = [0.0; PHASES];
    let mut jerks = [0.0; PHASES];
    for (i, (d, jk)) in [(t1, -j), (t2, 0.0), (t1, j)].into_iter().enumerate() {
        if let (Some(di), Some(ji)) = (durations.get_mut(i), jerks.get_mut(i)) {
            *di = d;
            *ji = jk;
        }
    }
    let mut record = SegmentRecord {
        seq: last.seq,
        flags: last.flags & !FLAG_LAST,
        u_start: last.u_end,
        u_end: last.u_end,
        s_start: last.s_start + last.length,
        length: 0.0,
        feed_start: v0,
        durations,
        jerks,
    };
    record.length = record.profile().table().end().s.max(0.0);
    record
}

/// Distance into a stop profile at which its (falling) feed has come down to `v`.
fn distance_at_feed(table: &SCurveTable, v: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, table.total_time());
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if table.state_at(mid).v > v {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    table.state_at(hi).s
}

/// The stop the module runs after `last` on its curve: deceleration `accel` and jerk `jerk`,
/// compressed in time just enough to pass every stop point of the curve (`points`, `(s, feed
/// cap)` pairs: the planner's critical points, corners, the curve end) no faster than its feed
/// cap. Bounded work: one pass over the stop points, a 60-step bisection for each one the stop
/// reaches too fast.
pub fn underrun_stop(points: &[f64], last: &SegmentRecord, accel: f64, jerk: f64) -> SegmentRecord {
    let nominal = stop_record(last, accel, jerk, 1.0);
    let table = nominal.profile().table();
    let (v0, s0, reach) = (nominal.feed_start, nominal.s_start, nominal.length);
    let mut k = 1.0f64;
    for pair in points.chunks_exact(2) {
        if let [s, cap] = *pair {
            // Points within a micrometre are the one the last segment ends at: passed as planned.
            let d = s - s0;
            if d > 1e-3 && d < reach && cap < v0 {
                // At scale k the feed at distance d is the nominal feed at distance k d.
                k = k.max(distance_at_feed(&table, cap) / (0.999 * d));
            }
        }
    }
    stop_record(last, accel, jerk, k)
}

/// Largest ratio of a path-block step's arc length to its chord: a step turns less than a half
/// circle (arc / chord of a semicircle = pi / 2). Only catches arc lengths that do not belong to
/// the positions; the planner's own arc lengths are exact.
const ARC_PER_CHORD: f64 = core::f64::consts::FRAC_PI_2;

/// A step's chord fits its arc length: no longer (to rounding), and not shorter than 2/pi of it.
fn step_fits(chord: f64, ds: f64) -> bool {
    chord <= ds * (1.0 + 1e-9) + 1e-9 && ds <= ARC_PER_CHORD * chord + 1e-9
}

/// The state a stop after `block` starts from: arc length, feed and tangential acceleration at
/// its last sample, from the quadratic through its last three arc lengths (backward
/// differences of period `dt`, centred at the last sample).
pub fn block_end_state(block: &PathBlock, dt: f64) -> (f64, f64, f64) {
    let n = block.len() + 1; // index of the last sample in `s_history`
    let (s0, s1, s2) = (
        block.s_history(n),
        block.s_history(n.saturating_sub(1)),
        block.s_history(n.saturating_sub(2)),
    );
    let a = (s0 - 2.0 * s1 + s2) / (dt * dt);
    let v = (3.0 * s0 - 4.0 * s1 + s2) / (2.0 * dt);
    (s0, v, a)
}

/// The stop the module runs after `block` (an underrun, hold or abort at its end): from the
/// block's end state ([`block_end_state`]) to rest along its curve with the block's checked
/// deceleration and jerk, both raised (deceleration by `k`, jerk by `k^2`) just enough to pass
/// every stop point of the curve (`points`) no faster than its cap, as [`underrun_stop`] does. Returns the
/// stop as a record (start, curve, profile) and its start acceleration (for
/// [`SCurve::table_from`](nurbs_rtcore::SCurve::table_from)). Bounded work: for each stop point
/// the stop reaches too fast, a 40-step bisection of `k` with a 60-step bisection inside.
pub fn block_stop(points: &[f64], block: &PathBlock, dt: f64) -> (SegmentRecord, f64) {
    let (s0, v0, a0) = block_end_state(block, dt);
    let (accel, jerk) = (block.stop_accel, block.stop_jerk);
    let profile = |k: f64| stop_from(v0, a0, accel * k, jerk * k * k);
    let reach = profile(1.0).table_from(a0).length();
    let mut k = 1.0f64;
    for pair in points.chunks_exact(2) {
        if let [s, cap] = *pair {
            let d = s - s0;
            let fits = |k: f64| distance_at_feed(&profile(k).table_from(a0), cap) <= 0.999 * d;
            if d > 1e-9 && d < reach && cap < v0 && !fits(k) {
                let (mut lo, mut hi) = (k, k * 2.0);
                for _ in 0..40 {
                    if fits(hi) {
                        break;
                    }
                    lo = hi;
                    hi *= 2.0;
                }
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if fits(mid) {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                k = hi;
            }
        }
    }
    let p = profile(k);
    let last = block.len().saturating_sub(1);
    let u = block.u.get(last).copied().unwrap_or(0.0);
    let record = SegmentRecord {
        seq: block.seq,
        flags: block.flags & !FLAG_LAST,
        u_start: u,
        u_end: u,
        s_start: s0,
        length: p.table_from(a0).length().max(0.0),
        feed_start: p.feed_start,
        durations: p.durations,
        jerks: p.jerks,
    };
    (record, if p.feed_start > 0.0 { a0 } else { 0.0 })
}

impl Instance {
    /// One servo period. `period_ns` is the thread's period.
    pub fn update(&mut self, period_ns: i64) {
        self.period = period_ns as f64 / 1e9;
        // SAFETY: the channel block stays mapped until rtapi_app_exit, after the last period.
        let channel: &'static Channel = unsafe { &*self.channel };
        if self.fault == FaultCode::None && channel.check().is_err() {
            self.fault = FaultCode::Channel;
        }
        if self.fault == FaultCode::None {
            self.accept_geometry(channel);
        }
        let (hold, abort) = (self.pins.hold.get(), self.pins.abort.get());
        let resume = self.pins.resume.get();
        // Only an edge while a plan from the stop point is queued counts; one without data (or
        // under hold) is dropped.
        let resume_edge = resume && !self.resume_pin;
        self.resume_pin = resume;
        if (self.awaiting_resume || (self.stopped && !self.aborted)) && abort {
            // Abort while stopped: the stopped motion is over; a new geometry starts a new
            // motion from its first record.
            self.end_motion(channel);
        }
        let command = match self.cause {
            StopCause::Hold => !hold,
            _ => resume_edge,
        };
        if self.awaiting_resume && command && !hold && self.fault == FaultCode::None && !channel.segments.is_empty() {
            // Data and the command: run the plan from the stop point.
            self.awaiting_resume = false;
            self.resuming = true;
            self.cause = StopCause::None;
            channel.stop.clear();
        }
        let mut active = false;
        let started = self.started();
        if abort && !started && self.geometry.is_valid() && !self.aborted && self.fault == FaultCode::None {
            self.end_motion(channel); // nothing moved yet: the queue is discarded at once
        }
        if self.fault == FaultCode::None
            && self.pins.enable.get()
            && self.geometry.is_valid()
            && !self.awaiting_resume
            && !self.aborted
            && !self.stopped
            && !((hold || abort) && !started)
        {
            let dt = period_ns as f64 / 1e9;
            active = self.advance(channel, dt, hold, abort);
        }
        if self.fault == FaultCode::None && (self.stopped || self.aborted || self.finished()) {
            // Over: what is still queued (or comes) belongs to a motion that will not run, and
            // an empty ring tells a new planner that it may publish.
            discard(channel, self.geometry.generation);
        }
        let pins = &self.pins;
        pins.active.set(active);
        pins.done.set(self.finished());
        pins.fault.set(self.fault != FaultCode::None);
        pins.fault_code.set(self.fault as u32);
        pins.underrun.set(self.cause == StopCause::Underrun);
        pins.held.set(self.stopped || self.awaiting_resume);
        pins.underruns.set(self.underruns);
        pins.records.set(self.records);
        let ready = self.awaiting_resume && self.fault == FaultCode::None && !channel.segments.is_empty();
        pins.resume_ready.set(ready);
        let buffered = if self.cause != StopCause::None {
            0.0
        } else {
            let left = if self.mode == Mode::Blocks {
                self.player.remaining() as f64 * period_ns as f64 / 1e9
            } else {
                self.interp.time_left_in_segment()
            };
            (channel.planned_time() - self.taken_time).max(0.0) + left
        };
        pins.buffered.set(buffered);
    }

    /// A motion is loaded and may still move (not finished, aborted or stopped).
    fn in_motion(&self) -> bool {
        self.started() && !self.finished() && !self.aborted && !self.stopped
    }

    /// The motion has taken its first record (of either kind).
    fn started(&self) -> bool {
        self.interp.record().is_some() || self.player.loaded
    }

    /// The motion has reached the path end.
    fn finished(&self) -> bool {
        match self.mode {
            Mode::Blocks => self.player.finished,
            _ => self.interp.is_finished(),
        }
    }

    /// Take a newly published geometry (only while no motion runs), or fault.
    fn accept_geometry(&mut self, channel: &'static Channel) {
        let generation = channel.geometry.generation();
        if generation == self.geometry.generation || generation & 1 == 1 {
            return; // unchanged, or being written: look again next period
        }
        if self.in_motion() {
            self.fault = FaultCode::GeometryChanged;
            return;
        }
        let Some((generation, g)) = channel.geometry.snapshot() else {
            return;
        };
        self.geometry.generation = 0;
        // A large geometry (a long G1 program is thousands of curves) is checked a slice per
        // period, so that no period runs long; a rewrite in between starts it over.
        let first = match self.validating {
            Some((g_at, next)) if g_at == generation => Ok(next),
            _ => validate_header(&g).map(|()| CurvesCursor::default()),
        };
        let checked = first.and_then(|first| validate_curves(&g, first, VALIDATION_VALUES_PER_PERIOD));
        self.validating = None;
        if !channel.geometry.unchanged(generation) {
            return; // rewritten while validating: again next period
        }
        match checked {
            Ok(CurvesChecked::All) => {
                self.geometry.values = g.values;
                self.geometry.curves = g.curves;
                self.geometry.cache.set(None);
                self.set_geometry(generation, &g.header);
            }
            Ok(CurvesChecked::UpTo(next)) => self.validating = Some((generation, next)),
            Err(_) => self.fault = FaultCode::Geometry,
        }
    }

    fn set_geometry(&mut self, generation: u32, header: &GeometryHeader) {
        let g = &mut self.geometry;
        g.header = *header;
        g.tip = header.tip_axes as usize;
        g.generation = generation;
        // After a stop on the path (underrun or hold) the new geometry carries the plan from the
        // stop point: it waits for the command, and its first record must start there.
        if self.held.is_some() && (self.stopped || self.awaiting_resume) && !self.aborted {
            self.awaiting_resume = true;
        } else {
            self.held = None;
            self.awaiting_resume = false;
            self.cause = StopCause::None;
        }
        self.resuming = false;
        // A new geometry starts a new motion.
        self.interp = Interpolator::new();
        self.mode = Mode::Undecided;
        self.player = BlockPlayer::IDLE;
        self.next_seq = 0;
        self.record_stop = RecordStop::default();
        self.points = StopPoints::NONE;
        self.taken_time = 0.0;
        self.stopping = false;
        self.stopped = false;
        self.aborted = false;
    }

    /// The stopped (or aborted) motion is over: nothing of it resumes.
    fn end_motion(&mut self, channel: &Channel) {
        self.aborted = true;
        self.awaiting_resume = false;
        self.held = None;
        self.cause = StopCause::None;
        channel.stop.clear();
    }

    /// Advance the interpolator by one period; true if it produced a sample. `hold`, `abort`:
    /// no further record is taken; the module stops at the next segment boundary instead.
    fn advance(&mut self, channel: &Channel, dt: f64, hold: bool, abort: bool) -> bool {
        if self.mode == Mode::Undecided {
            // The first record of the motion decides its kind (an unknown kind is refused by
            // the segment path).
            match channel.segments.peek() {
                Ok(Some(slot)) if slot.kind == KIND_BLOCK => self.mode = Mode::Blocks,
                Ok(Some(_)) => self.mode = Mode::Segments,
                Ok(None) => return false,
                Err(_) => {
                    self.fault = FaultCode::Channel;
                    return false;
                }
            }
        }
        if let (true, Some(cursor)) = (self.stopping, self.player.stored) {
            return self.advance_stored_stop(channel, cursor);
        }
        if self.mode == Mode::Blocks {
            return self.advance_blocks(channel, dt, hold, abort);
        }
        let mut pull = Pull::Fine;
        let step = {
            let ring = &channel.segments;
            let no_more = self.stopping || hold || abort;
            let resume_from = if self.resuming { self.held } else { None };
            let next_seq = &mut self.next_seq;
            let record_stop = &mut self.record_stop;
            let points = &mut self.points;
            let values = self.geometry.values;
            let records = &mut self.records;
            let taken_time = &mut self.taken_time;
            let pins = &self.pins;
            let mut next = || -> Option<SegmentRecord> {
                if no_more || pull != Pull::Fine {
                    return None;
                }
                let popped = match ring.pop() {
                    Ok(Some(slot)) => match slot.decode() {
                        Some(Record::Segment(r, stop)) => Ok(Some((r, stop))),
                        _ => {
                            pull = Pull::Fault(FaultCode::RecordKind);
                            return None;
                        }
                    },
                    Ok(None) => Ok(None),
                    Err(e) => Err(e),
                };
                match popped {
                    Ok(Some((r, _))) if r.seq != *next_seq => {
                        pull = Pull::Fault(FaultCode::Sequence);
                        None
                    }
                    Ok(Some((r, _))) if resume_from.is_some_and(|h| !starts_at(&r, &h)) => {
                        pull = Pull::Fault(FaultCode::ResumePoint);
                        None
                    }
                    Ok(Some((_, stop)))
                        if !stop.is_valid() || points.take(values, stop.points_offset, stop.points_len).is_none() =>
                    {
                        pull = Pull::Fault(FaultCode::Record);
                        None
                    }
                    Ok(Some((r, stop))) => match check_record(&r) {
                        Ok(()) => {
                            *next_seq = r.seq.wrapping_add(1);
                            *record_stop = stop;
                            *records = records.wrapping_add(1);
                            *taken_time += r.profile().total_time();
                            pins.seq.set(r.seq);
                            Some(r)
                        }
                        Err(_) => {
                            pull = Pull::Fault(FaultCode::Record);
                            None
                        }
                    },
                    Ok(None) => {
                        pull = Pull::Empty;
                        None
                    }
                    Err(_) => {
                        pull = Pull::Fault(FaultCode::Channel);
                        None
                    }
                }
            };
            self.interp.step(&self.geometry, dt, &mut next)
        };
        match (step, pull) {
            (_, Pull::Fault(code)) => {
                self.fault = code;
                false
            }
            (Step::Sample(s), _) => {
                if self.resuming {
                    // The resumed motion's first sample: it must be where the machine stands.
                    let here = self.held.map(|h| h.point);
                    if here.is_none_or(|p| distance(&p, &self.point_of(&s)) > RESUME_TOLERANCE) {
                        self.fault = FaultCode::ResumePoint;
                        return false;
                    }
                    self.resuming = false;
                    self.held = None;
                }
                self.output(&s);
                true
            }
            (Step::Finished, _) => false,
            (Step::BadRecord, _) => {
                self.fault = FaultCode::BadRecord;
                false
            }
            (Step::Starved, _) => {
                let Some(last) = self.interp.record().copied() else {
                    return false; // not started yet: waiting for the first record
                };
                if self.stopping {
                    let held = self.held_by_interp();
                    self.stop_over(channel, last.seq, held);
                    return false;
                }
                self.begin_stop(hold, abort);
                let planned = self.record_stop;
                if planned.stored_len > 0 {
                    // The planner's stop sequence from the last sample (which may cross a join).
                    let held = self.held_by_interp();
                    let player = &mut self.player;
                    (player.curve, player.u, player.s, player.point) = (held.curve, held.u, held.s, held.point);
                    let cursor = StoredCursor::new(last.seq, planned.stored_offset, planned.stored_len);
                    player.stored = Some(cursor);
                    return self.advance_stored_stop(channel, cursor);
                }
                let mut stop = Some(underrun_stop(self.points.pairs, &last, planned.accel, planned.jerk));
                match self.interp.step(&self.geometry, dt, &mut || stop.take()) {
                    Step::Sample(s) => {
                        self.output(&s);
                        true
                    }
                    Step::BadRecord => {
                        self.fault = FaultCode::BadRecord;
                        false
                    }
                    Step::Starved | Step::Finished => false,
                }
            }
        }
    }

    /// The stop is over: at rest on the path at `held`.
    fn stop_over(&mut self, channel: &Channel, seq: u32, held: Held) {
        self.stopped = true;
        if self.cause == StopCause::Abort {
            self.end_motion(channel);
        } else {
            self.publish_stop(channel, seq, held);
        }
    }

    /// Where the interpolator stands (after a stop it ran).
    fn held_by_interp(&self) -> Held {
        let c = *self.interp.cursor();
        let [x, y, z, ..] = c.point;
        Held {
            curve: self.interp.curve_index(),
            u: c.u,
            s: c.s,
            point: [x, y, if self.geometry.tip >= 3 { z } else { 0.0 }],
        }
    }

    /// No further record is taken: the module's own stop begins (why: `abort`, `hold`, or else
    /// the record it needs is missing).
    fn begin_stop(&mut self, hold: bool, abort: bool) {
        self.stopping = true;
        self.cause = if abort {
            StopCause::Abort
        } else if hold {
            StopCause::Hold
        } else {
            self.underruns = self.underruns.wrapping_add(1);
            StopCause::Underrun
        };
    }

    /// One period of a path-block motion: the next planned position, exactly; at a block end
    /// without a next block (underrun) or under hold/abort, the stop from the block's end state
    /// along the curve, run by the interpolator.
    fn advance_blocks(&mut self, channel: &Channel, dt: f64, hold: bool, abort: bool) -> bool {
        if self.stopping {
            return match self.interp.step(&self.geometry, dt, &mut || None) {
                Step::Sample(s) => {
                    self.output(&s);
                    true
                }
                Step::BadRecord => {
                    self.fault = FaultCode::BadRecord;
                    false
                }
                Step::Starved | Step::Finished => {
                    let held = self.held_by_interp();
                    self.stop_over(channel, self.player.block.seq, held);
                    false
                }
            };
        }
        if self.player.finished {
            return false;
        }
        if self.player.remaining() == 0 {
            let block = if hold || abort {
                None
            } else {
                match channel.segments.pop() {
                    Ok(Some(slot)) => match slot.decode() {
                        Some(Record::Block(b)) => Some(b),
                        _ => {
                            self.fault = FaultCode::RecordKind;
                            return false;
                        }
                    },
                    Ok(None) => None,
                    Err(_) => {
                        self.fault = FaultCode::Channel;
                        return false;
                    }
                }
            };
            let Some(block) = block else {
                if !self.player.loaded {
                    return false; // waiting for the first block
                }
                // Underrun, hold or abort at the block end: the checked stop from here.
                self.begin_stop(hold, abort);
                let last = self.player.block;
                if last.stop_len > 0 {
                    // The planner's own deceleration sequence, stored with the geometry.
                    let cursor = StoredCursor::new(last.seq, last.stop_offset, last.stop_len);
                    self.player.stored = Some(cursor);
                    return self.advance_stored_stop(channel, cursor);
                }
                let (stop, a0) = block_stop(self.points.pairs, &last, dt);
                let table = stop.profile().table_from(a0);
                if !self.interp.start_profile(&self.geometry, stop, table) {
                    self.fault = FaultCode::BadRecord;
                    return false;
                }
                return self.advance_blocks(channel, dt, hold, abort);
            };
            if let Err(code) = self.take_block(&block) {
                self.fault = code;
                return false;
            }
        }
        self.output_block_sample()
    }

    /// One period of a stored stop sequence: the next position (checked as a block sample);
    /// after the last one, at rest there.
    fn advance_stored_stop(&mut self, channel: &Channel, mut c: StoredCursor) -> bool {
        let p = self.player;
        if c.left == 0 {
            let held = Held {
                curve: p.curve,
                u: p.u,
                s: p.s,
                point: p.point,
            };
            self.stop_over(channel, c.seq, held);
            return false;
        }
        let values = self.geometry.values;
        let mut curve = p.curve;
        if c.run_left == 0 {
            let Some(run) = values.get(c.next..).and_then(StopRun::from_values) else {
                self.fault = FaultCode::BlockPath;
                return false;
            };
            c.next = c.next.saturating_add(StopRun::VALUES);
            c.run_left = run.count;
            c.run_s_before = Some(run.s_before);
            curve = run.curve;
        }
        let (Some(&u), Some(&s), Some(view)) = (
            values.get(c.next),
            values.get(c.next.saturating_add(1)),
            self.geometry.curve(curve),
        ) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        let Some(point) = self.interp.point_at(&self.geometry, curve, u) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        // On the same curve onwards from the last position, or at the start of a run on the
        // next curve (across the join), where the run gives the step's start in its measure.
        let s_before = c.run_s_before.take().unwrap_or(p.s);
        let follows = if curve == p.curve {
            u >= p.u && s_before == p.s
        } else {
            curve == p.curve.wrapping_add(1) && u >= view.u_min()
        };
        let sample = Sample {
            curve,
            u,
            s,
            point,
            feed: 0.0,
            accel: 0.0,
        };
        let here = self.point_of(&sample);
        let chord = distance(&p.point, &here);
        let finite = u.is_finite() && s.is_finite();
        if !(finite && follows && u <= view.u_max() && step_fits(chord, s - s_before)) {
            self.fault = FaultCode::BlockPath;
            return false;
        }
        self.output(&Sample {
            feed: chord / self.period,
            ..sample
        });
        c.next = c.next.saturating_add(2);
        c.run_left = c.run_left.saturating_sub(1);
        c.left = c.left.saturating_sub(1);
        let player = &mut self.player;
        player.stored = Some(c);
        player.curve = curve;
        player.s_before = s_before;
        player.u = u;
        player.s = s;
        player.point = here;
        true
    }

    /// Validates `block` against the sequence, the curve, the previous block and (on a
    /// resume) the stop point, then makes it the current block.
    fn take_block(&mut self, b: &PathBlock) -> Result<(), FaultCode> {
        if b.seq != self.next_seq {
            return Err(FaultCode::Sequence);
        }
        b.check().map_err(|_| FaultCode::Record)?;
        self.points
            .take(self.geometry.values, b.points_offset, b.points_len)
            .ok_or(FaultCode::Record)?;
        let n = b.len();
        let view = self.geometry.curve(b.curve()).ok_or(FaultCode::BadRecord)?;
        let (lo, hi) = (view.u_min(), view.u_max());
        if b.u.iter().take(n).any(|u| *u < lo || *u > hi) {
            return Err(FaultCode::BlockPath);
        }
        let p = &self.player;
        let continues = if self.resuming {
            // The plan from the stop point starts there, at rest.
            self.held
                .is_some_and(|h| h.curve == b.curve() && h.u == b.u[0] && h.s == b.s[0] && b.s_before == [h.s, h.s])
        } else if !p.loaded {
            b.s_before == [b.s[0], b.s[0]] // the motion starts at rest
        } else if b.curve() == p.curve {
            b.u[0] >= p.u && b.s_before == [p.s_before, p.s]
        } else {
            b.curve() > p.curve // the next element; its own arc-length measure
        };
        if !continues {
            return Err(if self.resuming {
                FaultCode::ResumePoint
            } else {
                FaultCode::BlockPath
            });
        }
        self.next_seq = b.seq.wrapping_add(1);
        self.records = self.records.wrapping_add(1);
        self.taken_time += n as f64 * self.period;
        self.pins.seq.set(b.seq);
        let player = &mut self.player;
        player.block = *b;
        player.index = 0;
        player.loaded = true;
        Ok(())
    }

    /// Outputs the current block's next sample: the curve point at its parameter, after
    /// checking it against the arc lengths (and, on a resume, the held position).
    fn output_block_sample(&mut self) -> bool {
        let p = self.player;
        let b = &p.block;
        let k = p.index;
        let (Some(&u), Some(&s)) = (b.u.get(k), b.s.get(k)) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        let Some(point) = self.interp.point_at(&self.geometry, b.curve(), u) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        let mut sample = Sample {
            curve: b.curve(),
            u,
            s,
            point,
            feed: 0.0,
            accel: 0.0,
        };
        let here = self.point_of(&sample);
        // The feed pin: the setpoints' speed over the last period (as VPOp reports it).
        let chord = distance(&p.point, &here);
        if p.has_sample {
            sample.feed = chord / self.period;
        }
        if self.resuming {
            let held = self.held.map(|h| h.point);
            if held.is_none_or(|h| distance(&h, &here) > RESUME_TOLERANCE) {
                self.fault = FaultCode::ResumePoint;
                return false;
            }
            self.resuming = false;
            self.held = None;
        } else if p.has_sample {
            // Not the motion's first sample: the step's chord must fit its arc length.
            let ds = s - b.s_history(k + 1);
            if !step_fits(chord, ds) {
                self.fault = FaultCode::BlockPath;
                return false;
            }
        }
        self.output(&sample);
        let player = &mut self.player;
        player.index = k + 1;
        player.curve = b.curve();
        player.s_before = b.s_history(k + 1);
        player.u = u;
        player.s = s;
        player.point = here;
        player.has_sample = true;
        if b.is_last() && player.index >= b.len() {
            player.finished = true;
        }
        true
    }

    /// The axis positions the module outputs for `s`.
    fn point_of(&self, s: &Sample) -> [f64; 3] {
        let [x, y, z, ..] = s.point;
        [x, y, if self.geometry.tip >= 3 { z } else { 0.0 }]
    }

    /// At rest after a hold or underrun stop: remember where, and tell the planner.
    fn publish_stop(&mut self, channel: &Channel, seq: u32, held: Held) {
        self.held = Some(held);
        self.stops = self.stops.wrapping_add(1).max(1);
        channel.stop.publish(&StopPoint {
            epoch: self.stops,
            cause: self.cause as u32,
            generation: self.geometry.generation,
            seq,
            curve: held.curve as u32,
            u: held.u,
            s: held.s,
            point: held.point,
        });
    }

    fn output(&self, s: &Sample) {
        let pins = &self.pins;
        let [x, y, z] = self.point_of(s);
        pins.pos_cmd_x.set(x);
        pins.pos_cmd_y.set(y);
        pins.pos_cmd_z.set(z);
        pins.feed.set(s.feed);
        pins.u.set(s.u);
        pins.curve.set(s.curve as u32);
    }
}

/// True if `r` starts at rest exactly at `held` (element, parameter and arc length as held).
fn starts_at(r: &SegmentRecord, held: &Held) -> bool {
    r.curve() == held.curve && r.u_start == held.u && r.s_start == held.s && r.feed_start == 0.0
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    (dx * dx + dy * dy + dz * dz).sqrt()
}

/// Rounding slack for a start feed: the planner hands on a segment's computed end feed, which
/// can come out a few ulps below zero where the path stops (seen: -2.8e-14 mm/s).
const FEED_ROUNDING: f64 = 1e-9;

/// `SegmentRecord::check`, except that a start feed within [`FEED_ROUNDING`] below zero counts
/// as zero. Only the check sees the adjusted copy: the record runs as sent, so the motion stays
/// the one the planner simulated.
fn check_record(r: &SegmentRecord) -> Result<(), nurbs_rtcore::RecordError> {
    let mut checked = *r;
    if (-FEED_ROUNDING..0.0).contains(&checked.feed_start) {
        checked.feed_start = 0.0;
    }
    checked.check()
}

/// Drop every queued record of the motion of geometry `generation` (aborted, stopped on an
/// underrun, or finished: nothing of that motion runs any more). Stops as soon as a new geometry
/// is published: the planner publishes before it pushes, so a record seen after the publish
/// (`len` acquires the ring's head first) is the new motion's and stays. Bounded: at most the
/// ring's capacity.
fn discard(channel: &Channel, generation: u32) {
    for _ in 0..channel.segments.capacity() {
        if channel.segments.is_empty() || channel.geometry.generation() != generation {
            break;
        }
        if !matches!(channel.segments.pop(), Ok(Some(_))) {
            break;
        }
    }
}

/// The exported HAL function `nurbs_interp.update`.
unsafe extern "C" fn update(arg: *mut c_void, period: c_long) {
    // SAFETY: `arg` is the Instance exported with this function; HAL calls a non-reentrant
    // function from one thread at a time.
    let instance = &mut *(arg as *mut Instance);
    #[allow(clippy::useless_conversion)] // c_long is i32 on some targets
    instance.update(i64::from(period));
}

fn error(msg: &CStr) {
    sys::print_msg(sys::RTAPI_MSG_ERR, msg);
}

/// Create pins, channel and function on an initialised component. Returns 0 or -errno.
unsafe fn create(comp_id: c_int) -> c_int {
    let inst = sys::hal_malloc(core::mem::size_of::<Instance>() as c_long) as *mut Instance;
    if inst.is_null() {
        error(c"nurbs_interp: hal_malloc failed");
        return -ENOMEM;
    }
    let p = addr_of_mut!((*inst).pins);
    let (i, o) = (sys::HAL_IN, sys::HAL_OUT);
    let id = comp_id;
    let results = [
        Pin::create(addr_of_mut!((*p).enable), c"nurbs_interp.enable", i, id),
        Pin::create(addr_of_mut!((*p).hold), c"nurbs_interp.hold", i, id),
        Pin::create(addr_of_mut!((*p).abort), c"nurbs_interp.abort", i, id),
        Pin::create(addr_of_mut!((*p).resume), c"nurbs_interp.resume", i, id),
        Pin::create(addr_of_mut!((*p).pos_cmd_x), c"nurbs_interp.pos-cmd-x", o, id),
        Pin::create(addr_of_mut!((*p).pos_cmd_y), c"nurbs_interp.pos-cmd-y", o, id),
        Pin::create(addr_of_mut!((*p).pos_cmd_z), c"nurbs_interp.pos-cmd-z", o, id),
        Pin::create(addr_of_mut!((*p).feed), c"nurbs_interp.feed", o, id),
        Pin::create(addr_of_mut!((*p).u), c"nurbs_interp.u", o, id),
        Pin::create(addr_of_mut!((*p).curve), c"nurbs_interp.curve", o, id),
        Pin::create(addr_of_mut!((*p).active), c"nurbs_interp.active", o, id),
        Pin::create(addr_of_mut!((*p).done), c"nurbs_interp.done", o, id),
        Pin::create(addr_of_mut!((*p).fault), c"nurbs_interp.fault", o, id),
        Pin::create(addr_of_mut!((*p).fault_code), c"nurbs_interp.fault-code", o, id),
        Pin::create(addr_of_mut!((*p).underrun), c"nurbs_interp.underrun", o, id),
        Pin::create(addr_of_mut!((*p).underruns), c"nurbs_interp.underruns", o, id),
        Pin::create(addr_of_mut!((*p).records), c"nurbs_interp.records", o, id),
        Pin::create(addr_of_mut!((*p).seq), c"nurbs_interp.seq", o, id),
        Pin::create(addr_of_mut!((*p).buffered), c"nurbs_interp.buffered", o, id),
        Pin::create(addr_of_mut!((*p).resume_ready), c"nurbs_interp.resume-ready", o, id),
        Pin::create(addr_of_mut!((*p).held), c"nurbs_interp.held", o, id),
    ];
    if let Some(&rc) = results.iter().find(|&&rc| rc < 0) {
        error(c"nurbs_interp: pin export failed");
        return rc;
    }

    let shmem_id = sys::rtapi_shmem_new(CHANNEL_KEY, comp_id, Channel::SIZE as _);
    if shmem_id < 0 {
        error(c"nurbs_interp: rtapi_shmem_new failed");
        return shmem_id;
    }
    SHMEM_ID.store(shmem_id, Ordering::Relaxed);
    let mut block: *mut c_void = ptr::null_mut();
    let rc = sys::rtapi_shmem_getptr(shmem_id, &mut block);
    if rc < 0 || block.is_null() || (block as usize) & 63 != 0 {
        error(c"nurbs_interp: rtapi_shmem_getptr failed");
        return if rc < 0 { rc } else { -EINVAL };
    }
    // A block left by a previous instance (same key) is re-initialised: no planner is attached
    // before hal_ready.
    ptr::write_bytes(block as *mut u8, 0, Channel::SIZE);
    let channel = Channel::init(block as *mut u8);

    addr_of_mut!((*inst).channel).write(channel);
    addr_of_mut!((*inst).geometry).write(RtGeometry::empty());
    addr_of_mut!((*inst).validating).write(None);
    addr_of_mut!((*inst).interp).write(Interpolator::new());
    addr_of_mut!((*inst).next_seq).write(0);
    addr_of_mut!((*inst).record_stop).write(RecordStop::default());
    addr_of_mut!((*inst).points).write(StopPoints::NONE);
    addr_of_mut!((*inst).records).write(0);
    addr_of_mut!((*inst).underruns).write(0);
    addr_of_mut!((*inst).taken_time).write(0.0);
    addr_of_mut!((*inst).stopping).write(false);
    addr_of_mut!((*inst).stopped).write(false);
    addr_of_mut!((*inst).cause).write(StopCause::None);

    addr_of_mut!((*inst).aborted).write(false);
    addr_of_mut!((*inst).fault).write(FaultCode::None);
    addr_of_mut!((*inst).stops).write(0);
    addr_of_mut!((*inst).held).write(None);
    addr_of_mut!((*inst).awaiting_resume).write(false);
    addr_of_mut!((*inst).resuming).write(false);
    addr_of_mut!((*inst).resume_pin).write(false);
    addr_of_mut!((*inst).mode).write(Mode::Undecided);
    addr_of_mut!((*inst).player).write(BlockPlayer::IDLE);
    addr_of_mut!((*inst).period).write(0.0);

    let rc = sys::hal_export_funct(
        c"nurbs_interp.update".as_ptr(),
        Some(update),
        inst as *mut c_void,
        1,
        0,
        comp_id,
    );
    if rc < 0 {
        error(c"nurbs_interp: hal_export_funct failed");
        return rc;
    }
    0
}

/// RTAPI entry point, called by `loadrt nurbs_interp`.
///
/// # Safety
/// Called by rtapi_app once, from its main thread.
#[no_mangle]
pub unsafe extern "C" fn rtapi_app_main() -> c_int {
    let comp_id = sys::hal_init(NAME.as_ptr());
    if comp_id < 0 {
        error(c"nurbs_interp: hal_init failed");
        return comp_id;
    }
    COMP_ID.store(comp_id, Ordering::Relaxed);
    let rc = create(comp_id);
    if rc < 0 {
        rtapi_app_exit();
        return rc;
    }
    sys::hal_ready(comp_id)
}

/// RTAPI exit point, called by `unload nurbs_interp` after the function left every thread.
///
/// # Safety
/// Called by rtapi_app once, after `rtapi_app_main`.
#[no_mangle]
pub unsafe extern "C" fn rtapi_app_exit() {
    let comp_id = COMP_ID.swap(-1, Ordering::Relaxed);
    let shmem_id = SHMEM_ID.swap(-1, Ordering::Relaxed);
    if comp_id < 0 {
        return;
    }
    if shmem_id >= 0 {
        sys::rtapi_shmem_delete(shmem_id, comp_id);
    }
    sys::hal_exit(comp_id);
}
