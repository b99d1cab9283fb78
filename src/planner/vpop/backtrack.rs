//! The VPOp iteration (section 2.4): go as fast as possible (s_{j+1} = s_max); when the
//! intersection is empty, search back by dichotomy for the last point from which a
//! full-deceleration sequence reaches rest, and re-plan from there (section 2.3).
//! Refinements of the paper:
//! - the deceleration sequence is not s_min at every step (which with jerk limits reaches
//!   ṡ = 0 with a large deceleration and then fails, as the paper notes) but aims each step at
//!   the jerk-limited switching curve, clamped into [s_min, s_max], so that ṡ and s̈ reach zero
//!   together;
//! - at the switching point the next position is not s_min but the largest position from which
//!   the deceleration sequence still reaches rest (bisection), and the following steps are
//!   chosen the same way while the deceleration limits them: the discrete counterpart of the
//!   time-optimal switching curve instead of alternating s_min / s_max;
//! - the path end is a constraint (s <= L) and the motion only finishes when the machine can
//!   stay at L (the verifier's "at rest after the last row"), so the end look-ahead of
//!   section 2.5 is the same search;
//! - "reaches rest" is tried with several deceleration settings ([`BRAKES`]), any one of which
//!   proves a state safe; the search then continues along that setting's sequence. With one
//!   setting the planner brakes wherever that one sequence fails, which is much earlier than
//!   it must (trident, VPOp limits: 1.950 s with one setting, 1.680 s with five);
//! - a careful step that finds nothing beyond the deceleration sequence makes the next ones
//!   follow it without searching, for a doubling number of periods up to `search_backoff`
//!   (failing checks are most of the cost, and the next step mostly fails the same way).

use super::constraints::{History, Stepper};
use super::path::PathPoint;

/// Counters of one planning run.
#[derive(Clone, Copy, Debug, Default)]
pub struct SearchStats {
    /// Empty intersections met by the forward pass.
    pub dead_ends: usize,
    /// Deceleration sequences simulated.
    pub brakes: usize,
    /// Steps simulated inside deceleration sequences.
    pub brake_steps: usize,
    /// Most points held at once, not yet final (the memory a streamed run needs).
    pub most_held: usize,
}

/// Search settings.
#[derive(Clone, Copy, Debug)]
pub struct SearchOptions {
    /// Bisection iterations when choosing a position between s_min and s_max.
    pub bisections: usize,
    /// Longest motion (periods) before giving up.
    pub max_steps: usize,
    /// Deceleration settings, tried in turn: a state is safe when the sequence of any of them
    /// reaches rest.
    pub brakes: &'static [BrakeSetting],
    /// A careful step that finds nothing safe beyond the deceleration sequence's own next
    /// point makes the next steps follow that sequence without searching, one period the first
    /// time, twice as many each time again, up to this long (s); a step that finds more resets it.
    pub search_backoff: f64,
    /// Share of the chord-error step cap (estimate kappa l^2 / 8) used as a first cap; the
    /// committed steps are checked with the exact chord error.
    pub chord_scale: f64,
    /// Start from rest at this element and curve parameter instead of the path start (the
    /// rest of a path after a stop on it). The first point carries `u` exactly.
    pub start: Option<(usize, f64)>,
}

impl Default for SearchOptions {
    fn default() -> Self {
        SearchOptions {
            bisections: 8,
            max_steps: 20_000_000,
            brakes: &BRAKES,
            search_backoff: 0.006,
            chord_scale: 0.9,
            start: None,
        }
    }
}

/// How a deceleration sequence brakes: each step aims at the jerk-limited switching curve of
/// `brake_fraction` of the tangential acceleration and jerk estimated from the joint limits,
/// and releases the deceleration assuming `switch_fraction` of the jerk `release` names
/// (margins for the curvature terms of the axis jerk, which the estimate leaves out).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrakeSetting {
    pub brake_fraction: f64,
    pub switch_fraction: f64,
    pub release: Release,
}

/// The tangential jerk a deceleration sequence plans its release with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Release {
    /// The whole tangential jerk the joint limits allow along the path there.
    Whole,
    /// What the joint limits leave after the curvature terms of the axis jerk at the state
    /// (q''' ṡ³ + 3 q'' ṡ s̈, by derivatives along the path): near a sharp turn those take most
    /// of the jerk, and a release planned with the whole runs out of it and fails there.
    Left,
}

