//! The shared-memory channel from the userspace planner to the realtime module.
//!
//! The realtime module creates one RTAPI shared-memory block ([`CHANNEL_KEY`], created in
//! `rtapi_app_main`, zeroed by RTAPI) and lays a [`Channel`] over it; the planner attaches to the
//! same key and checks the header before writing. The block holds a single-producer /
//! single-consumer ring of fixed-size tagged [`Slot`]s (a [`SegmentRecord`] or a
//! [`crate::record::PathBlock`]): the planner only advances `head`, the
//! module only advances `tail`, each with release ordering after touching a slot and acquire
//! ordering before reading the other side's counter. No locks, no syscalls, no allocation.
//!
//! After the ring comes the [`GeometryArea`]: the curves (knots, control points, weights) the
//! records refer to, in one fixed-capacity arena of `f64` published seqlock-style (a generation
//! counter, odd while the planner writes, even and non-zero once published, stored last). The
//! module validates a published geometry with `CurveView`'s checks (a slice of values per
//! period) before it runs a single record on it and refuses (fault, hold) anything that does
//! not validate. Behind the published curves
//! the planner appends the curves' stop points and the stored stop sequences while the motion
//! runs ([`GeometryArea::append`]), each before the first record that refers to it: the ring's
//! release/acquire pair orders them, so the planner can hand records out while it still
//! checks the stops of later ones.
//!
//! Why not `hal_stream`: it carries at most `HAL_STREAM_MAX_PINS` = 21 values per record, exactly
//! the size of a segment record, which leaves no room for a record kind, and curve geometry
//! (knots, control points, weights: variable size, possibly thousands of values) would have to be
//! chopped into 21-value pieces on a second stream. Our own block keeps one ABI-checked layout
//! (magic, version, record size, capacity) for both and grows without limits of HAL's.

use core::cell::UnsafeCell;
use core::sync::atomic::{fence, AtomicU32, AtomicU64, Ordering};

use nurbs_rtcore::{CurveView, ValuesChecked};

pub use crate::record::{PathBlock, Record, RecordStop, SegmentRecord, SegmentSlot, Slot};

/// RTAPI shared-memory key of the channel ("NRB0").
pub const CHANNEL_KEY: i32 = 0x4E52_4230;
/// "NRBS": written last by the creator, so a reader that sees it sees an initialised header.
pub const CHANNEL_MAGIC: u32 = 0x4E52_4253;
/// Layout version; bump on any change to [`Channel`] or the record types.
pub const CHANNEL_VERSION: u32 = 9;
/// Segment slots in the ring (a power of two). 1024 segments cover far more than the buffered
/// time margin the planner keeps.
pub const SEGMENT_SLOTS: usize = 1024;
/// Most curves (path elements) one geometry can hold: every curve index a record can carry (16
/// bits). A G1 program with its corners rounded is two elements per line.
pub const MAX_CURVES: usize = 1 << 16;
/// Capacity of the geometry arena in `f64` values (knots, coordinates and weights of all curves
/// together, then their stop points and the stored stop sequences): 32 MiB. The curves need
/// little (e.g. 64 cubic 3-D curves of 250 control points each: 64,000 values; the butterfly:
/// 208); a stored stop sequence needs two values per period and three per element it runs on.
/// The butterfly's VPOp blocks at lab set 1 need 766,256 values in all; a 1,000-line G1 program
/// with the Erwinski planner 631,844 (3,038 of its 3,958 boundaries, most at element joins, have
/// a stored stop): this capacity holds some 6,000 such lines.
pub const GEOMETRY_VALUES: usize = 1 << 22;

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

    /// Producer side: append one record, or `Full`.
    pub fn push(&self, record: &T) -> Result<(), ChannelError> {
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
    pub fn peek(&self) -> Result<Option<T>, ChannelError> {
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

    /// Consumer side: take the oldest record. Never allocates, locks or panics.
    pub fn pop(&self) -> Result<Option<T>, ChannelError> {
        let record = self.peek()?;
        if record.is_some() {
            // Only the consumer stores `tail`: the value `peek` read is still current.
            let tail = self.tail.0.load(Ordering::Relaxed);
            self.tail.0.store(tail.wrapping_add(1), Ordering::Release);
        }
        Ok(record)
    }
}

/// The layout of the shared-memory block.
#[repr(C)]
pub struct Channel {
    magic: AtomicU32,
    version: AtomicU32,
    record_size: AtomicU32,
    segment_slots: AtomicU32,
    geometry_values: AtomicU32,
    max_curves: AtomicU32,
    /// Total motion time (s, `f64` bits) of the records the planner has pushed so far; with the
    /// time the module has taken, this gives the buffered motion time.
    planned_time: AtomicU64,
    /// Module → planner: where the module stands after a hold or underrun stop.
    pub stop: StopStatus,
    /// Planner → module records (segments or path blocks).
    pub segments: SpscRing<Slot, SEGMENT_SLOTS>,
    /// Planner → module curve geometry.
    pub geometry: GeometryArea,
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
        channel.geometry_values.store(GEOMETRY_VALUES as u32, Ordering::Relaxed);
        channel.max_curves.store(MAX_CURVES as u32, Ordering::Relaxed);
        channel.planned_time.store(0, Ordering::Relaxed);
        channel.stop.clear();
        channel.geometry.generation.store(0, Ordering::Relaxed);
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
            && self.geometry_values.load(Ordering::Relaxed) as usize == GEOMETRY_VALUES
            && self.max_curves.load(Ordering::Relaxed) as usize == MAX_CURVES;
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
    pub point: [f64; 3],
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
    point: [AtomicU64; 3],
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
            point: [f(&self.point[0]), f(&self.point[1]), f(&self.point[2])],
        };
        fence(Ordering::Acquire);
        (self.epoch.load(Ordering::Relaxed) == epoch).then_some(p)
    }
}

