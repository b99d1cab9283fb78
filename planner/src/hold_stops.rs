//! Checked stops inside segment records, so that a hold or abort need not wait for the end of
//! the group.
//!
//! A group's stop is the only stop a record of the Erwinski plan carries, and a group may last
//! up to a second (a single long line is one record). So the planner also checks stops inside
//! the records, every [`HOLD_STOP_SPACING`] samples of the motion: it runs the module's own
//! interpolator over the records in the order the module runs them (a replica, sample for
//! sample the machine's), and at each such sample the stop that
//! [`nurbs_rtcore::block_stop::stop_record`] builds from it (an S-curve to rest along the element
//! from the sample's feed and tangential acceleration) is simulated through the same
//! interpolator and checked by finite differences against the axis limits, continuing the
//! motion's samples and holding at rest after it, as every stop of the plan is. The deceleration
//! and jerk start just inside what the axes allow along the tangent there and are lowered
//! until the stop passes ([`STOP_SCALES`]; on a curve the centripetal terms leave less). A stop that would leave the
//! element, or that does not pass, is not offered: the hold waits for the next one (or the
//! group's end). The module, holding, switches to the first offered stop at or after the
//! hold's edge, at exactly that sample.

use nurbs_hal::slot::MAX_HOLD_STOPS;
use nurbs_motion::geometry::ArcLengthTable;
use nurbs_motion::planner::axial::FiniteDifferences;
use nurbs_motion::planner::simulate::SimState;
use nurbs_motion::planner::verify::SLACK;
use nurbs_motion::planner::{Limits, PathCurves};
use nurbs_rtcore::block_stop::{stop_record, StopStart};
use nurbs_rtcore::interpolator::{Interpolator, Sample, Step};
use nurbs_rtcore::SegmentRecord;

/// Samples of motion between two checked hold stops: the longest a hold waits (5 ms at the
/// 0.25 ms servo period), if the stop there passes.
pub const HOLD_STOP_SPACING: u64 = 20;

/// Stops tried at a sample, in turn: (deceleration, jerk) as shares of the tangential limits
/// there. The first steps are small: near sharp curvature the centripetal terms take a few
/// percent of an axis' jerk, and a much softer stop keeps the feed up for longer, into more
/// curvature.
pub(crate) const STOP_SCALES: [(f64, f64); 8] = [
    (1.0, 1.0),
    (0.95, 0.9),
    (0.9, 0.8),
    (0.8, 0.65),
    (0.7, 0.5),
    (0.6, 0.36),
    (0.45, 0.2),
    (0.3, 0.1),
];

/// The first try aims this far inside the tangential limits: at the limits themselves the
/// rounding of a third difference of positions far from the origin (1e-6 relative at 1 m and
/// 0.25 ms) decides the check.
pub(crate) const INSIDE: f64 = 1.0 - 1e-3;

/// Below this feed (mm/s) the motion is as good as at rest: no stop is offered there.
const MOVING: f64 = 1e-6;

/// The replica of the module's motion and the stops checked along it.
pub struct HoldStops {
    replica: Interpolator,
    /// Finite differences of the motion so far (the history a stop continues).
    fd: FiniteDifferences,
    /// Index of the motion's next sample.
    samples: u64,
    limits: Limits,
    /// Arc length of the element the last stop was checked on.
    element_length: Option<ElementLength>,
    /// The motion's last sample.
    last: Option<Sample>,
    /// Accept stops on straight elements by their profile alone ([`Self::passes_on_line`]);
    /// off, every stop is simulated (to show that both agree).
    line_shortcut: bool,
}

impl HoldStops {
    /// Simulates every stop, on straight elements too (the check that the shortcut agrees).
    pub fn simulating_lines(self) -> HoldStops {
        HoldStops {
            line_shortcut: false,
            ..self
        }
    }

    pub fn new(limits: &Limits) -> HoldStops {
        HoldStops {
            replica: Interpolator::new(),
            fd: FiniteDifferences::new(limits.velocity.len(), limits.period),
            samples: 0,
            limits: limits.clone(),
            element_length: None,
            last: None,
            line_shortcut: true,
        }
    }

