//! Segment-record motions: the records the interpolator takes from the ring a group at a time
//! ([`SegmentSource`]), the stop record and chain a group ends with, and the hold stops checked
//! inside a record ([`hold_stop_at`]).

use super::blocks::StoredCursor;
use super::*;
use crate::channel::{Consumer, Join, Splice, AT_RECORD_END, SEGMENT_SLOTS, SPLICE_DONE, SPLICE_MISSED};
use crate::slot::Slot;

/// Where a segment-record motion stands: the slot of the record it runs and what is left of a
/// stop chain (plain data).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SegmentPlayer {
    /// The last segment record taken, with its stop and group (checked when taken).
    pub(super) slot: SegmentSlot,
    /// During a segment stop: the rest of its stop chain in the arena.
    pub(super) chain: ChainCursor,
    /// Samples of segment records output in this motion (the index hold stops refer to).
    pub(super) samples: u64,
}

/// Where the rest of a stop chain is read ([`SegmentSlot::chain_offset`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct ChainCursor {
    /// Arena index of the next record's first word.
    pub(super) next: usize,
    /// Records left.
    pub(super) left: u32,
    /// Sequence number the next one must carry.
    pub(super) seq: u32,
}

impl ChainCursor {
    /// The next record of the chain, checked (sequence and structure); `Err` if it is
    /// malformed or outside the arena, `Ok(None)` after the last.
    pub(super) fn next(&mut self, values: &[f64]) -> Result<Option<SegmentRecord>, FaultCode> {
        if self.left == 0 {
            return Ok(None);
        }
        let end = self.next.checked_add(SegmentRecord::WORDS).ok_or(FaultCode::Record)?;
        let words = values.get(self.next..end).ok_or(FaultCode::Record)?;
        let mut bits = [0u64; SegmentRecord::WORDS];
        for (b, v) in bits.iter_mut().zip(words) {
            *b = v.to_bits();
        }
        let r = SegmentRecord::from_words(&bits).ok_or(FaultCode::Record)?;
        let last = self.left == 1;
        if r.seq != self.seq || check_record(&r, 0.0).is_err() || (last && !ends_at_rest(&r)) {
            return Err(FaultCode::Record);
        }
        self.next = end;
        self.left -= 1;
        self.seq = r.seq.wrapping_add(1);
        Ok(Some(r))
    }
}

/// Where the interpolator takes segment records from: the ring, a group at a time.
struct SegmentSource<'a> {
    ring: Consumer<'a, Slot, SEGMENT_SLOTS>,
    splice: &'a Splice,
    geometry: &'a RtGeometry,
    /// Take nothing more at a group's end.
    no_more: bool,
    /// The first record must start here (a resumed motion).
    resume_from: Option<Held>,
    next_seq: &'a mut u32,
    /// The last slot taken.
    slot: &'a mut SegmentSlot,
    records: &'a mut u32,
    taken_time: &'a mut f64,
    seq_pin: &'a Pin<u32>,
    pull: &'a mut Pull,
}