/// Where one curve's data lies in the geometry arena (offsets and lengths in `f64` values).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CurveDesc {
    pub degree: u32,
    /// Coordinates per control point (2, 3, or 6 for a 5-axis tip + top curve).
    pub dim: u32,
    pub knots_offset: u32,
    pub knots_len: u32,
    pub points_offset: u32,
    pub points_len: u32,
    pub weights_offset: u32,
    pub weights_len: u32,
}

/// The fixed-size part of a geometry. (The stop after each record travels with the record:
/// [`RecordStop`], [`PathBlock::stop_accel`].)
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GeometryHeader {
    pub curve_count: u32,
    /// Tool-tip coordinates (2 or 3): the axes the module drives and the arc length measures.
    pub tip_axes: u32,
}

/// A geometry as the channel holds it: the header, the descriptors of its curves (in their own
/// array of the channel, indexed like the records' curve numbers) and the arena values.
#[derive(Clone, Copy, Debug)]
pub struct GeometryRef<'a> {
    pub header: GeometryHeader,
    pub curves: &'a [CurveDesc],
    pub values: &'a [f64],
}

/// Why a published geometry is refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeometryFault {
    /// No curve, more than [`MAX_CURVES`], or a tip-axis count outside 2..=3.
    Header,
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

/// Checks the header and every curve of `g` (see [`valid_curve`]). Allocation-free and
/// panic-free: the planner runs it before publishing; the realtime module runs the same checks
/// a slice per period ([`validate_header`], [`validate_curves`]).
pub fn validate_geometry(g: &GeometryRef) -> Result<(), GeometryFault> {
    validate_header(g)?;
    (0..g.header.curve_count as usize).try_for_each(|curve| valid_curve(g, curve).map(|_| ()))
}

/// Checks the header of `g`: 1..=[`MAX_CURVES`] curves, 2 or 3 tip axes.
pub fn validate_header(g: &GeometryRef) -> Result<(), GeometryFault> {
    let header = &g.header;
    let count = header.curve_count as usize;
    let tip = header.tip_axes as usize;
    if count == 0 || count > MAX_CURVES || count > g.curves.len() || !(2..=3).contains(&tip) {
        return Err(GeometryFault::Header);
    }
    Ok(())
}

/// Where [`validate_curves`] stands: a curve, and a value of it (in the order of
/// [`CurveView::check_values`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CurvesCursor {
    pub curve: usize,
    pub value: usize,
}

/// How far [`validate_curves`] got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurvesChecked {
    /// Every curve from where it started is valid.
    All,
    /// Everything before this point is valid; the budget is spent.
    UpTo(CurvesCursor),
}

