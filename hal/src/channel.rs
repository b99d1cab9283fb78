//! The shared-memory channel from the userspace planner to the realtime module.
//!
//! The realtime module creates one RTAPI shared-memory block ([`CHANNEL_KEY`], created in
//! `rtapi_app_main`, zeroed by RTAPI) and lays a [`Channel`] over it; the planner attaches to the
//! same key and checks the header before writing. The block holds a single-producer /
//! single-consumer ring of fixed-size tagged [`Slot`]s (a segment record with the stop after
//! it, or a [`crate::slot::PathBlock`]): the planner only advances `head`, the module only
//! advances `tail`, each with release ordering after touching a slot and acquire ordering
//! before reading the other side's counter. No locks, no syscalls, no allocation.
//!
//! After the ring comes the [`GeometryStream`]: the curves (knots, control points, weights) the
//! records refer to, streamed while the motion runs, so that a program of any length fits: a
//! ring of curve descriptors and an arena of values, both reused once the module has passed
//! what they held ([`Progress`]). The module checks every curve once, in path order, a slice of
//! values per period, and takes a record only on a checked curve; it refuses (fault, hold)
//! anything that does not validate.
//!
//! Why not `hal_stream`: it carries at most `HAL_STREAM_MAX_PINS` = 21 values per record, which
//! is less than one segment record, and curve geometry (knots, control points, weights:
//! variable size, possibly thousands of values) would have to be chopped into 21-value pieces
//! on a second stream. Our own block keeps one ABI-checked layout (magic, version, record size,
//! capacities) for both and grows without limits of HAL's.

// Reached from the update path: no unwrap, expect, panic or indexing that can fail.
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing)]

use core::cell::UnsafeCell;
use core::sync::atomic::{fence, AtomicU32, AtomicU64, Ordering};

use nurbs_rtcore::{CurveView, ValuesChecked};

pub use crate::slot::{PathBlock, Record, SegmentRecord, SegmentSlot, Slot};

/// RTAPI shared-memory key of the channel ("NRB0").
pub const CHANNEL_KEY: i32 = 0x4E52_4230;
/// "NRBS": written last by the creator, so a reader that sees it sees an initialised header.
pub const CHANNEL_MAGIC: u32 = 0x4E52_4253;
/// Layout version; bump on any change to [`Channel`], the record types or what the module
/// accepts in them (16: a stream states the servo period it was planned for).
pub const CHANNEL_VERSION: u32 = 16;
/// Slots in the record ring (a power of two). A group of records that share one stop goes into
/// the ring whole before the module takes its first record, so the longest group must fit.
pub const SEGMENT_SLOTS: usize = 8192;
/// Curve descriptors in flight (a power of two): curves published ahead of the module.
pub const CURVE_SLOTS: usize = 1 << 14;
/// Capacity of the geometry arena in `f64` values (32 MiB), reused as the motion goes on: the
/// curves ahead of the module (a G1 line takes 12 values, a rounded corner 27), and for path
/// blocks their curves' stop points and stored stop sequences.
pub const ARENA_VALUES: usize = 1 << 22;
/// Most joints a record may drive (5-axis machines; this build drives the tool tip only).
pub const MAX_JOINTS: usize = 5;

/// Why a channel cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelError {
    /// The creator has not initialised the block (yet).
    NotInitialised,
    /// The block was made by a different build (version, record size or capacity differ).
    Layout,
    /// The counters are inconsistent: more records in flight than slots.
    Corrupt,
    /// The ring is full (producer side only).
    Full,
}

/// Keeps the producer's and the consumer's counters on separate cache lines.
#[repr(C, align(64))]
struct CachePadded<T>(T);

/// A single-producer, single-consumer ring of `N` plain-data records in shared memory.
#[repr(C)]
pub struct SpscRing<T, const N: usize> {
    /// Records written so far (wrapping); only the producer stores it.
    head: CachePadded<AtomicU32>,
    /// Records read so far (wrapping); only the consumer stores it.
    tail: CachePadded<AtomicU32>,
    slots: [UnsafeCell<T>; N],
}

// SAFETY: a slot is written only by the producer while it is outside [tail, head) and read only
// by the consumer while it is inside; the release/acquire pairs on head and tail order the
// accesses. T is plain data (Copy).
unsafe impl<T: Copy + Send, const N: usize> Sync for SpscRing<T, N> {}

impl<T: Copy, const N: usize> SpscRing<T, N> {
    const MASK: u32 = {
        assert!(N.is_power_of_two() && N <= (1 << 31));
        (N - 1) as u32
    };

    /// Records waiting to be read.
    pub fn len(&self) -> usize {
        let head = self.head.0.load(Ordering::Acquire);
        let tail = self.tail.0.load(Ordering::Acquire);
        head.wrapping_sub(tail) as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub const fn capacity(&self) -> usize {
        N
    }

    /// The writing end (the planner's).
    pub fn producer(&self) -> Producer<'_, T, N> {
        Producer(self)
    }