    /// Continues a motion whose planner stands at `state` (a plan at another feed override,
    /// after a group already sent): the replica, its history and its sample count are the
    /// planner's there, as the module's are.
    pub fn continuing(limits: &Limits, state: &SimState) -> HoldStops {
        HoldStops {
            replica: state.interp,
            fd: state.check,
            samples: state.samples as u64,
            last: state.last_sample,
            ..HoldStops::new(limits)
        }
    }

    /// The motion's state after the records run so far, as the planner's [`SimState`] (the
    /// module's, sample for sample).
    pub fn state(&self) -> SimState {
        SimState {
            interp: self.replica,
            check: self.fd,
            samples: self.samples as usize,
            last_sample: self.last,
        }
    }

    /// [`Self::after`] for a record that cuts into the motion at its last sample: started there
    /// with tangential acceleration `accel_start` ([`nurbs_rtcore::block_stop::ramp_record`]).
    pub fn after_cut(&mut self, record: &SegmentRecord, accel_start: f64, curves: &PathCurves) -> Vec<f64> {
        let table = record.profile().table_from(accel_start);
        if !self.replica.start_profile(curves, *record, table) {
            return Vec::new();
        }
        self.run(record, None, curves)
    }

    /// Runs `record` (the motion's next) on the replica and returns the stops checked inside it,
    /// as arena values: triples (motion sample index, deceleration, jerk).
    pub fn after(&mut self, record: &SegmentRecord, curves: &PathCurves) -> Vec<f64> {
        self.run(record, Some(*record), curves)
    }

    /// Runs the replica until it needs a record after `pending` (`record`, or `None` where it is
    /// loaded already), checking stops inside `record`.
    fn run(&mut self, record: &SegmentRecord, mut pending: Option<SegmentRecord>, curves: &PathCurves) -> Vec<f64> {
        let (tip, dt) = (self.limits.velocity.len(), self.limits.period);
        let mut out = Vec::new();
        loop {
            match self.replica.step(curves, dt, &mut || pending.take()) {
                Step::Sample(s) => {
                    let n = self.samples;
                    self.samples += 1;
                    self.last = Some(s);
                    self.fd.push(&s.point[..tip], &self.limits);
                    // A record takes at most MAX_HOLD_STOPS (minutes of motion): a hold in the
                    // rest of such a record waits for its group's end.
                    let room = out.len() < 3 * MAX_HOLD_STOPS as usize;
                    if room && n.is_multiple_of(HOLD_STOP_SPACING) && s.feed > MOVING {
                        if let Some((accel, jerk)) = self.check(&s, record, curves) {
                            out.extend([n as f64, accel, jerk]);
                        }
                    }
                }
                Step::Starved | Step::Finished | Step::BadRecord => return out,
            }
        }
    }

    /// The deceleration and jerk of a stop from sample `s` that stays on its element and within
    /// the axis limits, if one of [`STOP_SCALES`] does.
    fn check(&mut self, s: &Sample, record: &SegmentRecord, curves: &PathCurves) -> Option<(f64, f64)> {
        let dt = self.limits.period;
        let mut length = self.element_length(s.curve, curves)?;
        let tangential = tangential_limits(curves, &self.limits, s.curve, s.u);
        let (accel0, jerk0) = (tangential.0 * INSIDE, tangential.1 * INSIDE);
        let from = StopStart {
            seq: record.seq.wrapping_add(1),
            flags: 0,
            curve: s.curve as u32,
            u: s.u,
            s: s.s,
            feed: s.feed,
            accel: s.accel,
        };
        let line = self.line_shortcut && curves.get(s.curve).is_some_and(|e| is_line(&e.curve));
        for (sa, sj) in STOP_SCALES {
            let (accel, jerk) = (accel0 * sa, jerk0 * sj);
            if let Some(landed) = landing_jerk(&from, accel, jerk, dt) {
                let passed = if line {
                    self.passes_on_line(&from, (accel, landed), tangential, &mut length, curves)
                } else {
                    self.passes(&from, accel, landed, &mut length, curves)
                };
                self.element_length = Some(length);
                if passed {
                    return Some((accel, landed));
                }
            }
        }
        None
    }