impl SegmentSource<'_> {
    /// The next record for the interpolator, or `None` (and why in `pull`). Within a group the
    /// next record is always queued (the group was complete when its first record was taken);
    /// at a group's end the next group is taken only if it is complete, on checked curves, and
    /// neither hold nor abort is on.
    pub(super) fn next(&mut self) -> Option<SegmentRecord> {
        if *self.pull != Pull::Fine {
            return None;
        }
        // Before the first record the last slot is the default one, of no group.
        let at_group_end = self.slot.group_left <= 1;
        if at_group_end && self.no_more {
            return None;
        }
        if at_group_end {
            // A plan at another feed override joins here: the old plan's records after this
            // group are dropped.
            if let Some(join) = self.splice.accepted().filter(|j| j.at_sample == AT_RECORD_END) {
                if self.ring.taken().wrapping_sub(1) == join.after {
                    if self.ring.skip_to(join.drop_to).is_err() {
                        *self.pull = Pull::Fault(FaultCode::Channel);
                        return None;
                    }
                    self.splice.answer(SPLICE_DONE);
                }
            }
        }
        let slot = match self.ring.peek() {
            Ok(Some(slot)) => slot,
            Ok(None) => {
                *self.pull = if at_group_end {
                    Pull::Empty
                } else {
                    Pull::Fault(FaultCode::Channel) // a queued group lost a record
                };
                return None;
            }
            Err(_) => {
                *self.pull = Pull::Fault(FaultCode::Channel);
                return None;
            }
        };
        let Some(Record::Segment(next)) = slot.decode() else {
            *self.pull = Pull::Fault(FaultCode::RecordKind);
            return None;
        };
        if at_group_end {
            // A new group: only whole, and on curves the module has checked.
            let queued = self.ring.len();
            if (queued as u64) < u64::from(next.group_left) || next.curve_needed >= self.geometry.checked {
                *self.pull = Pull::Empty;
                return None;
            }
        } else if next.group_left.wrapping_add(1) != self.slot.group_left {
            *self.pull = Pull::Fault(FaultCode::Record);
            return None;
        }
        if let Err(code) = self.check(&next) {
            *self.pull = Pull::Fault(code);
            return None;
        }
        if !matches!(self.ring.pop(), Ok(Some(_))) {
            *self.pull = Pull::Fault(FaultCode::Channel);
            return None;
        }
        let r = next.record;
        *self.next_seq = r.seq.wrapping_add(1);
        *self.slot = next;
        *self.records = self.records.wrapping_add(1);
        *self.taken_time += r.profile().total_time();
        self.seq_pin.set(r.seq);
        Some(r)
    }

    /// A slot's checks before its record runs ([`check_slot`]).
    pub(super) fn check(&self, next: &SegmentSlot) -> Result<(), FaultCode> {
        check_slot(next, *self.next_seq, self.resume_from, 0.0)
    }
}

/// A slot's checks before its record runs: sequence (`next_seq`), the resume point, structure
/// of the record (its profile started with tangential acceleration `accel_start`), its stop (a
/// record ending at rest, next in sequence) and its group fields.
fn check_slot(next: &SegmentSlot, next_seq: u32, resume_from: Option<Held>, accel_start: f64) -> Result<(), FaultCode> {
    let r = &next.record;
    if r.seq != next_seq {
        return Err(FaultCode::Sequence);
    }
    if resume_from.is_some_and(|h| !starts_at(r, &h)) {
        return Err(FaultCode::ResumePoint);
    }
    check_record(r, accel_start).map_err(|_| FaultCode::Record)?;
    if !next.is_consistent() {
        return Err(FaultCode::Record);
    }
    if let Some(stop) = next.stop() {
        // A one-record stop ends at rest; a chain's last record does (checked as it comes).
        let at_rest = next.chain_len > 0 || ends_at_rest(stop);
        let ok = stop.seq == r.seq.wrapping_add(1) && stop.curve <= next.curve_needed && at_rest;
        if !ok || check_record(stop, 0.0).is_err() {
            return Err(FaultCode::Record);
        }
    }
    Ok(())
}

/// What the record source saw while the interpolator pulled records.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pull {
    Fine,
    Empty,
    Fault(FaultCode),
}