    /// The reading end (the module's).
    pub fn consumer(&self) -> Consumer<'_, T, N> {
        Consumer(self)
    }

    /// Producer side: append one record, or `Full`.
    fn push(&self, record: &T) -> Result<(), ChannelError> {
        let head = self.head.0.load(Ordering::Relaxed);
        let tail = self.tail.0.load(Ordering::Acquire);
        let used = head.wrapping_sub(tail) as usize;
        if used > N {
            return Err(ChannelError::Corrupt);
        }
        if used == N {
            return Err(ChannelError::Full);
        }
        let slot = self
            .slots
            .get((head & Self::MASK) as usize)
            .ok_or(ChannelError::Corrupt)?;
        // SAFETY: the slot is outside [tail, head): the consumer does not read it.
        unsafe { slot.get().write_volatile(*record) };
        self.head.0.store(head.wrapping_add(1), Ordering::Release);
        Ok(())
    }

    /// Consumer side: a copy of the oldest record without taking it.
    fn peek(&self) -> Result<Option<T>, ChannelError> {
        let tail = self.tail.0.load(Ordering::Relaxed);
        let head = self.head.0.load(Ordering::Acquire);
        let used = head.wrapping_sub(tail) as usize;
        if used == 0 {
            return Ok(None);
        }
        if used > N {
            return Err(ChannelError::Corrupt);
        }
        let slot = self
            .slots
            .get((tail & Self::MASK) as usize)
            .ok_or(ChannelError::Corrupt)?;
        // SAFETY: the slot is inside [tail, head): the producer finished writing it.
        Ok(Some(unsafe { slot.get().read_volatile() }))
    }

    /// Consumer side: a copy of the record `i` places after the oldest, if it is queued.
    fn peek_at(&self, i: u32) -> Result<Option<T>, ChannelError> {
        let tail = self.tail.0.load(Ordering::Relaxed);
        let head = self.head.0.load(Ordering::Acquire);
        let used = head.wrapping_sub(tail) as usize;
        if used > N {
            return Err(ChannelError::Corrupt);
        }
        if i as usize >= used {
            return Ok(None);
        }
        let slot = self
            .slots
            .get((tail.wrapping_add(i) & Self::MASK) as usize)
            .ok_or(ChannelError::Corrupt)?;
        // SAFETY: the slot is inside [tail, head): the producer finished writing it.
        Ok(Some(unsafe { slot.get().read_volatile() }))
    }

    /// Consumer side: drop every record before count `n` (records read so far, wrapping); `n`
    /// must lie within the queue. O(1).
    fn skip_to(&self, n: u32) -> Result<(), ChannelError> {
        let tail = self.tail.0.load(Ordering::Relaxed);
        let head = self.head.0.load(Ordering::Acquire);
        if head.wrapping_sub(tail) as usize > N || n.wrapping_sub(tail) > head.wrapping_sub(tail) {
            return Err(ChannelError::Corrupt);
        }
        self.tail.0.store(n, Ordering::Release);
        Ok(())
    }

    /// Consumer side: take the oldest record. Never allocates, locks or panics.
    fn pop(&self) -> Result<Option<T>, ChannelError> {
        let record = self.peek()?;
        if record.is_some() {
            // Only the consumer stores `tail`: the value `peek` read is still current.
            let tail = self.tail.0.load(Ordering::Relaxed);
            self.tail.0.store(tail.wrapping_add(1), Ordering::Release);
        }
        Ok(record)
    }
}

/// The writing end of a ring: what the planner holds. Only one producer may exist per ring (the
/// planner that published the current geometry); the type keeps the two roles apart at every use.
#[derive(Clone, Copy)]
pub struct Producer<'a, T, const N: usize>(&'a SpscRing<T, N>);

impl<T: Copy, const N: usize> Producer<'_, T, N> {
    /// Append one record, or `Full`.
    pub fn push(&self, record: &T) -> Result<(), ChannelError> {
        self.0.push(record)
    }

    /// Records the consumer has not taken yet.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Records written so far (wrapping): the count the next one gets.
    pub fn pushed(&self) -> u32 {
        self.0.head.0.load(Ordering::Relaxed)
    }

    /// Records the consumer has read (or dropped) so far (wrapping).
    pub fn taken(&self) -> u32 {
        self.0.tail.0.load(Ordering::Acquire)
    }
}

/// The reading end of a ring: what the module holds (one consumer per ring).
#[derive(Clone, Copy)]
pub struct Consumer<'a, T, const N: usize>(&'a SpscRing<T, N>);

impl<T: Copy, const N: usize> Consumer<'_, T, N> {
    /// A copy of the oldest record without taking it.
    pub fn peek(&self) -> Result<Option<T>, ChannelError> {
        self.0.peek()
    }

    /// Take the oldest record. Never allocates, locks or panics.
    pub fn pop(&self) -> Result<Option<T>, ChannelError> {
        self.0.pop()
    }

    /// A copy of the record `i` places after the oldest, if it is queued.
    pub fn peek_at(&self, i: u32) -> Result<Option<T>, ChannelError> {
        self.0.peek_at(i)
    }

    /// Drop every record before count `n` (within the queue). O(1): no record is copied.
    pub fn skip_to(&self, n: u32) -> Result<(), ChannelError> {
        self.0.skip_to(n)
    }

    /// Records read (or dropped) so far (wrapping).
    pub fn taken(&self) -> u32 {
        self.0.tail.0.load(Ordering::Relaxed)
    }

    /// Records waiting to be read.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    pub const fn capacity(&self) -> usize {
        N
    }
}

/// The layout of the shared-memory block.
#[repr(C)]
pub struct Channel {
    magic: AtomicU32,
    version: AtomicU32,
    record_size: AtomicU32,
    segment_slots: AtomicU32,
    curve_slots: AtomicU32,
    arena_values: AtomicU32,
    /// Total motion time (s, `f64` bits) of the records the planner has pushed so far; with the
    /// time the module has taken, this gives the buffered motion time.
    planned_time: AtomicU64,
    /// Module → planner: where the module stands after a hold or underrun stop.
    pub stop: StopStatus,
    /// Module → planner: which curves it still needs.
    pub progress: Progress,
    /// Planner ⇄ module: a plan at another feed override joins the motion at a group end still
    /// queued.
    pub splice: Splice,
    /// Planner → module records (segments or path blocks).
    pub segments: SpscRing<Slot, SEGMENT_SLOTS>,
    /// Planner → module curve geometry.
    pub geometry: GeometryStream,
}

impl Channel {
    /// Bytes to request from `rtapi_shmem_new`.
    pub const SIZE: usize = core::mem::size_of::<Channel>();

