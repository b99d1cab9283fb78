//! Segment records: the compact, self-contained description of one planned S-curve segment that
//! the planner emits and the realtime interpolator consumes (through HAL shared memory).

use crate::scurve::{SCurve, PHASES};

/// This is the last segment of the toolpath: the motion ends at rest at `u_end`.
pub const FLAG_LAST: u32 = 1;
/// One planned segment along the curve (`#[repr(C)]`, 168 bytes, no pointers).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SegmentRecord {
    /// Consecutive number from 0; a gap or repeat means a lost or duplicated record.
    pub seq: u32,
    /// `FLAG_*` bits.
    pub flags: u32,
    /// Index of the path element (curve) the segment runs on.
    pub curve: u32,
    pub reserved: u32,
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
    /// 64-bit words of a record ([`SegmentRecord::to_words`]).
    pub const WORDS: usize = 21;

    /// The record as words (the four 32-bit fields in two, then the numbers' bits), e.g. to
    /// store it in an arena of `f64` by their bits.
    pub fn to_words(&self) -> [u64; Self::WORDS] {
        let ids = [
            u64::from(self.seq) | (u64::from(self.flags) << 32),
            u64::from(self.curve) | (u64::from(self.reserved) << 32),
        ];
        let numbers = [self.u_start, self.u_end, self.s_start, self.length, self.feed_start];
        let bits = numbers
            .iter()
            .chain(&self.durations)
            .chain(&self.jerks)
            .map(|v| v.to_bits());
        let mut w = [0u64; Self::WORDS];
        for (slot, v) in w.iter_mut().zip(ids.into_iter().chain(bits)) {
            *slot = v;
        }
        w
    }

    /// The record of [`SegmentRecord::to_words`]; `None` if `words` is shorter. No indexing
    /// that can fail (the module reads stop chains with it).
    pub fn from_words(words: &[u64]) -> Option<Self> {
        let [ids, curve, u_start, u_end, s_start, length, feed_start, phases @ ..] = words.get(..Self::WORDS)? else {
            return None;
        };
        let f = |b: &u64| f64::from_bits(*b);
        let mut r = SegmentRecord {
            seq: *ids as u32,
            flags: (*ids >> 32) as u32,
            curve: *curve as u32,
            reserved: (*curve >> 32) as u32,
            u_start: f(u_start),
            u_end: f(u_end),
            s_start: f(s_start),
            length: f(length),
            feed_start: f(feed_start),
            ..SegmentRecord::default()
        };
        let (durations, jerks) = phases.split_at(PHASES.min(phases.len()));
        for (d, w) in r.durations.iter_mut().zip(durations) {
            *d = f(w);
        }
        for (j, w) in r.jerks.iter_mut().zip(jerks) {
            *j = f(w);
        }
        Some(r)
    }

    pub fn profile(&self) -> SCurve {
        SCurve {
            feed_start: self.feed_start,
            durations: self.durations,
            jerks: self.jerks,
        }
    }

    /// Index of the curve (path element) this segment runs on.
    pub fn curve(&self) -> usize {
        self.curve as usize
    }

    pub fn is_last(&self) -> bool {
        self.flags & FLAG_LAST != 0
    }

    /// Structural checks that need no curve: finite numbers, ordered parameters, non-negative
    /// durations and feeds, and a profile whose distance matches `length`.
    pub fn check(&self) -> Result<(), RecordError> {
        self.check_from(0.0)
    }

    /// [`Self::check`] of a record whose profile starts with tangential acceleration
    /// `accel_start` (one that cuts into a running motion, [`crate::block_stop::ramp_record`]).
    pub fn check_from(&self, accel_start: f64) -> Result<(), RecordError> {
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
        if !accel_start.is_finite() {
            return Err(RecordError::NotFinite);
        }
        let end = self.profile().table_from(accel_start).end();
        let scale = 1.0 + self.length;
        if (end.s - self.length).abs() > 1e-6 * scale || end.v < -1e-9 || end.a.abs() > 1e-6 * (1.0 + end.v) {
            return Err(RecordError::Inconsistent);
        }
        Ok(())
    }
}

/// Samples one [`PathBlock`] holds at most (16 periods: 4 ms at a 250 µs period).
pub const BLOCK_SAMPLES: usize = 16;

