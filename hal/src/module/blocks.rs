//! Path-block motions (VPOp's per-period positions) and the stored stop sequences that end
//! them: the block player, the validation of every block and sample, the stop points.

use super::*;

/// Playback state of a path-block motion, and of a stored stop sequence (after a block or a
/// segment record; plain data).
#[derive(Clone, Copy, Debug)]
pub(super) struct BlockPlayer {
    pub(super) block: PathBlock,
    /// A block has been taken (the motion started).
    pub(super) loaded: bool,
    /// Samples of `block` output so far.
    pub(super) index: usize,
    /// The last sample of the last block has been output: at rest at the path end.
    pub(super) finished: bool,
    /// A sample of this motion has been output (the fields below describe it).
    has_sample: bool,
    /// The last output sample: curve, parameter, arc length, the one before's arc length, point.
    pub(super) curve: usize,
    pub(super) u: f64,
    pub(super) s: f64,
    pub(super) s_before: f64,
    pub(super) point: [f64; 3],
    /// Running a stored stop sequence: where it is read.
    pub(super) stored: Option<StoredCursor>,
    /// The stop points of the last block taken, validated (with the arena offset and length
    /// they came as: blocks on one curve share them, checked once).
    pub(super) points: StopPoints,
}

impl BlockPlayer {
    pub(super) const IDLE: BlockPlayer = BlockPlayer {
        block: PathBlock {
            seq: 0,
            flags: 0,
            count: 0,
            stop_len: 0,
            stop_offset: 0,
            points_offset: 0,
            points_len: 0,
            curve: 0,
            curve_needed: 0,
            group_left: 0,
            stop_accel: 0.0,
            stop_jerk: 0.0,
            s_before: [0.0; 2],
            u: [0.0; nurbs_rtcore::BLOCK_SAMPLES],
            s: [0.0; nurbs_rtcore::BLOCK_SAMPLES],
        },
        loaded: false,
        index: 0,
        finished: false,
        has_sample: false,
        curve: 0,
        u: 0.0,
        s: 0.0,
        s_before: 0.0,
        point: [0.0; 3],
        stored: None,
        points: StopPoints::NONE,
    };

    pub(super) fn remaining(&self) -> usize {
        self.block.len().saturating_sub(self.index)
    }
}

/// Where a stored stop sequence ([`StopRun`]s in the arena) is being read.
#[derive(Clone, Copy, Debug)]
pub(super) struct StoredCursor {
    /// The record or block it follows.
    pub(super) seq: u32,
    /// Arena index of the next value to read (a run header when `run_left` is 0).
    pub(super) next: usize,
    /// Positions of the sequence still to output.
    pub(super) left: usize,
    /// Positions of the current run still to read.
    pub(super) run_left: usize,
    /// The arc length before the run's first position, until that position is read.
    pub(super) run_s_before: Option<f64>,
}

impl StoredCursor {
    pub(super) fn new(seq: u32, offset: u32, len: u32) -> Self {
        StoredCursor {
            seq,
            next: offset as usize,
            left: len as usize,
            run_left: 0,
            run_s_before: None,
        }
    }
}

/// Validated stop points (`(s, feed cap)` pairs in the arena) and where they came from.
#[derive(Clone, Copy, Debug)]
pub(super) struct StopPoints {
    pub(super) key: Option<(u32, u32)>,
    pub(super) pairs: &'static [f64],
}

impl StopPoints {
    pub(super) const NONE: StopPoints = StopPoints { key: None, pairs: &[] };

    /// The `len` pairs at `offset` of `values`, checked unless they are the ones held already;
    /// `None` if they are not valid stop points ([`stop_points`]).
    pub(super) fn take(&mut self, values: &'static [f64], offset: u32, len: u32) -> Option<()> {
        if self.key != Some((offset, len)) {
            let pairs = stop_points(values, offset, len)?;
            *self = StopPoints {
                key: Some((offset, len)),
                pairs,
            };
        }
        Some(())
    }
}

