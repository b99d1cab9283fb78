//! The plan sampled at the servo period: each period's arc length from the pieces in closed
//! form, the curve parameter there from its interval's fit ([`Inverses`]; by Newton's method on
//! the arc length where the interval has none), and the finite-difference check of every
//! sample against the limits, which says where a plan ran over so that the planner can tighten
//! it there.

use super::grid::{piece_length, Grid, TIP};
use super::inverse::{Fit, Inverses};
use super::passes::Motion;
use crate::planner::axial::MAX_AXES;
use crate::planner::vpop::PathPoint;
use crate::planner::{Limits, PathCurves};

/// Finite differences of the samples, as `verify` takes them, that remember where they ran
/// over: velocity, acceleration and jerk per axis from the last four positions.
#[derive(Clone, Debug)]
pub struct Check {
    history: [[f64; TIP]; 3],
    started: bool,
    axes: usize,
    period: f64,
    velocity: [f64; TIP],
    acceleration: [f64; TIP],
    jerk: [f64; TIP],
    /// Largest ratio of a difference to its limit seen.
    pub worst: f64,
    /// The feed override the samples' feed is checked at (the sampler's feed check: the
    /// programmed feeds times it).
    pub feed_override: f64,
}

impl Check {
    pub fn new(limits: &Limits, axes: usize) -> Self {
        let mut c = Check {
            history: [[0.0; TIP]; 3],
            started: false,
            axes,
            period: limits.period,
            velocity: [f64::INFINITY; TIP],
            acceleration: [f64::INFINITY; TIP],
            jerk: [f64::INFINITY; TIP],
            worst: 0.0,
            feed_override: 1.0,
        };
        for i in 0..axes {
            c.velocity[i] = limits.velocity[i];
            c.acceleration[i] = limits.acceleration[i];
            c.jerk[i] = limits.jerk[i];
        }
        c
    }

    /// Adds a position; the largest ratio of its differences to their limits.
    pub fn push(&mut self, p: &[f64; TIP]) -> f64 {
        if !self.started {
            self.history = [*p; 3];
            self.started = true;
        }
        let [q3, q2, q1] = self.history;
        let dt = self.period;
        let mut ratio: f64 = 0.0;
        for i in 0..self.axes {
            let v0 = (p[i] - q1[i]) / dt;
            let v1 = (q1[i] - q2[i]) / dt;
            let v2 = (q2[i] - q3[i]) / dt;
            let a0 = (v0 - v1) / dt;
            let a1 = (v1 - v2) / dt;
            let j0 = (a0 - a1) / dt;
            ratio = ratio
                .max(v0.abs() / self.velocity[i])
                .max(a0.abs() / self.acceleration[i])
                .max(j0.abs() / self.jerk[i]);
        }
        self.history = [q2, q1, *p];
        self.worst = self.worst.max(ratio);
        ratio
    }
}

/// The feed a step from element `from` to element `to` may take: the limit, and the highest
/// programmed feed of the two (as `verify` takes it).
pub(super) fn step_feed(curves: &PathCurves, limits: &Limits, from: usize, to: usize) -> f64 {
    match (curves.programmed_feed(from), curves.programmed_feed(to)) {
        (Some(f0), Some(f1)) => limits.feed.min(f0.max(f1)),
        _ => limits.feed,
    }
}

/// Samples of one stretch, and where they ran over.
pub struct Sampled {
    pub points: Vec<PathPoint>,
    /// (time into the stretch, ratio) of every sample over its limits.
    pub over: Vec<(f64, f64)>,
    /// Time from the end of the motion to the next sample (a motion that goes on).
    pub next: f64,
}

/// Where the samples of a motion begin and end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    /// Time of the first sample into the motion (0 < first ≤ period; the one before is
    /// `before`).
    pub first: f64,
    /// Whether the motion ends at rest, the last sample at its end (a stretch's end); if not,
    /// it goes on and the samples stop at the last period within it.
    pub at_rest: bool,
}

