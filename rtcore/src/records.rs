//! Segment records: the compact, self-contained description of one planned S-curve segment that
//! the planner emits and the realtime interpolator consumes (through HAL shared memory).

use crate::scurve::{SCurve, PHASES};

/// This is the last segment of the toolpath: the motion ends at rest at `u_end`.
pub const FLAG_LAST: u32 = 1;
/// The path element (curve) a segment runs on is stored in the upper 16 bits of `flags`.
pub const CURVE_SHIFT: u32 = 16;

/// One planned segment along the curve (`#[repr(C)]`, 21 machine words, no pointers).
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
    /// Arc length from the start of its curve to the segment start, and the segment length (mm).
    pub s_start: f64,
    pub length: f64,
    /// Feed at the segment start (mm/s); the tangential acceleration there is zero.
    pub feed_start: f64,
    /// Phase durations (s).
    pub durations: [f64; PHASES],
    /// Constant jerk of each phase (mm/s^3).
    pub jerks: [f64; PHASES],
}

/// Why a record cannot be executed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    NotFinite,
    NegativeDuration,
    NegativeFeed,
    ParameterOrder,
    /// The S-curve does not cover the stated length, or ends with non-zero acceleration.
    Inconsistent,
    /// The sequence number is not the one expected.
    Sequence,
}

impl SegmentRecord {
    pub fn profile(&self) -> SCurve {
        SCurve {
            feed_start: self.feed_start,
            durations: self.durations,
            jerks: self.jerks,
        }
    }

    /// Index of the curve (path element) this segment runs on.
    pub fn curve(&self) -> usize {
        (self.flags >> CURVE_SHIFT) as usize
    }

    pub fn is_last(&self) -> bool {
        self.flags & FLAG_LAST != 0
    }

    /// Structural checks that need no curve: finite numbers, ordered parameters, non-negative
    /// durations and feeds, and a profile whose distance matches `length`.
    pub fn check(&self) -> Result<(), RecordError> {
        let values = [self.u_start, self.u_end, self.s_start, self.length, self.feed_start];
        if values
            .iter()
            .chain(&self.durations)
            .chain(&self.jerks)
            .any(|v| !v.is_finite())
        {
            return Err(RecordError::NotFinite);
        }
        if self.durations.iter().any(|d| *d < 0.0) {
            return Err(RecordError::NegativeDuration);
        }
        if self.feed_start < 0.0 || self.length < 0.0 {
            return Err(RecordError::NegativeFeed);
        }
        if self.u_end < self.u_start {
            return Err(RecordError::ParameterOrder);
        }
        let end = self.profile().table().end();
        let scale = 1.0 + self.length;
        if (end.s - self.length).abs() > 1e-6 * scale || end.v < -1e-9 || end.a.abs() > 1e-6 * (1.0 + end.v) {
            return Err(RecordError::Inconsistent);
        }
        Ok(())
    }
}
