//! Per-period interpolation: from a target arc length to the next curve parameter.
//!
//! [`rk2pc_step`] is the paper's RK2 predictor-corrector (Erwinski et al. 2022, eq. 1-9): a Heun predictor
//! of the parameter increment, the predicted arc length measured by Simpson's rule, and a
//! corrector on the remaining arc length. The printed eq. 9 has a slip (`sqrt(a^2 - 4ab)`); the
//! correct root of eq. 5 is `(-b + sqrt(b^2 - 4ac)) / 2a`. With the chord replaced by the
//! Simpson arc length `L` (as the paper does), eq. 5 becomes `(|C'| du + L)^2 = ds^2`, whose
//! root is `du = (ds - L) / |C'|`; that closed form is what the evaluated corrector uses (the
//! expanded one below adds the second-order term).
//!
//! The step's normal case is cheaper than the paper's (2 curve evaluations, as many as a
//! second-order Taylor step): the Heun predictor is replaced by a Taylor step from the speed and
//! its slope carried in the cursor, and the corrector is applied by expansion about the
//! predicted end; the paper's form remains the fallback (see [`rk2pc_step`]).
//!
//! Another improvement over the paper: the step aims at an absolute arc length `s_target` taken
//! from the exact S-curve distance, not at `F(t_i) * dt`, so neither the feed quadrature nor the
//! interpolation error accumulates along the path.
//!
//! [`sot_step`], [`tot_step`] (second- and third-order Taylor) and [`fcp_eval`] (feed correction
//! polynomial) are the comparison methods of the paper's Table I.

use crate::math::{dot, norm, Vector};
use crate::nurbs::Derivatives;
use crate::span_cache::CachedCurve;

/// Where the interpolator is on the curve after a period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathCursor {
    /// Curve parameter.
    pub u: f64,
    /// Arc length from the curve start that `u` is taken to represent (mm).
    pub s: f64,
    /// Curve point at `u` (machine coordinates; 6 values for a two-curve 5-axis path).
    pub point: Vector,
    /// Parametric speed |C'(u)| of the tool-tip coordinates.
    pub speed: f64,
    /// Its rate d|C'|/du = C'.C''/|C'| at `u` (tool-tip coordinates): what the next step's
    /// Taylor predictor needs. An approximation is enough (the step is measured afterwards);
    /// zero makes the predictor first-order.
    pub speed_slope: f64,
}

/// Smallest parametric speed used as a divisor; a curve with C'(u) = 0 (repeated control
/// points) is crossed with the corrector doing the work.
const MIN_SPEED: f64 = 1e-12;

impl PathCursor {
    /// Cursor at parameter `u`, taken to be at arc length `s`.
    pub fn at(curve: &mut CachedCurve, tip_axes: usize, u: f64, s: f64) -> Self {
        let d = curve.derivatives(u, 2);
        let speed = norm(&d[1], tip_axes);
        PathCursor {
            u,
            s,
            point: d[0],
            speed,
            speed_slope: slope_of_speed(&d[1], &d[2], speed, tip_axes),
        }
    }
}

#[inline]
fn speed_at(curve: &mut CachedCurve, tip_axes: usize, u: f64) -> f64 {
    norm(&curve.derivatives(u, 1)[1], tip_axes)
}

/// d|C'|/du from C' and C'' (zero where |C'| vanishes: no usable direction there).
#[inline]
fn slope_of_speed(first: &Vector, second: &Vector, speed: f64, tip_axes: usize) -> f64 {
    if speed > MIN_SPEED {
        dot(first, second, tip_axes) / speed
    } else {
        0.0
    }
}

/// RK2 predictor-corrector step from `cur` to arc length `s_target` (eq. 1-9, see module doc).
///
/// Normal case, 2 curve evaluations (SOT needs 2 as well): the predictor is a second-order
/// Taylor step of u(s) from the speed and its slope carried in `cur` (no evaluation); the
/// predicted step is measured by Simpson's rule (the midpoint with one derivative, the end
/// with two); and the corrector step is applied by a Taylor expansion about the predicted end
/// rather than by evaluating and measuring again (`taylor_correction` says when it may).
///
/// Otherwise the robust path: Heun's predictor where the carried slope is not usable
/// (1 evaluation), Simpson piecewise over the knot spans crossed, and a bracketed corrector
/// repeated until the residual is below 1e-12 (1 + |ds|). A step across one knot costs 10
/// evaluations (two measurements of 5). Bounded work in every case: at most
/// 1 + (1 + MAX_CORRECTIONS) (3 MAX_PANELS - 1) = 540 evaluations of at most two derivatives
/// (a measurement evaluates the end, MAX_PANELS midpoints and both sides of up to
/// MAX_PANELS - 1 knots), plus constant work.
pub fn rk2pc_step(curve: &mut CachedCurve, tip_axes: usize, cur: &PathCursor, s_target: f64) -> PathCursor {
    step_to(curve, tip_axes, cur, s_target, true)
}