/// Samples `motion` over `grid` at the servo period from `span.first` on, and checks each with
/// `check`, and its feed and chord error against `limits`. A ratio counts as over above
/// `1 + slack`. The intervals' fits are kept in `inverses`.
#[allow(clippy::too_many_arguments)]
pub fn sample(
    curves: &PathCurves,
    inverses: &Inverses,
    grid: &Grid,
    motion: &Motion,
    limits: &Limits,
    axes: usize,
    before: Option<PathPoint>,
    check: &mut Check,
    slack: f64,
    span: Span,
) -> Sampled {
    let period = limits.period;
    let mut out = Sampled {
        points: Vec::new(),
        over: Vec::new(),
        next: 0.0,
    };
    let total = motion.time();
    let mut k = 0;
    let mut t_k = 0.0;
    // The last position found: interval, distance into it, curve parameter.
    let mut last: Option<(usize, f64, f64)> = None;
    // The arc length's slope found by the last inversion: the next one's first guess.
    let mut slope: Option<f64> = None;
    // The fit of the interval sampled last.
    let mut fitted: Option<(usize, Option<Fit>)> = None;
    let mut n = 0u64;
    loop {
        let t = span.first + n as f64 * period;
        if !span.at_rest && t > total {
            out.next = t - total;
            break;
        }
        let (interval, sigma) = if t >= total {
            (grid.len() - 1, grid.intervals[grid.len() - 1].length)
        } else {
            while k + 1 < motion.durations.len() && t >= t_k + motion.durations[k] {
                t_k += motion.durations[k];
                k += 1;
            }
            let length = grid.intervals[k].length;
            (k, motion.pieces[k].at(t - t_k).0.clamp(0.0, length))
        };
        let st = &grid.stations[interval];
        let next = &grid.stations[interval + 1];
        let element = st.element;
        let view = curves.view(element);
        let u_end = if next.element == element { next.u } else { view.u_max() };
        let length = grid.intervals[interval].length;
        let u = if sigma >= length {
            u_end
        } else if sigma <= 0.0 {
            st.u
        } else if let Some(fit) = match &fitted {
            Some((i, fit)) if *i == interval => fit.clone(),
            _ => {
                let fit = inverses.fit(&view, element, (st.u, u_end), length, axes);
                fitted = Some((interval, fit.clone()));
                fit
            }
        } {
            fit.at(sigma)
        } else {
            let (mut u0, mut s0, mut hint) = (st.u, 0.0, None);
            if let Some((i, s, u)) = last {
                if i == interval && s <= sigma {
                    (u0, s0, hint) = (u, s, slope);
                }
            }
            let (u, found) = invert(&view, u0, s0, sigma, st.u, u_end, axes, hint);
            slope = Some(found);
            u
        };
        last = Some((interval, sigma, u));
        let point = path_point(&view, element, u, axes);
        let tip = point.tip;
        let mut ratio = check.push(&tip);
        if let Some(prev) = out.points.last().or(before.as_ref()) {
            // The feed of the step and its chord error (at the middle parameter of a step on
            // one element: where a bulge of the curve is largest).
            let step = (0..axes).map(|i| (tip[i] - prev.tip[i]).powi(2)).sum::<f64>().sqrt();
            let feed = check.feed_override * step_feed(curves, limits, prev.element, element);
            ratio = ratio.max(step / period / feed);
            if prev.element == element {
                let mut a = [0.0; nurbs_rtcore::MAX_DIM];
                let mut b = [0.0; nurbs_rtcore::MAX_DIM];
                a[..axes].copy_from_slice(&prev.tip[..axes]);
                b[..axes].copy_from_slice(&tip[..axes]);
                let mid = view.point(0.5 * (prev.u + u));
                let error = crate::planner::verify::distance_to_chord(&mid, &a, &b, axes);
                ratio = ratio.max(error / limits.chord_tolerance);
            }
        }
        if ratio > 1.0 + slack {
            out.over.push((t.min(total), ratio));
        }
        out.points.push(point);
        if t >= total {
            out.next = t - total + period;
            break;
        }
        n += 1;
    }
    out
}

