//! The record type the channel carries.
//!
//! INTEGRATION POINT: this is a byte-for-byte stand-in for `nurbs_rtcore::records::SegmentRecord`
//! (same fields, same order, `#[repr(C)]`, 160 bytes) so that this crate builds before rtcore
//! does. Once `nurbs-rtcore` is a dependency, replace the struct by
//! `pub use nurbs_rtcore::records::SegmentRecord;` and keep the layout assertions.

/// Number of phases of a jerk-limited S-curve.
pub const PHASES: usize = 7;

/// One planned segment (mirror of `nurbs_rtcore::records::SegmentRecord`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SegmentRecord {
    /// Consecutive number from 0; a gap or repeat means a lost or duplicated record.
    pub seq: u32,
    /// `FLAG_*` bits.
    pub flags: u32,
    /// Curve parameter at the segment start and end.
    pub u_start: f64,
    pub u_end: f64,
    /// Arc length from the curve start to the segment start, and the segment length (mm).
    pub s_start: f64,
    pub length: f64,
    /// Feed at the segment start (mm/s).
    pub feed_start: f64,
    /// Phase durations (s).
    pub durations: [f64; PHASES],
    /// Constant jerk of each phase (mm/s^3).
    pub jerks: [f64; PHASES],
}

// The shared-memory layout is an ABI between two separately built programs: pin it.
const _: () = assert!(core::mem::size_of::<SegmentRecord>() == 160);
const _: () = assert!(core::mem::align_of::<SegmentRecord>() == 8);