/// Checks the curves of `g` from `from` on ([`valid_curve`]'s checks) until `budget` value
/// checks are run ([`CurveView::value_checks`]: knots, coordinates and weights once, interior
/// knots once more), within a curve if need be: a curve of a million control points is checked
/// over many calls. The header must be valid ([`validate_header`]).
/// O(budget), allocation-free and panic-free.
pub fn validate_curves(g: &GeometryRef, from: CurvesCursor, budget: usize) -> Result<CurvesChecked, GeometryFault> {
    let count = g.header.curve_count as usize;
    let mut at = from;
    let mut left = budget;
    while at.curve < count {
        let (desc, knots, points, weights) = curve_data(g, at.curve)?;
        let curve = at.curve;
        match CurveView::check_values(
            desc.degree as usize,
            desc.dim as usize,
            knots,
            points,
            weights,
            at.value,
            left,
        )
        .map_err(|error| GeometryFault::Curve { curve, error })?
        {
            ValuesChecked::UpTo(value) => return Ok(CurvesChecked::UpTo(CurvesCursor { curve, value })),
            ValuesChecked::All => {
                let total = CurveView::value_checks(desc.degree as usize, knots, points, weights);
                left = left.saturating_sub(total.saturating_sub(at.value).max(1));
                at = CurvesCursor {
                    curve: curve + 1,
                    value: 0,
                };
                if left == 0 && at.curve < count {
                    return Ok(CurvesChecked::UpTo(at));
                }
            }
        }
    }
    Ok(CurvesChecked::All)
}

/// Curve `curve` of `g`, checked: its data within the arena, at least the tip axes, and a NURBS
/// `CurveView::new` accepts (O(size of the curve)). Allocation-free and panic-free.
pub fn valid_curve<'a>(g: &GeometryRef<'a>, curve: usize) -> Result<CurveView<'a>, GeometryFault> {
    let (desc, knots, points, weights) = curve_data(g, curve)?;
    CurveView::new(desc.degree as usize, desc.dim as usize, knots, points, weights)
        .map_err(|error| GeometryFault::Curve { curve, error })
}

/// Curve `curve` of a geometry whose curves [`validate_curves`] has passed and which has not
/// been rewritten since (its generation unchanged): O(1) ([`CurveView::trusted`]).
pub fn trusted_curve<'a>(g: &GeometryRef<'a>, curve: usize) -> Result<CurveView<'a>, GeometryFault> {
    let (desc, knots, points, weights) = curve_data(g, curve)?;
    CurveView::trusted(desc.degree as usize, desc.dim as usize, knots, points, weights)
        .map_err(|error| GeometryFault::Curve { curve, error })
}

type CurveData<'a> = (&'a CurveDesc, &'a [f64], &'a [f64], &'a [f64]);

/// The descriptor and the knots, coordinates and weights of curve `curve`, within the arena and
/// with at least the tip axes (O(1)).
fn curve_data<'a>(g: &GeometryRef<'a>, curve: usize) -> Result<CurveData<'a>, GeometryFault> {
    let header = &g.header;
    let desc = g
        .curves
        .get(curve)
        .filter(|_| curve < header.curve_count as usize)
        .ok_or(GeometryFault::Header)?;
    let values = g.values;
    let (Some(knots), Some(points), Some(weights)) = (
        slice_of(values, desc.knots_offset, desc.knots_len),
        slice_of(values, desc.points_offset, desc.points_len),
        slice_of(values, desc.weights_offset, desc.weights_len),
    ) else {
        return Err(GeometryFault::OutOfBounds { curve });
    };
    if (desc.dim as usize) < header.tip_axes as usize {
        return Err(GeometryFault::Dimension { curve });
    }
    Ok((desc, knots, points, weights))
}

/// The stop points a record or block refers to: `pairs` `(s, feed cap)` pairs in `values` from
/// value `offset`, if they lie within the arena and are finite with a cap >= 0. O(pairs),
/// allocation-free and panic-free.
pub fn stop_points(values: &[f64], offset: u32, pairs: u32) -> Option<&[f64]> {
    let points = slice_of(values, offset, pairs.checked_mul(2)?)?;
    points
        .chunks_exact(2)
        .all(|p| matches!(*p, [s, cap] if s.is_finite() && cap.is_finite() && cap >= 0.0))
        .then_some(points)
}