/// The sample at `(element, u)` of `view` (that element's curve): its point, tool tip and
/// place along the path.
pub(super) fn path_point(view: &nurbs_rtcore::CurveView, element: usize, u: f64, axes: usize) -> PathPoint {
    let p = view.point(u);
    let mut tip = [0.0; TIP];
    tip[..axes].copy_from_slice(&p[..axes]);
    let mut q = [0.0; MAX_AXES];
    q[..axes].copy_from_slice(&p[..axes]);
    PathPoint {
        w: element as f64 + (u - view.u_min()) / (view.u_max() - view.u_min()),
        element,
        u,
        q,
        tip,
    }
}

/// The parameter in `[lo, hi]` at arc length `target` from the interval start, from the
/// known point `(u0, s0)` (Newton on the arc length, safeguarded by bisection).
///
/// The first step from `(u0, s0)` integrates over a whole sample's step; once the steps are
/// short (the end game, one or two of them) the arc length is carried on from the last point
/// by a 2-point rule and the slope is kept: both exact far below rounding over such steps,
/// and together a third of the curve evaluations. A step below 1e-10 of the interval ends it:
/// Newton's next error would be its square. `slope_hint`, the slope near `u0` (the last
/// inversion's, a sample before), saves evaluating it there for the first guess. Returns the
/// parameter and the last slope evaluated, the hint for the next sample.
#[allow(clippy::too_many_arguments)]
pub(super) fn invert(
    view: &nurbs_rtcore::CurveView,
    u0: f64,
    s0: f64,
    target: f64,
    lo: f64,
    hi: f64,
    axes: usize,
    slope_hint: Option<f64>,
) -> (f64, f64) {
    let (mut lo_u, mut hi_u) = (u0.max(lo), hi);
    let mut slope = slope_hint.filter(|&s| s > 0.0).unwrap_or_else(|| view.speed(u0, axes));
    let mut u = if slope > 0.0 {
        (u0 + (target - s0) / slope).clamp(lo_u, hi_u)
    } else {
        0.5 * (lo_u + hi_u)
    };
    let short = 1e-3 * (hi - lo);
    // The last point whose arc length was found, to carry it on over a short step.
    let mut known: Option<(f64, f64)> = None;
    for _ in 0..60 {
        let near = known.filter(|&(uk, _)| (u - uk).abs() <= short);
        let s = match near {
            Some((uk, sk)) => sk + gauss2(view, uk, u, axes),
            None => s0 + piece_length(view, u0, u, axes),
        };
        let err = s - target;
        if err.abs() <= 1e-14 * (1.0 + target) {
            break;
        }
        if err > 0.0 {
            hi_u = u;
        } else {
            lo_u = u;
        }
        if near.is_none() {
            slope = view.speed(u, axes);
        }
        known = Some((u, s));
        let step = err / slope;
        if slope > 0.0 && step.abs() <= 1e-10 * (hi - lo) {
            u = (u - step).clamp(lo_u, hi_u);
            break;
        }
        let newton = u - step;
        u = if slope > 0.0 && newton > lo_u && newton < hi_u {
            newton
        } else {
            0.5 * (lo_u + hi_u)
        };
        if hi_u - lo_u <= 1e-16 * (1.0 + hi_u.abs()) {
            break;
        }
    }
    (u, slope)
}

/// Arc length from `a` to `b` by the 2-point Gauss rule (signed): for the end game's short
/// steps.
fn gauss2(view: &nurbs_rtcore::CurveView, a: f64, b: f64, axes: usize) -> f64 {
    const X: f64 = 0.211_324_865_405_187_1; // (1 - 1/√3) / 2
    let h = b - a;
    0.5 * h * (view.speed(a + X * h, axes) + view.speed(b - X * h, axes))
}
