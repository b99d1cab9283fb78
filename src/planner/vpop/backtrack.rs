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
//!   section 2.5 is the same search.

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
}

/// Search settings.
#[derive(Clone, Copy, Debug)]
pub struct SearchOptions {
    /// Bisection iterations when choosing a position between s_min and s_max.
    pub bisections: usize,
    /// Longest motion (periods) before giving up.
    pub max_steps: usize,
    /// Share of the estimated tangential acceleration and jerk a deceleration sequence aims at.
    pub brake_fraction: f64,
    /// The switching curve of a deceleration assumes only this share of that jerk to release
    /// the deceleration (margin for the curvature terms of the axis jerk).
    pub switch_fraction: f64,
}

impl Default for SearchOptions {
    fn default() -> Self {
        SearchOptions {
            bisections: 8,
            max_steps: 20_000_000,
            brake_fraction: 0.9,
            switch_fraction: 0.5,
        }
    }
}

pub struct Search<'s, 'p, 'a> {
    pub stepper: &'s Stepper<'p, 'a>,
    pub options: SearchOptions,
    pub stats: SearchStats,
}

const CHORD_SCALE: f64 = 0.9;

impl Search<'_, '_, '_> {
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
    /// point), clamped into [s_min, s_max]: both ṡ and s̈ reach zero together.
    fn brakes(&mut self, mut h: History) -> bool {
        self.stats.brakes += 1;
        let l = self.stepper.limits;
        let vmax = l.feed.max(l.velocity.iter().copied().fold(0.0, f64::max));
        let amin = l.min_accel();
        let limit = (10.0 * (vmax / amin + amin / l.min_jerk()) / l.period) as usize + 100;
        for _ in 0..limit.min(self.options.max_steps) {
            if h.is_rest() {
                return true;
            }
            self.stats.brake_steps += 1;
            let Some(p) = self.brake_step(&h) else {
                return false;
            };
            h.push(p);
        }
        false
    }

    /// The next point of the deceleration sequence (exactly feasible, chord error checked).
    fn brake_step(&self, h: &History) -> Option<PathPoint> {
        let target = self.brake_target(h);
        let cap = self.stepper.step_cap(h, CHORD_SCALE);
        // The target itself is feasible most of the time; otherwise it is projected onto the
        // linearised feasible interval (a few Newton corrections), and only then is the whole
        // interval searched.
        let p = match self.stepper.project(h, target, cap) {
            Some(p) => p,
            None => {
                let (lo, hi) = self.stepper.interval(h, CHORD_SCALE)?;
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

    /// Next position of a jerk-limited stop in path coordinates.
    fn brake_target(&self, h: &History) -> f64 {
        let dt = self.stepper.limits.period;
        let [p2, p1, p0] = h.p;
        let v = (p0.w - p1.w) / dt;
        let v1 = (p1.w - p2.w) / dt;
        let a = (v - v1) / dt;
        if v <= 0.0 {
            return p0.w;
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
        let (jw, aw) = (self.options.brake_fraction * jw, self.options.brake_fraction * aw);
        let desired = -(2.0 * self.options.switch_fraction * jw * v).sqrt();
        let a_next = desired.clamp(a - jw * dt, a + jw * dt).max(-aw);
        let v_next = v + a_next * dt;
        if v_next <= 0.0 {
            p0.w
        } else {
            p0.w + v_next * dt
        }
    }

    fn brakes_after(&mut self, h: &History, p: PathPoint) -> bool {
        let mut n = *h;
        n.push(p);
        self.brakes(n)
    }

    /// Largest point up to `hi` after which the deceleration sequence reaches rest, searched
    /// between the deceleration sequence's own next point (safe when `h` is) and `hi`; also
    /// says whether that is `hi` itself.
    fn largest_safe(&mut self, h: &History, hi: PathPoint, cap_scale: f64) -> Option<(PathPoint, bool)> {
        if self.chord_ok(h.current(), &hi) && self.brakes_after(h, hi) {
            return Some((hi, true));
        }
        let cap = self.stepper.step_cap(h, cap_scale);
        let mut good = self.brake_step(h)?;
        let mut bad = hi.w;
        for _ in 0..self.options.bisections {
            let mid = 0.5 * (good.w + bad);
            if mid <= good.w || mid >= bad {
                break;
            }
            let p = self.stepper.path.eval(mid);
            if self.stepper.feasible(h, &p, cap) && self.chord_ok(h.current(), &p) && self.brakes_after(h, p) {
                good = p;
            } else {
                bad = mid;
            }
        }
        Some((good, false))
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

    /// Runs the whole motion from rest at the path start to rest at its end.
    pub fn run(&mut self) -> Result<Vec<PathPoint>, String> {
        let path = self.stepper.path;
        let end = path.end();
        let mut points = vec![path.eval(0.0)];
        let mut safe = 0usize;
        let mut careful = false;
        let mut stalls = 0usize;
        let eps = self.stepper.limits.chord_tolerance;
        loop {
            if points.len() > self.options.max_steps {
                return Err(format!("no motion found within {} periods", self.options.max_steps));
            }
            let j = points.len() - 1;
            let h = Self::history(&points, j);
            if h.current().w == end && self.can_stop_here(&h) {
                break;
            }
            let mut chosen = None;
            let mut checked = false;
            let mut was_max = false;
            let mut scale = CHORD_SCALE;
            for _ in 0..10 {
                let Some((_, hi)) = self.stepper.interval(&h, scale) else {
                    break;
                };
                let p = if careful {
                    checked = true;
                    let Some((p, m)) = self.largest_safe(&h, hi, scale) else {
                        break;
                    };
                    was_max = m;
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
                        // s_max itself was safe: the deceleration no longer limits the motion.
                        if was_max {
                            careful = false;
                        }
                    }
                    stalls = 0;
                }
                None => {
                    // Empty intersection: dichotomy back to the last point from which the
                    // deceleration sequence reaches rest.
                    self.stats.dead_ends += 1;
                    stalls += 1;
                    if stalls > 1000 || self.stats.dead_ends > 100 * (points.len() + 1000) {
                        return Err(format!("no feasible step at s = {}", h.current().w));
                    }
                    let (mut good, mut bad) = (safe, j);
                    if !self.brakes(Self::history(&points, good)) {
                        good = 0;
                    }
                    while bad - good > 1 {
                        let mid = (good + bad) / 2;
                        if self.brakes(Self::history(&points, mid)) {
                            good = mid;
                        } else {
                            bad = mid;
                        }
                    }
                    points.truncate(good + 1);
                    safe = good;
                    careful = true;
                }
            }
        }
        Ok(points)
    }
}
