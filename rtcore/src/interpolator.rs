//! The per-period interpolator: turns a stream of segment records into curve positions.
//!
//! Time runs continuously across segments: a sample at `t` in a segment that ends at `T < t`
//! falls `t - T` into the next one, so segment boundaries need not lie on the servo period. The
//! arc length of a sample is the exact S-curve distance; [`rk2pc_step`] turns it into the curve
//! parameter. The planner runs this very code to check its plan, so what the servo thread
//! produces is what was checked.

use crate::nurbs::CurveView;
use crate::records::SegmentRecord;
use crate::scurve::SCurveTable;
use crate::span_cache::{CachedCurve, SpanCache};
use crate::step_methods::{rk2pc_step, PathCursor};
use crate::Vector;

pub use crate::nurbs::Derivatives as Derivs;

/// Curves (path elements) addressed by the index in a record's flags.
pub trait CurveSet {
    fn curve(&self, index: usize) -> Option<CurveView<'_>>;
    /// Number of tool-tip coordinates (the rest of a 6-D curve is the tool-axis top curve).
    fn tip_axes(&self) -> usize;
    /// Changes whenever curve data may have been rewritten in place (the interpolator's
    /// [`SpanCache`] is keyed by where the data lies).
    fn generation(&self) -> u64 {
        0
    }
}

/// One interpolated setpoint.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    pub curve: usize,
    pub u: f64,
    pub s: f64,
    pub point: Vector,
    /// Planned feed and tangential acceleration at this sample.
    pub feed: f64,
    pub accel: f64,
}

/// What one period produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Sample(Sample),
    /// The sample falls beyond the loaded segments and no next record was available; nothing
    /// changed (the caller decides: wait, or stop).
    Starved,
    /// The last segment has been completed; the position stays at the end.
    Finished,
    /// A record refers to a curve that does not exist or is malformed.
    BadRecord,
}

/// Interpolation state between periods (plain data, `Copy`, so the planner can checkpoint it).
///
/// One 10 mm line, one record from rest to rest at 10 mm/s (ramps of jerk 4,000 mm/s³), run at
/// a 1 ms period as the servo thread runs it:
///
/// ```
/// use nurbs_rtcore::interpolator::{CurveSet, Interpolator, Step};
/// use nurbs_rtcore::records::FLAG_LAST;
/// use nurbs_rtcore::{CurveView, SegmentRecord};
///
/// struct Line;
/// impl CurveSet for Line {
///     fn curve(&self, index: usize) -> Option<CurveView<'_>> {
///         const KNOTS: [f64; 4] = [0.0, 0.0, 10.0, 10.0];
///         const POINTS: [f64; 4] = [0.0, 0.0, 10.0, 0.0];
///         (index == 0).then(|| CurveView::new(1, 2, &KNOTS, &POINTS, &[1.0, 1.0]).unwrap())
///     }
///     fn tip_axes(&self) -> usize {
///         2
///     }
/// }
///
/// let (j, t1) = (4000.0, 0.05); // peak feed j t1^2 = 10 mm/s, each ramp 0.5 mm
/// let record = SegmentRecord {
///     flags: FLAG_LAST,
///     u_end: 10.0,
///     length: 10.0,
///     durations: [t1, 0.0, t1, 0.9, t1, 0.0, t1],
///     jerks: [j, 0.0, -j, 0.0, -j, 0.0, j],
///     ..SegmentRecord::default()
/// };
/// let mut interp = Interpolator::new();
/// let mut queue = Some(record);
/// let mut last = [0.0; 2];
/// loop {
///     match interp.step(&Line, 0.001, &mut || queue.take()) {
///         Step::Sample(s) => last = [s.point[0], s.point[1]],
///         Step::Finished => break,
///         Step::Starved | Step::BadRecord => unreachable!(),
///     }
/// }
/// assert!((last[0] - 10.0).abs() < 1e-9 && last[1] == 0.0);
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct Interpolator {
    cursor: PathCursor,
    curve: usize,
    record: SegmentRecord,
    table: SCurveTable,
    /// Time of the last sample relative to the start of the loaded segment.
    t_local: f64,
    loaded: bool,
    finished: bool,
    /// Taylor data of the knot spans in use (results never depend on it, see [`SpanCache`]).
    spans: SpanCache,
}

/// A record ending at or below this feed (mm/s) ends at rest.
const REST_FEED: f64 = 1e-9;

impl Interpolator {
    /// An interpolator that has not started (the first record positions it).
    pub fn new() -> Self {
        Self::default()
    }

    pub fn is_finished(&self) -> bool {
        self.finished
    }
    pub fn cursor(&self) -> &PathCursor {
        &self.cursor
    }
    pub fn curve_index(&self) -> usize {
        self.curve
    }
    /// The loaded segment record, if any.
    pub fn record(&self) -> Option<&SegmentRecord> {
        self.loaded.then_some(&self.record)
    }
    /// Time left in the loaded segment after the last sample (s).
    pub fn time_left_in_segment(&self) -> f64 {
        if self.loaded {
            (self.table.total_time() - self.t_local).max(0.0)
        } else {
            0.0
        }
    }