const fn brake(brake_fraction: f64, switch_fraction: f64) -> BrakeSetting {
    BrakeSetting {
        brake_fraction,
        switch_fraction,
        release: Release::Whole,
    }
}

const fn brake_left(brake_fraction: f64, switch_fraction: f64) -> BrakeSetting {
    BrakeSetting {
        brake_fraction,
        switch_fraction,
        release: Release::Left,
    }
}

/// The default deceleration settings. No one setting suits every state: a hard brake stops
/// before a tight turn that a gentle one runs into, a gentle one keeps the curvature terms of
/// the axis jerk small where a hard one overruns them. A state that any of them brings to rest
/// is safe, and the more states count as safe the later the planner has to brake; each setting
/// also costs a deceleration sequence on every state none of them saves. Measured on the
/// trident at the VPOp limits: the first setting alone 1.950 s, the first five 1.680 s with 3.0 ×
/// its deceleration checks (nine settings 0.1 to 1.0 of the whole jerk gave 1.680 s too, with
/// 5.3 ×). The same five releasing with the jerk left after the curvature terms
/// ([`Release::Left`]) save states the first five do not, near sharp turns at speed: with all
/// ten (2026-12-05, lab set 1 unless named) the butterfly 3.3923 -> 3.3140 s, at F250 A2000
/// J2e4 4.8628 -> 4.7743 s, the trident 0.7708 -> 0.7460 s, the fan 2.8948 -> 2.8915 s, the
/// open pocket 0.9310 -> 0.9228 s, a 1,000-line dense G1 program 6.970 -> 6.653 s, the trident
/// at the VPOp limits the same 1.680 s; planning takes 2.0-2.5 times as long. The five with
/// the jerk left alone: the trident at the VPOp limits 1.722 s, the fan 2.9035 s.
pub const BRAKES: [BrakeSetting; 10] = [
    brake(0.9, 0.5),
    brake(1.0, 0.8),
    brake(0.3, 0.3),
    brake(0.1, 0.05),
    brake(0.7, 0.3),
    brake_left(0.9, 0.5),
    brake_left(1.0, 0.8),
    brake_left(0.3, 0.3),
    brake_left(0.1, 0.05),
    brake_left(0.7, 0.3),
];

/// Least share of the whole tangential jerk a [`Release::Left`] plans its release with.
const LEAST_RELEASE: f64 = 0.05;

pub struct Search<'s, 'p> {
    pub stepper: &'s Stepper<'p>,
    pub options: SearchOptions,
    pub stats: SearchStats,
    /// Where in [deceleration point, s_max] the last careful step found its position.
    pub last_fraction: Option<f64>,
    /// The deceleration setting (index in `options.brakes`) whose sequence reaches rest from
    /// the last state checked safe.
    safe_brake: usize,
    /// Steps still to follow the deceleration sequence without searching, the last such run's
    /// length, and its longest (`search_backoff` in periods).
    skip: usize,
    backoff: usize,
    max_backoff: usize,
}

impl<'s, 'p> Search<'s, 'p> {
    /// A search on `stepper` with no statistics yet.
    pub fn new(stepper: &'s Stepper<'p>, options: SearchOptions) -> Self {
        // No setting at all would leave no way to brake: the defaults then.
        let brakes = if options.brakes.is_empty() {
            &BRAKES[..]
        } else {
            options.brakes
        };
        Search {
            stepper,
            options: SearchOptions { brakes, ..options },
            stats: SearchStats::default(),
            last_fraction: None,
            safe_brake: 0,
            skip: 0,
            backoff: 0,
            max_backoff: (options.search_backoff / stepper.limits.period).max(0.0) as usize,
        }
    }
}

impl Search<'_, '_> {
    fn history(points: &[PathPoint], k: usize) -> History {
        let at = |i: isize| points[i.max(0) as usize];
        let k = k as isize;
        History {
            p: [at(k - 2), at(k - 1), at(k)],
        }
    }

