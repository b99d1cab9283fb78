//! The shared-memory channel from the userspace planner to the realtime module.
//!
//! The realtime module creates one RTAPI shared-memory block ([`CHANNEL_KEY`], created in
//! `rtapi_app_main`, zeroed by RTAPI) and lays a [`Channel`] over it; the planner attaches to the
//! same key and checks the header before writing. The block holds a single-producer /
//! single-consumer ring of fixed-size [`SegmentRecord`]s: the planner only advances `head`, the
//! module only advances `tail`, each with release ordering after touching a slot and acquire
//! ordering before reading the other side's counter. No locks, no syscalls, no allocation.
//!
//! Why not `hal_stream`: it carries at most `HAL_STREAM_MAX_PINS` = 21 values per record, exactly
//! the size of a segment record, which leaves no room for a record kind, and curve geometry
//! (knots, control points, weights: variable size, possibly thousands of values) would have to be
//! chopped into 21-value pieces on a second stream. Our own block keeps one ABI-checked layout
//! (magic, version, record size, capacity) for both and grows without limits of HAL's.
//! GEOMETRY: the geometry area (a fixed-capacity arena published with a generation counter) goes
//! after `segments` in [`Channel`] and bumps [`CHANNEL_VERSION`].

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicU32, Ordering};

pub use crate::record::SegmentRecord;

/// RTAPI shared-memory key of the channel ("NRB0").
pub const CHANNEL_KEY: i32 = 0x4E52_4230;
/// "NRBS": written last by the creator, so a reader that sees it sees an initialised header.
pub const CHANNEL_MAGIC: u32 = 0x4E52_4253;
/// Layout version; bump on any change to [`Channel`] or the record types.
pub const CHANNEL_VERSION: u32 = 1;
/// Segment slots in the ring (a power of two). 1024 segments cover far more than the buffered
/// time margin the planner keeps.
pub const SEGMENT_SLOTS: usize = 1024;

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

    /// Consumer side: take the oldest record. Never allocates, locks or panics.
    pub fn pop(&self) -> Result<Option<T>, ChannelError> {
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
        let record = unsafe { slot.get().read_volatile() };
        self.tail.0.store(tail.wrapping_add(1), Ordering::Release);
        Ok(Some(record))
    }
}

/// The layout of the shared-memory block.
#[repr(C)]
pub struct Channel {
    magic: AtomicU32,
    version: AtomicU32,
    record_size: AtomicU32,
    segment_slots: AtomicU32,
    /// Planner → module segment records.
    pub segments: SpscRing<SegmentRecord, SEGMENT_SLOTS>,
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
        channel.record_size.store(
            core::mem::size_of::<SegmentRecord>() as u32,
            Ordering::Relaxed,
        );
        channel
            .segment_slots
            .store(SEGMENT_SLOTS as u32, Ordering::Relaxed);
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
            && self.record_size.load(Ordering::Relaxed) as usize
                == core::mem::size_of::<SegmentRecord>()
            && self.segment_slots.load(Ordering::Relaxed) as usize == SEGMENT_SLOTS;
        if layout_ok {
            Ok(())
        } else {
            Err(ChannelError::Layout)
        }
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

    fn record(seq: u32) -> SegmentRecord {
        SegmentRecord {
            seq,
            u_start: seq as f64 / 7.0,
            ..SegmentRecord::default()
        }
    }

    #[test]
    fn attach_refuses_uninitialised_and_foreign_layouts() {
        let mut b = block();
        let p = aligned(&mut b);
        assert_eq!(
            unsafe { Channel::attach(p) }.err(),
            Some(ChannelError::NotInitialised)
        );
        let c = unsafe { Channel::init(p) };
        assert!(unsafe { Channel::attach(p) }.is_ok());
        c.version.store(CHANNEL_VERSION + 1, Ordering::Relaxed);
        assert_eq!(
            unsafe { Channel::attach(p) }.err(),
            Some(ChannelError::Layout)
        );
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
        c.segments
            .head
            .0
            .store(SEGMENT_SLOTS as u32 + 1, Ordering::Relaxed);
        assert_eq!(c.segments.pop(), Err(ChannelError::Corrupt));
        assert_eq!(c.segments.push(&record(0)), Err(ChannelError::Corrupt));
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
