//! The station grid along a stretch of the tool-tip path, and the path's geometry at the
//! stations and inside every interval, with respect to arc length.
//!
//! The planner's state lives at stations; every constraint is imposed at the stations and at
//! collocation points inside each interval, where the arc-length derivatives q', q'', q''' of
//! the axis positions are evaluated here once per grid. Stations sit on every element join and
//! knot (the geometry is taken one-sided there), at most [`GridOptions::turn`] radians of turn
//! apart, and otherwise one expected speed × [`GridOptions::spacing`] apart, denser towards a
//! rest at either end.

use crate::planner::PathCurves;
use nurbs_rtcore::{CurveView, MAX_DIM};

/// Collocation points of an interval, as fractions of its parameter span.
pub const COLLOCATION: [f64; 3] = [0.25, 0.5, 0.75];
/// Gauss-Legendre nodes and weights on [0, 1] (5 points): arc length of short pieces.
const GL5: [(f64, f64); 5] = [
    (0.046_910_077_030_668_004, 0.118_463_442_528_094_54),
    (0.230_765_344_947_158_45, 0.239_314_335_249_683_23),
    (0.5, 0.284_444_444_444_444_45),
    (0.769_234_655_052_841_6, 0.239_314_335_249_683_23),
    (0.953_089_922_969_332, 0.118_463_442_528_094_54),
];

/// Tool-tip coordinates handled (x, y, z).
pub const TIP: usize = 3;
pub type Axes = [f64; TIP];

/// The path at one point, with respect to arc length: the axis derivatives and the cap the
/// feed, axis velocities and chord error put on a = ṡ².
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Local {
    pub q1: Axes,
    pub q2: Axes,
    pub q3: Axes,
    pub cap: f64,
}

impl Local {
    /// Curvature |q''|.
    pub fn curvature(&self) -> f64 {
        self.q2.iter().map(|x| x * x).sum::<f64>().sqrt()
    }
}

/// A station: where on which element, its arc length from the start of the stretch, and the
/// geometry on either side (they differ at knots and joins).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Station {
    pub element: usize,
    pub u: f64,
    pub s: f64,
    pub left: Local,
    pub right: Local,
}

/// The interval from one station to the next: its length and its collocation points
/// (distance θ from the interval start, and the geometry there).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Interval {
    pub length: f64,
    pub points: [(f64, Local); COLLOCATION.len()],
}

/// What bounds a = ṡ² at a point before any dynamics: feed, axis velocities, chord error.
#[derive(Clone, Debug, PartialEq)]
pub struct Caps {
    pub feed: f64,
    pub velocity: Axes,
    pub chord_tolerance: f64,
    pub period: f64,
    pub axes: usize,
    /// The feed override: the feeds (the planner's and each element's) times this factor.
    pub feed_override: f64,
    /// A lower override that takes over from an arc length on (a plan that continues a faster
    /// motion: the old feeds hold until it can have braked to the new ones).
    pub slow_down: Option<SlowDown>,
}

/// A feed override that holds from arc length `from` of the stretch on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlowDown {
    pub from: f64,
    pub feed_override: f64,
}

impl Caps {
    /// The cap on ṡ² at arc length `s` of the stretch, where the path has derivatives `q1`,
    /// `q2`, with the element's own programmed feed if it has one.
    pub fn at(&self, s: f64, q1: &Axes, q2: &Axes, programmed: Option<f64>) -> f64 {
        let feed_override = match self.slow_down {
            Some(slow) if s >= slow.from => slow.feed_override,
            _ => self.feed_override,
        };
        let mut v = programmed.map_or(self.feed, |f| f.min(self.feed)) * feed_override;
        for i in 0..self.axes {
            if q1[i].abs() > 1e-12 {
                v = v.min(self.velocity[i] / q1[i].abs());
            }
        }
        let kappa = q2[..self.axes].iter().map(|x| x * x).sum::<f64>().sqrt();
        v = v.min(chord_speed(kappa, self.chord_tolerance, self.period));
        v * v
    }
}

/// Highest speed whose chord over one period stays within `eps` of a circle of curvature
/// `kappa`: 2·sqrt(2ρε − ε²)/T (2ρ/T where the tolerance exceeds the radius).
pub fn chord_speed(kappa: f64, eps: f64, period: f64) -> f64 {
    if kappa <= 1e-12 {
        return f64::INFINITY;
    }
    let rho = 1.0 / kappa;
    if 2.0 * rho * eps > eps * eps {
        2.0 * (2.0 * rho * eps - eps * eps).sqrt() / period
    } else {
        2.0 * rho / period
    }
}

