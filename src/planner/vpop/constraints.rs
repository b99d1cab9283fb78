//! One VPOp step (section 2.2): the interval of next positions s_{j+1} that satisfy every
//! constraint, given the last three positions.
//!
//! With the backward differences of eq. 6, each axial inequality of eq. 7-9 bounds the next
//! joint position q_i(s_{j+1}) to a slab:
//! velocity `|q - q_j| <= V dt`, acceleration `|q - 2q_j + q_{j-1}| <= A dt^2`,
//! jerk `|q - 3q_j + 3q_{j-1} - q_{j-2}| <= J dt^3` (eq. 14). The intersection of the slabs is
//! a box; the feasible next positions are where the path crosses the box, inside the feed ball
//! `|tip(s) - tip_j| <= F dt` and the chord-error cap. F is the feed limit, lowered on every
//! element to its programmed feed (G-code `F`); a step across elements takes the lowest. The
//! crossing is located with the geometric derivative at the unknown point (eq. 13),
//! re-linearised Newton-style at each estimate, and every returned point is checked with
//! exactly the arithmetic of [`crate::planner::axial`], so no overrun can pass (the paper
//! allowed 120 % jerk).

use super::path::{JointPath, PathPoint};
use crate::planner::axial::MAX_AXES;
use crate::planner::Limits;

/// The last three points of a motion, oldest first (before the start they repeat the start:
/// the machine is at rest, as the finite-difference check assumes).
#[derive(Clone, Copy, Debug)]
pub struct History {
    pub p: [PathPoint; 3],
}

impl History {
    pub fn at_rest(p: PathPoint) -> Self {
        History { p: [p; 3] }
    }
    pub fn push(&mut self, p: PathPoint) {
        self.p = [self.p[1], self.p[2], p];
    }
    pub fn current(&self) -> &PathPoint {
        &self.p[2]
    }
    /// Three equal positions: velocity and acceleration are zero.
    pub fn is_rest(&self) -> bool {
        self.p[0].w == self.p[2].w && self.p[1].w == self.p[2].w
    }
}

/// Relative margin of the Newton targets inside the limits (the accepted points are checked
/// against the limits themselves).
const TARGET_MARGIN: f64 = 2e-7;
/// Axes whose derivative is below this share of the largest are left out of the fallback model.
const WEAK: f64 = 0.05;

/// Computes feasible next positions.
pub struct Stepper<'p> {
    pub path: &'p JointPath,
    pub limits: &'p Limits,
    axes: usize,
    /// How far a step looks for the next exact stop (mm): no step is longer.
    horizon: f64,
}

/// Steps at the feed limit that a step looks ahead for the next exact stop. A step is one of
/// them, but the linearised constraints in `w` can throw a first estimate much further on a
/// run of very short elements (their length per unit of `w` is tiny): with 8 steps a dense G1
/// program's plan came out different (1.5 % longer) from the one with the whole path in view,
/// with 64 the same.
const HORIZON_STEPS: f64 = 64.0;

impl<'p> Stepper<'p> {
    pub fn new(path: &'p JointPath, limits: &'p Limits) -> Self {
        Stepper {
            path,
            limits,
            axes: path.axes(),
            horizon: HORIZON_STEPS * limits.feed * limits.period,
        }
    }

    /// Feed cap of a step from element `from` to element `to`: the feed limit, or the lowest
    /// programmed feed of the elements it touches, so that no part of the step runs faster
    /// than its element's programmed feed (stricter than the verifier, which allows the highest).
    fn step_feed(&self, from: usize, to: usize) -> f64 {
        self.path.feed_cap(from, to, self.limits.feed)
    }

    /// How far the next point may go: the next exact stop (a tangent break or the path end),
    /// or past the one the machine stands at once it is at rest there.
    fn bound(&self, h: &History) -> f64 {
        self.path.next_stop(h.current().w, h.is_rest(), self.horizon)
    }

    /// Largest step length (mm) allowed by the feed and the chord-error estimate
    /// (chord error ~ kappa l^2 / 8), at `scale` of the chord cap.
    pub fn step_cap(&self, h: &History, chord_scale: f64) -> f64 {
        let cur = h.current();
        let pred = (3.0 * cur.w - 3.0 * h.p[1].w + h.p[0].w).clamp(cur.w, self.bound(h));
        let reach = (2.0 * pred - cur.w).min(self.bound(h));
        let kappa = self.path.max_curvature(cur.w, reach);
        let chord = if kappa > 0.0 {
            chord_scale * (8.0 * self.limits.chord_tolerance / kappa).sqrt()
        } else {
            f64::INFINITY
        };
        chord.min(self.step_feed(cur.element, cur.element) * self.limits.period)
    }