    /// Creator side: initialise a zeroed block and publish it.
    ///
    /// # Safety
    /// `ptr` points to at least [`Channel::SIZE`] zeroed, 64-byte aligned bytes that stay mapped
    /// for `'a`, and no other party uses them before this returns.
    pub unsafe fn init<'a>(ptr: *mut u8) -> &'a Channel {
        let channel = &*(ptr as *const Channel);
        channel.segments.head.0.store(0, Ordering::Relaxed);
        channel.segments.tail.0.store(0, Ordering::Relaxed);
        channel.version.store(CHANNEL_VERSION, Ordering::Relaxed);
        channel
            .record_size
            .store(core::mem::size_of::<Slot>() as u32, Ordering::Relaxed);
        channel.segment_slots.store(SEGMENT_SLOTS as u32, Ordering::Relaxed);
        channel.curve_slots.store(CURVE_SLOTS as u32, Ordering::Relaxed);
        channel.arena_values.store(ARENA_VALUES as u32, Ordering::Relaxed);
        channel.planned_time.store(0, Ordering::Relaxed);
        channel.stop.clear();
        channel.splice.state.store(SPLICE_IDLE, Ordering::Relaxed);
        channel.progress.report(Report {
            generation: 0,
            moving: false,
            curve: 0,
        });
        channel.geometry.generation.store(0, Ordering::Relaxed);
        channel.geometry.published.store(0, Ordering::Relaxed);
        channel.magic.store(CHANNEL_MAGIC, Ordering::Release);
        channel
    }

    /// Attaching side: check that the block was initialised by a build with the same layout.
    ///
    /// # Safety
    /// `ptr` points to at least [`Channel::SIZE`] bytes, 64-byte aligned, mapped for `'a`.
    pub unsafe fn attach<'a>(ptr: *const u8) -> Result<&'a Channel, ChannelError> {
        let channel = &*(ptr as *const Channel);
        channel.check()?;
        Ok(channel)
    }

    /// Header check (also usable by the consumer each period: four relaxed loads).
    pub fn check(&self) -> Result<(), ChannelError> {
        if self.magic.load(Ordering::Acquire) != CHANNEL_MAGIC {
            return Err(ChannelError::NotInitialised);
        }
        let layout_ok = self.version.load(Ordering::Relaxed) == CHANNEL_VERSION
            && self.record_size.load(Ordering::Relaxed) as usize == core::mem::size_of::<Slot>()
            && self.segment_slots.load(Ordering::Relaxed) as usize == SEGMENT_SLOTS
            && self.curve_slots.load(Ordering::Relaxed) as usize == CURVE_SLOTS
            && self.arena_values.load(Ordering::Relaxed) as usize == ARENA_VALUES;
        if layout_ok {
            Ok(())
        } else {
            Err(ChannelError::Layout)
        }
    }
}

impl Channel {
    /// Producer side: total motion time (s) of all records pushed so far.
    pub fn set_planned_time(&self, seconds: f64) {
        self.planned_time.store(seconds.to_bits(), Ordering::Release);
    }

    pub fn planned_time(&self) -> f64 {
        f64::from_bits(self.planned_time.load(Ordering::Acquire))
    }
}

/// Where the module stopped (hold or underrun), at rest: the point a resumed plan must start
/// from (element, parameter and arc length as the module's interpolator holds them, and the
/// position it outputs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopPoint {
    /// Counts the module's stops (from 1): a planner re-plans once per stop.
    pub epoch: u32,
    /// Why it stopped: 1 underrun (resumes on a `resume` edge), 2 hold (resumes on release).
    pub cause: u32,
    /// Geometry generation of the motion that stopped.
    pub generation: u32,
    /// Sequence number of the last planned record the module ran.
    pub seq: u32,
    pub curve: u32,
    pub u: f64,
    pub s: f64,
    /// The position the module outputs there (the tool-tip axes first, then zeros).
    pub point: [f64; MAX_JOINTS],
}

/// Module → planner status: the [`StopPoint`] of the last stop, while the module waits
/// for a plan from there. Single writer (the module), seqlock-style: `epoch` is 0 while there is
/// nothing to resume from (or while the module writes), and is stored last with release.
#[repr(C)]
pub struct StopStatus {
    epoch: AtomicU32,
    cause: AtomicU32,
    generation: AtomicU32,
    seq: AtomicU32,
    curve: AtomicU32,
    u: AtomicU64,
    s: AtomicU64,
    point: [AtomicU64; MAX_JOINTS],
}

impl StopStatus {
    /// Module side: publish where it stands (`p.epoch` must be non-zero).
    pub fn publish(&self, p: &StopPoint) {
        self.epoch.store(0, Ordering::Relaxed);
        fence(Ordering::Release);
        self.cause.store(p.cause, Ordering::Relaxed);
        self.generation.store(p.generation, Ordering::Relaxed);
        self.seq.store(p.seq, Ordering::Relaxed);
        self.curve.store(p.curve, Ordering::Relaxed);
        self.u.store(p.u.to_bits(), Ordering::Relaxed);
        self.s.store(p.s.to_bits(), Ordering::Relaxed);
        for (slot, v) in self.point.iter().zip(p.point) {
            slot.store(v.to_bits(), Ordering::Relaxed);
        }
        self.epoch.store(p.epoch, Ordering::Release);
    }

    /// Module side: nothing to resume from (resumed, aborted, or a new motion).
    pub fn clear(&self) {
        self.epoch.store(0, Ordering::Release);
    }

    /// Planner side: the published stop point, if any (a consistent copy).
    pub fn read(&self) -> Option<StopPoint> {
        let epoch = self.epoch.load(Ordering::Acquire);
        if epoch == 0 {
            return None;
        }
        let f = |a: &AtomicU64| f64::from_bits(a.load(Ordering::Relaxed));
        let p = StopPoint {
            epoch,
            cause: self.cause.load(Ordering::Relaxed),
            generation: self.generation.load(Ordering::Relaxed),
            seq: self.seq.load(Ordering::Relaxed),
            curve: self.curve.load(Ordering::Relaxed),
            u: f(&self.u),
            s: f(&self.s),
            point: core::array::from_fn(|i| self.point.get(i).map_or(0.0, f)),
        };
        fence(Ordering::Acquire);
        (self.epoch.load(Ordering::Relaxed) == epoch).then_some(p)
    }
}

/// Where one curve's data lies in the geometry arena (physical offsets and lengths in `f64`
/// values) and which curve it is.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CurveDesc {
    /// Path element index of the curve (absolute; its descriptor slot is `index % CURVE_SLOTS`).
    pub index: u32,
    pub degree: u32,
    /// Coordinates per control point (2, 3, or 6 for a 5-axis tip + top curve).
    pub dim: u32,
    pub knots_offset: u32,
    pub knots_len: u32,
    pub points_offset: u32,
    pub points_len: u32,
    pub weights_offset: u32,
    pub weights_len: u32,
    pub reserved: u32,
}

