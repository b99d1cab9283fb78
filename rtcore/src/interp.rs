//! Per-period interpolation: from a target arc length to the next curve parameter.
//!
//! [`rk2pc_step`] is the paper's RK2 predictor-corrector (paper 000, eq. 1-9): a Heun predictor
//! of the parameter increment, the predicted arc length measured by Simpson's rule, and a
//! corrector on the remaining arc length. The printed eq. 9 has a slip (`sqrt(a^2 - 4ab)`); the
//! correct root of eq. 5 is `(-b + sqrt(b^2 - 4ac)) / 2a`. With the chord replaced by the
//! Simpson arc length `L` (as the paper does), eq. 5 becomes `(|C'| du + L)^2 = ds^2`, whose
//! root is `du = (ds - L) / |C'|`; that closed form is what is used below.
//!
//! Second improvement over the paper: the step aims at an absolute arc length `s_target` taken
//! from the exact S-curve distance, not at `F(t_i) * dt`, so neither the feed quadrature nor the
//! interpolation error accumulates along the path.
//!
//! [`sot_step`], [`tot_step`] (second- and third-order Taylor) and [`fcp_eval`] (feed correction
//! polynomial) are the comparison methods of the paper's Table I.

use crate::math::{dot, norm, Vector};
use crate::nurbs::CurveView;

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
}

/// Smallest parametric speed used as a divisor; a curve with C'(u) = 0 (repeated control
/// points) is crossed with the corrector doing the work.
const MIN_SPEED: f64 = 1e-12;

impl PathCursor {
    /// Cursor at parameter `u`, taken to be at arc length `s`.
    pub fn at(curve: &CurveView, tip_axes: usize, u: f64, s: f64) -> Self {
        let d = curve.derivatives(u, 1);
        PathCursor {
            u,
            s,
            point: d[0],
            speed: norm(&d[1], tip_axes),
        }
    }
}

#[inline]
fn speed_at(curve: &CurveView, tip_axes: usize, u: f64) -> f64 {
    norm(&curve.derivatives(u, 1)[1], tip_axes)
}

/// RK2 predictor-corrector step from `cur` to arc length `s_target` (eq. 1-9, see module doc).
/// Bounded work: at most 2 + (1 + MAX_CORRECTIONS) * (2 MAX_PANELS) curve evaluations (5 in the
/// normal case, where the step stays in one knot span and one correction suffices).
pub fn rk2pc_step(curve: &CurveView, tip_axes: usize, cur: &PathCursor, s_target: f64) -> PathCursor {
    let (u_lo, u_hi) = (curve.u_min(), curve.u_max());
    let ds = s_target - cur.s;
    if ds == 0.0 {
        return PathCursor { s: s_target, ..*cur };
    }
    // Predictor (eq. 1-2): Heun's method on du/ds = 1/|C'(u)|.
    let k1 = 1.0 / cur.speed.max(MIN_SPEED);
    let u_trial = (cur.u + k1 * ds).clamp(u_lo, u_hi);
    let k2 = 1.0 / speed_at(curve, tip_axes, u_trial).max(MIN_SPEED);
    let u_pred = (cur.u + 0.5 * (k1 + k2) * ds).clamp(u_lo, u_hi);
    // Arc length actually covered by the prediction, by Simpson's rule, piecewise over the knot
    // spans crossed: at a knot |C'| may have a kink or (C0 knot, e.g. two collinear lines of a
    // rational polyline) a jump, which a single Simpson panel across it would misjudge.
    let knots = curve.knots();
    let first_knot = curve.find_span(cur.u) + 1;
    let simpson = |u: f64, end_speed: f64| {
        let panel = |a: f64, b: f64, speed_a: f64, speed_b: f64| {
            (b - a) / 6.0 * (speed_a + 4.0 * speed_at(curve, tip_axes, 0.5 * (a + b)) + speed_b)
        };
        let (mut a, mut speed_a, mut total) = (cur.u, cur.speed, 0.0);
        let mut k = first_knot;
        // Bounded: at most MAX_PANELS - 1 knots are split off; beyond that (many tiny spans
        // within one period) the last panel spans the rest.
        while k < knots.len() && knots[k] < u && knots[k] > a && k < first_knot + MAX_PANELS - 1 {
            let b = knots[k];
            total += panel(a, b, speed_a, norm(&curve.derivatives_left(b, 1)[1], tip_axes));
            a = b;
            speed_a = speed_at(curve, tip_axes, b);
            k += 1;
        }
        total + panel(a, u, speed_a, end_speed)
    };
    let mut d = curve.derivatives(u_pred, 1);
    let mut u = u_pred;
    let mut speed = norm(&d[1], tip_axes);
    let mut covered = simpson(u, speed);
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
        d = curve.derivatives(u, 1);
        speed = norm(&d[1], tip_axes);
        covered = simpson(u, speed);
    }
    // The next step aims at its own target from the arc length actually reached, so the
    // corrector's residual never accumulates along the path.
    PathCursor {
        u,
        s: cur.s + covered,
        point: d[0],
        speed,
    }
}

/// Simpson panels at most per arc-length measurement (one per knot span crossed).
const MAX_PANELS: usize = 4;

/// Corrector iterations at most (two curve evaluations each); one in the normal case. Where
/// |C'| nearly vanishes the predictor can overshoot to the end of the curve and the bracket
/// must shrink by bisection from the whole parameter range: 48 halvings reach the f64
/// resolution of u, so the step converges there too (a cusp at the start of a curve needed 20).
const MAX_CORRECTIONS: usize = 48;

/// Second-order Taylor step of u(s) by the arc-length increment `ds`.
pub fn sot_step(curve: &CurveView, tip_axes: usize, cur: &PathCursor, ds: f64) -> PathCursor {
    taylor_step(curve, tip_axes, cur, ds, false)
}

/// Third-order Taylor step of u(s) by the arc-length increment `ds`.
pub fn tot_step(curve: &CurveView, tip_axes: usize, cur: &PathCursor, ds: f64) -> PathCursor {
    taylor_step(curve, tip_axes, cur, ds, true)
}

fn taylor_step(curve: &CurveView, tip_axes: usize, cur: &PathCursor, ds: f64, third: bool) -> PathCursor {
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
    let u = (cur.u + du).clamp(curve.u_min(), curve.u_max());
    let e = curve.derivatives(u, 1);
    PathCursor {
        u,
        s: cur.s + ds,
        point: e[0],
        speed: norm(&e[1], tip_axes),
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
