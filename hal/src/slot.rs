//! The record types the channel carries: the realtime core's own [`SegmentRecord`] (Erwinski
//! planner: S-curve segments, in a [`SegmentSlot`] with the stop after it) and [`PathBlock`]
//! (VPOp: per-period positions), each in a tagged ring [`Slot`].

// Reached from the update path: no unwrap, expect, panic or indexing that can fail.
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing)]

pub use nurbs_rtcore::records::{PathBlock, SegmentRecord, FLAG_LAST};

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

/// A segment record as the ring carries it: with the stop after it and where it stands in
/// its group.
///
/// The planner hands records out in groups that end at a boundary with a stop: the next
/// segment re-planned to end at rest from that boundary, checked by finite differences with
/// the machine holding at its end (`nurbs_motion::planner::FinalRecord`). The
/// records inside a group have no stop of their own: the motion may end only at a group's end.
/// So the module takes the first record of a group only once the whole group is in the ring
/// (`group_left` records from it on) on checked curves (up to `curve_needed`), and holds,
/// aborts or stops for an underrun only at a group's end, by running `stop`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SegmentSlot {
    pub record: SegmentRecord,
    /// The stop after this record (when `has_stop` is 1): a record of sequence number
    /// `record.seq + 1` that ends at rest.
    pub stop: SegmentRecord,
    /// Records of the group from this one on (1: this record ends its group).
    pub group_left: u32,
    /// 1: `stop` is the stop after this record; 0: none (inside a group, or the path's last
    /// record, which ends at rest).
    pub has_stop: u32,
    /// Highest curve index the rest of the group and its stop run on.
    pub curve_needed: u32,
    /// The stop goes on after `stop` with `chain_len` more records (a stop chain over short
    /// segments), stored as words ([`SegmentRecord::to_words`], each word the bits of an
    /// `f64`) in the geometry arena from value `chain_offset`, written before the slot was
    /// pushed.
    pub chain_offset: u32,
    pub chain_len: u32,
    /// Checked stops inside this record, for a hold or abort that should not wait for the
    /// group's end: `hold_stops_len` triples in the arena from value `hold_stops_offset`, in
    /// increasing sample order. A triple (motion sample index, deceleration, jerk) with both
    /// positive: at that sample the module may switch to the stop
    /// [`nurbs_rtcore::block_stop::stop_record`] builds from it. A triple (motion sample index,
    /// -count, offset): a stored stop sequence of `count` positions in [`StopRun`]s from arena
    /// value `hold_stops_offset + offset` (after the triples), output one per period from the
    /// sample after it (the planner's per-period deceleration, where no S-curve stop passes).
    /// The planner checked exactly what the module then runs.
    ///
    /// [`StopRun`]: nurbs_rtcore::StopRun
    pub hold_stops_offset: u32,
    pub hold_stops_len: u32,
    pub reserved: u32,
}

/// Most checked hold stops one record may carry.
pub const MAX_HOLD_STOPS: u32 = 1 << 16;

impl SegmentSlot {
    /// The stop after this record, if it has one.
    pub fn stop(&self) -> Option<&SegmentRecord> {
        (self.has_stop == 1).then_some(&self.stop)
    }

    /// The group fields fit together: a group's last record has a stop or ends the path, the
    /// others have none.
    pub fn is_consistent(&self) -> bool {
        let ends_group = self.group_left == 1;
        self.group_left >= 1
            && self.has_stop <= 1
            && (self.has_stop == 1) == (ends_group && !self.record.is_last())
            && (self.has_stop == 1 || self.chain_len == 0)
            && self.hold_stops_len <= MAX_HOLD_STOPS
            && self.curve_needed >= self.record.curve
    }
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
    Segment(SegmentSlot),
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

    pub fn segment(segment: &SegmentSlot) -> Slot {
        let mut slot = Slot::zeroed(KIND_SEGMENT);
        slot.data.segment = *segment;
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
                KIND_SEGMENT => Some(Record::Segment(self.data.segment)),
                KIND_BLOCK => Some(Record::Block(self.data.block)),
                _ => None,
            }
        }
    }

    /// Sequence number (either kind; 0 for an unknown kind).
    pub fn seq(&self) -> u32 {
        match self.decode() {
            Some(Record::Segment(s)) => s.record.seq,
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
const _: () = assert!(core::mem::size_of::<SegmentRecord>() == 168);
const _: () = assert!(core::mem::align_of::<SegmentRecord>() == 8);
const _: () = assert!(core::mem::size_of::<SegmentSlot>() == 368);
const _: () = assert!(core::mem::size_of::<PathBlock>() == 328);
const _: () = assert!(core::mem::size_of::<Slot>() == 376);
const _: () = assert!(core::mem::align_of::<Slot>() == 8);
