//! The realtime module `nurbs_interp`: `loadrt nurbs_interp`, then
//! `addf nurbs_interp.update servo-thread` (after `motion-controller` in a LinuxCNC machine,
//! with `nurbs_interp.feedback` before it: the hand-over, [`nurbs_rtcore::handover`]).
//!
//! `rtapi_app_main` creates the component, its pins (all instance state lives in `hal_malloc`'d
//! memory, as in C components), the shared-memory [`Channel`] the planner writes to, and exports
//! `nurbs_interp.update`. [`Instance::update`] runs every servo period: it follows the geometry
//! stream the planner publishes (checking each curve once, in path order, a slice of values
//! per period), drives the `nurbs_rtcore` [`Interpolator`] with the segment records it pops
//! from the channel (S-curve feed, RK2 predictor-corrector step of the curve parameter, NURBS
//! evaluation) and writes the output pins. It never allocates, locks, calls the OS or panics
//! (no indexing that can fail); failures are pins (fault, fault-code, underrun), not errors.
//!
//! Its pins, fault codes and the stop and resume protocol, for integrators:
//! `docs/integration.md` and `man nurbs_interp`, both rendered from [`PINS`].
//!
//! Every stop is a planned stop. Segment records come in groups ([`SegmentSlot`]), and the
//! last record of a group carries the stop after it: the next segment re-planned by the planner
//! to end at rest, checked by finite differences like every segment of the plan and with the
//! machine holding at its end. The module takes the first record of a group only once the whole
//! group is queued on checked curves; so an underrun (the next group is not there in time) stops
//! at a group's end, with that stop, through the same interpolator: no jump, within the axis
//! limits by the planner's own check, and no stop checks of its own. A hold or abort need not
//! wait for the group's end: records also carry stops the planner checked inside them (every
//! 20 samples where one passes, `nurbs_planner::hold_stops`), each an S-curve to rest from the
//! exact sample it starts at, which the module builds with the same function
//! ([`stop_record`]) at that sample. A hold during the last group with no such stop left lets
//! the motion end at C(1). Afterwards the module holds that position; records arriving later
//! are not run (they were planned from a feed the machine no longer has).
//!
//! Resume (after a hold or an underrun): at rest, the module publishes where it stands in the
//! channel ([`crate::channel::StopStatus`]: cause, element, parameter `u`, arc length `s`,
//! position, the last record's sequence number). A planner (the running `nurbs-planner`, or one
//! started afterwards) plans the rest of the path from rest at exactly that point
//! (`PlanOptions::start`) and publishes it as a new geometry stream with its own records
//! (sequence from 0). The module takes it but does not move until the command: for a hold,
//! `hold` false; for an underrun, a rising edge on `resume` (with records queued:
//! `resume-ready`; `hold` must be false). Then it runs the new plan with a fresh interpolator,
//! whose first setpoint is the stop point, at rest, as in the planner's own check. The first
//! record must start at rest at exactly the held element, `u` and `s` (or at the start of the
//! next element when the machine stands at its element's end), and its first sample must be
//! the held position (within [`RESUME_TOLERANCE`]); otherwise nothing moves and the module
//! faults ([`FaultCode::ResumePoint`]). `abort` while stopped ends the stopped motion (and
//! withdraws the stop point): the next geometry is a new motion from its own first record.

// The update path must not panic: no unwrap, expect, panic or indexing that can fail.
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing)]

use core::cell::Cell;
use core::ffi::{c_int, c_long, c_void, CStr};
use core::ptr::{self, addr_of_mut};
use core::sync::atomic::{AtomicI32, Ordering};

use nurbs_rtcore::block_stop::{block_stop, step_fits, stop_record, StopStart};
use nurbs_rtcore::handover::{self, Handover};
use nurbs_rtcore::interpolator::{CurveSet, Interpolator, Sample, Step};
use nurbs_rtcore::{CurveView, StopRun};

use crate::channel::{
    check_curve, period_matches, stop_points, trusted_curve, validate_header, Channel, GeometryHeader, GeometryStream,
    Report, StopPoint, ValueCursor, AT_RECORD_END, CHANNEL_KEY, SPLICE_ACCEPTED, SPLICE_MISSED,
};
use crate::pins::Pin;
use crate::slot::{PathBlock, Record, SegmentRecord, SegmentSlot, KIND_BLOCK};
use crate::sys;

mod blocks;
mod geometry;
mod segments;

