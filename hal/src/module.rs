//! The realtime module `nurbs_interp`: `loadrt nurbs_interp`, then
//! `addf nurbs_interp.update servo-thread`.
//!
//! `rtapi_app_main` creates the component, its pins (all instance state lives in `hal_malloc`'d
//! memory, as in C components), the shared-memory [`Channel`] the planner writes to, and exports
//! `nurbs_interp.update`. [`Instance::update`] runs every servo period: it takes the curve
//! geometry once the planner has published it (validated with `CurveView::new`), drives the
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
//! Its deceleration and jerk come from the per-record stop table the planner published with the
//! geometry: the planner ran this very stop from every boundary, by finite differences on the
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
//! from 0) and stop table. The module takes it but does not move until the command: for a hold,
//! `hold` false; for an underrun, a rising edge on `resume` (with records queued:
//! `resume-ready`; `hold` must be false). Then it runs the new plan with a fresh interpolator,
//! whose first setpoint is the stop point, at rest, as in the planner's own check. The first
//! record must start at rest at exactly the held element, `u` and `s`, and its first sample must
//! be the held position (within [`RESUME_TOLERANCE`]); otherwise nothing moves and the module
//! faults ([`FaultCode::ResumePoint`]). `abort` while stopped ends the stopped motion (and
//! withdraws the stop point): the next geometry is a new motion from its own first record.

use core::ffi::{c_int, c_long, c_void, CStr};
use core::ptr::{self, addr_of_mut};
use core::sync::atomic::{AtomicI32, Ordering};

use nurbs_rtcore::executor::{CurveSet, Interpolator, Sample, Step};
use nurbs_rtcore::CurveView;

use nurbs_rtcore::scurve::SCurveTable;

use crate::channel::{
    validate_geometry, Channel, CurveViews, GeometryHeader, StopPoint, ValidCurve, CHANNEL_KEY, MAX_CURVES,
};
use crate::pins::Pin;
use crate::record::{SegmentRecord, FLAG_LAST, PHASES};
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
    /// A record failed its structural check (non-finite, negative, inconsistent profile).
    Record = 4,
    /// A record's sequence number is not the next one (lost or repeated record).
    Sequence = 5,
    /// The interpolator refused a record (curve index without a curve).
    BadRecord = 6,
    /// After a stop, the first record of the resumed motion does not start at rest
    /// exactly where the machine stands (element, parameter, position): refused, position held.
    ResumePoint = 7,
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

/// The accepted curve geometry: views into the channel's arena, validated once.
#[derive(Clone, Copy)]
pub struct RtGeometry {
    /// Generation of the channel geometry these views were made from (0: none).
    generation: u32,
    count: usize,
    tip: usize,
    stop_accel: f64,
    stop_jerk: f64,
    /// `(accel, jerk)` of the stop after each record, by sequence number.
    stop_table: &'static [f64],
    views: CurveViews<'static>,
}

impl RtGeometry {
    const EMPTY: RtGeometry = RtGeometry {
        generation: 0,
        count: 0,
        tip: 2,
        stop_accel: 0.0,
        stop_jerk: 0.0,
        stop_table: &[],
        views: [None; MAX_CURVES],
    };

    fn is_valid(&self) -> bool {
        self.generation != 0
    }

    /// Deceleration and jerk of the stop after record `seq`.
    fn stop_limits(&self, seq: u32) -> (f64, f64) {
        let i = (seq as usize).saturating_mul(2);
        match (self.stop_table.get(i), self.stop_table.get(i.saturating_add(1))) {
            (Some(&a), Some(&j)) => (a, j),
            _ => (self.stop_accel, self.stop_jerk),
        }
    }
}