/// What one geometry stream (one planned motion) is about; fixed while it runs.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GeometryHeader {
    /// Index of the first path element in the stream (0, or where a resumed plan starts).
    pub first_curve: u32,
    /// Tool-tip coordinates (2 or 3): the axes the module drives and the arc length measures.
    pub tip_axes: u32,
    /// Machine joints the records drive directly (0: the tool-tip axes; up to [`MAX_JOINTS`]
    /// is reserved for 5-axis paths, which this build refuses).
    pub joints: u32,
    /// The servo period (ns) the plan was made for: its limits hold when its samples are
    /// played at that period, so the module refuses a stream made for another one.
    pub period_ns: u32,
}

/// Why a geometry stream or one of its curves is refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeometryFault {
    /// A tip-axis count outside 2..=3, or joints (not supported by this build).
    Header,
    /// A descriptor that is not the curve it should be (slot reused, or never written).
    Descriptor { curve: usize },
    /// A curve's data lies (partly) outside the arena.
    OutOfBounds { curve: usize },
    /// A curve has fewer coordinates than the tip axes.
    Dimension { curve: usize },
    /// `CurveView::new` refused the curve.
    Curve {
        curve: usize,
        error: nurbs_rtcore::GeometryError,
    },
}

fn slice_of(values: &[f64], offset: u32, len: u32) -> Option<&[f64]> {
    let start = offset as usize;
    let end = start.checked_add(len as usize)?;
    values.get(start..end)
}

/// Checks a stream's header: 2 or 3 tip axes, no joints, a servo period.
pub fn validate_header(header: &GeometryHeader) -> Result<(), GeometryFault> {
    if !(2..=3).contains(&(header.tip_axes as usize)) || header.joints != 0 || header.period_ns == 0 {
        return Err(GeometryFault::Header);
    }
    Ok(())
}

/// Whether a plan made for `planned_ns` may run on a thread of period `thread_ns`: equal up to
/// the rounding of a period in seconds to whole nanoseconds (1 ns, or a millionth of the period,
/// the slack of the limit checks).
pub fn period_matches(planned_ns: u32, thread_ns: i64) -> bool {
    let slack = (thread_ns / 1_000_000).max(1).unsigned_abs();
    i64::from(planned_ns).abs_diff(thread_ns) <= slack
}

/// The knots, coordinates and weights of the curve `desc` describes, within `values` and with
/// at least `tip` coordinates (O(1)).
type CurveData<'a> = (&'a [f64], &'a [f64], &'a [f64]);
fn curve_data<'a>(desc: &CurveDesc, values: &'a [f64], tip: usize) -> Result<CurveData<'a>, GeometryFault> {
    let curve = desc.index as usize;
    let (Some(knots), Some(points), Some(weights)) = (
        slice_of(values, desc.knots_offset, desc.knots_len),
        slice_of(values, desc.points_offset, desc.points_len),
        slice_of(values, desc.weights_offset, desc.weights_len),
    ) else {
        return Err(GeometryFault::OutOfBounds { curve });
    };
    if (desc.dim as usize) < tip {
        return Err(GeometryFault::Dimension { curve });
    }
    Ok((knots, points, weights))
}

/// Where the check of one curve stands: the first value not yet checked (in the order of
/// [`CurveView::check_values`]).
pub type ValueCursor = usize;

/// Checks the curve `desc` describes from value `from` on ([`CurveView::check_values`]: knots,
/// coordinates and weights once, interior knots once more) until `budget` value checks are run:
/// a curve of a million control points is checked over many calls. Returns the checks run and
/// `None` once the curve is checked through, or the cursor to go on from. O(budget),
/// allocation-free and panic-free.
pub fn check_curve(
    desc: &CurveDesc,
    values: &[f64],
    tip: usize,
    from: ValueCursor,
    budget: usize,
) -> Result<(usize, Option<ValueCursor>), GeometryFault> {
    let (knots, points, weights) = curve_data(desc, values, tip)?;
    let curve = desc.index as usize;
    let (degree, dim) = (desc.degree as usize, desc.dim as usize);
    match CurveView::check_values(degree, dim, knots, points, weights, from, budget)
        .map_err(|error| GeometryFault::Curve { curve, error })?
    {
        ValuesChecked::UpTo(next) => Ok((budget, Some(next))),
        ValuesChecked::All => {
            let total = CurveView::value_checks(degree, knots, points, weights);
            Ok((total.saturating_sub(from).max(1), None))
        }
    }
}

/// The curve `desc` describes, checked in full (`CurveView::new`, O(size of the curve)).
/// Allocation-free and panic-free.
pub fn valid_curve<'a>(desc: &CurveDesc, values: &'a [f64], tip: usize) -> Result<CurveView<'a>, GeometryFault> {
    let (knots, points, weights) = curve_data(desc, values, tip)?;
    CurveView::new(desc.degree as usize, desc.dim as usize, knots, points, weights).map_err(|error| {
        GeometryFault::Curve {
            curve: desc.index as usize,
            error,
        }
    })
}

/// The curve `desc` describes, which [`check_curve`] has passed and which has not been
/// rewritten since: O(1) ([`CurveView::trusted`]).
pub fn trusted_curve<'a>(desc: &CurveDesc, values: &'a [f64], tip: usize) -> Result<CurveView<'a>, GeometryFault> {
    let (knots, points, weights) = curve_data(desc, values, tip)?;
    CurveView::trusted(desc.degree as usize, desc.dim as usize, knots, points, weights).map_err(|error| {
        GeometryFault::Curve {
            curve: desc.index as usize,
            error,
        }
    })
}

/// The stop points a path block refers to: `pairs` `(s, feed cap)` pairs in `values` from
/// value `offset`, if they lie within the arena and are finite with a cap >= 0. O(pairs),
/// allocation-free and panic-free.
pub fn stop_points(values: &[f64], offset: u32, pairs: u32) -> Option<&[f64]> {
    let points = slice_of(values, offset, pairs.checked_mul(2)?)?;
    points
        .chunks_exact(2)
        .all(|p| matches!(*p, [s, cap] if s.is_finite() && cap.is_finite() && cap >= 0.0))
        .then_some(points)
}