/// Arc-length derivatives of the first `n` coordinates of `view` at `u` (one-sided from the
/// left with `left`), and the parametric speed |C'(u)|.
pub fn arc_derivatives(view: &CurveView, u: f64, n: usize, left: bool) -> (f64, Axes, Axes, Axes) {
    let d = if left {
        view.derivatives_left(u, 3)
    } else {
        view.derivatives(u, 3)
    };
    let (r1, r2, r3) = (&d[1], &d[2], &d[3]);
    let dot = |x: &[f64; MAX_DIM], y: &[f64; MAX_DIM]| (0..n).map(|i| x[i] * y[i]).sum::<f64>();
    let sg = dot(r1, r1).sqrt();
    let (mut q1, mut q2, mut q3) = ([0.0; TIP], [0.0; TIP], [0.0; TIP]);
    if sg <= 0.0 {
        return (0.0, q1, q2, q3);
    }
    // σ = |r'|, σ' = r'·r''/σ, σ'' = (r''·r'' + r'·r''' − σ'²)/σ.
    let s1 = dot(r1, r2) / sg;
    let s2 = (dot(r2, r2) + dot(r1, r3) - s1 * s1) / sg;
    let (g2, g3) = (sg * sg, sg * sg * sg);
    for i in 0..n.min(TIP) {
        q1[i] = r1[i] / sg;
        q2[i] = r2[i] / g2 - r1[i] * s1 / g3;
        q3[i] = r3[i] / g3 - 3.0 * r2[i] * s1 / (g2 * g2) - r1[i] * s2 / (g2 * g2) + 3.0 * r1[i] * s1 * s1 / (g3 * g2);
    }
    (sg, q1, q2, q3)
}

/// Arc length of `view`'s first `n` coordinates from `a` to `b` (one 5-point Gauss-Legendre
/// rule: the pieces are short, within one knot span).
pub fn piece_length(view: &CurveView, a: f64, b: f64, n: usize) -> f64 {
    let h = b - a;
    GL5.iter().map(|&(x, w)| w * view.speed(a + h * x, n)).sum::<f64>() * h
}

/// How the stations are placed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridOptions {
    /// Motion time between stations at the expected speed (s).
    pub spacing: f64,
    /// Most turn of the tangent over an interval (rad).
    pub turn: f64,
    /// Longest interval (mm).
    pub longest: f64,
    /// Shortest interval next to a rest (mm).
    pub shortest: f64,
}

impl Default for GridOptions {
    fn default() -> Self {
        GridOptions {
            spacing: 0.002,
            turn: 0.03,
            longest: 2.0,
            shortest: 2e-4,
        }
    }
}

/// Where a stretch of path runs: from `(element, u)` to `(element, u)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stretch {
    pub from: (usize, f64),
    pub to: (usize, f64),
    /// The motion is at rest at the start / must come to rest at the end.
    pub rest_at_start: bool,
    /// The speed at the start where it is not at rest (a plan that continues a motion).
    pub start_speed: f64,
    pub rest_at_end: bool,
    /// Approximate length (mm): where the grid grows denser towards a rest at the end.
    pub length: f64,
    /// Whether `to` is only as far as the path was read yet (the stretch goes on).
    pub open: bool,
}

/// The stations and intervals of one stretch.
#[derive(Clone, Debug, Default)]
pub struct Grid {
    pub stations: Vec<Station>,
    pub intervals: Vec<Interval>,
}

impl Grid {
    pub fn len(&self) -> usize {
        self.intervals.len()
    }

    pub fn is_empty(&self) -> bool {
        self.intervals.is_empty()
    }

    /// Length of the stretch (mm).
    pub fn length(&self) -> f64 {
        self.stations.last().map_or(0.0, |s| s.s)
    }

    /// Lays stations along `stretch`; `speed(s, here)` is the expected speed at arc length `s`
    /// from the stretch start where the path is `here` (mm/s).
    pub fn build(
        curves: &PathCurves,
        stretch: &Stretch,
        caps: &Caps,
        options: &GridOptions,
        speed: &dyn Fn(f64, &Local) -> f64,
    ) -> Grid {
        Self::build_part(
            curves,
            stretch,
            (stretch.from, 0.0),
            f64::INFINITY,
            caps,
            options,
            speed,
        )
        .0
    }