use blocks::BlockPlayer;
use geometry::Followed;
pub use geometry::RtGeometry;
use segments::SegmentPlayer;

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
    /// A new geometry stream began while a motion was running.
    GeometryChanged = 3,
    /// A record failed its structural check (non-finite, negative, inconsistent profile, a stop
    /// that is not a record ending at rest after it, or group fields that do not fit).
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
    /// The interpolator produced a position, feed or parameter that is not a finite number (a
    /// record that does not fit its curve): not written, the last position held.
    NonFinite = 10,
    /// The geometry stream was planned for another servo period than the thread's: its samples
    /// would run faster or slower than planned, so nothing of it is taken.
    Period = 11,
}

crate::declare_pins! { "nurbs_interp", Pins, PINS,
    enable: bool, In, "enable", "",
        "run; when false nothing advances and the outputs hold (an immediate freeze: use `hold` to stop a moving machine)";
    hold: bool, In, "hold", "",
        "feed hold: the planner's next checked stop to rest on the path (inside the record, every 5 ms where one passes, else at the end of the group); released, the plan from the stop point runs";
    feed_override: f64, In, "feed-override", "",
        "the operator's feed override (wire `halui.feed-override.value`, also to `nurbs-planner.feed-override`, which plans for it); 0 or less holds as `hold` does; 1 when unconnected";
    abort: bool, In, "abort", "",
        "stop as for hold, then discard the queue; the motion is over until a planner begins a new stream";
    resume: bool, In, "resume", "",
        "after an underrun stop: a rising edge starts the plan from the stop point once one is queued (`resume-ready`); an edge without it is ignored";
    pos_cmd_x: f64, Out, "pos-cmd-x", "mm", "X position command";
    pos_cmd_y: f64, Out, "pos-cmd-y", "mm", "Y position command";
    pos_cmd_z: f64, Out, "pos-cmd-z", "mm", "Z position command (0 on a 2-D path)";
    feed: f64, Out, "feed", "mm/s", "path feed at this sample";
    u: f64, Out, "u", "", "curve parameter";
    curve: u32, Out, "curve", "", "index of the path element (curve)";
    active: bool, Out, "active", "", "a new sample was produced this period";
    done: bool, Out, "done", "", "the last segment has been completed (at rest at its end)";
    fault: bool, Out, "fault", "",
        "malformed channel, geometry or record, or a resumed plan that does not start where the machine stands; latched, outputs hold";
    fault_code: u32, Out, "fault-code", "", "why (the fault codes below)";
    underrun: bool, Out, "underrun", "",
        "the planner fell behind; the module stops or stopped on the path; set until the resumed motion starts (or an abort)";
    underruns: u32, Out, "underruns", "", "underrun stops so far";
    records: u32, Out, "records", "", "records taken so far";
    seq: u32, Out, "seq", "", "sequence number of the last record taken";
    buffered: f64, Out, "buffered", "s", "motion time queued ahead of the current sample";
    resume_ready: bool, Out, "resume-ready", "",
        "stopped (hold or underrun) and a plan from the stop point is queued: releasing `hold` / a `resume` edge starts it";
    held: bool, Out, "held", "", "at rest on the path after a stop (hold, underrun or abort), not moving";
    path_ready: bool, Out, "path-ready", "",
        "a motion is loaded and has not started: `pos-cmd-*` show its start (where the machine must stand to engage)";
    path_3d: bool, Out, "path-3d", "", "the loaded path drives Z (a 2-D path leaves joint 2 to motion)";
    engage: bool, In, "engage", "",
        "hand-over: take the drives (at rest, our start within 1e-6 mm of `joint.N.pos-cmd`); false: give them back once every offset is within 1e-6 mm and motion stands still";
    machine_on: bool, In, "machine-on", "",
        "hand-over: `motion.motion-enabled`; off while engaged releases at once (drives follow their feedback) and ends our motion where it stands";
    engaged: bool, Out, "engaged", "",
        "hand-over: the drives follow our path (wire to `enable`: the path moves only while engaged)";
    handover_refused: u32, Out, "handover-refused", "",
        "hand-over: why `engage` (or its release) is not carried out: 0 none, 1 machine off (or switched off since the request: `engage` must go false first), 2 no path loaded, 3 not at rest, 4 our start is elsewhere, 5 offset left (release)";
    j0_pos_cmd: f64, In, "joint.0.pos-cmd", "mm", "hand-over: motion's `joint.0.pos-cmd` (X)";
    j0_motor_pos_cmd: f64, In, "joint.0.motor-pos-cmd", "mm", "hand-over: motion's `joint.0.motor-pos-cmd`";
    j0_drive_fb: f64, In, "joint.0.drive-fb", "mm", "hand-over: the drive's position feedback (motor coordinates)";
    j0_drive_cmd: f64, Out, "joint.0.drive-cmd", "mm",
        "hand-over: to the drive: `motor-pos-cmd`, plus our position less motion's while engaged";
    j0_motor_pos_fb: f64, Out, "joint.0.motor-pos-fb", "mm",
        "hand-over: to motion's `joint.0.motor-pos-fb`: `drive-fb`, less our position less motion's while engaged";
    j0_offset: f64, Out, "joint.0.offset", "mm", "hand-over: our position less motion's `pos-cmd` while engaged, else 0";
    j1_pos_cmd: f64, In, "joint.1.pos-cmd", "mm", "hand-over: motion's `joint.1.pos-cmd` (Y)";
    j1_motor_pos_cmd: f64, In, "joint.1.motor-pos-cmd", "mm", "hand-over: motion's `joint.1.motor-pos-cmd`";
    j1_drive_fb: f64, In, "joint.1.drive-fb", "mm", "hand-over: the drive's position feedback (motor coordinates)";
    j1_drive_cmd: f64, Out, "joint.1.drive-cmd", "mm",
        "hand-over: to the drive: `motor-pos-cmd`, plus our position less motion's while engaged";
    j1_motor_pos_fb: f64, Out, "joint.1.motor-pos-fb", "mm",
        "hand-over: to motion's `joint.1.motor-pos-fb`: `drive-fb`, less our position less motion's while engaged";
    j1_offset: f64, Out, "joint.1.offset", "mm", "hand-over: our position less motion's `pos-cmd` while engaged, else 0";
    j2_pos_cmd: f64, In, "joint.2.pos-cmd", "mm", "hand-over: motion's `joint.2.pos-cmd` (Z)";
    j2_motor_pos_cmd: f64, In, "joint.2.motor-pos-cmd", "mm", "hand-over: motion's `joint.2.motor-pos-cmd`";
    j2_drive_fb: f64, In, "joint.2.drive-fb", "mm", "hand-over: the drive's position feedback (motor coordinates)";
    j2_drive_cmd: f64, Out, "joint.2.drive-cmd", "mm",
        "hand-over: to the drive: `motor-pos-cmd`, plus our position less motion's while engaged";
    j2_motor_pos_fb: f64, Out, "joint.2.motor-pos-fb", "mm",
        "hand-over: to motion's `joint.2.motor-pos-fb`: `drive-fb`, less our position less motion's while engaged";
    j2_offset: f64, Out, "joint.2.offset", "mm", "hand-over: our position less motion's `pos-cmd` while engaged, else 0";
}