    /// Does a full-deceleration sequence from `h` reach rest? The paper takes s_min at every
    /// step, which with jerk limits ends with ṡ = 0 but a large deceleration, and then fails
    /// (section 2.3, last paragraph). Here each step aims at the jerk-limited switching curve
    /// s̈ = -sqrt(2 J ṡ) (tangential limits estimated from the joint limits at the current
    /// point), clamped into [s_min, s_max]: both ṡ and s̈ reach zero together. The first
    /// setting of `options.brakes` whose sequence reaches rest, if any.
    fn brakes(&mut self, h: History) -> Option<usize> {
        (0..self.options.brakes.len()).find(|&b| self.brakes_with(h, b))
    }

    /// Does the deceleration sequence of setting `b` reach rest from `h`?
    fn brakes_with(&mut self, h: History, b: usize) -> bool {
        self.stats.brakes += 1;
        self.brake_sequence(h, b, None)
    }

    /// Runs the deceleration sequence of setting `b` from `h`: whether it reaches rest, its
    /// positions appended to `points` where given (to rest: the machine stays at the last one).
    fn brake_sequence(&mut self, mut h: History, b: usize, mut points: Option<&mut Vec<PathPoint>>) -> bool {
        let l = self.stepper.limits;
        let vmax = l.feed.max(l.velocity.iter().copied().fold(0.0, f64::max));
        let amin = l.min_accel();
        let limit = (10.0 * (vmax / amin + amin / l.min_jerk()) / l.period) as usize + 100;
        for _ in 0..limit.min(self.options.max_steps) {
            if h.is_rest() {
                return true;
            }
            self.stats.brake_steps += 1;
            let (target, jw) = self.brake_target(&h, b);
            if let Some(p) = self.finish_point(&h, jw) {
                // Checked to rest (three periods).
                if let Some(points) = points.as_deref_mut() {
                    points.push(p);
                }
                return true;
            }
            let Some(p) = self.brake_step_to(&h, target) else {
                return false;
            };
            if let Some(points) = points.as_deref_mut() {
                points.push(p);
            }
            h.push(p);
        }
        false
    }

    /// A position S from which the machine comes to rest in three periods (next position S,
    /// then staying at S), exactly checked: the S that minimises the largest path-space jerk of
    /// the three steps, then S = current position, each tried when that jerk is within a
    /// multiple of the tangential estimate `jw`.
    fn finish_point(&self, h: &History, jw: f64) -> Option<PathPoint> {
        let [p2, p1, p0] = h.p;
        let (v0, v1) = (p0.w - p1.w, p1.w - p2.w);
        if v0 < 0.0 {
            return None;
        }
        let c = 2.0 * v0 - v1;
        // Third differences of the three steps for S = p0 + d: d - c, v0 - 2d, d.
        let worst = |d: f64| (d - c).abs().max((v0 - 2.0 * d).abs()).max(d.abs());
        let (d, m) = [0.0, 0.5 * c, v0 / 3.0, v0, (v0 + c) / 3.0, v0 - c]
            .into_iter()
            .filter(|d| *d >= 0.0)
            .map(|d| (d, worst(d)))
            .fold((0.0, f64::INFINITY), |b, x| if x.1 < b.1 { x } else { b });
        let dt = self.stepper.limits.period;
        let screen = 4.0 * jw * dt * dt * dt;
        for (d, m) in [(d, m), (0.0, worst(0.0))] {
            if m <= screen {
                if let Some(p) = self.finishes_at(h, p0.w + d) {
                    return Some(p);
                }
            }
        }
        None
    }

    /// Exact check of stopping at `w`: the step there, then three equal samples.
    fn finishes_at(&self, h: &History, w: f64) -> Option<PathPoint> {
        let p = if w == h.current().w {
            *h.current()
        } else {
            self.stepper.path.eval(w)
        };
        let mut n = *h;
        let cap = self.stepper.step_cap(&n, self.options.chord_scale);
        if !(self.stepper.feasible(&n, &p, cap) && self.chord_ok(h.current(), &p)) {
            return None;
        }
        for _ in 0..3 {
            n.push(p);
            if !self.stepper.feasible(&n, &p, f64::INFINITY) {
                return None;
            }
        }
        Some(p)
    }