/// [`rk2pc_step`]; `expand_correction = false` always takes the robust corrector (tests compare
/// the two).
#[inline(always)]
fn step_to(
    curve: &mut CachedCurve,
    tip_axes: usize,
    cur: &PathCursor,
    s_target: f64,
    expand_correction: bool,
) -> PathCursor {
    let view = curve.view();
    let (u_lo, u_hi) = (view.u_min(), view.u_max());
    let ds = s_target - cur.s;
    if ds == 0.0 {
        return PathCursor { s: s_target, ..*cur };
    }
    // Predictor. Where the cursor's speed and slope describe u(s) well, a Taylor step
    // u_s = 1/|C'|, u_ss = -|C'|'/|C'|^3 costs nothing; otherwise Heun's method on
    // du/ds = 1/|C'(u)| (eq. 1-2).
    let k1 = 1.0 / cur.speed.max(MIN_SPEED);
    let curvature_term = -0.5 * ds * cur.speed_slope * k1 * k1;
    let u_pred = if ds > 0.0 && cur.speed > MIN_SPEED && curvature_term.abs() <= MAX_TAYLOR_TERM {
        cur.u + k1 * ds * (1.0 + curvature_term)
    } else {
        let u_trial = (cur.u + k1 * ds).clamp(u_lo, u_hi);
        let k2 = 1.0 / speed_at(curve, tip_axes, u_trial).max(MIN_SPEED);
        cur.u + 0.5 * (k1 + k2) * ds
    }
    .clamp(u_lo, u_hi);
    // Arc length actually covered by the prediction, by Simpson's rule, piecewise over the knot
    // spans crossed: at a knot |C'| may have a kink or (C0 knot, e.g. two collinear lines of a
    // rational polyline) a jump, which a single Simpson panel across it would misjudge.
    let knots = view.knots();
    let first_knot = view.find_span(cur.u) + 1;
    let simpson = |curve: &mut CachedCurve, u: f64, end_speed: f64| {
        let panel = |curve: &mut CachedCurve, a: f64, b: f64, speed_a: f64, speed_b: f64| {
            (b - a) / 6.0 * (speed_a + 4.0 * speed_at(curve, tip_axes, 0.5 * (a + b)) + speed_b)
        };
        let (mut a, mut speed_a, mut total) = (cur.u, cur.speed, 0.0);
        let mut k = first_knot;
        // Bounded: at most MAX_PANELS - 1 knots are split off; beyond that (many tiny spans
        // within one period) the last panel spans the rest.
        while k < knots.len() && knots[k] < u && knots[k] > a && k < first_knot + MAX_PANELS - 1 {
            let b = knots[k];
            let speed_b = norm(&curve.derivatives_left(b, 1)[1], tip_axes);
            total += panel(curve, a, b, speed_a, speed_b);
            a = b;
            speed_a = speed_at(curve, tip_axes, b);
            k += 1;
        }
        total + panel(curve, a, u, speed_a, end_speed)
    };
    let mut d = curve.derivatives(u_pred, 2);
    let mut u = u_pred;
    let mut speed = norm(&d[1], tip_axes);
    let mut covered = simpson(curve, u, speed);
    let span_end = knots.get(first_knot).copied().unwrap_or(u_hi);
    if expand_correction {
        if let Some(next) = taylor_correction(cur, u_pred, &d, covered, ds, span_end, tip_axes) {
            return next;
        }
    }
    // Corrector (eq. 5-9 with the arc length in place of the chord). Normally one step; where
    // |C'| nearly vanishes (repeated control points) the linear correction is unreliable, so it
    // is safeguarded by the bracket [lo, hi] and repeated at most MAX_CORRECTIONS times.
    let (mut lo, mut hi) = (cur.u, u_hi);
    let tolerance = 1e-12 * (1.0 + ds.abs());
    for _ in 0..MAX_CORRECTIONS {
        let residual = ds - covered;
        if residual.abs() <= tolerance {
            break;
        }
        if residual > 0.0 {
            lo = u;
        } else {
            hi = u;
        }
        let newton = u + residual / speed.max(MIN_SPEED);
        u = if newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        d = curve.derivatives(u, 2);
        speed = norm(&d[1], tip_axes);
        covered = simpson(curve, u, speed);
    }
    // The next step aims at its own target from the arc length actually reached, so the
    // corrector's residual never accumulates along the path.
    PathCursor {
        u,
        s: cur.s + covered,
        point: d[0],
        speed,
        speed_slope: slope_of_speed(&d[1], &d[2], speed, tip_axes),
    }
}