impl Instance {
    /// One period of a path-block motion: the next planned position, exactly; at a block end
    /// without a next block (underrun) or under hold/abort, the stop from the block's end state
    /// along the curve, run by the interpolator.
    pub(super) fn advance_blocks(&mut self, channel: &Channel, dt: f64, hold: bool, abort: bool) -> bool {
        if self.stopping {
            return match self.interp.step(&self.geometry, dt, &mut || None) {
                Step::Sample(s) => self.output(&s),
                Step::BadRecord => {
                    self.fault = FaultCode::BadRecord;
                    false
                }
                Step::Starved | Step::Finished => {
                    let held = self.held_by_interp();
                    self.stop_over(channel, self.block_player.block.seq, held);
                    false
                }
            };
        }
        if self.block_player.finished {
            return false;
        }
        if self.block_player.remaining() == 0 {
            // Within a group the next block is queued (the group was whole when its first block
            // was taken) and runs whatever the commands; at a group's end the next group runs
            // only if it is whole, on checked curves, and neither hold nor abort is on.
            let in_group = self.block_player.loaded && self.block_player.block.group_left > 1;
            let block = if (hold || abort) && !in_group {
                None
            } else {
                match channel.segments.consumer().peek() {
                    Ok(Some(slot)) => match slot.decode() {
                        Some(Record::Block(b)) => {
                            let whole = channel.segments.len() as u64 >= u64::from(b.group_left);
                            let ready = in_group || (whole && b.curve_needed < self.geometry.checked);
                            if in_group && b.group_left.wrapping_add(1) != self.block_player.block.group_left {
                                self.fault = FaultCode::Record;
                                return false;
                            }
                            if ready {
                                let _ = channel.segments.consumer().pop();
                            }
                            ready.then_some(b)
                        }
                        _ => {
                            self.fault = FaultCode::RecordKind;
                            return false;
                        }
                    },
                    Ok(None) if in_group => {
                        self.fault = FaultCode::Channel; // a queued group lost a block
                        return false;
                    }
                    Ok(None) => None,
                    Err(_) => {
                        self.fault = FaultCode::Channel;
                        return false;
                    }
                }
            };
            let Some(block) = block else {
                if !self.block_player.loaded {
                    return false; // waiting for the first block
                }
                // Underrun, hold or abort at the block end: the checked stop from here.
                self.begin_stop(hold, abort);
                let last = self.block_player.block;
                if last.stop_len > 0 {
                    // The planner's own deceleration sequence, stored with the geometry.
                    let cursor = StoredCursor::new(last.seq, last.stop_offset, last.stop_len);
                    self.block_player.stored = Some(cursor);
                    return self.advance_stored_stop(channel, cursor);
                }
                let (stop, a0) = block_stop(self.block_player.points.pairs, &last, dt);
                let table = stop.profile().table_from(a0);
                if !self.interp.start_profile(&self.geometry, stop, table) {
                    self.fault = FaultCode::BadRecord;
                    return false;
                }
                return self.advance_blocks(channel, dt, hold, abort);
            };
            if let Err(code) = self.take_block(&block) {
                self.fault = code;
                return false;
            }
        }
        self.output_block_sample()
    }

    /// One period of a stored stop sequence: the next position (checked as a block sample);
    /// after the last one, at rest there.
    pub(super) fn advance_stored_stop(&mut self, channel: &Channel, mut c: StoredCursor) -> bool {
        let p = self.block_player;
        if c.left == 0 {
            let held = self.held_at(p.curve, p.u, p.s, p.point);
            self.stop_over(channel, c.seq, held);
            return false;
        }
        let values = self.geometry.values();
        let mut curve = p.curve;
        if c.run_left == 0 {
            let Some(run) = values.get(c.next..).and_then(StopRun::from_values) else {
                self.fault = FaultCode::BlockPath;
                return false;
            };
            c.next = c.next.saturating_add(StopRun::VALUES);
            c.run_left = run.count;
            c.run_s_before = Some(run.s_before);
            curve = run.curve;
        }
        let (Some(&u), Some(&s), Some(view)) = (
            values.get(c.next),
            values.get(c.next.saturating_add(1)),
            self.geometry.curve(curve),
        ) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        let Some(point) = self.interp.point_at(&self.geometry, curve, u) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        // On the same curve onwards from the last position, or at the start of a run on a
        // later curve (across the join, and past elements shorter than the step), where the run
        // gives the step's start in its measure.
        let s_before = c.run_s_before.take().unwrap_or(p.s);
        let follows = if curve == p.curve {
            u >= p.u && s_before == p.s
        } else {
            curve > p.curve && u >= view.u_min()
        };
        let sample = Sample {
            curve,
            u,
            s,
            point,
            feed: 0.0,
            accel: 0.0,
        };
        let here = self.point_of(&sample);
        let chord = distance(&p.point, &here);
        let finite = u.is_finite() && s.is_finite();
        if !(finite && follows && u <= view.u_max() && step_fits(chord, s - s_before)) {
            self.fault = FaultCode::BlockPath;
            return false;
        }
        if !self.output(&Sample {
            feed: chord / self.period,
            ..sample
        }) {
            return false;
        }
        c.next = c.next.saturating_add(2);
        c.run_left = c.run_left.saturating_sub(1);
        c.left = c.left.saturating_sub(1);
        let player = &mut self.block_player;
        player.stored = Some(c);
        player.curve = curve;
        player.s_before = s_before;
        player.u = u;
        player.s = s;
        player.point = here;
        true
    }