    /// The next point of the deceleration sequence: the three-period stop when it is
    /// feasible, otherwise the step towards the jerk-limited stop.
    fn brake_next(&self, h: &History, b: usize) -> Option<PathPoint> {
        let (target, jw) = self.brake_target(h, b);
        if let Some(p) = self.finish_point(h, jw) {
            return Some(p);
        }
        self.brake_step_to(h, target)
    }

    /// The deceleration sequence's next point aiming at `target`.
    fn brake_step_to(&self, h: &History, target: f64) -> Option<PathPoint> {
        let cap = self.stepper.step_cap(h, self.options.chord_scale);
        // The target itself is feasible most of the time; otherwise it is projected onto the
        // linearised feasible interval (a few Newton corrections), and only then is the whole
        // interval searched.
        let p = match self.stepper.project(h, target, cap) {
            Some(p) => p,
            None => {
                let (lo, hi) = self.stepper.interval(h, self.options.chord_scale)?;
                if target >= hi.w {
                    hi
                } else {
                    lo
                }
            }
        };
        self.chord_ok(h.current(), &p).then_some(p)
    }

    /// Chord error within the tolerance: measured exactly unless the tabulated curvature over
    /// the step puts the estimate kappa l^2 / 8 below half the tolerance.
    fn chord_ok(&self, a: &PathPoint, b: &PathPoint) -> bool {
        let path = self.stepper.path;
        let eps = self.stepper.limits.chord_tolerance;
        let l = super::constraints::tip_distance(&a.tip, &b.tip, path.tip_dim());
        let kappa = path.max_curvature(a.w, b.w);
        kappa * l * l / 8.0 < 0.5 * eps || path.chord_error(a, b) <= eps
    }

    /// Next position of a jerk-limited stop in path coordinates, and the tangential jerk
    /// estimated from the joint limits at the current point.
    fn brake_target(&self, h: &History, b: usize) -> (f64, f64) {
        let BrakeSetting {
            brake_fraction,
            switch_fraction,
            release,
        } = self.options.brakes[b];
        let dt = self.stepper.limits.period;
        let [p2, p1, p0] = h.p;
        let v = (p0.w - p1.w) / dt;
        let v1 = (p1.w - p2.w) / dt;
        let a = (v - v1) / dt;
        if v <= 0.0 {
            return (p0.w, 0.0);
        }
        let (dq, _) = self.stepper.path.derivative(p0.w);
        let l = self.stepper.limits;
        let (mut jw, mut aw) = (f64::INFINITY, f64::INFINITY);
        for i in 0..self.stepper.path.axes() {
            let d = dq[i].abs();
            if d > 0.0 {
                jw = jw.min(l.jerk[i] / d);
                aw = aw.min(l.acceleration[i] / d);
            }
        }
        let full = jw;
        let released = match release {
            Release::Whole => full,
            Release::Left => {
                let (q2, q3) = self.stepper.path.higher_derivatives(p0.w);
                let mut left = f64::INFINITY;
                for i in 0..self.stepper.path.axes() {
                    let d = dq[i].abs();
                    if d > 0.0 {
                        let used = (q3[i] * v * v * v + 3.0 * q2[i] * v * a).abs();
                        left = left.min((l.jerk[i] - used).max(0.0) / d);
                    }
                }
                // Never more than the whole, never so little that the stop cannot end.
                left.clamp(LEAST_RELEASE * full, full)
            }
        };
        let (jw, aw) = (brake_fraction * jw, brake_fraction * aw);
        let a_next = stop_acceleration(v, a, jw, aw, switch_fraction * brake_fraction * released, dt);
        let v_next = v + a_next * dt;
        let w = if v_next <= 0.0 { p0.w } else { p0.w + v_next * dt };
        (w, full)
    }

    /// The positions of the deceleration sequence from `h` of the first setting that reaches
    /// rest (as [`Self::brakes`] finds it), to rest (the machine stays at the last one), or
    /// `None` where none does.
    pub fn brake_points(&mut self, h: History) -> Option<Vec<PathPoint>> {
        (0..self.options.brakes.len()).find_map(|b| {
            let mut points = Vec::new();
            self.brake_sequence(h, b, Some(&mut points)).then_some(points)
        })
    }

    /// [`Self::brakes`] from `h` continued by `p`.
    fn brakes_after(&mut self, h: &History, p: PathPoint) -> Option<usize> {
        let mut n = *h;
        n.push(p);
        self.brakes(n)
    }