/// Where the machine stands after a hold or underrun stop (what a resumed plan must start from).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Held {
    pub curve: usize,
    pub u: f64,
    pub s: f64,
    pub point: [f64; 3],
    /// At the end of its curve (not the path's last): a plan from here starts on the next one.
    pub at_curve_end: bool,
}

impl Held {
    /// Whether a plan from rest at element `curve`, parameter `u` and arc length `s` starts
    /// exactly here: the same element, `u` and `s`, or at the end of the element the start
    /// (arc length 0) of the next.
    fn is_at(&self, curve: usize, u: f64, s: f64) -> bool {
        let here = curve == self.curve && u == self.u && s == self.s;
        here || (self.at_curve_end && curve == self.curve.wrapping_add(1) && s == 0.0)
    }
}

/// Checks of curve values (knots, coordinates and weights once, interior knots once more) the
/// module runs per period on the curves of the geometry stream (a few microseconds), within a
/// curve if it is larger ([`check_curve`]).
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
    interp: Interpolator,
    /// Sequence number the next record must carry.
    next_seq: u32,
    /// A segment-record motion: the record it runs, its stop chain.
    segment_player: SegmentPlayer,
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
    /// Servo period of the current update (s, and as the thread gives it, ns).
    period: f64,
    period_ns: i64,
    /// A path-block motion: the block being output, its stop points.
    block_player: BlockPlayer,
    /// The position pins hold a position of the path (its start, shown before the motion, or
    /// the last sample).
    position_known: bool,
    /// The current stream's start is on the position pins (or the motion has started).
    start_shown: bool,
    /// Between motion's joints and the drives.
    handover: Handover,
}

