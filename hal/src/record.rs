//! The record type the channel carries: the realtime core's own [`SegmentRecord`].

pub use nurbs_rtcore::records::{SegmentRecord, CURVE_SHIFT, FLAG_LAST};

/// Number of phases of a jerk-limited S-curve (the length of the records' phase arrays;
/// spelled out for the C header).
pub const PHASES: usize = 7;
const _: () = assert!(PHASES == nurbs_rtcore::scurve::PHASES);

// The shared-memory layout is an ABI between two separately built programs: pin it.
const _: () = assert!(core::mem::size_of::<SegmentRecord>() == 160);
const _: () = assert!(core::mem::align_of::<SegmentRecord>() == 8);