    /// The loaded record is not the last and ends at rest: the path has an interior stop there
    /// (a corner), and the next record's first sample lands exactly on it (see [`Self::step`]).
    pub fn ends_at_rest(&self) -> bool {
        self.loaded && !self.record.is_last() && self.table.end().v <= REST_FEED
    }

    /// Local time of the loaded record at which the next record's first sample falls, minus
    /// one period (the offset the next record is loaded with).
    fn next_offset(&self, dt: f64) -> f64 {
        if self.ends_at_rest() {
            -dt
        } else {
            self.t_local - self.table.total_time()
        }
    }

    /// The point of curve `index` at `u`, evaluated as the samples are (so that a position
    /// taken from elsewhere on the path, e.g. a stored stop's, meets them without a rounding
    /// step); `None` if the curve does not exist.
    pub fn point_at<C: CurveSet + ?Sized>(&mut self, curves: &C, index: usize, u: f64) -> Option<Vector> {
        let view = curves.curve(index)?;
        self.spans.use_generation(curves.generation());
        Some(CachedCurve::new(view, &mut self.spans).point(u))
    }

    fn load<C: CurveSet + ?Sized>(&mut self, curves: &C, record: SegmentRecord, t_local: f64) -> bool {
        let index = record.curve();
        // At a stop the machine is at rest exactly at the record's start: place the cursor there
        // (as on a change of curve) rather than carry the interpolated one.
        let at_rest = self.ends_at_rest();
        if !self.loaded || index != self.curve || at_rest {
            let Some(view) = curves.curve(index) else { return false };
            self.spans.use_generation(curves.generation());
            let curve = &mut CachedCurve::new(view, &mut self.spans);
            self.cursor = PathCursor::at(curve, curves.tip_axes(), record.u_start, record.s_start);
            self.curve = index;
        }
        self.record = record;
        self.table = record.profile().table();
        self.t_local = t_local;
        self.loaded = true;
        true
    }

    /// Continues from where a planner's own positions left off: `record` (not the last) on its
    /// curve from `record.u_start` at arc length `record.s_start`, with the feed profile `table`,
    /// which may start with non-zero acceleration (the module's stop after a [`PathBlock`]).
    /// The first sample falls one period after that point; [`Self::step`] continues it.
    ///
    /// [`PathBlock`]: crate::records::PathBlock
    pub fn start_profile<C: CurveSet + ?Sized>(
        &mut self,
        curves: &C,
        record: SegmentRecord,
        table: SCurveTable,
    ) -> bool {
        let index = record.curve();
        let Some(view) = curves.curve(index) else { return false };
        self.spans.use_generation(curves.generation());
        let curve = &mut CachedCurve::new(view, &mut self.spans);
        self.cursor = PathCursor::at(curve, curves.tip_axes(), record.u_start, record.s_start);
        self.curve = index;
        self.record = record;
        self.table = table;
        self.t_local = 0.0;
        self.loaded = true;
        self.finished = false;
        true
    }

    /// Advances one period `dt`, pulling records from `next` as segments are used up.
    pub fn step<C: CurveSet + ?Sized>(
        &mut self,
        curves: &C,
        dt: f64,
        next: &mut dyn FnMut() -> Option<SegmentRecord>,
    ) -> Step {
        if self.finished {
            return Step::Finished;
        }
        if !self.loaded {
            match next() {
                // The first sample lands on the segment start.
                Some(r) => {
                    if !self.load(curves, r, -dt) {
                        return Step::BadRecord;
                    }
                }
                None => return Step::Starved,
            }
        }
        loop {
            let total = self.table.total_time();
            if self.t_local + dt <= total || self.record.is_last() {
                break;
            }
            match next() {
                // The last sample lies before the new segment's start: negative local time.
                // After a stop at rest the motion waits there for the rest of the period, so
                // that a sample lands exactly on the stop point (a corner): no pair of samples
                // straddles it, and the chord between them cannot cut the corner.
                Some(r) => {
                    if !self.load(curves, r, self.next_offset(dt)) {
                        return Step::BadRecord;
                    }
                }
                None => return Step::Starved,
            }
        }
        let t = (self.t_local + dt).min(self.table.total_time());
        let Some(view) = curves.curve(self.curve) else {
            return Step::BadRecord;
        };
        self.spans.use_generation(curves.generation());
        let curve = &mut CachedCurve::new(view, &mut self.spans);
        let mut state = self.table.state_at(t);
        let s_target = self.record.s_start + state.s;
        if self.record.is_last() && t >= self.table.total_time() {
            // End of the path: land exactly on the end parameter, at rest (the profile's end
            // feed is zero up to rounding).
            self.cursor = PathCursor::at(curve, curves.tip_axes(), self.record.u_end, s_target);
            self.finished = true;
            (state.v, state.a) = (0.0, 0.0);
        } else {
            self.cursor = rk2pc_step(curve, curves.tip_axes(), &self.cursor, s_target);
        }
        self.t_local = t;
        Step::Sample(Sample {
            curve: self.curve,
            u: self.cursor.u,
            s: self.cursor.s,
            point: self.cursor.point,
            feed: state.v,
            accel: state.a,
        })
    }
}
