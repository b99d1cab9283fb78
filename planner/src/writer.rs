//! Planner side of the geometry stream ([`crate::channel::GeometryStream`]): writes curves, and
//! for path blocks their stop points and stored stop sequences, into the channel's descriptor
//! ring and arena as the motion needs them, and reuses what the module has passed. Userspace
//! only (it allocates its bookkeeping); nothing here runs on the servo thread.

use std::collections::VecDeque;

use nurbs_hal::channel::{
    Channel, CurveDesc, GeometryHeader, PublishError, Report, ARENA_VALUES, CURVE_SLOTS, MAX_JOINTS,
};

/// Largest curve index a stream may carry (the module reports curves in 31 bits).
pub const MAX_CURVE_INDEX: u32 = (1 << 31) - 1;

/// When arena values may be written over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Release {
    /// Once the module is past curve `c` (it reports a later curve).
    Curve(u32),
    /// Once the module has taken the ring slot after slot `k` (counted from the stream's first
    /// push): it runs past the end of slot `k`, whose stop it will not need.
    Slot(u64),
}

/// Values written, and when their range may be written over.
#[derive(Clone, Copy, Debug)]
struct Held {
    start: usize,
    end: usize,
    release: Release,
}

/// Why a write cannot happen.
#[derive(Clone, Debug, PartialEq)]
pub enum WriteError {
    /// Not now: the module still needs what lies there; try again once it has moved on.
    Full,
    /// Never: the data are larger than the channel, malformed, or the stream is too long.
    Refused(String),
}

/// One geometry stream being written.
pub struct GeometryWriter<'a> {
    channel: &'a Channel,
    generation: u32,
    first_curve: u32,
    /// Next curve index to publish.
    next_curve: u32,
    /// Next arena value to write (physical index).
    write: usize,
    /// What the module may still read, oldest first.
    held: VecDeque<Held>,
    /// Arena values and curve descriptors this stream uses at most ([`GeometryWriter::limit`]).
    arena_values: usize,
    curves_in_flight: u64,
    /// Values written in all, and how often the writing wrapped to the arena's start.
    written: u64,
    wraps: u64,
}

impl<'a> GeometryWriter<'a> {
    /// Begins a new stream (the module must run no motion: it refuses one that begins during
    /// motion) whose first curve is path element `first_curve`, planned for the servo period
    /// `period` (s; the module refuses the stream on a thread of another period).
    pub fn begin(channel: &'a Channel, first_curve: u32, tip_axes: usize, period: f64) -> Result<Self, String> {
        if first_curve > MAX_CURVE_INDEX {
            return Err(format!(
                "path element {first_curve} is beyond the channel's {MAX_CURVE_INDEX}"
            ));
        }
        let period_ns = (period * 1e9).round();
        if !(period_ns >= 1.0 && period_ns <= f64::from(u32::MAX)) {
            return Err(format!("a servo period of {period} s cannot be stated in the channel"));
        }
        let header = GeometryHeader {
            first_curve,
            tip_axes: tip_axes as u32,
            joints: 0,
            period_ns: period_ns as u32,
        };
        let generation = channel.geometry.begin(&header).map_err(|e| {
            format!("geometry stream refused: {e:?} (tool-tip axes {tip_axes}, at most {MAX_JOINTS} joints)")
        })?;
        Ok(GeometryWriter {
            channel,
            generation,
            first_curve,
            next_curve: first_curve,
            write: 0,
            held: VecDeque::new(),
            arena_values: ARENA_VALUES,
            curves_in_flight: CURVE_SLOTS as u64,
            written: 0,
            wraps: 0,
        })
    }

    pub fn generation(&self) -> u32 {
        self.generation
    }

    /// Uses at most `arena_values` of the arena and `curves_in_flight` descriptor slots (at
    /// most the channel's): short programs then reuse both as long ones do (tests).
    pub fn limit(&mut self, arena_values: usize, curves_in_flight: usize) {
        self.arena_values = arena_values.min(ARENA_VALUES);
        self.curves_in_flight = curves_in_flight.clamp(1, CURVE_SLOTS) as u64;
    }

    /// Arena values the writer may use ([`Self::limit`]).
    pub fn arena_capacity(&self) -> usize {
        self.arena_values
    }

    /// Index of the next curve [`GeometryWriter::publish_curve`] publishes.
    pub fn next_curve(&self) -> u32 {
        self.next_curve
    }

    /// The path element the module is on (the stream's first before its first report).
    pub fn module_curve(&self) -> u32 {
        self.report().curve
    }