/// The curve geometry in shared memory, written by the planner, read by the module.
///
/// Seqlock protocol: the writer makes `generation` odd, writes header and values, then stores
/// the next even value (release). A reader takes a snapshot only at an even, non-zero
/// generation and confirms the generation unchanged after it has validated the data.
#[repr(C)]
pub struct GeometryArea {
    generation: AtomicU32,
    header: UnsafeCell<GeometryHeader>,
    curves: UnsafeCell<[CurveDesc; MAX_CURVES]>,
    values: UnsafeCell<[f64; GEOMETRY_VALUES]>,
}

// SAFETY: writes happen only under an odd generation, reads are confirmed by an unchanged even
// generation (seqlock); the data are plain numbers.
unsafe impl Sync for GeometryArea {}

/// Why the planner cannot publish a geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PublishError {
    /// More values than [`GEOMETRY_VALUES`].
    TooLarge,
    /// The geometry does not validate (the module would refuse it).
    Invalid(GeometryFault),
}

impl GeometryArea {
    /// Current generation: 0 = nothing published, odd = being written.
    pub fn generation(&self) -> u32 {
        self.generation.load(Ordering::Acquire)
    }

    /// Producer side: validate and publish `g`; returns the new generation. The module must be
    /// idle (it refuses a geometry that changes during motion).
    pub fn publish(&self, g: &GeometryRef) -> Result<u32, PublishError> {
        if g.values.len() > GEOMETRY_VALUES || g.curves.len() > MAX_CURVES {
            return Err(PublishError::TooLarge);
        }
        validate_geometry(g).map_err(PublishError::Invalid)?;
        Ok(self.write(g))
    }

    /// Writes `g` under the seqlock protocol (odd generation while writing).
    fn write(&self, g: &GeometryRef) -> u32 {
        let old = self.generation.load(Ordering::Relaxed);
        let writing = (old | 1).wrapping_add(if old & 1 == 1 { 2 } else { 0 });
        self.generation.store(writing, Ordering::Relaxed);
        fence(Ordering::Release);
        // SAFETY: the generation is odd: a reader will discard what it sees now; the lengths
        // are within the arrays (checked by the callers, `take` for the test helper).
        unsafe {
            self.header.get().write_volatile(g.header);
            let curves = self.curves.get() as *mut CurveDesc;
            for (i, c) in g.curves.iter().take(MAX_CURVES).enumerate() {
                curves.add(i).write_volatile(*c);
            }
            let base = self.values.get() as *mut f64;
            for (i, v) in g.values.iter().take(GEOMETRY_VALUES).enumerate() {
                base.add(i).write_volatile(*v);
            }
        }
        let published = writing.wrapping_add(1).max(2);
        self.generation.store(published, Ordering::Release);
        published
    }

    /// Producer side, after [`GeometryArea::publish`]: writes `values` into the arena from value
    /// `offset`, behind everything published and appended before (the caller keeps count), for
    /// records pushed afterwards to refer to (stored stop sequences). No reader looks there
    /// before it has taken such a record, so the generation stays as it is.
    pub fn append(&self, offset: usize, values: &[f64]) -> Result<(), PublishError> {
        let end = offset.checked_add(values.len()).ok_or(PublishError::TooLarge)?;
        if end > GEOMETRY_VALUES {
            return Err(PublishError::TooLarge);
        }
        let base = self.values.get() as *mut f64;
        for (i, v) in values.iter().enumerate() {
            // SAFETY: within the array (checked above); the module reads these values only
            // after the ring has handed it a record pushed after this write.
            unsafe { base.add(offset + i).write_volatile(*v) };
        }
        Ok(())
    }

    /// Test helper: publish without validating (to prove the module refuses bad geometry).
    #[cfg(test)]
    pub(crate) fn publish_unchecked(&self, g: &GeometryRef) -> u32 {
        self.write(g)
    }

    /// Consumer side: the published geometry (a copy of the header, the curve descriptors and
    /// the whole arena in place), if there is one (generation even and non-zero). Confirm with
    /// [`GeometryArea::unchanged`] after using the data.
    pub fn snapshot(&self) -> Option<(u32, GeometryRef<'_>)> {
        let generation = self.generation.load(Ordering::Acquire);
        if generation == 0 || generation & 1 == 1 {
            return None;
        }
        // SAFETY: read of plain data; a concurrent writer is detected by `unchanged`. The arrays
        // stay mapped as long as the channel.
        let (header, curves, values) = unsafe {
            (
                self.header.get().read_volatile(),
                &*self.curves.get(),
                &*self.values.get(),
            )
        };
        let count = (header.curve_count as usize).min(MAX_CURVES);
        Some((
            generation,
            GeometryRef {
                header,
                curves: &curves[..count],
                values,
            },
        ))
    }