/// The curve geometry of one planned motion, streamed by the planner while the motion runs
/// and read by the module: a header, a ring of curve descriptors ([`CURVE_SLOTS`], the slot of
/// curve `i` is `i % CURVE_SLOTS`) and an arena of values (knots, coordinates and weights of the
/// curves; for path blocks also stop points and stored stop sequences).
///
/// A stream begins ([`GeometryStream::begin`], only while the module runs no motion) with a
/// new generation: odd while the header is written, then even and non-zero (release). Curves
/// follow in path order: the planner writes a curve's values, then its descriptor, then
/// advances [`GeometryStream::published`] (release); the module reads a descriptor only below
/// `published` (acquire), checks it once, and takes records only on checked curves. The planner
/// reuses a descriptor slot or arena values only once the module has reported that it no
/// longer needs them ([`Channel::progress`]): the curves before the one it is on, and the
/// arena values written before that curve's (blocks: and before the stored data of the block
/// it runs).
#[repr(C)]
pub struct GeometryStream {
    generation: AtomicU32,
    published: AtomicU32,
    header: UnsafeCell<GeometryHeader>,
    curves: UnsafeCell<[CurveDesc; CURVE_SLOTS]>,
    values: UnsafeCell<[f64; ARENA_VALUES]>,
}

// SAFETY: the header is written only under an odd generation (seqlock); a descriptor and the
// values it points to are written before `published` passes it and not rewritten while the
// module may use them (the release protocol above); the data are plain numbers.
unsafe impl Sync for GeometryStream {}

/// Why the planner cannot write into the geometry stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PublishError {
    /// Values beyond the arena, or a curve descriptor out of order.
    OutOfPlace,
    /// The curve does not validate (the module would refuse it).
    Invalid(GeometryFault),
}

impl GeometryStream {
    /// Current generation: 0 = nothing published, odd = being begun.
    pub fn generation(&self) -> u32 {
        self.generation.load(Ordering::Acquire)
    }

    /// One past the index of the last curve whose descriptor is written (acquire: its values
    /// and descriptor are visible).
    pub fn published(&self) -> u32 {
        self.published.load(Ordering::Acquire)
    }

    /// Producer side: starts a new stream with `header` (the module must be idle: it refuses a
    /// stream that changes during motion); returns its generation.
    pub fn begin(&self, header: &GeometryHeader) -> Result<u32, PublishError> {
        validate_header(header).map_err(PublishError::Invalid)?;
        let old = self.generation.load(Ordering::Relaxed);
        let writing = (old | 1).wrapping_add(if old & 1 == 1 { 2 } else { 0 });
        self.generation.store(writing, Ordering::Relaxed);
        fence(Ordering::Release);
        // SAFETY: the generation is odd: a reader discards what it sees now.
        unsafe { self.header.get().write_volatile(*header) };
        self.published.store(header.first_curve, Ordering::Relaxed);
        let begun = writing.wrapping_add(1).max(2);
        self.generation.store(begun, Ordering::Release);
        Ok(begun)
    }

    /// Producer side: writes `values` into the arena from physical value `offset`. The caller
    /// owns that range: nothing the module may still read lies there.
    pub fn write_values(&self, offset: usize, values: &[f64]) -> Result<(), PublishError> {
        let end = offset.checked_add(values.len()).ok_or(PublishError::OutOfPlace)?;
        if end > ARENA_VALUES {
            return Err(PublishError::OutOfPlace);
        }
        let base = self.values.get() as *mut f64;
        for (i, v) in values.iter().enumerate() {
            // SAFETY: within the array (checked above); the module reads these values only
            // after a descriptor or record pushed after this write refers to them.
            unsafe { base.add(offset + i).write_volatile(*v) };
        }
        Ok(())
    }

    /// Producer side: publishes the next curve, whose values are written; checks it first as
    /// the module will (what it refuses, the planner does not send).
    pub fn publish_curve(&self, desc: &CurveDesc) -> Result<(), PublishError> {
        let next = self.published.load(Ordering::Relaxed);
        if desc.index != next {
            return Err(PublishError::OutOfPlace);
        }
        let tip = self.header().tip_axes as usize;
        valid_curve(desc, self.values(), tip).map_err(PublishError::Invalid)?;
        self.write_descriptor(desc);
        Ok(())
    }

    fn write_descriptor(&self, desc: &CurveDesc) {
        let slot = desc.index as usize % CURVE_SLOTS;
        // SAFETY: the slot index is within the array; the module reads this slot only once
        // `published` passes `desc.index` (stored below, release), and the previous curve in
        // the slot is released (the planner's protocol).
        unsafe { (self.curves.get() as *mut CurveDesc).add(slot).write_volatile(*desc) };
        self.published.store(desc.index.wrapping_add(1), Ordering::Release);
    }

    /// Test helper: publish a descriptor without checking it (to prove the module refuses bad
    /// curves).
    #[cfg(any(test, feature = "mock-hal"))]
    pub fn publish_unchecked(&self, desc: &CurveDesc) {
        self.write_descriptor(desc);
    }

    /// The stream's header (read it under an unchanged generation).
    pub fn header(&self) -> GeometryHeader {
        // SAFETY: plain data; a concurrent `begin` is detected by the generation.
        unsafe { self.header.get().read_volatile() }
    }

    /// The descriptor of curve `index`, if it is published and its slot still holds it.
    pub fn descriptor(&self, index: u32) -> Option<CurveDesc> {
        if index >= self.published() {
            return None;
        }
        // SAFETY: within the array; written before `published` passed it (acquire above).
        let desc = unsafe {
            (self.curves.get() as *const CurveDesc)
                .add(index as usize % CURVE_SLOTS)
                .read_volatile()
        };
        (desc.index == index).then_some(desc)
    }

    /// True if stream `generation` is still the current one (after reading its data).
    pub fn unchanged(&self, generation: u32) -> bool {
        fence(Ordering::Acquire);
        self.generation.load(Ordering::Relaxed) == generation
    }

    /// The arena in place.
    pub fn values(&self) -> &[f64] {
        // SAFETY: the array stays mapped as long as the channel; values are plain numbers,
        // read only where the protocol says they are written.
        unsafe { &*self.values.get() }
    }
}