    /// Largest point up to `hi` after which a deceleration sequence reaches rest, searched
    /// between the next point of the sequence that makes `h` safe and `hi`; also says whether
    /// that is `hi` itself, and which setting's sequence makes the point safe.
    fn largest_safe(&mut self, h: &History, hi: PathPoint, cap_scale: f64) -> Option<(PathPoint, bool, usize)> {
        let resolution = 0.5f64.powi(self.options.bisections as i32);
        // Mostly the deceleration sequence itself is the largest safe choice, step after step:
        // then the smallest step above it is tried first (one deceleration sequence per step).
        let small_first = self.last_fraction.is_some_and(|f| f <= resolution);
        if self.skip > 0 {
            // Backing off: the deceleration sequence, safe as `h` is.
            self.skip -= 1;
            let base = self.brake_next(h, self.safe_brake)?;
            return Some((base, false, self.safe_brake));
        }
        if self.chord_ok(h.current(), &hi) {
            if let Some(b) = self.brakes_after(h, hi) {
                return Some((hi, true, b));
            }
        }
        let cap = self.stepper.step_cap(h, cap_scale);
        let base_brake = self.safe_brake;
        let base = self.brake_next(h, base_brake)?;
        let width = hi.w - base.w;
        if width.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Some((base, false, base_brake));
        }
        // Fractions of [base, hi]: `lo` safe, `up` not; resolution 2^-bisections. The search
        // starts at the previous step's fraction (it moves little from step to step) and
        // widens from there before bisecting.
        let mut good = (base, base_brake);
        let (mut lo, mut up) = (0.0f64, 1.0f64);
        let test = |search: &mut Self, f: f64, good: &mut (PathPoint, usize)| {
            let p = search.stepper.path.eval(base.w + f * width);
            let ok =
                p.w > base.w && p.w < hi.w && search.stepper.feasible(h, &p, cap) && search.chord_ok(h.current(), &p);
            let safe_by = if ok { search.brakes_after(h, p) } else { None };
            if let Some(b) = safe_by {
                *good = (p, b);
            }
            safe_by.is_some()
        };
        if small_first {
            if test(self, resolution, &mut good) {
                lo = resolution;
            } else if test(self, 0.5, &mut good) {
                // Safety is not monotone in the step: a longer step can be safe again.
                lo = 0.5;
            } else {
                self.last_fraction = Some(0.0);
                self.backoff = (2 * self.backoff).max(1).min(self.max_backoff);
                self.skip = self.backoff;
                return Some((base, false, base_brake));
            }
        } else if let Some(f) = self.last_fraction.filter(|f| *f > resolution && *f < 1.0 - resolution) {
            let mut step = 4.0 * resolution;
            if test(self, f, &mut good) {
                lo = f;
                while lo + step < up {
                    if test(self, lo + step, &mut good) {
                        lo += step;
                        step *= 2.0;
                    } else {
                        up = lo + step;
                        break;
                    }
                }
            } else {
                up = f;
                while up - step > lo {
                    if test(self, up - step, &mut good) {
                        lo = up - step;
                        break;
                    }
                    up -= step;
                    step *= 2.0;
                }
            }
        }
        while up - lo > resolution {
            let mid = 0.5 * (lo + up);
            if test(self, mid, &mut good) {
                lo = mid;
            } else {
                up = mid;
            }
        }
        self.last_fraction = Some(lo);
        self.backoff = 0;
        Some((good.0, false, good.1))
    }

    /// Can the machine stay at the end of the path (three more equal samples)?
    fn can_stop_here(&self, h: &History) -> bool {
        let mut n = *h;
        for _ in 0..3 {
            let p = *n.current();
            if !self.stepper.feasible(&n, &p, f64::INFINITY) {
                return false;
            }
            n.push(p);
        }
        true
    }

    /// Runs the whole motion from rest at the path start to rest at its end, handing each
    /// point to `emit` as soon as no back-tracking can revise it:
    /// back-tracking never goes behind the last state checked safe (the dichotomy runs between
    /// it and the dead end), so every point up to it is final. While the motion runs free
    /// (no deceleration check limits it) the state is checked every [`COMMIT_EVERY`] of motion
    /// and becomes the safe point when its deceleration reaches rest, so that points keep
    /// going out on long free runs too, and the points kept are those of a few
    /// milliseconds. Returns the number of points; an error from `emit` ends the search.
    pub fn run_streamed(&mut self, emit: &mut dyn FnMut(&PathPoint) -> Result<(), String>) -> Result<usize, String> {
        let path = self.stepper.path;
        let first = match self.options.start {
            None => path.eval(0.0),
            Some((element, u)) => path
                .eval_at(element, u)
                .ok_or_else(|| format!("start point (element {element}, u = {u}) is not on the path"))?,
        };
        // The points not yet handed out; `base` of them have been (the first of `points` is
        // point `base` of the motion). Before the first hand-out the motion starts at rest:
        // the history before point 0 repeats it.
        let mut points = vec![first];
        let mut base = 0usize;
        let mut safe = 0usize;
        let mut careful = false;
        let mut stalls = 0usize;
        let commit_every = ((COMMIT_EVERY / self.stepper.limits.period).ceil() as usize).max(1);
        let mut free_run = 0usize;
        let eps = self.stepper.limits.chord_tolerance;
        loop {
            if base + points.len() > self.options.max_steps {
                return Err(format!("no motion found within {} periods", self.options.max_steps));
            }
            let j = points.len() - 1;
            let h = Self::history(&points, j);
            // The path end (known once a streamed path has been read to it).
            if h.current().w == path.end() && self.can_stop_here(&h) {
                break;
            }
            let mut chosen = None;
            let mut checked = false;
            let mut was_max = false;
            let mut brake = self.safe_brake;
            let mut scale = self.options.chord_scale;
            for _ in 0..10 {
                let Some((_, hi)) = self.stepper.interval(&h, scale) else {
                    if careful {
                        // The state is safe: its deceleration sequence continues it.
                        chosen = self
                            .brake_next(&h, self.safe_brake)
                            .filter(|p| !(h.is_rest() && p.w == h.current().w))
                            .filter(|p| path.chord_error(h.current(), p) <= eps);
                        checked = chosen.is_some();
                    }
                    break;
                };
                let p = if careful {
                    checked = true;
                    let Some((p, m, b)) = self.largest_safe(&h, hi, scale) else {
                        break;
                    };
                    was_max = m;
                    brake = b;
                    p
                } else {
                    hi
                };
                // Committed steps: the exact chord error, as the verifier measures it.
                if path.chord_error(h.current(), &p) <= eps {
                    chosen = Some(p);
                    break;
                }
                scale *= 0.5;
            }
            match chosen {
                Some(p) => {
                    points.push(p);
                    if checked {
                        safe = points.len() - 1;
                        self.safe_brake = brake;
                        // s_max itself was safe: the deceleration no longer limits the motion.
                        if was_max {
                            careful = false;
                        }
                        free_run = 0;
                    } else {
                        free_run += 1;
                        if free_run >= commit_every {
                            free_run = 0;
                            let k = points.len() - 1;
                            if let Some(b) = self.brakes(Self::history(&points, k)) {
                                safe = k;
                                self.safe_brake = b;
                            }
                        }
                    }
                    stalls = 0;
                }
                None => {
                    // Empty intersection: dichotomy back to the last point from which the
                    // deceleration sequence reaches rest.
                    self.stats.dead_ends += 1;
                    stalls += 1;
                    if stalls > 1000 || self.stats.dead_ends > 100 * (base + points.len() + 1000) {
                        return Err(format!("no feasible step at s = {}", h.current().w));
                    }
                    let (mut good, mut bad) = (safe, j);
                    let mut good_brake = match self.brakes(Self::history(&points, good)) {
                        Some(b) => b,
                        // Not met: the safe point was checked with the same deceleration
                        // sequences, which depend on the state alone.
                        None if base > 0 => {
                            return Err(format!(
                                "back-tracking from s = {} reached points already handed out",
                                h.current().w
                            ))
                        }
                        None => {
                            good = 0;
                            0
                        }
                    };
                    // Galloping back from the dead end first: the safe state nearest to it
                    // (safety is not monotone along the motion; a bisection over the whole
                    // run may settle on an earlier boundary).
                    let mut step = 1;
                    while bad - good > step {
                        let at = bad - step;
                        if let Some(b) = self.brakes(Self::history(&points, at)) {
                            (good, good_brake) = (at, b);
                            break;
                        }
                        bad = at;
                        step *= 2;
                    }
                    while bad - good > 1 {
                        let mid = (good + bad) / 2;
                        if let Some(b) = self.brakes(Self::history(&points, mid)) {
                            good = mid;
                            good_brake = b;
                        } else {
                            bad = mid;
                        }
                    }
                    self.safe_brake = good_brake;
                    points.truncate(good + 1);
                    safe = good;
                    careful = true;
                    self.last_fraction = None;
                    (self.skip, self.backoff) = (0, 0);
                    free_run = 0;
                }
            }
            self.stats.most_held = self.stats.most_held.max(points.len());
            // Hand out the final points, keeping the two before the safe point (its history).
            if safe >= HAND_OUT_AFTER + 2 {
                let out = safe - 2;
                for p in points.drain(..out) {
                    emit(&p)?;
                }
                base += out;
                safe -= out;
                path.release_before(points[0].w);
            }
        }
        for p in &points {
            emit(p)?;
        }
        Ok(base + points.len())
    }
}