    /// Whether the stop from `from` with `accel` and `jerk` stays on its element (of arc length
    /// `length`) and, continuing the motion's samples and held at rest after it, within the axis
    /// limits.
    fn passes(&self, from: &StopStart, accel: f64, jerk: f64, length: &mut ElementLength, curves: &PathCurves) -> bool {
        let (tip, dt) = (self.limits.velocity.len(), self.limits.period);
        let (stop, a0) = stop_record(from, accel, jerk);
        // Room for rounding of the arc length at the element's end.
        let leaves = |length: f64| stop.s_start + stop.length >= length * (1.0 - 1e-9) - 1e-9;
        // Beyond the bound it leaves the exact length too (most stops on short elements).
        if length.bound.is_some_and(leaves) || leaves(length.exact(curves)) {
            return false;
        }
        let mut sim = self.replica;
        if !sim.start_profile(curves, stop, stop.profile().table_from(a0)) {
            return false;
        }
        // A stop that starts while the plan still accelerates speeds up first: never beyond the
        // feed the plan may run there.
        let cap = curves
            .programmed_feed(stop.curve())
            .map_or(self.limits.feed, |f| f.min(self.limits.feed));
        let mut f = self.fd;
        f.reset_peaks();
        while let Step::Sample(x) = sim.step(curves, dt, &mut || None) {
            f.push(&x.point[..tip], &self.limits);
            let too_fast = x.feed > cap && x.feed > from.feed;
            if too_fast || x.curve != stop.curve() || f.worst_ratio(&self.limits) > 1.0 + SLACK {
                return false;
            }
        }
        f.finish(&self.limits);
        f.worst_ratio(&self.limits) <= 1.0 + SLACK
    }

    /// [`Self::passes`] on a straight element, from the stop's profile alone: on a line every
    /// axis moves in proportion to the arc length, so a stop whose tangential deceleration and
    /// jerk stay within `tangential` (the axes' limits along the line) and whose feed stays
    /// within the axes' velocities keeps every axis within its limits, and so do the finite
    /// differences of its samples (a third difference is the jerk averaged over three periods
    /// with a non-negative kernel of unit mass, and the motion is continuous in acceleration
    /// from the plan into the stop and from the stop, landing just after a sample, to rest).
    /// What it checks beyond that: the stop stays on the element, and never runs faster than
    /// the feed the plan may run there (unless it started faster).
    fn passes_on_line(
        &self,
        from: &StopStart,
        (accel, jerk): (f64, f64),
        tangential: (f64, f64),
        length: &mut ElementLength,
        curves: &PathCurves,
    ) -> bool {
        let (stop, a0) = stop_record(from, accel, jerk);
        let leaves = |length: f64| stop.s_start + stop.length >= length * (1.0 - 1e-9) - 1e-9;
        if length.bound.is_some_and(leaves) || leaves(length.exact(curves)) {
            return false;
        }
        let table = stop.profile().table_from(a0);
        // Within the tangential limits (the profile's jerks, and its acceleration at every phase
        // boundary: it is linear in between), at rest at the end.
        let (max_accel, max_jerk) = tangential;
        let jerks_ok = stop.jerks.iter().all(|j| j.abs() <= max_jerk);
        let accels_ok = table.states.iter().all(|st| st.a.abs() <= max_accel.max(a0.abs()));
        // The feed peaks where the acceleration crosses zero (a stop that starts accelerating).
        let peak = if a0 > 0.0 && stop.jerks[0] < 0.0 {
            table.state_at(a0 / -stop.jerks[0]).v
        } else {
            from.feed
        };
        let cap = curves
            .programmed_feed(stop.curve())
            .map_or(self.limits.feed, |f| f.min(self.limits.feed));
        let d = curves.view(stop.curve()).derivatives(from.u, 1)[1];
        let tip = self.limits.velocity.len();
        let norm = d[..tip].iter().map(|x| x * x).sum::<f64>().sqrt();
        let velocity_ok = norm > 0.0
            && d[..tip]
                .iter()
                .zip(&self.limits.velocity)
                .all(|(di, vmax)| peak * (di / norm).abs() <= *vmax);
        let at_rest = table.end().v.abs() <= 1e-9 * (1.0 + from.feed);
        jerks_ok && accels_ok && velocity_ok && at_rest && (peak <= cap || peak <= from.feed)
    }