/// The corrector step of [`rk2pc_step`] without evaluating the curve again. `end` holds the
/// point and two derivatives at the predicted parameter `u_pred`, `covered` the Simpson arc
/// length from `cur` to it. Returns `None` (the caller runs the robust corrector) unless the
/// step goes forward and stays inside the knot span of `cur.u` (below `span_end`: no kink or
/// jump of |C'| inside, not clamped at the curve end), and the correction
/// `delta = (ds - covered) / |C'(u_pred)|` is tiny against the step (so |C'| is well away from
/// zero there and the expansions below err by O(delta^3)).
fn taylor_correction(
    cur: &PathCursor,
    u_pred: f64,
    end: &Derivatives,
    covered: f64,
    ds: f64,
    span_end: f64,
    tip_axes: usize,
) -> Option<PathCursor> {
    let residual = ds - covered;
    let step = u_pred - cur.u;
    let end_speed = norm(&end[1], tip_axes);
    let end_slope = slope_of_speed(&end[1], &end[2], end_speed, tip_axes);
    // The corrector of eq. 5-9 to second order: the root of |C'| d + |C'|' d^2 / 2 = residual,
    // so the step lands on its target to O(delta^3) rather than O(delta^2).
    let linear = residual / end_speed;
    let u = u_pred + (linear - 0.5 * end_slope * linear * linear / end_speed);
    // Written so that NaN or an infinite correction fails every test.
    let small = residual.abs() <= MAX_TAYLOR_CORRECTION * ds && (u - u_pred).abs() <= MAX_TAYLOR_CORRECTION * step;
    if !(step > 0.0 && u_pred < span_end && u > cur.u && u < span_end && small) {
        return None;
    }
    // The correction as represented in u, so that point and u agree to rounding.
    let delta = u - u_pred;
    let mut point = end[0];
    let mut tangent = end[1];
    for i in 0..point.len() {
        point[i] += delta * (end[1][i] + 0.5 * delta * end[2][i]);
        tangent[i] += delta * end[2][i];
    }
    let speed = norm(&tangent, tip_axes);
    // `s` stays the arc length actually reached, not the target: Simpson's measurement up to
    // u_pred plus the arc length of the correction, |C'| delta + |C'|' delta^2 / 2, whose
    // Taylor error (|C'|'' delta^3 / 6) is far below Simpson's. The next step then aims at its
    // own target from where the cursor really is, so nothing accumulates.
    Some(PathCursor {
        u,
        s: cur.s + (covered + delta * (end_speed + 0.5 * end_slope * delta)),
        point,
        speed,
        // For the next predictor only, so C'' is taken as constant over delta.
        speed_slope: slope_of_speed(&tangent, &end[2], speed, tip_axes),
    })
}

/// Largest second-order term of the Taylor predictor relative to the first-order one; beyond
/// it (|C'| changing fast against the step, or nearly zero) Heun's predictor is used.
const MAX_TAYLOR_TERM: f64 = 0.25;

/// Largest correction applied by expansion instead of evaluation, relative to the step (in u
/// and in s). The neglected terms then are at most 1e-8 of the step's own second-order terms
/// (|C'''| delta^2 / 2 in the speed the next measurement starts from; delta^3 in point and
/// arc length): in a step Simpson measures to ~1e-14, that is below the robust corrector's
/// tolerance. About 1 % of the butterfly's steps (predictor error above this) fall back.
const MAX_TAYLOR_CORRECTION: f64 = 1e-4;

/// Simpson panels at most per arc-length measurement (one per knot span crossed).
const MAX_PANELS: usize = 4;

/// Corrector iterations at most (one measurement each); one on the robust path as a rule. Where
/// |C'| nearly vanishes the predictor can overshoot to the end of the curve and the bracket
/// must shrink by bisection from the whole parameter range: 48 halvings reach the f64
/// resolution of u, so the step converges there too (a cusp at the start of a curve needed 20).
const MAX_CORRECTIONS: usize = 48;

/// Second-order Taylor step of u(s) by the arc-length increment `ds`.
pub fn sot_step(curve: &mut CachedCurve, tip_axes: usize, cur: &PathCursor, ds: f64) -> PathCursor {
    taylor_step(curve, tip_axes, cur, ds, false)
}