/// Motion time after which a free run (no deceleration check limiting it) checks its state
/// and, if that is safe, hands out the points before it (s).
pub const COMMIT_EVERY: f64 = 0.005;

/// Final points gathered before they are handed out (fewer, larger hand-outs).
const HAND_OUT_AFTER: usize = 64;

/// Next acceleration of the fastest discrete stop in path coordinates: the most negative jerk
/// in `[-jw, jw]` (acceleration kept above `-aw`) after which releasing the deceleration with
/// jerk `jr` (by backward differences, period `dt`) brings the acceleration to zero before
/// the velocity crosses zero: the discrete counterpart of the switching curve
/// s̈ = -sqrt(2 jr ṡ), which in continuous form overshoots by a step and then stops with a
/// jerk far over the limit.
fn stop_acceleration(v: f64, a: f64, jw: f64, aw: f64, jr: f64, dt: f64) -> f64 {
    let ok = |j: f64| {
        let a1 = a + j * dt;
        let v1 = v + a1 * dt;
        if v1 < 0.0 {
            return false;
        }
        if a1 >= 0.0 {
            return true;
        }
        // Release: a1 + k jr dt for k = 1 .. n - 1, then zero.
        let n = (-a1 / (jr * dt)).ceil();
        let loss = dt * ((n - 1.0) * a1 + jr * dt * (n - 1.0) * n / 2.0);
        v1 + loss >= 0.0
    };
    let hi = jw;
    let lo = (-jw).max((-aw - a) / dt).min(hi);
    if ok(lo) {
        return a + lo * dt;
    }
    if !ok(hi) {
        return a + hi * dt;
    }
    // Closed form: with x = -a1 released in n steps ((n - 1) jr dt < x <= n jr dt), the
    // condition reads x <= (v + jr dt^2 n (n - 1) / 2) / (n dt); n from the continuous root.
    let xc = jr * (-dt + (dt * dt + 2.0 * v / jr).sqrt());
    let n0 = (xc / (jr * dt)).ceil().max(1.0);
    let mut x_best = f64::NEG_INFINITY;
    for n in [n0 - 1.0, n0, n0 + 1.0] {
        if n < 1.0 {
            continue;
        }
        let x = ((v + jr * dt * dt * n * (n - 1.0) / 2.0) / (n * dt)).min(n * jr * dt);
        if x > (n - 1.0) * jr * dt {
            x_best = x_best.max(x);
        }
    }
    if x_best.is_finite() {
        let j = ((-x_best - a) / dt).clamp(lo, hi);
        // Rounding: step up by a few ulps of the range until the condition holds.
        let mut jj = j;
        for k in 0..4 {
            if ok(jj) {
                return a + jj * dt;
            }
            jj = (j + (hi - lo) * 1e-12 * (1 << (4 * k)) as f64).min(hi);
        }
    }
    let (mut bad, mut good) = (lo, hi);
    for _ in 0..60 {
        let mid = 0.5 * (bad + good);
        if mid <= bad || mid >= good {
            break;
        }
        if ok(mid) {
            good = mid;
        } else {
            bad = mid;
        }
    }
    a + good * dt
}