    /// Arc length of element `e` (kept for the element the last check was on).
    fn element_length(&mut self, e: usize, curves: &PathCurves) -> Option<ElementLength> {
        match self.element_length {
            Some(l) if l.element == e => Some(l),
            _ => {
                let curve = &curves.get(e)?.curve;
                // Above the polygon's length by more than the table's rounding (1e-14 per piece).
                let bound = curve.polygon_length().map(|l| l * (1.0 + 1e-9) + 1e-12);
                Some(ElementLength {
                    element: e,
                    bound,
                    exact: None,
                })
            }
        }
    }
}

/// The arc length of an element: an upper bound first (it decides most stops on short
/// elements: integrating the arc length of every element the motion passes was a sixth of the
/// planning time on dense G1 programs), the exact length where it must.
#[derive(Clone, Copy)]
struct ElementLength {
    element: usize,
    bound: Option<f64>,
    exact: Option<f64>,
}

impl ElementLength {
    fn exact(&mut self, curves: &PathCurves) -> f64 {
        *self.exact.get_or_insert_with(|| {
            curves
                .get(self.element)
                .map_or(0.0, |e| ArcLengthTable::new(&e.curve).total())
        })
    }
}

/// The jerk at most `jerk` with which the stop from `from` (deceleration `accel`) ends just after
/// a sample, [`LANDING`] after it: the last sample of the stop is then at rest to within
/// nanometres, and holding there adds nothing to the finite differences (a stop ending between
/// two samples leaves the last one moving, and holding after it jerks). `None` if the search
/// does not land.
fn landing_jerk(from: &StopStart, accel: f64, jerk: f64, dt: f64) -> Option<f64> {
    let total = |j: f64| {
        let (stop, a0) = stop_record(from, accel, j);
        stop.profile().table_from(a0).total_time()
    };
    let t0 = total(jerk);
    let target = (t0 / dt).ceil() * dt + LANDING;
    if t0 > target - LANDING && t0 <= target {
        return Some(jerk);
    }
    // A lower jerk stops later; the search stays within a factor 4 of `jerk`.
    let (mut lo, mut hi) = (0.25 * jerk, jerk);
    if total(lo) < target {
        return None;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        let t = total(mid);
        if t >= target && t <= target + LANDING {
            return Some(mid);
        }
        if t >= target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    None
}

/// True if `curve` is a straight line through its tool-tip coordinates at a pace uniform in its
/// parameter (degree 1, two control points, equal weights): its points are linear in the arc
/// length, and the interpolator's are too, to rounding.
fn is_line(curve: &nurbs_motion::geometry::Nurbs) -> bool {
    curve.degree() == 1 && curve.control_point_count() == 2 && curve.weights().windows(2).all(|w| w[0] == w[1])
}

/// How long after its last sample a hold stop reaches rest (s).
const LANDING: f64 = 1e-9;

/// Tangential deceleration and jerk the axes allow at parameter `u` of element `e`: min over the
/// axes of the limit over the axis' share of the unit tangent.
pub fn tangential_limits(curves: &PathCurves, limits: &Limits, e: usize, u: f64) -> (f64, f64) {
    let tip = limits.velocity.len();
    let d = curves.view(e).derivatives(u, 1)[1];
    let norm = d[..tip].iter().map(|x| x * x).sum::<f64>().sqrt();
    let (mut a, mut j) = (f64::INFINITY, f64::INFINITY);
    for ((di, ai), ji) in d.iter().zip(&limits.acceleration).zip(&limits.jerk).take(tip) {
        let share = if norm > 0.0 { (di / norm).abs() } else { 1.0 };
        if share > 0.0 {
            a = a.min(ai / share);
            j = j.min(ji / share);
        }
    }
    (a.max(limits.min_accel()), j.max(limits.min_jerk()))
}