/// Third-order Taylor step of u(s) by the arc-length increment `ds`.
pub fn tot_step(curve: &mut CachedCurve, tip_axes: usize, cur: &PathCursor, ds: f64) -> PathCursor {
    taylor_step(curve, tip_axes, cur, ds, true)
}

fn taylor_step(curve: &mut CachedCurve, tip_axes: usize, cur: &PathCursor, ds: f64, third: bool) -> PathCursor {
    let d = curve.derivatives(cur.u, if third { 3 } else { 2 });
    let g2 = dot(&d[1], &d[1], tip_axes).max(MIN_SPEED * MIN_SPEED);
    let g = g2.sqrt_rt();
    let c12 = dot(&d[1], &d[2], tip_axes);
    // u_s = 1/g, u_ss = -(C'.C'')/g^4, u_sss = -(|C''|^2 + C'.C''')/g^5 + 4 (C'.C'')^2/g^7.
    let mut du = ds / g - ds * ds * c12 / (2.0 * g2 * g2);
    if third {
        let c22 = dot(&d[2], &d[2], tip_axes);
        let c13 = dot(&d[1], &d[3], tip_axes);
        let g5 = g2 * g2 * g;
        let u_sss = -(c22 + c13) / g5 + 4.0 * c12 * c12 / (g5 * g2);
        du += ds * ds * ds * u_sss / 6.0;
    }
    let u = (cur.u + du).clamp(curve.view().u_min(), curve.view().u_max());
    let e = curve.derivatives(u, 1);
    PathCursor {
        u,
        s: cur.s + ds,
        point: e[0],
        speed: norm(&e[1], tip_axes),
        // Not evaluated (it would cost the comparison a derivative): RK2-PC from here starts
        // with a first-order predictor.
        speed_slope: 0.0,
    }
}

/// Feed correction polynomial: u = sum c_k x^k with x the normalised arc length in a span
/// (coefficients fitted offline by the planner).
#[inline]
pub fn fcp_eval(coefficients: &[f64; 8], x: f64) -> f64 {
    let mut u = 0.0;
    for c in coefficients.iter().rev() {
        u = u * x + c;
    }
    u
}