/// A run of per-period path positions on one curve (`#[repr(C)]`, no pointers): what a planner
/// that works period by period (VPOp) sends. The module sets the position of each period to
/// the curve point at `u[k]`, with no integration, so it outputs exactly the planned positions.
///
/// `s` is the arc length from the curve start (mm, the measure of [`SegmentRecord::s_start`]);
/// `s_before` are the arc lengths of the two samples before `u[0]` in this curve's measure
/// (negative on the previous curve; equal to `s[0]` at the start of the motion, at rest). So the
/// block alone gives the tangential feed and acceleration at every sample, and at its end the
/// state the module's stop starts from. `stop_accel`, `stop_jerk`: the tangential limits of that
/// stop (after an underrun, hold or abort at the block's end), chosen and checked by the planner.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathBlock {
    /// Consecutive number from 0, as for segment records.
    pub seq: u32,
    /// `FLAG_*` bits, as for segment records.
    pub flags: u32,
    /// Index of the path element (curve) of every sample.
    pub curve: u32,
    /// Samples used (1..=[`BLOCK_SAMPLES`]).
    pub count: u32,
    /// Non-zero: the stop after this block is not the tangential one but `stop_len` planned
    /// positions (the planner's own deceleration sequence, to rest) stored in the geometry
    /// arena as [`StopRun`]s from value `stop_offset`; it may go on across element joins.
    pub stop_len: u32,
    pub stop_offset: u32,
    /// The stop points of the block's curve: `points_len` `(s, feed cap)` pairs in the geometry
    /// arena from value `points_offset` (the places the module's stop after this block must not
    /// pass faster than their cap).
    pub points_offset: u32,
    pub points_len: u32,
    /// Highest curve index the rest of the block's group and its stop run on (a stored stop
    /// may cross joins).
    pub curve_needed: u32,
    /// Blocks of the group from this one on (1: the block ends its group). Only a group's last
    /// block has a stop the planner found within the limits; the module takes a group's first
    /// block only once the whole group is queued, and stops only at a group's end.
    pub group_left: u32,
    pub stop_accel: f64,
    pub stop_jerk: f64,
    pub s_before: [f64; 2],
    pub u: [f64; BLOCK_SAMPLES],
    pub s: [f64; BLOCK_SAMPLES],
}

impl PathBlock {
    pub fn curve(&self) -> usize {
        self.curve as usize
    }

    pub fn is_last(&self) -> bool {
        self.flags & FLAG_LAST != 0
    }

    /// Number of samples, clamped to the arrays (a bad count is refused by [`Self::check`]).
    pub fn len(&self) -> usize {
        (self.count as usize).min(BLOCK_SAMPLES)
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Arc length of sample `k` counted from the block's first sample minus 2: index 0 and 1 are
    /// `s_before`, 2.. the samples.
    pub fn s_history(&self, k: usize) -> f64 {
        match k {
            0 | 1 => self.s_before.get(k).copied().unwrap_or(0.0),
            _ => self.s.get(k - 2).copied().unwrap_or(0.0),
        }
    }

    /// Structural checks that need no curve: count within the arrays, group fields, finite
    /// numbers, `u` and `s` non-decreasing (with `s_before` before `s[0]`), positive finite
    /// stop limits.
    pub fn check(&self) -> Result<(), RecordError> {
        let n = self.count as usize;
        if n == 0 || n > BLOCK_SAMPLES || self.group_left == 0 || self.curve_needed < self.curve {
            return Err(RecordError::Inconsistent);
        }
        let (u, s) = (&self.u[..n], &self.s[..n]);
        let limits = [self.stop_accel, self.stop_jerk];
        if u.iter()
            .chain(s)
            .chain(&self.s_before)
            .chain(&limits)
            .any(|v| !v.is_finite())
        {
            return Err(RecordError::NotFinite);
        }
        if limits.iter().any(|v| *v <= 0.0) {
            return Err(RecordError::NegativeFeed);
        }
        if u.windows(2).any(|w| w[1] < w[0]) {
            return Err(RecordError::ParameterOrder);
        }
        let mut previous = f64::NEG_INFINITY;
        for k in 0..n + 2 {
            let v = self.s_history(k);
            if v < previous {
                return Err(RecordError::NegativeFeed);
            }
            previous = v;
        }
        Ok(())
    }
}

/// The header of one run of a stored stop sequence in the geometry arena: the positions of a
/// sequence are stored as runs, each a header of [`StopRun::VALUES`] values (curve index,
/// number of positions, arc length of the position before the run in the run curve's measure)
/// followed by that many `(u, s)` pairs on that curve (`s` in its measure). A sequence that
/// crosses an element join has a run per element; within a run, each position's step starts
/// at the one before, so the arc length of every step is known, as in a [`PathBlock`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StopRun {
    pub curve: usize,
    pub count: usize,
    pub s_before: f64,
}

impl StopRun {
    /// Arena values of the header.
    pub const VALUES: usize = 3;

    pub fn to_values(&self) -> [f64; Self::VALUES] {
        [self.curve as f64, self.count as f64, self.s_before]
    }

    /// The header stored in `values`; `None` unless the curve index is a whole number below
    /// 2^32, the count a whole number from 1 to 2^32 - 1 and the arc length finite.
    pub fn from_values(values: &[f64]) -> Option<Self> {
        let &[curve, count, s_before] = values.get(..Self::VALUES)? else {
            return None;
        };
        let whole = |x: f64, max: f64| x >= 0.0 && x <= max && x == (x as u64) as f64;
        if !(whole(curve, u32::MAX as f64) && whole(count, u32::MAX as f64) && count >= 1.0 && s_before.is_finite()) {
            return None;
        }
        Some(StopRun {
            curve: curve as usize,
            count: count as usize,
            s_before,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_survives_its_words_bit_for_bit() {
        let r = SegmentRecord {
            seq: 7,
            flags: FLAG_LAST,
            curve: 123_456,
            reserved: 9,
            u_start: 0.25,
            u_end: 0.5,
            s_start: -0.0,
            length: 1.0 / 3.0,
            feed_start: f64::MIN_POSITIVE,
            durations: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
            jerks: [-1.0, 0.0, 1.0, 1e300, -1e-300, 2.5, f64::NAN],
        };
        let back = SegmentRecord::from_words(&r.to_words()).unwrap();
        assert_eq!(back.to_words(), r.to_words());
        assert!(SegmentRecord::from_words(&r.to_words()[..20]).is_none());
    }
}