/// The record kind of a motion.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Undecided = 0,
    Segments = 1,
    Blocks = 2,
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

impl Instance {
    /// One servo period. `period_ns` is the thread's period.
    pub fn update(&mut self, period_ns: i64) {
        self.period = period_ns as f64 / 1e9;
        self.period_ns = period_ns;
        // SAFETY: the channel block stays mapped until rtapi_app_exit, after the last period.
        let channel: &'static Channel = unsafe { &*self.channel };
        if self.fault == FaultCode::None && channel.check().is_err() {
            self.fault = FaultCode::Channel;
        }
        if self.fault == FaultCode::None {
            self.follow_geometry(channel);
        }
        // A feed override of 0 (or a value that is not a number) is a hold.
        let feed_override = self.pins.feed_override.get();
        let stopped_by_override = feed_override.is_nan() || feed_override <= 0.0;
        let (hold, abort) = (self.pins.hold.get() || stopped_by_override, self.pins.abort.get());
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
        self.answer_splice(channel, hold || abort);
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
                self.block_player.remaining() as f64 * period_ns as f64 / 1e9
            } else {
                self.interp.time_left_in_segment()
            };
            (channel.planned_time() - self.taken_time).max(0.0) + left
        };
        pins.buffered.set(buffered);
        channel.progress.report(Report {
            generation: self.geometry.generation,
            moving: self.in_motion(),
            curve: u32::try_from(self.current_curve()).unwrap_or(u32::MAX),
        });
        self.show_start();
        self.hand_over(channel);
    }

    /// The planner asks to join a plan at another feed override ([`crate::channel::Splice`]):
    /// accepted while a segment motion runs on undisturbed (no stop begun or asked for) and the
    /// record `after` is the one running or one queued, with `drop_to` beyond it within the
    /// queue, and the join is at its end where it ends a group, or cuts into it at a sample still
    /// ahead that has a checked hold stop; otherwise missed. An accepted join the motion stops
    /// before is missed too.
    fn answer_splice(&mut self, channel: &Channel, stop_asked: bool) {
        let running = self.mode == Mode::Segments
            && self.fault == FaultCode::None
            && self.in_motion()
            && !self.stopping
            && !stop_asked
            && !self.awaiting_resume;
        if channel.splice.accepted().is_some() && !running {
            channel.splice.answer(SPLICE_MISSED);
        }
        let Some(join) = channel.splice.requested() else {
            return;
        };
        let ring = channel.segments.consumer();
        let (taken, queued) = (ring.taken(), ring.len() as u32);
        // Places after the oldest queued record: -1 is the record running.
        let at = join.after.wrapping_sub(taken) as i32;
        let drop_at = join.drop_to.wrapping_sub(taken) as i32;
        let slot = match at {
            -1 => Some(self.segment_player.slot),
            i if i >= 0 && (i as u32) < queued => match ring.peek_at(i as u32).map(|s| s.and_then(|s| s.decode())) {
                Ok(Some(Record::Segment(slot))) => Some(slot),
                _ => None,
            },
            _ => None,
        };
        let place_ok = slot.is_some_and(|slot| {
            if join.at_sample == AT_RECORD_END {
                slot.group_left == 1
            } else {
                // A cut at a sample still ahead that has a checked hold stop: the stop the
                // motion takes there should the new plan not be in the ring by then.
                let ahead = at >= 0 || self.segment_player.samples <= join.at_sample;
                ahead
                    && matches!(
                        segments::hold_stop_at(&slot, self.geometry.values(), join.at_sample),
                        Ok(Some(_))
                    )
            }
        });
        let ok = running && place_ok && at < drop_at && drop_at >= 0 && drop_at as u32 <= queued;
        channel.splice.answer(if ok { SPLICE_ACCEPTED } else { SPLICE_MISSED });
    }

    /// Before the motion starts, its start on the position pins: where the machine must stand
    /// for the hand-over to engage (a G-code program reads it with `M66`).
    fn show_start(&mut self) {
        let waiting = self.fault == FaultCode::None
            && self.geometry.is_valid()
            && !self.started()
            && !self.aborted
            && !self.awaiting_resume;
        if waiting && !self.start_shown {
            let first = self.geometry.header.first_curve as usize;
            let start = self.geometry.valid(first).map(|view| view.u_min());
            if let Some(point) = start.and_then(|u| self.interp.point_at(&self.geometry, first, u)) {
                let sample = Sample {
                    curve: first,
                    u: start.unwrap_or(0.0),
                    s: 0.0,
                    point,
                    feed: 0.0,
                    accel: 0.0,
                };
                self.start_shown = self.output(&sample);
            }
        }
        self.pins
            .path_ready
            .set(waiting && self.start_shown && self.fault == FaultCode::None);
        self.pins.path_3d.set(self.geometry.tip >= 3);
    }

    /// The first half of the hand-over, before motion runs: its feedback from the drives'.
    pub fn feedback(&self) {
        let pins = &self.pins;
        let drive_fb = [pins.j0_drive_fb.get(), pins.j1_drive_fb.get(), pins.j2_drive_fb.get()];
        let [f0, f1, f2] = self.handover.motor_pos_fb(&drive_fb);
        pins.j0_motor_pos_fb.set(f0);
        pins.j1_motor_pos_fb.set(f1);
        pins.j2_motor_pos_fb.set(f2);
    }

    /// The second half of the hand-over between motion's joints and the drives
    /// ([`nurbs_rtcore::handover`]); the machine switched off while engaged ends our motion
    /// where it stands.
    fn hand_over(&mut self, channel: &Channel) {
        let pins = &self.pins;
        let ours = [pins.pos_cmd_x.get(), pins.pos_cmd_y.get(), pins.pos_cmd_z.get()];
        let inputs = handover::Inputs {
            engage: pins.engage.get(),
            machine_on: pins.machine_on.get(),
            ours: self.position_known.then_some(ours),
            driven: [true, true, self.geometry.tip >= 3],
            ours_at_rest: !self.in_motion(),
            pos_cmd: [pins.j0_pos_cmd.get(), pins.j1_pos_cmd.get(), pins.j2_pos_cmd.get()],
            motor_pos_cmd: [
                pins.j0_motor_pos_cmd.get(),
                pins.j1_motor_pos_cmd.get(),
                pins.j2_motor_pos_cmd.get(),
            ],
            drive_fb: [pins.j0_drive_fb.get(), pins.j1_drive_fb.get(), pins.j2_drive_fb.get()],
        };
        let out = self.handover.step(&inputs);
        let [c0, c1, c2] = out.drive_cmd;
        let [o0, o1, o2] = out.offset;
        pins.j0_drive_cmd.set(c0);
        pins.j1_drive_cmd.set(c1);
        pins.j2_drive_cmd.set(c2);
        pins.j0_offset.set(o0);
        pins.j1_offset.set(o1);
        pins.j2_offset.set(o2);
        pins.engaged.set(out.engaged);
        pins.handover_refused.set(out.refused as u32);
        if out.machine_off && (self.geometry.is_valid() && !self.aborted) {
            // The drives are off: nothing of this motion may run when they come back.
            self.end_motion(channel);
        }
    }

    /// The first curve the motion may still use: the one it is on.
    fn current_curve(&self) -> usize {
        let first = self.geometry.header.first_curve as usize;
        match self.mode {
            Mode::Blocks if self.block_player.loaded => self.block_player.curve,
            Mode::Segments if self.interp.record().is_some() => self.interp.curve_index(),
            _ => first,
        }
    }

    /// A motion is loaded and may still move (not finished, aborted or stopped).
    fn in_motion(&self) -> bool {
        self.started() && !self.finished() && !self.aborted && !self.stopped
    }

    /// The motion has taken its first record (of either kind).
    fn started(&self) -> bool {
        self.interp.record().is_some() || self.block_player.loaded
    }

    /// The motion has reached the path end.
    fn finished(&self) -> bool {
        match self.mode {
            Mode::Blocks => self.block_player.finished,
            _ => self.interp.is_finished(),
        }
    }

    /// Follows the geometry stream: a new one starts a new motion (only while none runs, else a
    /// fault); the curves of the current one are checked a slice per period.
    fn follow_geometry(&mut self, channel: &'static Channel) {
        let in_motion = self.in_motion();
        match self.geometry.follow(&channel.geometry, in_motion, self.period_ns) {
            Ok(Followed::New) => self.start_stream(),
            Ok(Followed::Same) => {}
            Err(code) => self.fault = code,
        }
    }

    /// A new geometry stream has been taken: a new motion (after a stop on the path, the plan
    /// from the stop point, which waits for the command and must start there).
    fn start_stream(&mut self) {
        if self.held.is_some() && (self.stopped || self.awaiting_resume) && !self.aborted {
            self.awaiting_resume = true;
        } else {
            self.held = None;
            self.awaiting_resume = false;
            self.cause = StopCause::None;
        }
        self.resuming = false;
        self.interp = Interpolator::new();
        self.mode = Mode::Undecided;
        self.block_player = BlockPlayer::IDLE;
        self.next_seq = 0;
        self.segment_player = SegmentPlayer::default();
        self.taken_time = 0.0;
        self.stopping = false;
        self.stopped = false;
        self.aborted = false;
        self.start_shown = false;
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
            match channel.segments.consumer().peek() {
                Ok(Some(slot)) if slot.kind == KIND_BLOCK => self.mode = Mode::Blocks,
                Ok(Some(_)) => self.mode = Mode::Segments,
                Ok(None) => return false,
                Err(_) => {
                    self.fault = FaultCode::Channel;
                    return false;
                }
            }
        }
        if let (true, Some(cursor)) = (self.stopping, self.block_player.stored) {
            return self.advance_stored_stop(channel, cursor);
        }
        if self.mode == Mode::Blocks {
            return self.advance_blocks(channel, dt, hold, abort);
        }
        self.advance_segments(channel, dt, hold, abort)
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
        self.held_at(
            self.interp.curve_index(),
            c.u,
            c.s,
            [x, y, if self.geometry.tip >= 3 { z } else { 0.0 }],
        )
    }

    /// The machine at rest at `point`, element `curve`, parameter `u`, arc length `s`.
    fn held_at(&self, curve: usize, u: f64, s: f64, point: [f64; 3]) -> Held {
        let at_curve_end = self.geometry.valid(curve).is_some_and(|v| u >= v.u_max());
        Held {
            curve,
            u,
            s,
            point,
            at_curve_end,
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
            point: core::array::from_fn(|i| held.point.get(i).copied().unwrap_or(0.0)),
        });
    }

    /// Writes sample `s` to the pins; a sample that is not finite is not written (the outputs
    /// hold their last position) and faults the module. Whether it was written.
    fn output(&mut self, s: &Sample) -> bool {
        let [x, y, z] = self.point_of(s);
        if !(x.is_finite() && y.is_finite() && z.is_finite() && s.feed.is_finite() && s.u.is_finite()) {
            self.fault = FaultCode::NonFinite;
            return false;
        }
        self.position_known = true;
        let pins = &self.pins;
        pins.pos_cmd_x.set(x);
        pins.pos_cmd_y.set(y);
        pins.pos_cmd_z.set(z);
        pins.feed.set(s.feed);
        pins.u.set(s.u);
        pins.curve.set(s.curve as u32);
        true
    }
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    libm::sqrt(dx * dx + dy * dy + dz * dz)
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
        if !matches!(channel.segments.consumer().pop(), Ok(Some(_))) {
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

/// The exported HAL function `nurbs_interp.feedback` (before `motion-controller`).
unsafe extern "C" fn feedback(arg: *mut c_void, _period: c_long) {
    // SAFETY: as in `update`; the two functions run on the same thread, one after the other.
    let instance = &*(arg as *const Instance);
    instance.feedback();
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
    let rc = Pins::create(addr_of_mut!((*inst).pins), comp_id);
    if rc < 0 {
        error(c"nurbs_interp: pin export failed");
        return rc;
    }
    // Unconnected, the programmed feed (not a hold).
    (*inst).pins.feed_override.set(1.0);

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
    addr_of_mut!((*inst).interp).write(Interpolator::new());
    addr_of_mut!((*inst).next_seq).write(0);
    addr_of_mut!((*inst).segment_player).write(SegmentPlayer::default());
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
    addr_of_mut!((*inst).block_player).write(BlockPlayer::IDLE);
    addr_of_mut!((*inst).period).write(0.0);
    addr_of_mut!((*inst).period_ns).write(0);
    addr_of_mut!((*inst).position_known).write(false);
    addr_of_mut!((*inst).start_shown).write(false);
    addr_of_mut!((*inst).handover).write(Handover::new());

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
    let rc = sys::hal_export_funct(
        c"nurbs_interp.feedback".as_ptr(),
        Some(feedback),
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