impl Instance {
    /// One period of a segment-record motion: the next sample of the interpolator on the records
    /// of the ring (or, during a stop, of its stop record and chain); at a group's end under
    /// hold or abort, or without the next group, the group's checked stop.
    pub(super) fn advance_segments(&mut self, channel: &Channel, dt: f64, hold: bool, abort: bool) -> bool {
        let mut pull = Pull::Fine;
        let step = if self.stopping {
            // A stop chain goes on from the arena; a one-record stop has nothing more.
            let (values, chain, pull) = (self.geometry.values(), &mut self.segment_player.chain, &mut pull);
            self.interp.step(&self.geometry, dt, &mut || match chain.next(values) {
                Ok(r) => r,
                Err(code) => {
                    *pull = Pull::Fault(code);
                    None
                }
            })
        } else {
            let source = SegmentSource {
                ring: channel.segments.consumer(),
                splice: &channel.splice,
                geometry: &self.geometry,
                // Hold and abort wait for the end of the group; nothing is taken during a stop.
                no_more: self.stopping || hold || abort,
                resume_from: if self.resuming { self.held } else { None },
                next_seq: &mut self.next_seq,
                slot: &mut self.segment_player.slot,
                records: &mut self.records,
                taken_time: &mut self.taken_time,
                seq_pin: &self.pins.seq,
                pull: &mut pull,
            };
            let mut source = source;
            self.interp.step(&self.geometry, dt, &mut || source.next())
        };
        match (step, pull) {
            (_, Pull::Fault(code)) => {
                self.fault = code;
                false
            }
            (Step::Sample(s), _) => {
                if self.resuming {
                    // The resumed motion's first sample: it must be where the machine stands.
                    let here = self.held.map(|h| h.point);
                    if here.is_none_or(|p| distance(&p, &self.point_of(&s)) > RESUME_TOLERANCE) {
                        self.fault = FaultCode::ResumePoint;
                        return false;
                    }
                    self.resuming = false;
                    self.held = None;
                }
                if !self.output(&s) {
                    return false;
                }
                let n = self.segment_player.samples;
                self.segment_player.samples = self.segment_player.samples.wrapping_add(1);
                if (hold || abort) && !self.stopping {
                    // A checked stop inside the record at this very sample: take it now rather
                    // than at the group's end.
                    match hold_stop_at(&self.segment_player.slot, self.geometry.values(), n) {
                        Ok(Some(stop)) => self.stop_here(&s, stop, hold, abort),
                        Ok(None) => {}
                        Err(code) => self.fault = code,
                    }
                } else if let Some(join) = channel.splice.accepted().filter(|j| j.at_sample == n) {
                    self.cut_in(channel, &s, join);
                }
                channel.splice.report_samples(self.segment_player.samples);
                true
            }
            (Step::Finished, _) => false,
            (Step::BadRecord, _) => {
                self.fault = FaultCode::BadRecord;
                false
            }
            (Step::Starved, _) => {
                let Some(last) = self.interp.record().copied() else {
                    return false; // not started yet: waiting for the first group
                };
                if self.stopping {
                    let held = self.held_by_interp();
                    self.stop_over(channel, last.seq, held);
                    return false;
                }
                // At a group's end (hold, abort, or the next group is not there): its stop, the
                // next segment re-planned to rest, checked when the record was taken.
                self.begin_stop(hold, abort);
                let Some(stop) = self.segment_player.slot.stop().copied() else {
                    self.fault = FaultCode::Record;
                    return false;
                };
                self.next_seq = stop.seq.wrapping_add(1);
                self.segment_player.chain = ChainCursor {
                    next: self.segment_player.slot.chain_offset as usize,
                    left: self.segment_player.slot.chain_len,
                    seq: self.next_seq,
                };
                // The stop record, then (within the same period if it is that short) its chain.
                let mut stop = Some(stop);
                let (values, chain, mut failed) = (self.geometry.values(), &mut self.segment_player.chain, None);
                let step = self.interp.step(&self.geometry, dt, &mut || {
                    stop.take().or_else(|| {
                        chain.next(values).unwrap_or_else(|code| {
                            failed = Some(code);
                            None
                        })
                    })
                });
                if let Some(code) = failed {
                    self.fault = code;
                    return false;
                }
                match step {
                    Step::Sample(s) => self.output(&s),
                    Step::BadRecord => {
                        self.fault = FaultCode::BadRecord;
                        false
                    }
                    Step::Starved | Step::Finished => false,
                }
            }
        }
    }