    /// True if the geometry of `generation` is still the published one.
    pub fn unchanged(&self, generation: u32) -> bool {
        fence(Ordering::Acquire);
        self.generation.load(Ordering::Relaxed) == generation
    }
}

#[cfg(test)]
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
                ..PathBlock::default()
            };
            b.u[0] = seq as f64 / 7.0;
            Slot::block(&b)
        } else {
            let stop = RecordStop {
                accel: 1e4,
                jerk: 6e4,
                stored_len: seq,
                stored_offset: 2 * seq,
                points_offset: 3 * seq,
                points_len: 1,
            };
            let r = SegmentRecord {
                seq,
                u_start: seq as f64 / 7.0,
                ..SegmentRecord::default()
            };
            Slot::segment(&r, &stop)
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
            while ring.push(&record(next_in)).is_ok() {
                next_in += 1;
            }
            assert_eq!(ring.len(), SEGMENT_SLOTS);
            assert_eq!(ring.push(&record(next_in)), Err(ChannelError::Full));
            for _ in 0..(SEGMENT_SLOTS as u32 - 3 * lap - 1) {
                assert_eq!(ring.pop(), Ok(Some(record(next_out))));
                next_out += 1;
            }
        }
        while let Ok(Some(r)) = ring.pop() {
            assert_eq!(r, record(next_out));
            next_out += 1;
        }
        assert_eq!(next_in, next_out);
        assert_eq!(ring.pop(), Ok(None));
    }

    #[test]
    fn counters_wrap_at_u32() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        let ring = &c.segments;
        ring.head.0.store(u32::MAX - 2, Ordering::Relaxed);
        ring.tail.0.store(u32::MAX - 2, Ordering::Relaxed);
        for i in 0..6 {
            ring.push(&record(i)).unwrap();
        }
        for i in 0..6 {
            assert_eq!(ring.pop(), Ok(Some(record(i))));
        }
    }

    #[test]
    fn corrupt_counters_are_refused_not_followed() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        c.segments.head.0.store(SEGMENT_SLOTS as u32 + 1, Ordering::Relaxed);
        assert_eq!(c.segments.pop(), Err(ChannelError::Corrupt));
        assert_eq!(c.segments.push(&record(0)), Err(ChannelError::Corrupt));
    }

    /// A clamped cubic: the trident's control polygon.
    fn trident() -> (GeometryHeader, Vec<CurveDesc>, Vec<f64>) {
        let knots = [0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0, 1.0];
        let points = [
            10.0, 0.0, 20.0, 27.0, 12.0, 8.0, 10.0, 20.0, 8.0, 8.0, 0.0, 27.0, 10.0, 0.0,
        ];
        let weights = [1.0; 7];
        let mut values = Vec::new();
        let mut desc = CurveDesc {
            degree: 3,
            dim: 2,
            ..CurveDesc::default()
        };
        desc.knots_offset = values.len() as u32;
        desc.knots_len = knots.len() as u32;
        values.extend_from_slice(&knots);
        desc.points_offset = values.len() as u32;
        desc.points_len = points.len() as u32;
        values.extend_from_slice(&points);
        desc.weights_offset = values.len() as u32;
        desc.weights_len = weights.len() as u32;
        values.extend_from_slice(&weights);
        let header = GeometryHeader {
            curve_count: 1,
            tip_axes: 2,
        };
        (header, vec![desc], values)
    }

    fn geometry<'a>(header: GeometryHeader, curves: &'a [CurveDesc], values: &'a [f64]) -> GeometryRef<'a> {
        GeometryRef { header, curves, values }
    }

    #[test]
    fn geometry_publishes_and_validates() {
        let mut b = block();
        let c = unsafe { Channel::init(aligned(&mut b)) };
        assert!(c.geometry.snapshot().is_none());
        let (header, curves, values) = trident();
        let g = geometry(header, &curves, &values);
        let generation = c.geometry.publish(&g).unwrap();
        assert_eq!(generation, 2);
        let (gen, snap) = c.geometry.snapshot().unwrap();
        assert_eq!((gen, snap.header, snap.curves), (generation, header, &curves[..]));
        validate_geometry(&snap).unwrap();
        let p = valid_curve(&snap, 0).unwrap().point(1.0);
        assert_eq!((p[0], p[1]), (10.0, 0.0));
        assert_eq!(valid_curve(&snap, 1).unwrap_err(), GeometryFault::Header);
        assert!(c.geometry.unchanged(gen));
        // Values appended behind the published ones: seen in place, the generation kept.
        c.geometry.append(values.len(), &[1.5, -2.5]).unwrap();
        let (gen2, snap) = c.geometry.snapshot().unwrap();
        assert_eq!((gen2, &snap.values[values.len()..][..2]), (gen, &[1.5, -2.5][..]));
        assert_eq!(
            c.geometry.append(GEOMETRY_VALUES - 1, &[0.0, 0.0]),
            Err(PublishError::TooLarge)
        );
        assert_eq!(c.geometry.append(usize::MAX, &[0.0]), Err(PublishError::TooLarge));
        assert_eq!(c.geometry.publish(&g), Ok(4));
        assert!(!c.geometry.unchanged(gen));
    }

    /// Any budget: each call runs exactly that many value checks (the last one what is left),
    /// across curve boundaries, and the calls cover every check of every curve once.
    #[test]
    fn curves_are_validated_a_budget_at_a_time() {
        let (mut header, one, values) = trident();
        header.curve_count = 3;
        let curves = [one[0]; 3];
        let g = geometry(header, &curves, &values);
        let (k, p, w) = (&values[..11], &values[11..25], &values[25..]);
        let per_curve = CurveView::value_checks(3, k, p, w);
        assert_eq!(per_curve, 11 + 3 + 14 + 7);
        for budget in 1..=2 * per_curve + 1 {
            let (mut at, mut calls) = (CurvesCursor::default(), 0);
            while let CurvesChecked::UpTo(next) = validate_curves(&g, at, budget).unwrap() {
                let checks = |c: CurvesCursor| c.curve * per_curve + c.value;
                assert_eq!(checks(next) - checks(at), budget, "budget {budget}");
                (at, calls) = (next, calls + 1);
            }
            assert_eq!(calls + 1, (3 * per_curve).div_ceil(budget), "budget {budget}");
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
    fn malformed_geometry_is_refused() {
        let (header, curves, values) = trident();
        let check = |h: GeometryHeader, c: &[CurveDesc], v: &[f64]| validate_geometry(&geometry(h, c, v)).map(|_| ());
        let mut c = curves.clone();
        c[0].weights_len = 8; // past the end of the values
        assert_eq!(check(header, &c, &values), Err(GeometryFault::OutOfBounds { curve: 0 }));
        let mut c = curves.clone();
        c[0].knots_offset = u32::MAX; // offset + len overflows
        assert_eq!(check(header, &c, &values), Err(GeometryFault::OutOfBounds { curve: 0 }));
        let mut h = header;
        h.curve_count = MAX_CURVES as u32 + 1;
        assert_eq!(check(h, &curves, &values), Err(GeometryFault::Header));
        let mut h = header;
        h.curve_count = 2; // more than the descriptors
        assert_eq!(check(h, &curves, &values), Err(GeometryFault::Header));
        let mut h = header;
        h.tip_axes = 4;
        assert_eq!(check(h, &curves, &values), Err(GeometryFault::Header));
        let mut v = values.clone();
        v[5] = 0.1; // knots decrease
        assert!(matches!(
            check(header, &curves, &v),
            Err(GeometryFault::Curve { curve: 0, .. })
        ));
        let mut b = block();
        let ch = unsafe { Channel::init(aligned(&mut b)) };
        assert!(matches!(
            ch.geometry.publish(&geometry(header, &curves, &v)),
            Err(PublishError::Invalid(_))
        ));
        assert_eq!(ch.geometry.generation(), 0);
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
                    if c.segments.push(&record(i)).is_ok() {
                        i += 1;
                    }
                }
            });
            let mut expect = 0;
            while expect < COUNT {
                if let Some(r) = c.segments.pop().unwrap() {
                    assert_eq!(r, record(expect));
                    expect += 1;
                }
            }
        });
    }
}
