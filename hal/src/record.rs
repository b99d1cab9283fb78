//! The record types the channel carries: the realtime core's own [`SegmentRecord`] (Erwinski
//! planner: S-curve segments) and [`PathBlock`] (VPOp: per-period positions), each in a tagged
//! ring [`Slot`].

pub use nurbs_rtcore::records::{PathBlock, SegmentRecord, CURVE_SHIFT, FLAG_LAST};

/// Number of phases of a jerk-limited S-curve (the length of the records' phase arrays;
/// spelled out for the C header).
pub const PHASES: usize = 7;
const _: () = assert!(PHASES == nurbs_rtcore::scurve::PHASES);

/// Samples one path block holds at most (spelled out for the C header).
pub const BLOCK_SAMPLES: usize = 16;
const _: () = assert!(BLOCK_SAMPLES == nurbs_rtcore::BLOCK_SAMPLES);

/// [`Slot::kind`] of a [`SegmentRecord`].
pub const KIND_SEGMENT: u32 = 1;
/// [`Slot::kind`] of a [`PathBlock`].
pub const KIND_BLOCK: u32 = 2;

/// The stop the module makes after a segment record if no further record is taken (underrun,
/// hold, abort), as the planner chose and checked it (within the axis limits by finite
/// differences). Every segment record carries its own: a record is never run before its stop
/// is known, and the planner can hand records out while it is still choosing later stops.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RecordStop {
    /// Tangential deceleration and jerk of the module's stop (mm/s^2, mm/s^3).
    pub accel: f64,
    pub jerk: f64,
    /// Non-zero: instead, the planner's stop sequence of this many positions, stored as
    /// [`StopRun`](nurbs_rtcore::StopRun)s in the geometry arena from value `stored_offset`
    /// (written before the record was pushed).
    pub stored_len: u32,
    pub stored_offset: u32,
    /// The stop points of the record's curve: `points_len` `(s, feed cap)` pairs in the arena
    /// from value `points_offset` (arc length from the curve start in the records' measure, mm;
    /// feed cap, mm/s): the planner's critical points and the curve end (feed 0), which the
    /// tangential stop must not pass faster than their cap.
    pub points_offset: u32,
    pub points_len: u32,
}

impl RecordStop {
    /// The limits are positive and finite (the stored sequence is checked as it is played).
    pub fn is_valid(&self) -> bool {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        positive(self.accel) && positive(self.jerk)
    }
}

/// A segment record with the stop after it: the segment payload of a [`Slot`].
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SegmentSlot {
    pub record: SegmentRecord,
    pub stop: RecordStop,
}

/// The payload of a [`Slot`]; which field is meant is [`Slot::kind`]. Both are plain numbers,
/// so any bytes read as either are valid values (the module still validates them).
#[repr(C)]
#[derive(Clone, Copy)]
pub union SlotData {
    pub segment: SegmentSlot,
    pub block: PathBlock,
}

/// One ring slot: a record of either kind, tagged.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct Slot {
    /// `KIND_*`; anything else is refused.
    pub kind: u32,
    pub reserved: u32,
    pub data: SlotData,
}

/// A decoded slot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Record {
    Segment(SegmentRecord, RecordStop),
    Block(PathBlock),
}

impl Slot {
    /// Every byte initialised (the shorter kind leaves zeros behind it).
    fn zeroed(kind: u32) -> Slot {
        Slot {
            kind,
            reserved: 0,
            data: SlotData {
                block: PathBlock::default(),
            },
        }
    }

    pub fn segment(record: &SegmentRecord, stop: &RecordStop) -> Slot {
        let mut slot = Slot::zeroed(KIND_SEGMENT);
        slot.data.segment = SegmentSlot {
            record: *record,
            stop: *stop,
        };
        slot
    }

    pub fn block(b: &PathBlock) -> Slot {
        let mut slot = Slot::zeroed(KIND_BLOCK);
        slot.data.block = *b;
        slot
    }

    /// The record, or `None` for an unknown kind.
    pub fn decode(&self) -> Option<Record> {
        // SAFETY: both union fields are plain f64/u32 data, valid for any bit pattern, and a
        // slot is always written whole (`Slot::segment`, `Slot::block`, or zeroed memory).
        unsafe {
            match self.kind {
                KIND_SEGMENT => Some(Record::Segment(self.data.segment.record, self.data.segment.stop)),
                KIND_BLOCK => Some(Record::Block(self.data.block)),
                _ => None,
            }
        }
    }

    /// Sequence number (either kind; 0 for an unknown kind).
    pub fn seq(&self) -> u32 {
        match self.decode() {
            Some(Record::Segment(r, _)) => r.seq,
            Some(Record::Block(b)) => b.seq,
            None => 0,
        }
    }
}

impl Default for Slot {
    fn default() -> Self {
        Slot::zeroed(0)
    }
}

impl PartialEq for Slot {
    fn eq(&self, other: &Self) -> bool {
        self.kind == other.kind && self.decode() == other.decode()
    }
}

impl core::fmt::Debug for Slot {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Slot({}, {:?})", self.kind, self.decode())
    }
}

impl From<&PathBlock> for Slot {
    fn from(b: &PathBlock) -> Slot {
        Slot::block(b)
    }
}

// The shared-memory layout is an ABI between two separately built programs: pin it.
const _: () = assert!(core::mem::size_of::<SegmentRecord>() == 160);
const _: () = assert!(core::mem::align_of::<SegmentRecord>() == 8);
const _: () = assert!(core::mem::size_of::<SegmentSlot>() == 192);
const _: () = assert!(core::mem::size_of::<PathBlock>() == 320);
const _: () = assert!(core::mem::size_of::<Slot>() == 328);
const _: () = assert!(core::mem::align_of::<Slot>() == 8);