    /// A plan at another feed override cuts in after sample `s` (just output, motion sample
    /// `join.at_sample` of record `join.after`; [`crate::channel::Splice`]): the old plan's
    /// records are dropped up to `join.drop_to`, and the new plan's first record, which starts at
    /// this very sample (its feed changing from the sample's feed and acceleration), runs from
    /// here. Where the new plan's first group is not whole in the ring (its planner came late),
    /// the join is missed and the motion stops with the checked hold stop at this sample (the
    /// join was accepted only with one there), as an underrun.
    fn cut_in(&mut self, channel: &Channel, s: &Sample, join: Join) {
        let ring = channel.segments.consumer();
        let skip = join.drop_to.wrapping_sub(ring.taken());
        let queued = ring.len() as u32;
        let in_record = ring.taken().wrapping_sub(1) == join.after;
        let first = match ring.peek_at(skip) {
            Ok(Some(slot)) if in_record && skip < queued => slot.decode(),
            _ => None,
        };
        let next = match first {
            Some(Record::Segment(next))
                if queued - skip >= next.group_left
                    && next.curve_needed < self.geometry.checked
                    && starts_at_sample(&next.record, s) =>
            {
                next
            }
            _ => {
                channel.splice.answer(SPLICE_MISSED);
                match hold_stop_at(&self.segment_player.slot, self.geometry.values(), join.at_sample) {
                    Ok(Some(stop)) => self.stop_here(s, stop, false, false),
                    Ok(None) | Err(_) => self.fault = FaultCode::Record,
                }
                return;
            }
        };
        let seq = self.segment_player.slot.record.seq.wrapping_add(1);
        if let Err(code) = check_slot(&next, seq, None, s.accel) {
            self.fault = code;
            return;
        }
        if ring.skip_to(join.drop_to).is_err() || !matches!(ring.pop(), Ok(Some(_))) {
            self.fault = FaultCode::Channel;
            return;
        }
        let r = next.record;
        let table = r.profile().table_from(s.accel);
        if !self.interp.start_profile(&self.geometry, r, table) {
            self.fault = FaultCode::BadRecord;
            return;
        }
        self.next_seq = r.seq.wrapping_add(1);
        self.segment_player.slot = next;
        self.records = self.records.wrapping_add(1);
        self.taken_time += table.total_time();
        self.pins.seq.set(r.seq);
        channel.splice.answer(SPLICE_DONE);
    }

    /// Stops from sample `s` (just output) with the checked hold stop there
    /// ([`SegmentSlot::hold_stops_offset`]): the S-curve record the planner simulated, started
    /// from that sample, or its stored sequence of positions from the next period on; nothing is
    /// taken from the ring any more.
    fn stop_here(&mut self, s: &Sample, stop: HoldStop, hold: bool, abort: bool) {
        let seq = self.segment_player.slot.record.seq.wrapping_add(1);
        match stop {
            HoldStop::SCurve { accel, jerk } => {
                let from = StopStart {
                    seq,
                    flags: 0,
                    curve: u32::try_from(s.curve).unwrap_or(u32::MAX),
                    u: s.u,
                    s: s.s,
                    feed: s.feed,
                    accel: s.accel,
                };
                let (stop, a0) = stop_record(&from, accel, jerk);
                if !self
                    .interp
                    .start_profile(&self.geometry, stop, stop.profile().table_from(a0))
                {
                    self.fault = FaultCode::BadRecord;
                    return;
                }
            }
            HoldStop::Stored { offset, len } => {
                // Read as a path-block motion's stored stop is, from where this sample stands.
                let point = self.point_of(s);
                let player = &mut self.block_player;
                player.curve = s.curve;
                player.u = s.u;
                player.s = s.s;
                player.s_before = s.s;
                player.point = point;
                player.stored = Some(StoredCursor::new(seq, offset, len));
            }
        }
        self.begin_stop(hold, abort);
        self.segment_player.chain = ChainCursor::default();
    }
}

/// A checked stop inside a record ([`SegmentSlot::hold_stops_offset`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum HoldStop {
    /// The S-curve stop [`stop_record`] builds from the sample with this deceleration and jerk.
    SCurve { accel: f64, jerk: f64 },
    /// The stored sequence of `len` positions from arena value `offset`.
    Stored { offset: u32, len: u32 },
}