    /// Exact check of a candidate next point: the same floating-point operations as
    /// [`crate::planner::axial::FiniteDifferences::push`] and the verifier's feed check.
    pub fn feasible(&self, h: &History, p: &PathPoint, cap: f64) -> bool {
        let cur = h.current();
        if p.w < cur.w || p.w > self.bound(h) {
            return false;
        }
        let dt = self.limits.period;
        let (q3, q2, q1) = (&h.p[0].q, &h.p[1].q, &cur.q);
        for i in 0..self.axes {
            let v0 = (p.q[i] - q1[i]) / dt;
            let v1 = (q1[i] - q2[i]) / dt;
            let v2 = (q2[i] - q3[i]) / dt;
            let a0 = (v0 - v1) / dt;
            let a1 = (v1 - v2) / dt;
            let j0 = (a0 - a1) / dt;
            if !(v0.abs() <= self.limits.velocity[i]
                && a0.abs() <= self.limits.acceleration[i]
                && j0.abs() <= self.limits.jerk[i])
            {
                return false;
            }
        }
        let step = tip_distance(&p.tip, &cur.tip, self.path.tip_dim());
        step / dt <= self.step_feed(cur.element, p.element) && step <= cap
    }

    /// Per-axis box of next joint positions (targets, slightly inside the limits).
    fn target_box(&self, h: &History) -> Option<([f64; MAX_AXES], [f64; MAX_AXES])> {
        let dt = self.limits.period;
        let k = 1.0 - TARGET_MARGIN;
        let (q3, q2, q1) = (&h.p[0].q, &h.p[1].q, &h.current().q);
        let mut lo = [f64::NEG_INFINITY; MAX_AXES];
        let mut hi = [f64::INFINITY; MAX_AXES];
        for i in 0..self.axes {
            let rv = k * self.limits.velocity[i] * dt;
            let ra = k * self.limits.acceleration[i] * dt * dt;
            let rj = k * self.limits.jerk[i] * dt * dt * dt;
            let ca = 2.0 * q1[i] - q2[i];
            let cj = 3.0 * q1[i] - 3.0 * q2[i] + q3[i];
            lo[i] = (q1[i] - rv).max(ca - ra).max(cj - rj);
            hi[i] = (q1[i] + rv).min(ca + ra).min(cj + rj);
            if lo[i] > hi[i] {
                return None;
            }
        }
        Some((lo, hi))
    }

    /// Interval of `w` where the constraints linearised at `w0` hold.
    fn linear_interval(
        &self,
        h: &History,
        bx: &([f64; MAX_AXES], [f64; MAX_AXES]),
        w0: f64,
        cap: f64,
        skip_weak: bool,
    ) -> (f64, f64, PathPoint) {
        let (p, dq, dtip) = self.path.eval_d(w0);
        let mut a = h.current().w;
        let mut b = self.bound(h);
        let strongest = (0..self.axes).map(|i| dq[i].abs()).fold(0.0, f64::max);
        for i in 0..self.axes {
            let (lo, hi) = (bx.0[i], bx.1[i]);
            if skip_weak && dq[i].abs() < WEAK * strongest {
                // Near a reversal of this axis the linear model fails; checked exactly later.
                continue;
            }
            if dq[i] != 0.0 {
                let t1 = w0 + (lo - p.q[i]) / dq[i];
                let t2 = w0 + (hi - p.q[i]) / dq[i];
                a = a.max(t1.min(t2));
                b = b.min(t1.max(t2));
            } else if p.q[i] < lo || p.q[i] > hi {
                return (f64::INFINITY, f64::NEG_INFINITY, p);
            }
        }
        // Feed ball / chord cap on the tip step.
        let n = self.path.tip_dim();
        let cur = h.current();
        let dist = tip_distance(&p.tip, &cur.tip, n);
        let rate = if dist > 0.0 {
            (0..n).map(|i| (p.tip[i] - cur.tip[i]) * dtip[i]).sum::<f64>() / dist
        } else {
            (0..n).map(|i| dtip[i] * dtip[i]).sum::<f64>().sqrt()
        };
        if rate > 0.0 {
            b = b.min(w0 + (cap * (1.0 - TARGET_MARGIN) - dist) / rate);
        }
        (a, b, p)
    }