/// Planner ⇄ module: the rest of a motion planned again (at another feed override) joins it
/// inside the old plan's records still to run: at the end of a group (`at_sample` is
/// [`AT_RECORD_END`]), or cutting into record `after` at motion sample `at_sample`, where the
/// new plan's first record starts from that very sample (a change of feed from the sample's
/// feed and acceleration, [`nurbs_rtcore::block_stop::ramp_record`]). There the module drops
/// the old plan's records queued after `after`, up to `drop_to`, and runs on with what follows.
/// The planner writes the fields, then the state [`SPLICE_REQUESTED`], and pushes nothing
/// until the module answers: [`SPLICE_ACCEPTED`] (then it pushes the new plan, which lands at
/// `drop_to`) or [`SPLICE_MISSED`] (too late, or not in a running segment motion: nothing
/// changes). The module sets [`SPLICE_DONE`] once it has joined, or [`SPLICE_MISSED`] if its
/// motion stops before. Each party writes the state only while it is the other's answer that
/// is awaited, so they never write it at once. `samples` (module → planner) counts the motion
/// samples of segment records output so far, the numbering of `at_sample`.
#[repr(C)]
pub struct Splice {
    /// Count (in the ring's numbering) of the record the join is in or after.
    after: AtomicU32,
    /// Count of the new plan's first record: the old plan's records before it are dropped.
    drop_to: AtomicU32,
    state: AtomicU32,
    _pad: u32,
    at_sample: AtomicU64,
    samples: AtomicU64,
}

/// A join asked for ([`Splice`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Join {
    pub after: u32,
    pub drop_to: u32,
    /// The motion sample after which the new plan cuts into record `after`, or
    /// [`AT_RECORD_END`]: at its end (a group's end).
    pub at_sample: u64,
}

/// [`Join::at_sample`] of a join at the end of record `after`.
pub const AT_RECORD_END: u64 = u64::MAX;

pub const SPLICE_IDLE: u32 = 0;
pub const SPLICE_REQUESTED: u32 = 1;
pub const SPLICE_ACCEPTED: u32 = 2;
pub const SPLICE_MISSED: u32 = 3;
pub const SPLICE_DONE: u32 = 4;

impl Splice {
    pub fn state(&self) -> u32 {
        self.state.load(Ordering::Acquire)
    }

    fn open(state: u32) -> bool {
        state == SPLICE_REQUESTED || state == SPLICE_ACCEPTED
    }

    /// Planner side: asks for `join`; false while an earlier request is open.
    pub fn request(&self, join: Join) -> bool {
        if Self::open(self.state()) {
            return false;
        }
        self.after.store(join.after, Ordering::Relaxed);
        self.drop_to.store(join.drop_to, Ordering::Relaxed);
        self.at_sample.store(join.at_sample, Ordering::Relaxed);
        self.state.store(SPLICE_REQUESTED, Ordering::Release);
        true
    }

    /// Planner side: forgets a finished request (a new stream); false while one is open.
    pub fn reset(&self) -> bool {
        if Self::open(self.state()) {
            return false;
        }
        self.state.store(SPLICE_IDLE, Ordering::Release);
        true
    }

    /// Module side: the request waiting for an answer.
    pub fn requested(&self) -> Option<Join> {
        (self.state() == SPLICE_REQUESTED).then(|| self.fields())
    }

    /// Module side: the request accepted and not yet carried out.
    pub fn accepted(&self) -> Option<Join> {
        (self.state() == SPLICE_ACCEPTED).then(|| self.fields())
    }

    fn fields(&self) -> Join {
        Join {
            after: self.after.load(Ordering::Relaxed),
            drop_to: self.drop_to.load(Ordering::Relaxed),
            at_sample: self.at_sample.load(Ordering::Relaxed),
        }
    }

    /// Module side: the answer to an open request ([`SPLICE_ACCEPTED`], [`SPLICE_MISSED`],
    /// [`SPLICE_DONE`]); nothing when none is open.
    pub fn answer(&self, state: u32) {
        if Self::open(self.state()) {
            self.state.store(state, Ordering::Release);
        }
    }

    /// Module side: motion samples of segment records output so far in this motion.
    pub fn report_samples(&self, samples: u64) {
        self.samples.store(samples, Ordering::Relaxed);
    }

    /// Planner side: what the module last reported ([`Self::report_samples`]).
    pub fn samples(&self) -> u64 {
        self.samples.load(Ordering::Relaxed)
    }
}

/// Module → planner: how far the module has got, so the planner may reuse what lies behind
/// and knows when it may begin a new stream. One 64-bit word (the stream's generation, whether
/// a motion is running, and a curve index), so the three are read together.
#[repr(C)]
pub struct Progress {
    word: AtomicU64,
}

/// What the module last reported ([`Progress`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Report {
    pub generation: u32,
    /// A motion is running (it may still read curves and stored stops).
    pub moving: bool,
    /// The module will not use curves before this one again.
    pub curve: u32,
}

const MOVING: u64 = 1 << 31;

impl Progress {
    /// Module side.
    pub fn report(&self, r: Report) {
        let moving = if r.moving { MOVING } else { 0 };
        let word = (u64::from(r.generation) << 32) | moving | (u64::from(r.curve) & (MOVING - 1));
        self.word.store(word, Ordering::Release);
    }