trait SqrtRt {
    fn sqrt_rt(self) -> f64;
}
impl SqrtRt for f64 {
    #[inline]
    fn sqrt_rt(self) -> f64 {
        libm::sqrt(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nurbs::CurveView;
    use crate::span_cache::SpanCache;

    /// Arc length from the curve start to `u`: 5-point Gauss-Legendre on 64 pieces per knot
    /// span (|C'| is smooth inside a span), exact to rounding for these curves.
    fn length_to(curve: &CurveView, u: f64) -> f64 {
        const X: [f64; 5] = [
            0.0,
            -0.538_469_310_105_683,
            0.538_469_310_105_683,
            -0.906_179_845_938_664,
            0.906_179_845_938_664,
        ];
        const W: [f64; 5] = [
            0.568_888_888_888_889,
            0.478_628_670_499_366,
            0.478_628_670_499_366,
            0.236_926_885_056_189,
            0.236_926_885_056_189,
        ];
        let mut total = 0.0;
        let knots = curve.knots();
        for pair in knots.windows(2) {
            let (a, b) = (pair[0], pair[1].min(u));
            if b <= a {
                continue;
            }
            let pieces = 64;
            let h = (b - a) / pieces as f64;
            for k in 0..pieces {
                let mid = a + (k as f64 + 0.5) * h;
                for (x, w) in X.iter().zip(W) {
                    // Evaluated inside the span (never at its end knot), so C0 knots are fine.
                    total += 0.5 * h * w * curve.speed(mid + 0.5 * h * x, 2);
                }
            }
        }
        total
    }

    /// Walks `curve` with steps growing from `ds0` by `growth` per step (to 0.25) and checks every
    /// cursor: the step covers its target (to Simpson's accuracy), and the expanded corrector
    /// agrees with the evaluated one: same `u`, honest `s`, the point and speed of its `u`.
    /// Returns how many steps there were and how many took the expansion (differ from the
    /// robust corrector's result).
    fn walk(view: &CurveView, ds0: f64, growth: f64) -> (usize, usize) {
        let mut cache = SpanCache::new();
        let curve = &mut CachedCurve::new(*view, &mut cache);
        let total = length_to(view, view.u_max());
        let mut cur = PathCursor::at(curve, 2, view.u_min(), 0.0);
        let (mut ds, mut steps, mut expanded) = (ds0, 0, 0);
        while cur.s + ds < total {
            let target = cur.s + ds;
            let next = rk2pc_step(curve, 2, &cur, target);
            let robust = step_to(curve, 2, &cur, target, false);
            let covered = length_to(view, next.u) - length_to(view, cur.u);
            assert!(
                (covered - ds).abs() <= 1e-8 * ds + 1e-12,
                "step {steps}: {covered} for {ds}"
            );
            assert!(
                (next.s - target).abs() <= 1e-12 * (1.0 + ds),
                "step {steps}: s {} for {target}",
                next.s
            );
            // Both within the robust corrector's tolerance of the target (it is the looser one).
            let tolerance = 2e-12 * (1.0 + ds);
            assert!((next.u - robust.u).abs() * robust.speed <= tolerance, "step {steps}: u");
            assert!((next.s - robust.s).abs() <= tolerance, "step {steps}: s");
            let at = PathCursor::at(curve, 2, next.u, next.s);
            for i in 0..2 {
                assert!((next.point[i] - at.point[i]).abs() <= 1e-13, "step {steps}: point");
            }
            // |C'''| delta^2 / 2 neglected: the next measurement starts from this speed, and
            // its error there stays far below Simpson's in these (long) steps.
            assert!((next.speed - at.speed).abs() <= 1e-11 * at.speed, "step {steps}: speed");
            // Only the next predictor uses the slope.
            assert!((next.speed_slope - at.speed_slope).abs() <= 1e-3 * (at.speed + at.speed_slope.abs()));
            if next != robust {
                expanded += 1;
            }
            cur = next;
            ds = (ds * growth).min(0.25);
            steps += 1;
        }
        // A target beyond the end stops at the end with the arc length actually reached.
        let last = rk2pc_step(curve, 2, &cur, total + 1.0);
        assert_eq!(last.u, view.u_max());
        assert!((last.s - total).abs() <= 1e-6 * (total - cur.s));
        (steps, expanded)
    }

    #[test]
    fn cubic_with_interior_knots() {
        let knots = [0.0, 0.0, 0.0, 0.0, 0.2, 0.45, 0.7, 1.0, 1.0, 1.0, 1.0];
        let points = [
            0.0, 0.0, 10.0, 25.0, 30.0, -5.0, 45.0, 20.0, 70.0, 40.0, 80.0, 0.0, 100.0, 10.0,
        ];
        let curve = CurveView::new(3, 2, &knots, &points, &[1.0; 7]).unwrap();
        // Not counted: steps across the 3 interior knots (robust corrector), and very short
        // steps, where both correctors leave the prediction as it is.
        for (ds0, growth) in [(1e-6, 1.05), (0.25, 1.0)] {
            let (steps, expanded) = walk(&curve, ds0, growth);
            assert!(expanded * 10 > steps * 8, "{expanded} of {steps}");
        }
    }

    #[test]
    fn rational_quarter_circle() {
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let points = [50.0, 0.0, 50.0, 50.0, 0.0, 50.0];
        let weights = [1.0, core::f64::consts::FRAC_1_SQRT_2, 1.0];
        let curve = CurveView::new(2, 2, &knots, &points, &weights).unwrap();
        assert!((length_to(&curve, 1.0) - 25.0 * core::f64::consts::PI).abs() < 1e-12);
        let (steps, expanded) = walk(&curve, 0.2, 1.0);
        assert_eq!(expanded, steps);
    }

    #[test]
    fn polyline_with_a_repeated_point() {
        // The middle segment has zero length: |C'| = 0 over a whole span, and jumps at C0 knots.
        let knots = [0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0];
        let points = [0.0, 0.0, 10.0, 0.0, 10.0, 0.0, 10.0, 5.0, 30.0, 5.0];
        let curve = CurveView::new(1, 2, &knots, &points, &[1.0, 1.5, 1.0, 1.0, 0.8]).unwrap();
        let (steps, expanded) = walk(&curve, 0.3, 1.0);
        assert!(expanded > 0 && expanded < steps);
    }

    #[test]
    fn first_order_start_from_a_cursor_without_slope() {
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let points = [0.0, 0.0, 40.0, 60.0, 80.0, 0.0];
        let curve = CurveView::new(2, 2, &knots, &points, &[1.0; 3]).unwrap();
        let mut cache = SpanCache::new();
        let cached = &mut CachedCurve::new(curve, &mut cache);
        let cur = PathCursor {
            speed_slope: 0.0,
            ..PathCursor::at(cached, 2, 0.3, length_to(&curve, 0.3))
        };
        let next = rk2pc_step(cached, 2, &cur, cur.s + 0.5);
        assert!((length_to(&curve, next.u) - (cur.s + 0.5)).abs() <= 1e-10);
        assert!((next.s - (cur.s + 0.5)).abs() <= 1e-12);
    }
}