impl CurveSet for RtGeometry {
    fn curve(&self, index: usize) -> Option<CurveView<'_>> {
        if index < self.count {
            self.views.get(index).copied().flatten().map(|c| c.view)
        } else {
            None
        }
    }
    fn tip_axes(&self) -> usize {
        self.tip
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
    interp: Interpolator,
    /// Sequence number the next record must carry.
    next_seq: u32,
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

/// The stop the module runs after `last` on `curve`: deceleration `accel` and jerk `jerk`,
/// compressed in time just enough to pass every stop point of the curve (the planner's critical
/// points, corners, the curve end) no faster than its feed cap. Bounded work: one pass over the
/// curve's stop points, a 60-step bisection for each one the stop reaches too fast.
pub fn underrun_stop(curve: Option<ValidCurve>, last: &SegmentRecord, accel: f64, jerk: f64) -> SegmentRecord {
    let nominal = stop_record(last, accel, jerk, 1.0);
    let table = nominal.profile().table();
    let (v0, s0, reach) = (nominal.feed_start, nominal.s_start, nominal.length);
    let mut k = 1.0f64;
    for pair in curve.map_or(&[][..], |c| c.stops).chunks_exact(2) {
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

impl Instance {
    /// One servo period. `period_ns` is the thread's period.
    pub fn update(&mut self, period_ns: i64) {
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
        let started = self.interp.record().is_some();
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
        if self.fault == FaultCode::None && (self.stopped || self.aborted || self.interp.is_finished()) {
            // Over: what is still queued (or comes) belongs to a motion that will not run, and
            // an empty ring tells a new planner that it may publish.
            discard(channel, self.geometry.generation);
        }
        let pins = &self.pins;
        pins.active.set(active);
        pins.done.set(self.interp.is_finished());
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
            (channel.planned_time() - self.taken_time).max(0.0) + self.interp.time_left_in_segment()
        };
        pins.buffered.set(buffered);
    }

    /// A motion is loaded and may still move (not finished, aborted or stopped).
    fn in_motion(&self) -> bool {
        self.interp.record().is_some() && !self.interp.is_finished() && !self.aborted && !self.stopped
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
        let Some((generation, header, values)) = channel.geometry.snapshot() else {
            return;
        };
        self.geometry.generation = 0;
        match validate_geometry(&header, values, &mut self.geometry.views) {
            Ok(table) if channel.geometry.unchanged(generation) => {
                self.geometry.stop_table = table;
                self.set_geometry(generation, &header);
            }
            Ok(_) => {} // rewritten while validating: again next period
            Err(_) if !channel.geometry.unchanged(generation) => {}
            Err(_) => self.fault = FaultCode::Geometry,
        }
    }

    fn set_geometry(&mut self, generation: u32, header: &GeometryHeader) {
        let g = &mut self.geometry;
        g.count = header.curve_count as usize;
        g.tip = header.tip_axes as usize;
        g.stop_accel = header.stop_accel;
        g.stop_jerk = header.stop_jerk;
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
        self.next_seq = 0;
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
        let mut pull = Pull::Fine;
        let step = {
            let ring = &channel.segments;
            let no_more = self.stopping || hold || abort;
            let resume_from = if self.resuming { self.held } else { None };
            let next_seq = &mut self.next_seq;
            let records = &mut self.records;
            let taken_time = &mut self.taken_time;
            let pins = &self.pins;
            let mut next = || -> Option<SegmentRecord> {
                if no_more || pull != Pull::Fine {
                    return None;
                }
                match ring.pop() {
                    Ok(Some(r)) if r.seq != *next_seq => {
                        pull = Pull::Fault(FaultCode::Sequence);
                        None
                    }
                    Ok(Some(r)) if resume_from.is_some_and(|h| !starts_at(&r, &h)) => {
                        pull = Pull::Fault(FaultCode::ResumePoint);
                        None
                    }
                    Ok(Some(r)) => match check_record(&r) {
                        Ok(()) => {
                            *next_seq = r.seq.wrapping_add(1);
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
                    // The stop is over: at rest.
                    self.stopped = true;
                    if self.cause == StopCause::Abort {
                        self.end_motion(channel);
                    } else {
                        self.publish_stop(channel, last.seq);
                    }
                    return false;
                }
                self.stopping = true;
                self.cause = if abort {
                    StopCause::Abort
                } else if hold {
                    StopCause::Hold
                } else {
                    self.underruns = self.underruns.wrapping_add(1);
                    StopCause::Underrun
                };
                let curve = self.geometry.views.get(last.curve()).copied().flatten();
                let (accel, jerk) = self.geometry.stop_limits(last.seq);
                let mut stop = Some(underrun_stop(curve, &last, accel, jerk));
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

    /// The axis positions the module outputs for `s`.
    fn point_of(&self, s: &Sample) -> [f64; 3] {
        let [x, y, z, ..] = s.point;
        [x, y, if self.geometry.tip >= 3 { z } else { 0.0 }]
    }

    /// At rest after a hold or underrun stop: remember where, and tell the planner.
    fn publish_stop(&mut self, channel: &Channel, seq: u32) {
        let c = *self.interp.cursor();
        let [x, y, z, ..] = c.point;
        let held = Held {
            curve: self.interp.curve_index(),
            u: c.u,
            s: c.s,
            point: [x, y, if self.geometry.tip >= 3 { z } else { 0.0 }],
        };
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
    addr_of_mut!((*inst).geometry).write(RtGeometry::EMPTY);
    addr_of_mut!((*inst).interp).write(Interpolator::new());
    addr_of_mut!((*inst).next_seq).write(0);
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