    /// The module's report on this stream (before its first report: at the first curve).
    fn report(&self) -> Report {
        let r = self.channel.progress.read();
        if r.generation == self.generation {
            r
        } else {
            Report {
                generation: self.generation,
                moving: false,
                curve: self.first_curve,
            }
        }
    }

    /// Forgets what the module no longer needs: `taken` is how many slots of this stream it
    /// has taken from the ring.
    pub fn reclaim(&mut self, taken: u64) {
        let curve = self.report().curve;
        while let Some(h) = self.held.front() {
            let released = match h.release {
                Release::Curve(c) => c < curve,
                Release::Slot(k) => taken >= k.saturating_add(2),
            };
            if !released {
                break;
            }
            self.held.pop_front();
        }
    }

    /// Where `n` values can go now (physical offset), without wrapping inside them: after the
    /// last write, else at the arena's start, where no value the module may still read lies.
    /// (Where the writing has come round to the oldest value held, the arena is full: the two
    /// positions alone cannot tell that from an empty arena, so every held range is looked at.)
    fn room(&self, n: usize) -> Result<usize, WriteError> {
        let capacity = self.arena_values;
        if n > capacity {
            return Err(WriteError::Refused(format!(
                "{n} values do not fit the channel's arena of {capacity}"
            )));
        }
        let free = |at: usize| {
            at + n <= capacity
                && self
                    .held
                    .iter()
                    .all(|h| h.start == h.end || h.end <= at || at + n <= h.start)
        };
        [self.write, 0].into_iter().find(|&at| free(at)).ok_or(WriteError::Full)
    }

    /// Writes `values` into the arena to stay until `release`; returns their offset.
    pub fn put(&mut self, values: &[f64], release: Release) -> Result<u32, WriteError> {
        let at = self.room(values.len())?;
        self.channel
            .geometry
            .write_values(at, values)
            .map_err(|e| WriteError::Refused(format!("arena write refused: {e:?}")))?;
        let end = at + values.len();
        self.count(at, values.len());
        self.held.push_back(Held {
            start: at,
            end,
            release,
        });
        self.write = end;
        u32::try_from(at).map_err(|_| WriteError::Refused("arena offset beyond 32 bits".into()))
    }

    /// Publishes the next curve (its values, then its descriptor); checked first as the module
    /// will check it.
    pub fn publish_curve(
        &mut self,
        degree: usize,
        dim: usize,
        knots: &[f64],
        points: &[f64],
        weights: &[f64],
    ) -> Result<(), WriteError> {
        let index = self.next_curve;
        if index > MAX_CURVE_INDEX {
            return Err(WriteError::Refused(format!(
                "more than {MAX_CURVE_INDEX} path elements"
            )));
        }
        // The descriptor slot must be free: the module is past the curve that used it.
        if u64::from(index) >= u64::from(self.report().curve) + self.curves_in_flight {
            return Err(WriteError::Full);
        }
        let n = knots.len() + points.len() + weights.len();
        let at = self.room(n)?;
        let data: Vec<f64> = knots.iter().chain(points).chain(weights).copied().collect();
        let len = |x: &[f64]| x.len() as u32;
        let offset = at as u32;
        let desc = CurveDesc {
            index,
            degree: degree as u32,
            dim: dim as u32,
            knots_offset: offset,
            knots_len: len(knots),
            points_offset: offset + len(knots),
            points_len: len(points),
            weights_offset: offset + len(knots) + len(points),
            weights_len: len(weights),
            reserved: 0,
        };
        let geometry = &self.channel.geometry;
        geometry
            .write_values(at, &data)
            .map_err(|e| WriteError::Refused(format!("arena write refused: {e:?}")))?;
        geometry.publish_curve(&desc).map_err(|e| match e {
            PublishError::Invalid(f) => WriteError::Refused(format!("curve {index} refused: {f:?}")),
            PublishError::OutOfPlace => WriteError::Refused(format!("curve {index} out of order")),
        })?;
        self.count(at, n);
        self.held.push_back(Held {
            start: at,
            end: at + n,
            release: Release::Curve(index),
        });
        self.write = at + n;
        self.next_curve = index + 1;
        Ok(())
    }

    /// Arena values held for the module (what it may still read).
    pub fn held_values(&self) -> usize {
        self.held.iter().map(|h| h.end - h.start).sum()
    }

    /// Curves published, arena values written, and how often the arena was reused from its
    /// start, in this stream.
    pub fn usage(&self) -> (u32, u64, u64) {
        (self.next_curve - self.first_curve, self.written, self.wraps)
    }

    /// Counts a write of `n` values at `at`.
    fn count(&mut self, at: usize, n: usize) {
        if at < self.write {
            self.wraps += 1;
        }
        self.written += n as u64;
    }
}