/// The checked hold stop of `slot` at motion sample `n`, if it has one there; `Err` if its hold
/// stops do not lie in the arena or the one found is not valid. The triples are in increasing
/// sample order: a binary search, at most 17 probes (their count is at most
/// [`crate::slot::MAX_HOLD_STOPS`], checked when the slot was taken), so a period under hold
/// costs the same whatever the record's length.
pub(super) fn hold_stop_at(slot: &SegmentSlot, values: &[f64], n: u64) -> Result<Option<HoldStop>, FaultCode> {
    if slot.hold_stops_len == 0 {
        return Ok(None);
    }
    let start = slot.hold_stops_offset as usize;
    let len = (slot.hold_stops_len as usize).checked_mul(3).ok_or(FaultCode::Record)?;
    let end = start.checked_add(len).ok_or(FaultCode::Record)?;
    let triples = values.get(start..end).ok_or(FaultCode::Record)?;
    let target = n as f64;
    let (mut lo, mut hi) = (0usize, triples.len() / 3);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        let Some(&[at, a, b]) = triples.get(3 * mid..3 * mid + 3) else {
            return Err(FaultCode::Record);
        };
        if at < target {
            lo = mid + 1;
        } else if at > target {
            hi = mid;
        } else if at == target && a > 0.0 && b > 0.0 && a.is_finite() && b.is_finite() {
            return Ok(Some(HoldStop::SCurve { accel: a, jerk: b }));
        } else {
            // A stored sequence: a whole count, and an offset past the triples within the
            // arena's index range (what lies there is checked as it is read). Anything else
            // (not a number, not a valid stop) the planner never writes.
            let whole = |x: f64| x >= 0.0 && x <= u32::MAX as f64 && x == (x as u64) as f64;
            let (count, offset) = (-a, b);
            let stored = at == target && whole(count) && count >= 1.0 && whole(offset) && offset >= len as f64;
            return match (start as u64).checked_add(offset as u64) {
                Some(o) if stored && o <= u64::from(u32::MAX) => Ok(Some(HoldStop::Stored {
                    offset: o as u32,
                    len: count as u32,
                })),
                _ => Err(FaultCode::Record),
            };
        }
    }
    Ok(None)
}

/// True if `r` ends at rest (to rounding): the last record of a stop.
fn ends_at_rest(r: &SegmentRecord) -> bool {
    r.profile().table().end().v <= FEED_ROUNDING
}

/// True if `r` starts exactly at sample `s`: its element, parameter, arc length and feed (a
/// record that cuts into a running one, [`nurbs_rtcore::block_stop::ramp_record`]).
fn starts_at_sample(r: &SegmentRecord, s: &Sample) -> bool {
    r.curve() == s.curve
        && r.u_start.to_bits() == s.u.to_bits()
        && r.s_start.to_bits() == s.s.to_bits()
        && r.feed_start.to_bits() == s.feed.to_bits()
}

/// True if `r` starts at rest exactly at `held` (element, parameter and arc length as held).
fn starts_at(r: &SegmentRecord, held: &Held) -> bool {
    held.is_at(r.curve(), r.u_start, r.s_start) && r.feed_start == 0.0
}

/// Rounding slack for a start feed: the planner hands on a segment's computed end feed, which
/// can come out a few ulps below zero where the path stops (seen: -2.8e-14 mm/s).
const FEED_ROUNDING: f64 = 1e-9;

/// `SegmentRecord::check_from(accel_start)`, except that a start feed within
/// [`FEED_ROUNDING`] below zero counts as zero. Only the check sees the adjusted copy: the record
/// runs as sent, so the motion stays the one the planner simulated.
fn check_record(r: &SegmentRecord, accel_start: f64) -> Result<(), nurbs_rtcore::RecordError> {
    let mut checked = *r;
    if (-FEED_ROUNDING..0.0).contains(&checked.feed_start) {
        checked.feed_start = 0.0;
    }
    checked.check_from(accel_start)
}