    /// Planner side.
    pub fn read(&self) -> Report {
        let word = self.word.load(Ordering::Acquire);
        Report {
            generation: (word >> 32) as u32,
            moving: word & MOVING != 0,
            curve: (word & (MOVING - 1)) as u32,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn block() -> Vec<u64> {
        vec![0u64; Channel::SIZE.div_ceil(8) + 8]
    }

    fn aligned(block: &mut [u64]) -> *mut u8 {
        let p = block.as_mut_ptr() as *mut u8;
        // SAFETY: block has 64 spare bytes.
        unsafe { p.add(p.align_offset(64)) }
    }

    fn record(seq: u32) -> Slot {
        if seq.is_multiple_of(3) {
            let mut b = PathBlock {
                seq,
                count: 1,
                group_left: 1,
                ..PathBlock::default()
            };
            b.u[0] = seq as f64 / 7.0;
            Slot::block(&b)
        } else {
            let record = SegmentRecord {
                seq,
                u_start: seq as f64 / 7.0,
                ..SegmentRecord::default()
            };
            Slot::segment(&SegmentSlot {
                record,
                stop: SegmentRecord { seq: seq + 1, ..record },
                group_left: 1 + seq % 4,
                has_stop: u32::from(seq.is_multiple_of(4)),
                curve_needed: seq,
                chain_offset: 3 * seq,
                chain_len: seq % 5,
                hold_stops_offset: 7 * seq,
                hold_stops_len: seq % 3,
                reserved: 0,
            })
        }
    }

    #[test]
    fn attach_refuses_uninitialised_and_foreign_layouts() {
        let mut b = block();
        let p = aligned(&mut b);
        assert_eq!(unsafe { Channel::attach(p) }.err(), Some(ChannelError::NotInitialised));
        let c = unsafe { Channel::init(p) };
        assert!(unsafe { Channel::attach(p) }.is_ok());
        c.version.store(CHANNEL_VERSION + 1, Ordering::Relaxed);
        assert_eq!(unsafe { Channel::attach(p) }.err(), Some(ChannelError::Layout));
    }

    #[test]
    fn fifo_order_full_and_wraparound() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let ring = &c.segments;
        let mut next_in = 0u32;
        let mut next_out = 0u32;
        // Several laps around the ring with varying fill levels.
        for lap in 0..5u32 {
            while ring.producer().push(&record(next_in)).is_ok() {
                next_in += 1;
            }
            assert_eq!(ring.len(), SEGMENT_SLOTS);
            assert_eq!(ring.producer().push(&record(next_in)), Err(ChannelError::Full));
            for _ in 0..(SEGMENT_SLOTS as u32 - 3 * lap - 1) {
                assert_eq!(ring.consumer().pop(), Ok(Some(record(next_out))));
                next_out += 1;
            }
        }
        while let Ok(Some(r)) = ring.consumer().pop() {
            assert_eq!(r, record(next_out));
            next_out += 1;
        }
        assert_eq!(next_in, next_out);
        assert_eq!(ring.consumer().pop(), Ok(None));
    }

    #[test]
    fn counters_wrap_at_u32() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let ring = &c.segments;
        ring.head.0.store(u32::MAX - 2, Ordering::Relaxed);
        ring.tail.0.store(u32::MAX - 2, Ordering::Relaxed);
        for i in 0..6 {
            ring.producer().push(&record(i)).unwrap();
        }
        for i in 0..6 {
            assert_eq!(ring.consumer().pop(), Ok(Some(record(i))));
        }
    }

    /// A join's tools on the module's side: a record further down the queue read in place, the
    /// queue dropped up to a count (across the counters' wrap), never beyond what is queued;
    /// and the join's states: one request at a time, answered only while open.
    #[test]
    fn peek_at_skip_to_and_the_splice_states() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let ring = &c.segments;
        ring.head.0.store(u32::MAX - 2, Ordering::Relaxed);
        ring.tail.0.store(u32::MAX - 2, Ordering::Relaxed);
        for i in 0..8 {
            ring.producer().push(&record(i)).unwrap();
        }
        let consumer = ring.consumer();
        assert_eq!(consumer.peek_at(5), Ok(Some(record(5))));
        assert_eq!(consumer.peek_at(8), Ok(None));
        assert_eq!(consumer.skip_to(u32::MAX.wrapping_add(7)), Err(ChannelError::Corrupt));
        let base = consumer.taken();
        consumer.skip_to(base.wrapping_add(6)).unwrap();
        assert_eq!(consumer.pop(), Ok(Some(record(6))));
        assert_eq!(ring.len(), 1);
        assert_eq!(ring.producer().taken(), base.wrapping_add(7));