    /// A feasible next point near `target`: the target itself, or the target clamped into the
    /// constraints linearised at the last estimate (up to four corrections); `None` when that
    /// does not find an exactly feasible point.
    pub fn project(&self, h: &History, target: f64, cap: f64) -> Option<PathPoint> {
        let cur = h.current().w;
        let p = self.path.eval(target.clamp(cur, self.bound(h)));
        if self.feasible(h, &p, cap) {
            return Some(p);
        }
        let bx = self.target_box(h)?;
        let mut w = p.w;
        for _ in 0..4 {
            let (a, b, _) = self.linear_interval(h, &bx, w, cap, false);
            if a.is_nan() || b.is_nan() || a > b {
                return None;
            }
            let next = target.clamp(a, b).clamp(cur, self.bound(h));
            if next == w {
                return None;
            }
            w = next;
            let p = self.path.eval(w);
            if self.feasible(h, &p, cap) {
                return Some(p);
            }
        }
        None
    }

    /// Lowest and highest exactly feasible next points, or `None` when the intersection is
    /// empty (eq. 7-9 have no common solution). `chord_scale` scales the chord-error cap.
    pub fn interval(&self, h: &History, chord_scale: f64) -> Option<(PathPoint, PathPoint)> {
        let bx = self.target_box(h)?;
        let cap = self.step_cap(h, chord_scale);
        let cur = *h.current();
        // Eq. 13: the next point predicted from the last steps; then Newton on the centre.
        let mut w = (3.0 * cur.w - 3.0 * h.p[1].w + h.p[0].w).clamp(cur.w, self.bound(h));
        let mut centre = None;
        let mut ab = (f64::INFINITY, f64::NEG_INFINITY);
        for _ in 0..6 {
            let (a, b, p) = self.linear_interval(h, &bx, w, cap, false);
            if a <= b && p.w >= a && p.w <= b && self.feasible(h, &p, cap) {
                centre = Some(p);
                ab = (a, b);
                // Close enough to the middle: stop.
                if (w - 0.5 * (a + b)).abs() <= 0.25 * (b - a) {
                    break;
                }
            }
            if !(a.is_finite() && b.is_finite()) {
                break;
            }
            let next = (0.5 * (a + b)).clamp(cur.w, self.bound(h));
            if next == w {
                break;
            }
            w = next;
        }
        if centre.is_none() {
            // Fallback: drop the axes whose linear model is weak (reversals), and scan the
            // interval of the others with the exact check.
            let w0 = (3.0 * cur.w - 3.0 * h.p[1].w + h.p[0].w).clamp(cur.w, self.bound(h));
            let (a, b, _) = self.linear_interval(h, &bx, w0, cap, true);
            if a <= b {
                const N: usize = 48;
                for k in 0..=N {
                    // From the middle outwards.
                    let off = (k as f64 / N as f64 - 0.5) * (b - a);
                    let wk = 0.5 * (a + b) + if k % 2 == 0 { off } else { -off };
                    let p = self.path.eval(wk.clamp(cur.w, self.bound(h)));
                    if self.feasible(h, &p, cap) {
                        centre = Some(p);
                        ab = (a, b);
                        break;
                    }
                }
            }
        }
        let centre = centre?;
        let hi = self.edge(h, &bx, cap, centre, ab.1, true);
        let stay = cur;
        let lo = if self.feasible(h, &stay, cap) {
            stay
        } else {
            self.edge(h, &bx, cap, centre, ab.0, false)
        };
        Some((lo, hi))
    }

    /// Highest (`upper`) or lowest feasible point, from a feasible `inside` point and a first
    /// estimate of the edge.
    fn edge(
        &self,
        h: &History,
        bx: &([f64; MAX_AXES], [f64; MAX_AXES]),
        cap: f64,
        inside: PathPoint,
        estimate: f64,
        upper: bool,
    ) -> PathPoint {
        let clamp = |w: f64| w.clamp(h.current().w, self.bound(h));
        let mut x = clamp(estimate);
        for _ in 0..3 {
            let (a, b, _) = self.linear_interval(h, bx, x, cap, false);
            if a.partial_cmp(&b) != Some(std::cmp::Ordering::Less) && a != b {
                break;
            }
            let nx = clamp(if upper { b } else { a });
            if nx == x {
                break;
            }
            x = nx;
        }
        let mut good = inside;
        let p = self.path.eval(x);
        if self.feasible(h, &p, cap) {
            return p;
        }
        let mut bad = x;
        for _ in 0..40 {
            let mid = 0.5 * (good.w + bad);
            if mid == good.w || mid == bad {
                break;
            }
            let p = self.path.eval(mid);
            if self.feasible(h, &p, cap) {
                good = p;
            } else {
                bad = mid;
            }
            if (bad - good.w).abs() <= 1e-9 * (bad - inside.w).abs() {
                break;
            }
        }
        good
    }
}

/// Euclidean distance between two tips, computed as the verifier computes it.
pub fn tip_distance(a: &[f64; 3], b: &[f64; 3], n: usize) -> f64 {
    let mut s = 0.0;
    for i in 0..n {
        let d = a[i] - b[i];
        s += d * d;
    }
    s.sqrt()
}