    /// Lays stations along `stretch` from `(element, u)` at arc length `s` from the stretch
    /// start (`from`), until the first station at or past arc length `until` that is no
    /// element's end (its far side is known), or the stretch's end; whether it reached that.
    pub fn build_part(
        curves: &PathCurves,
        stretch: &Stretch,
        (from, s0): ((usize, f64), f64),
        until: f64,
        caps: &Caps,
        options: &GridOptions,
        speed: &dyn Fn(f64, &Local) -> f64,
    ) -> (Grid, bool) {
        let n = caps.axes;
        let mut grid = Grid::default();
        let mut s = s0;
        for e in from.0..=stretch.to.0 {
            let view = curves.view(e);
            let feed = curves.programmed_feed(e);
            let u_from = if e == from.0 { from.1 } else { view.u_min() };
            let u_to = if e == stretch.to.0 { stretch.to.1 } else { view.u_max() };
            if u_to <= u_from {
                continue;
            }
            // Stations at every distinct knot inside, and at the ends.
            let mut breaks: Vec<f64> = vec![u_from];
            for &k in view.knots() {
                if k > u_from && k < u_to && breaks.last() != Some(&k) {
                    breaks.push(k);
                }
            }
            breaks.push(u_to);
            let local = |u: f64, left: bool, s: f64| {
                let (_, q1, q2, q3) = arc_derivatives(&view, u, n, left);
                Local {
                    q1,
                    q2,
                    q3,
                    cap: caps.at(s, &q1, &q2, feed),
                }
            };
            // The station at the element start (joins keep the previous element's left side).
            let right = local(u_from, false, s);
            match grid.stations.last_mut() {
                Some(last) => last.right = right,
                None => grid.stations.push(Station {
                    element: e,
                    u: u_from,
                    s: s0,
                    left: right,
                    right,
                }),
            }
            if let Some(last) = grid.stations.last_mut() {
                // A join belongs to the element that starts there.
                last.element = e;
                last.u = u_from;
            }
            let mut u = u_from;
            let mut next_break = 1;
            while u < u_to {
                let here = grid.stations.last().map_or(right, |st| st.right);
                let kappa = here.curvature();
                let mut ds = (speed(s, &here).max(1e-3) * options.spacing)
                    .min(options.longest)
                    .min(options.turn / kappa.max(1e-12));
                // Denser towards a rest: geometric growth away from it.
                if stretch.rest_at_start {
                    ds = ds.min((0.5 * s).max(options.shortest));
                }
                if stretch.rest_at_end {
                    ds = ds.min((0.4 * (stretch.length - s)).max(options.shortest));
                }
                let sp = view.speed(u, n).max(1e-300);
                let mut du = ds / sp;
                let target = breaks[next_break];
                let mut next = u + du;
                if next >= target - 0.3 * du {
                    next = target;
                    next_break += 1;
                }
                let mut d = piece_length(&view, u, next, n);
                if d > 1.5 * ds && next != target {
                    du *= ds / d;
                    next = u + du;
                    d = piece_length(&view, u, next, n);
                } else if d > 1.5 * ds {
                    // Too far to the break: go half way.
                    next_break -= 1;
                    next = u + 0.5 * (target - u);
                    d = piece_length(&view, u, next, n);
                }
                let mut points = [(0.0, Local::default()); COLLOCATION.len()];
                let mut theta = 0.0;
                let mut prev = u;
                for (p, f) in points.iter_mut().zip(COLLOCATION) {
                    let um = u + f * (next - u);
                    theta += piece_length(&view, prev, um, n);
                    prev = um;
                    *p = (theta, local(um, false, s + theta));
                }
                let length = theta + piece_length(&view, prev, next, n);
                if length <= 1e-12 * (1.0 + s) {
                    // No arc length (the parameter runs over coincident control points): the
                    // station moves on instead of a new one.
                    if let Some(last) = grid.stations.last_mut() {
                        last.u = next;
                        last.element = e;
                        last.right = local(next, false, s);
                    }
                    u = next;
                    continue;
                }
                s += length;
                grid.intervals.push(Interval { length, points });
                grid.stations.push(Station {
                    element: e,
                    u: next,
                    s,
                    left: local(next, true, s),
                    right: local(next, false, s),
                });
                u = next;
                if s >= until && u < u_to {
                    return (grid, false);
                }
            }
        }
        (grid, true)
    }

    /// Appends `part`, whose first station is this grid's last (laid again: its far side and
    /// its place at a join come from `part`).
    pub fn append(&mut self, part: Grid) {
        let mut stations = part.stations.into_iter();
        if let Some(first) = stations.next() {
            match self.stations.last_mut() {
                Some(last) => {
                    last.right = first.right;
                    last.element = first.element;
                    last.u = first.u;
                }
                None => self.stations.push(first),
            }
        }
        self.stations.extend(stations);
        self.intervals.extend(part.intervals);
    }

    /// Keeps stations `..=k` and the intervals between them.
    pub fn truncate(&mut self, k: usize) {
        self.stations.truncate(k + 1);
        self.intervals.truncate(k);
    }
}