        let splice = &c.splice;
        assert_eq!(splice.state(), SPLICE_IDLE);
        splice.answer(SPLICE_ACCEPTED); // nothing open: no effect
        assert_eq!(splice.state(), SPLICE_IDLE);
        let join = Join {
            after: 3,
            drop_to: 9,
            at_sample: AT_RECORD_END,
        };
        assert!(splice.request(join));
        assert!(!splice.request(Join { after: 4, ..join }), "one request at a time");
        assert!(!splice.reset());
        assert_eq!(splice.requested(), Some(join));
        splice.answer(SPLICE_ACCEPTED);
        assert_eq!(splice.accepted(), Some(join));
        splice.answer(SPLICE_DONE);
        assert_eq!(splice.state(), SPLICE_DONE);
        assert!(splice.reset());
        assert_eq!(splice.state(), SPLICE_IDLE);
    }

    #[test]
    fn corrupt_counters_are_refused_not_followed() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        c.segments.head.0.store(SEGMENT_SLOTS as u32 + 1, Ordering::Relaxed);
        assert_eq!(c.segments.consumer().pop(), Err(ChannelError::Corrupt));
        assert_eq!(c.segments.producer().push(&record(0)), Err(ChannelError::Corrupt));
    }

    /// A clamped cubic: the trident's control polygon, as (knots, points, weights).
    fn trident() -> ([f64; 11], [f64; 14], [f64; 7]) {
        let knots = [0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0, 1.0];
        let points = [
            10.0, 0.0, 20.0, 27.0, 12.0, 8.0, 10.0, 20.0, 8.0, 8.0, 0.0, 27.0, 10.0, 0.0,
        ];
        (knots, points, [1.0; 7])
    }

    /// Curve `index` written at `offset` of the arena of `g`; its descriptor.
    fn write_trident(g: &GeometryStream, index: u32, offset: u32, weights: &[f64]) -> CurveDesc {
        let (knots, points, _) = trident();
        let data: Vec<f64> = knots.iter().chain(&points).chain(weights).copied().collect();
        g.write_values(offset as usize, &data).unwrap();
        CurveDesc {
            index,
            degree: 3,
            dim: 2,
            knots_offset: offset,
            knots_len: 11,
            points_offset: offset + 11,
            points_len: 14,
            weights_offset: offset + 25,
            weights_len: weights.len() as u32,
            reserved: 0,
        }
    }

    fn header(first_curve: u32) -> GeometryHeader {
        GeometryHeader {
            first_curve,
            tip_axes: 2,
            joints: 0,
            period_ns: 250_000,
        }
    }

    #[test]
    fn a_stream_publishes_curves_in_order() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let g = &c.geometry;
        assert_eq!(g.generation(), 0);
        let generation = g.begin(&header(5)).unwrap();
        assert_eq!((generation, g.published(), g.header()), (2, 5, header(5)));
        assert!(g.descriptor(5).is_none(), "not published yet");
        let desc = write_trident(g, 5, 100, &[1.0; 7]);
        assert_eq!(
            g.publish_curve(&CurveDesc { index: 6, ..desc }),
            Err(PublishError::OutOfPlace)
        );
        g.publish_curve(&desc).unwrap();
        assert_eq!((g.published(), g.descriptor(5)), (6, Some(desc)));
        let view = valid_curve(&desc, g.values(), 2).unwrap();
        let p = view.point(1.0);
        assert_eq!((p[0], p[1]), (10.0, 0.0));
        // The slot of curve 5 + CURVE_SLOTS is curve 5's: a descriptor that is not the curve
        // asked for is not taken.
        assert!(g.descriptor(5 + CURVE_SLOTS as u32).is_none());
        assert!(g.unchanged(generation));
        assert_eq!(g.begin(&header(0)), Ok(4));
        assert!(!g.unchanged(generation));
        assert_eq!(g.published(), 0);
        for bad in [
            GeometryHeader {
                tip_axes: 1,
                ..header(0)
            },
            GeometryHeader { joints: 5, ..header(0) },
            GeometryHeader {
                period_ns: 0,
                ..header(0)
            },
        ] {
            assert_eq!(g.begin(&bad), Err(PublishError::Invalid(GeometryFault::Header)));
        }
        assert_eq!(
            g.write_values(ARENA_VALUES - 1, &[0.0, 0.0]),
            Err(PublishError::OutOfPlace)
        );
        assert_eq!(g.write_values(usize::MAX, &[0.0]), Err(PublishError::OutOfPlace));
    }

    #[test]
    fn the_module_reports_its_progress_in_one_word() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        for r in [
            Report {
                generation: 7,
                moving: true,
                curve: 123_456,
            },
            Report {
                generation: u32::MAX,
                moving: false,
                curve: (1 << 31) - 1,
            },
        ] {
            c.progress.report(r);
            assert_eq!(c.progress.read(), r);
        }
    }

    /// Any budget: each call runs at most that many value checks (the last one what is left)
    /// and the calls cover every check of the curve once.
    #[test]
    fn a_curve_is_checked_a_budget_at_a_time() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let desc = write_trident(&c.geometry, 0, 0, &[1.0; 7]);
        let values = c.geometry.values();
        let (k, p, w) = trident();
        let total = CurveView::value_checks(3, &k, &p, &w);
        assert_eq!(total, 11 + 3 + 14 + 7);
        for budget in 1..=total + 1 {
            let (mut at, mut calls, mut used_all) = (0, 0, 0);
            loop {
                let (used, next) = check_curve(&desc, values, 2, at, budget).unwrap();
                calls += 1;
                used_all += used;
                match next {
                    Some(n) => at = n,
                    None => break,
                }
            }
            assert_eq!(used_all, total, "budget {budget}");
            assert_eq!(calls, total.div_ceil(budget), "budget {budget}");
        }
    }

    #[test]
    fn stop_points_are_checked_pairs_within_the_arena() {
        let values = [1.0, 0.5, 2.0, 0.0, 3.0, -1.0, f64::NAN, 1.0];
        assert_eq!(stop_points(&values, 0, 2), Some(&values[..4]));
        assert_eq!(stop_points(&values, 0, 0), Some(&values[..0]));
        assert_eq!(stop_points(&values, 2, 3), None, "negative cap");
        assert_eq!(stop_points(&values, 6, 1), None, "NaN");
        assert_eq!(stop_points(&values, 6, 2), None, "past the end");
        assert_eq!(stop_points(&values, u32::MAX, 1), None);
        assert_eq!(stop_points(&values, 0, u32::MAX), None);
    }

    #[test]
    fn malformed_curves_are_refused() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let g = &c.geometry;
        g.begin(&header(0)).unwrap();
        let values = g.values();
        let good = write_trident(g, 0, 0, &[1.0; 7]);
        let past = CurveDesc {
            weights_offset: (ARENA_VALUES - 3) as u32,
            ..good
        };
        assert_eq!(
            valid_curve(&past, values, 2).err(),
            Some(GeometryFault::OutOfBounds { curve: 0 })
        );
        let overflow = CurveDesc {
            knots_offset: u32::MAX,
            ..good
        };
        assert_eq!(
            valid_curve(&overflow, values, 2).err(),
            Some(GeometryFault::OutOfBounds { curve: 0 })
        );
        assert_eq!(
            valid_curve(&good, values, 3).err(),
            Some(GeometryFault::Dimension { curve: 0 })
        );
        let negative = write_trident(g, 0, 0, &[1.0, 1.0, -1.0, 1.0, 1.0, 1.0, 1.0]);
        assert!(matches!(
            valid_curve(&negative, values, 2),
            Err(GeometryFault::Curve { curve: 0, .. })
        ));
        assert!(matches!(
            check_curve(&negative, values, 2, 0, 1000),
            Err(GeometryFault::Curve { .. })
        ));
        assert!(matches!(g.publish_curve(&negative), Err(PublishError::Invalid(_))));
        assert_eq!(g.published(), 0);
    }

    #[test]
    fn two_threads_transfer_every_record_in_order() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        const COUNT: u32 = 200_000;
        std::thread::scope(|s| {
            s.spawn(|| {
                let mut i = 0;
                while i < COUNT {
                    if c.segments.producer().push(&record(i)).is_ok() {
                        i += 1;
                    }
                }
            });
            let mut expect = 0;
            while expect < COUNT {
                if let Some(r) = c.segments.consumer().pop().unwrap() {
                    assert_eq!(r, record(expect));
                    expect += 1;
                }
            }
        });
    }
}