    /// Validates `block` against the sequence, the curve, the previous block and (on a
    /// resume) the stop point, then makes it the current block.
    fn take_block(&mut self, b: &PathBlock) -> Result<(), FaultCode> {
        if b.seq != self.next_seq {
            return Err(FaultCode::Sequence);
        }
        b.check().map_err(|_| FaultCode::Record)?;
        self.block_player
            .points
            .take(self.geometry.values(), b.points_offset, b.points_len)
            .ok_or(FaultCode::Record)?;
        let n = b.len();
        let view = self.geometry.curve(b.curve()).ok_or(FaultCode::BadRecord)?;
        let (lo, hi) = (view.u_min(), view.u_max());
        if b.u.iter().take(n).any(|u| *u < lo || *u > hi) {
            return Err(FaultCode::BlockPath);
        }
        let p = &self.block_player;
        let continues = if self.resuming {
            // The plan from the stop point starts there, at rest.
            self.held
                .is_some_and(|h| h.is_at(b.curve(), b.u[0], b.s[0]) && b.s_before == [b.s[0], b.s[0]])
        } else if !p.loaded {
            b.s_before == [b.s[0], b.s[0]] // the motion starts at rest
        } else if b.curve() == p.curve {
            b.u[0] >= p.u && b.s_before == [p.s_before, p.s]
        } else {
            b.curve() > p.curve // the next element; its own arc-length measure
        };
        if !continues {
            return Err(if self.resuming {
                FaultCode::ResumePoint
            } else {
                FaultCode::BlockPath
            });
        }
        self.next_seq = b.seq.wrapping_add(1);
        self.records = self.records.wrapping_add(1);
        self.taken_time += n as f64 * self.period;
        self.pins.seq.set(b.seq);
        let player = &mut self.block_player;
        player.block = *b;
        player.index = 0;
        player.loaded = true;
        Ok(())
    }

    /// Outputs the current block's next sample: the curve point at its parameter, after
    /// checking it against the arc lengths (and, on a resume, the held position).
    fn output_block_sample(&mut self) -> bool {
        let p = self.block_player;
        let b = &p.block;
        let k = p.index;
        let (Some(&u), Some(&s)) = (b.u.get(k), b.s.get(k)) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        let Some(point) = self.interp.point_at(&self.geometry, b.curve(), u) else {
            self.fault = FaultCode::BlockPath;
            return false;
        };
        let mut sample = Sample {
            curve: b.curve(),
            u,
            s,
            point,
            feed: 0.0,
            accel: 0.0,
        };
        let here = self.point_of(&sample);
        // The feed pin: the setpoints' speed over the last period (as VPOp reports it).
        let chord = distance(&p.point, &here);
        if p.has_sample {
            sample.feed = chord / self.period;
        }
        if self.resuming {
            let held = self.held.map(|h| h.point);
            if held.is_none_or(|h| distance(&h, &here) > RESUME_TOLERANCE) {
                self.fault = FaultCode::ResumePoint;
                return false;
            }
            self.resuming = false;
            self.held = None;
        } else if p.has_sample {
            // Not the motion's first sample: the step's chord must fit its arc length.
            let ds = s - b.s_history(k + 1);
            if !step_fits(chord, ds) {
                self.fault = FaultCode::BlockPath;
                return false;
            }
        }
        if !self.output(&sample) {
            return false;
        }
        let player = &mut self.block_player;
        player.index = k + 1;
        player.curve = b.curve();
        player.s_before = b.s_history(k + 1);
        player.u = u;
        player.s = s;
        player.point = here;
        player.has_sample = true;
        if b.is_last() && player.index >= b.len() {
            player.finished = true;
        }
        true
    }
}
