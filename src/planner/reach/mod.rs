//! The reachability planner: near time-optimal feed along the tool-tip path with per-axis
//! velocity, acceleration and jerk limits, planned over arc-length stations by third-order
//! reachability analysis.
//!
//! The state at each station is (a, b) = (ṡ², s̈); each interval has one control c = s⃛/ṡ, so the
//! dynamics along arc length are exact (a' = 2b, b' = c) and every constraint at a station or at
//! a collocation point inside an interval is a linear row in (a, b, c) ([`rows`]; the axis jerk
//! linearised from the inside). A backward pass computes the controllable set of every
//! station, a convex polygon in (a, b); a forward pass takes the largest c whose successor stays
//! in the next set ([`passes`]). Every accepted state can stop. A few passes re-linearise the
//! jerk rows at the last plan, and the grid is laid again once from the planned speed. The
//! plan is a chain of closed-form pieces in time ([`pieces`]), sampled at the servo period and
//! checked there by finite differences ([`sampler`]); where a sample runs over, the limits of
//! the intervals around it are tightened and the stretch planned again, so what leaves the
//! planner passes the check.
//!
//! The method follows the time-optimal path parameterisation by reachability analysis
//! (Pham & Pham 2018) carried to third order with the inner linearisation of the axis jerk of
//! Wang et al. (the `copp` solver, 2026); the constraints are those of Erwinski et al. 2022
//! and Beudaert et al. 2012.

pub mod grid;
mod inverse;
pub mod passes;
pub mod pieces;
pub mod polygon;
mod rests;
pub mod rows;
pub mod sampler;
pub mod stops;
pub mod window;

use std::time::Instant;

use crate::geometry::Toolpath;
use crate::planner::vpop::PathPoint;
use crate::planner::{Limits, LimitsError, PathCurves};
use grid::{Caps, Grid, GridOptions, Local, SlowDown, Stretch, COLLOCATION, TIP};
use nurbs_rtcore::scurve::stop_from;
use passes::{Motion, PassError, Passes, Start};
use rests::Resting;
use rows::AxisLimits;
use sampler::Check;
use stops::{hand_out, Along, Branches, FindStops};

const NC: usize = COLLOCATION.len();

/// How hard the planner works.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReachOptions {
    pub grid: GridOptions,
    /// Backward and forward passes per stretch (the jerk rows re-linearised at each plan): at
    /// least `iterations`, more while a pass still shortens the motion by more than `gain`
    /// (a share), at most `most_iterations`.
    pub iterations: usize,
    pub most_iterations: usize,
    pub gain: f64,
    /// After which pass the grid is laid again from the planned speed (0: never).
    pub regrid_after: usize,
    /// Floor on a at every point, as a share of the (scaled) linearisation (0: none).
    pub floor: f64,
    /// The jerk rows are linearised at the last plan's a times `scale_early`, for the last
    /// pass times `scale_last`. Above the plan the tangent gives up some jerk where the plan
    /// is but lets the next plan rise further (the tangent of J/√a at a_l falls to zero at
    /// 3·a_l); a linearisation at the plan itself keeps any dip where it is.
    pub scale_early: f64,
    pub scale_last: f64,
    /// Most vertices of a controllable set.
    pub max_vertices: usize,
    /// Share of every limit kept unused from the start (rounding between collocation points).
    pub margin: f64,
    /// Most re-plans of a stretch whose samples ran over.
    pub repairs: usize,
    /// Long stretches planned window by window (their points handed out as each window is
    /// done), or whole.
    pub window: Option<window::WindowOptions>,
    /// Stops offered along the plan about this often (s of motion), each the quickest stop
    /// the controllable sets allow from the state at a station, sampled from the next period
    /// ([`Planned::Stop`]); none where `None`.
    pub stops_every: Option<f64>,
    /// The feed override: the programmed feeds (the planner's and each element's) times this
    /// factor; the axis limits stay the limits (1: as programmed).
    pub feed_override: f64,
}

impl Default for ReachOptions {
    fn default() -> Self {
        ReachOptions {
            grid: GridOptions::default(),
            iterations: 4,
            most_iterations: 8,
            gain: 0.03,
            regrid_after: 1,
            floor: 0.3,
            scale_early: 2.5,
            scale_last: 1.2,
            max_vertices: 12,
            margin: 1e-4,
            repairs: 8,
            window: None,
            stops_every: None,
            feed_override: 1.0,
        }
    }
}

/// What the planner hands out, in path order: the plan's next point, or a stop branching off
/// after the last point handed out (its positions from the next period on, to rest), with the
/// place and state it branches off at.
#[derive(Clone, Copy, Debug)]
pub enum Planned<'p> {
    Point(&'p PathPoint),
    Stop(&'p [PathPoint], &'p Branch),
}

/// Where a stop branches off the plan: a place and the motion's state there, from which a plan
/// at another feed override may continue the motion instead ([`Begin::Moving`]).
#[derive(Clone, Debug)]
pub struct Branch {
    /// Element and curve parameter.
    pub element: usize,
    pub u: f64,
    /// Path speed ṡ (mm/s) and tangential acceleration s̈ (mm/s²).
    pub speed: f64,
    pub acceleration: f64,
    /// Time from the branch to the first sample after it (0 < next ≤ period).
    pub next: f64,
    /// The plan's last three samples at or before the branch, oldest first: where the finite
    /// differences of what follows begin.
    pub before: [PathPoint; 3],
    /// The rows the motion was planned on there (branches at the stations of a plan in
    /// windows).
    pub fork: Option<Forked>,
}

/// What a plan continuing from a branch takes over ([`Begin::Moving`]): the stretch, the rows
/// the motion there was planned on (from the window's start to its frozen end, or the whole
/// stretch) and that motion (its speeds are what the new plan's stations expect at least). A
/// plan on the same rows holds the branch's state in its first set ([`Forked`]); a plan on
/// rows of its own, its stations elsewhere, can miss a state the old plan reached on the edge
/// of its sets.
#[derive(Debug)]
pub struct Fork {
    stretch: Stretch,
    grid: Grid,
    lin: Linearisation,
    tight: Vec<f64>,
    motion: Motion,
}

/// A branch's place in a [`Fork`]: its station there, and the quickest stop its sets allow
/// from it (states per station to rest): the continuation under the fork's rows that holds the
/// branch's state in the new plan's first set while those rows stay as they were.
#[derive(Clone)]
pub struct Forked {
    fork: std::sync::Arc<Fork>,
    station: usize,
    stop: Vec<(f64, f64)>,
}

impl Forked {
    /// Arc length of the station where the stop rests (in the fork's stretch).
    fn stop_end(&self) -> f64 {
        self.fork.grid.stations[self.station + self.stop.len() - 1].s
    }
}

impl std::fmt::Debug for Forked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "station {} of {}, its stop {} stations",
            self.station,
            self.fork.grid.stations.len(),
            self.stop.len()
        )
    }
}

/// Where a plan begins.
#[derive(Clone, Debug)]
pub enum Begin {
    /// At rest at the path start, or at `(element, curve parameter)`.
    Rest(Option<(usize, f64)>),
    /// Continuing a motion at one of its branches (a plan at another feed override), planned
    /// in windows ([`ReachOptions::window`], the default windows where `None`).
    Moving {
        branch: Box<Branch>,
        /// The feed override of the plan continued. Where the new one
        /// ([`ReachOptions::feed_override`]) is lower, the old feeds hold until a ramp from the
        /// branch's speed down to the new feed at a share of the smallest axis acceleration
        /// and jerk could have reached it ([`BRAKE_SHARES`], tried in turn).
        feed_override: f64,
    },
}

/// Shares of the smallest axis acceleration and jerk with which a plan continuing a motion
/// faster than its new feed brakes to it at the latest ([`Begin::Moving`]), gentlest last:
/// where the path bends the axes need part of their limits for the bend.
pub const BRAKE_SHARES: [f64; 3] = [0.7, 0.35, 0.15];

/// A plan's handing out: [`Planned`] to `emit`, which may refuse (the planning then ends).
pub type Emit<'e> = dyn FnMut(Planned<'_>) -> Result<(), String> + 'e;

/// A plan: one point per servo period, at rest before the first and after the last.
#[derive(Clone, Debug)]
pub struct ReachPlan {
    pub points: Vec<PathPoint>,
    pub limits: Limits,
    pub motion_time: f64,
    pub plan_time: f64,
    pub stats: ReachStats,
}

/// What the planning took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReachStats {
    pub stretches: usize,
    pub stations: usize,
    pub passes: usize,
    /// Re-plans after samples ran over, and the worst ratio of a sample to its limit.
    pub repairs: usize,
    pub worst_ratio: f64,
    /// Wall-clock time to the first points handed out (s).
    pub first_points_time: f64,
    /// Windows planned, and windows that ran the last one's stop and started again from rest.
    pub windows: usize,
    pub restarts: usize,
    /// A plan continuing a faster motion ([`Begin::Moving`] at a lower feed override): the
    /// arc length from its start from which its feed override holds (0 elsewhere).
    pub slowed_within: f64,
}

/// Why no plan.
#[derive(Clone, Debug, PartialEq)]
pub enum ReachError {
    Limits(LimitsError),
    Path(String),
    Plan(String),
    /// A pass would stand still in the interval from `from` to `to` (element, parameter): the
    /// planner may rest there ([`rests`]).
    Stands {
        from: (usize, f64),
        to: (usize, f64),
        why: String,
    },
}

impl std::fmt::Display for ReachError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReachError::Limits(e) => write!(f, "{e}"),
            ReachError::Path(e) => write!(f, "invalid path: {e}"),
            ReachError::Plan(e) | ReachError::Stands { why: e, .. } => write!(f, "reachability planner: {e}"),
        }
    }
}
impl std::error::Error for ReachError {}

/// Plans the tool-tip path of `toolpath`, from its start or from rest at `start` (element,
/// curve parameter).
pub fn plan_tip(
    toolpath: &Toolpath,
    limits: &Limits,
    options: &ReachOptions,
    start: Option<(usize, f64)>,
) -> Result<ReachPlan, ReachError> {
    let mut curves = PathCurves::new(toolpath);
    let mut points = Vec::new();
    let (limits, stats, plan_time) = run(&mut curves, limits, options, &Begin::Rest(start), &mut |p| {
        if let Planned::Point(p) = p {
            points.push(*p);
        }
        Ok(())
    })?;
    let motion_time = points.len().saturating_sub(1) as f64 * limits.period;
    Ok(ReachPlan {
        points,
        limits,
        motion_time,
        plan_time,
        stats,
    })
}

/// Plans `curves` stretch by stretch (rest to rest between tangent breaks), from `begin`,
/// handing every point (and the stops of [`ReachOptions::stops_every`]) to `emit` once its
/// stretch passed the check. The limits as used, the figures and the planning time.
pub fn run(
    curves: &mut PathCurves,
    limits: &Limits,
    options: &ReachOptions,
    begin: &Begin,
    emit: &mut Emit<'_>,
) -> Result<(Limits, ReachStats, f64), ReachError> {
    let (branch, before) = match begin {
        Begin::Rest(start) => return run_from(curves, limits, options, *start, None, emit),
        Begin::Moving { branch, feed_override } => (branch, *feed_override),
    };
    let after = options.feed_override;
    if ![before, after].iter().all(|k| k.is_finite() && *k > 0.0) {
        return Err(ReachError::Plan(format!(
            "feed override {after} is not a positive factor"
        )));
    }
    // Each brake share in turn, while nothing has been handed out (a share the path leaves no
    // room for fails in the first window).
    let shares: &[f64] = if after < before { &BRAKE_SHARES } else { &[1.0] };
    let mut failed = None;
    for &share in shares {
        let mut emitted = false;
        let mut counted = |p: Planned<'_>| {
            emitted = true;
            emit(p)
        };
        let moving = Moving {
            branch: (**branch).clone(),
            feed_override: before,
            brake_share: share,
        };
        match run_from(curves, limits, options, None, Some(&moving), &mut counted) {
            Err(e) if !emitted => failed = Some(e),
            done => return done,
        }
    }
    Err(failed.unwrap_or_else(|| ReachError::Plan("no brake share".into())))
}

/// A motion a plan continues ([`Begin::Moving`]) with one brake share.
struct Moving {
    branch: Branch,
    feed_override: f64,
    brake_share: f64,
}

/// [`run`] from rest at the path start or at `start`, or continuing `moving`.
fn run_from(
    curves: &mut PathCurves,
    limits: &Limits,
    options: &ReachOptions,
    start: Option<(usize, f64)>,
    moving: Option<&Moving>,
    emit: &mut Emit<'_>,
) -> Result<(Limits, ReachStats, f64), ReachError> {
    let started = Instant::now();
    let start = moving.map_or(start, |m| Some((m.branch.element, m.branch.u)));
    let first_element = start.map_or(0, |s| s.0);
    if !curves.load(first_element) {
        return Err(ReachError::Path(match start {
            None => "no elements".into(),
            Some((e, _)) => format!("no element {e} to start from"),
        }));
    }
    let axes = curves.tip_dim();
    let limits = limits.for_axes(axes).map_err(ReachError::Limits)?;
    let mut planner = Planner::new(&limits, axes, options);
    let mut stats = ReachStats::default();
    let mut check = Check::new(&limits, axes);
    let from_start = start.unwrap_or((0, curves.view(0).u_min()));
    let mut last = match moving {
        None => {
            // The first point: at rest at the path start.
            let first = rests::point_at(curves, from_start, axes);
            check.push(&first.tip);
            emit(Planned::Point(&first)).map_err(ReachError::Plan)?;
            Some(first)
        }
        Some(m) => {
            // The old feeds hold until the motion can have braked to the new ones.
            let (before, after) = (m.feed_override, options.feed_override);
            planner.caps.feed_override = before.max(after);
            if after < before {
                let programmed = curves
                    .programmed_feed(m.branch.element)
                    .map_or(limits.feed, |f| f.min(limits.feed));
                let (accel, jerk) = planner.least_limits();
                let share = m.brake_share;
                // From the branch's arc length in the stretch it continues (its fork's), and no
                // sooner than its stop rests: the rows there stay the fork's.
                let s0 = m
                    .branch
                    .fork
                    .as_ref()
                    .map_or(0.0, |f| f.fork.grid.stations[f.station].s);
                let length = slow_down_length(
                    m.branch.speed,
                    m.branch.acceleration,
                    programmed * after,
                    share * accel,
                    share * jerk,
                );
                let stop_end = m.branch.fork.as_ref().map_or(0.0, Forked::stop_end);
                let from = (s0 + length).max(stop_end);
                planner.caps.slow_down = Some(SlowDown {
                    from,
                    feed_override: after,
                });
                stats.slowed_within = from - s0;
            }
            check.feed_override = before.max(after);
            for p in &m.branch.before {
                check.push(&p.tip);
            }
            Some(m.branch.before[2])
        }
    };
    // The time the first planned points leave.
    let mut first_points: Option<f64> = None;
    let mut out = |p: Planned<'_>| {
        first_points.get_or_insert_with(|| started.elapsed().as_secs_f64());
        emit(p)
    };
    let mut from = from_start;
    let mut continuing = moving;
    while let Some(mut stretch) = begin_stretch(curves, from) {
        stats.stretches += 1;
        let window = match continuing {
            Some(m) => {
                stretch.start_speed = m.branch.speed;
                Some(options.window.unwrap_or_default())
            }
            None => options.window,
        };
        let continued = continuing.map(|m| window::Continued {
            state: (m.branch.speed.powi(2), m.branch.acceleration),
            next: m.branch.next,
            fork: m.branch.fork.as_ref(),
        });
        let whole = match &window {
            Some(w) => {
                match planner.plan_stretch_windowed(curves, stretch, last, &mut check, w, continued, &mut out)? {
                    Ok(run) => {
                        stats.stations += run.stations;
                        stats.passes += run.passes;
                        stats.repairs += run.repairs;
                        stats.windows += run.windows;
                        stats.restarts += run.restarts;
                        last = run.last;
                        from = run.to;
                        None
                    }
                    Err(_) if continuing.is_some() => {
                        return Err(ReachError::Plan(
                            "the motion continued has no plan from its branch".into(),
                        ))
                    }
                    Err(stretch) => Some(stretch),
                }
            }
            None => Some(stretch),
        };
        if continuing.take().is_some() {
            // Past the first stretch (it ends at rest) the new feeds hold everywhere.
            planner.caps.feed_override = options.feed_override;
            planner.caps.slow_down = None;
            check.feed_override = options.feed_override;
        }
        if let Some(mut stretch) = whole {
            read_on(curves, &mut stretch, f64::INFINITY, &planner.rests.borrow());
            match planner.plan_resting(curves, &mut stretch, last, &mut check)? {
                Resting::Planned(plan) => {
                    stats.stations += plan.grid.stations.len();
                    stats.passes += plan.passes;
                    stats.repairs += plan.repairs;
                    let along = Along {
                        grid: &plan.grid,
                        lin: &plan.lin,
                        tight: &plan.tight,
                        start: Start::default(),
                        motion: &plan.motion,
                        stretch: Some(&stretch),
                    };
                    let (n, period) = (plan.grid.len(), planner.period);
                    let stops =
                        |found: &mut Branches<'_>| planner.branch_stops(curves, &along, n, period, &plan.points, found);
                    hand_out(&plan.points, &stops, &mut out)?;
                    last = plan.points.last().copied().or(last);
                }
                Resting::Stepped(points) => {
                    for p in &points {
                        out(Planned::Point(p)).map_err(ReachError::Plan)?;
                    }
                    last = points.last().copied().or(last);
                }
            }
            from = stretch.to;
        }
        if from.0 >= curves.len() - 1 && from.1 >= curves.view(from.0).u_max() {
            break;
        }
        curves.release_before(from.0);
    }
    stats.first_points_time = first_points.unwrap_or(0.0);
    if let Some(e) = curves.error() {
        return Err(ReachError::Path(e.to_string()));
    }
    stats.worst_ratio = check.worst;
    Ok((limits, stats, started.elapsed().as_secs_f64()))
}

/// Distance a ramp from speed `v0` and tangential acceleration `a0` down to speed `v1` takes
/// with deceleration `accel` and jerk `jerk` (the S-curve stop from `v0 - v1`, shifted by
/// `v1`); 0 where `v0` is no faster.
fn slow_down_length(v0: f64, a0: f64, v1: f64, accel: f64, jerk: f64) -> f64 {
    if v0 <= v1 {
        return 0.0;
    }
    let table = stop_from(v0 - v1, a0, accel, jerk).table_from(a0);
    table.length() + v1 * table.total_time()
}

/// A stretch from `from` (a rest: the path start or the last stretch's end) with nothing read
/// yet. `None` at the path end.
fn begin_stretch(curves: &mut PathCurves, from: (usize, f64)) -> Option<Stretch> {
    let (mut e, mut u) = from;
    if !curves.load(e) {
        return None;
    }
    if u >= curves.view(e).u_max() {
        if !curves.load(e + 1) {
            return None;
        }
        e += 1;
        u = curves.view(e).u_min();
    }
    Some(Stretch {
        from: (e, u),
        to: (e, u),
        rest_at_start: true,
        start_speed: 0.0,
        rest_at_end: false,
        length: 0.0,
        open: true,
    })
}

/// Reads `stretch` on by at least `more` mm (whole elements), or to its end: a tangent break
/// inside an element or at a join, one of the `rests`, or the path's end.
fn read_on(curves: &mut PathCurves, stretch: &mut Stretch, more: f64, rests: &rests::Rests) {
    if !stretch.open {
        return;
    }
    let axes = curves.tip_dim();
    let (mut e, mut u) = stretch.to;
    let target = stretch.length + more;
    let close = |stretch: &mut Stretch, to: (usize, f64)| {
        stretch.to = to;
        stretch.open = false;
        stretch.rest_at_end = true;
    };
    if u >= curves.view(e).u_max() && stretch.to != stretch.from {
        // At the end of the elements read: the join to the next one.
        if stops_after(curves, e, u) {
            return close(stretch, (e, u));
        }
        e += 1;
        u = curves.view(e).u_min();
    }
    loop {
        let view = curves.view(e);
        // A C0 knot inside the element whose tangents differ.
        let mut end = view.u_max();
        let mut inside = false;
        crate::planner::vpop::path::interior_breaks(&view, &mut |k| {
            if k > u && !inside {
                end = k;
                inside = true;
            }
        });
        if let Some(r) = rests.after(e, u).filter(|&r| r < end) {
            end = r;
            inside = true;
        }
        stretch.length += approximate_length(&view, u, end, axes);
        if inside || stops_after(curves, e, end) {
            return close(stretch, (e, end));
        }
        if stretch.length >= target {
            stretch.to = (e, end);
            return;
        }
        e += 1;
        u = curves.view(e).u_min();
    }
}

/// Whether the motion must stop at the end `end` of element `e`: the path ends there, or the
/// next element starts in another direction.
fn stops_after(curves: &mut PathCurves, e: usize, end: f64) -> bool {
    let end_tangent = curves.view(e).derivatives(end, 1)[1];
    if !curves.load(e + 1) {
        return true;
    }
    let next = curves.view(e + 1);
    let start_tangent = next.derivatives(next.u_min(), 1)[1];
    crate::planner::vpop::path::turns(&end_tangent, &start_tangent, curves.tip_dim())
}

/// Arc length of `view` from `a` to `b`, knot span by knot span, each in pieces (Gauss-Legendre)
/// halved until the length settles: where the grid's stations grow denser towards the end, a
/// length short of the grid's own measure would lay them ever denser past it.
fn approximate_length(view: &nurbs_rtcore::CurveView, a: f64, b: f64, axes: usize) -> f64 {
    let mut cuts = vec![a];
    for &k in view.knots() {
        if k > a && k < b && cuts.last() != Some(&k) {
            cuts.push(k);
        }
    }
    cuts.push(b);
    let in_pieces = |lo: f64, hi: f64, n: usize| {
        let h = (hi - lo) / n as f64;
        (0..n)
            .map(|i| grid::piece_length(view, lo + h * i as f64, lo + h * (i + 1) as f64, axes))
            .sum::<f64>()
    };
    cuts.windows(2)
        .map(|w| {
            let (mut n, mut length) = (8, in_pieces(w[0], w[1], 8));
            while n < 1024 {
                n *= 2;
                let finer = in_pieces(w[0], w[1], n);
                let settled = (finer - length).abs() <= 1e-9 * finer;
                length = finer;
                if settled {
                    break;
                }
            }
            length
        })
        .sum()
}

/// What every stretch is planned with.
struct Planner<'o> {
    limits: Limits,
    caps: Caps,
    axis: AxisLimits,
    period: f64,
    options: &'o ReachOptions,
    /// Where stretches end at rest besides the path's tangent breaks ([`rests`]).
    rests: std::cell::RefCell<rests::Rests>,
}

impl<'o> Planner<'o> {
    fn new(limits: &Limits, axes: usize, options: &'o ReachOptions) -> Self {
        let mut velocity = [f64::INFINITY; TIP];
        let mut acceleration = [f64::INFINITY; TIP];
        let mut jerk = [f64::INFINITY; TIP];
        velocity[..axes].copy_from_slice(&limits.velocity[..axes]);
        acceleration[..axes].copy_from_slice(&limits.acceleration[..axes]);
        jerk[..axes].copy_from_slice(&limits.jerk[..axes]);
        Planner {
            limits: limits.clone(),
            caps: Caps {
                feed: limits.feed,
                velocity,
                // Just inside: the cap holds at the points where the grid looks, the samples
                // fall between them.
                chord_tolerance: limits.chord_tolerance * (1.0 - 1e-3),
                period: limits.period,
                axes,
                feed_override: options.feed_override,
                slow_down: None,
            },
            axis: AxisLimits {
                acceleration,
                jerk,
                axes,
            },
            period: limits.period,
            options,
            rests: Default::default(),
        }
    }

    /// A speed no plan exceeds much at a point (the grid's first guess): the caps, and what
    /// the acceleration and jerk allow through the curvature there.
    fn speed_bound(&self, here: &Local) -> f64 {
        let mut v = here.cap.sqrt();
        for i in 0..self.axis.axes {
            if here.q2[i].abs() > 1e-12 {
                v = v.min((self.axis.acceleration[i] / here.q2[i].abs()).sqrt());
            }
            if here.q3[i].abs() > 1e-12 {
                v = v.min((self.axis.jerk[i] / here.q3[i].abs()).cbrt());
            }
        }
        v
    }

    /// The smallest axis acceleration and jerk.
    fn least_limits(&self) -> (f64, f64) {
        let axes = self.axis.axes;
        let least = |x: &[f64]| x[..axes].iter().copied().fold(f64::INFINITY, f64::min);
        (least(&self.axis.acceleration), least(&self.axis.jerk))
    }

    /// Speed reachable from rest within `d` with the smallest axis jerk.
    fn ramp(&self, d: f64) -> f64 {
        let j = self.least_limits().1;
        let t = (6.0 * d.max(0.0) / j).cbrt();
        0.5 * j * t * t
    }

    /// Distance such a ramp takes to speed `v` (the inverse of [`Planner::ramp`]).
    fn ramp_length(&self, v: f64) -> f64 {
        let j = self.least_limits().1;
        let t = (2.0 * v.max(0.0) / j).sqrt();
        j * t * t * t / 6.0
    }

    /// The first guess of the speed at arc length `s` of `stretch` where the path is `here`:
    /// what the caps and the curvature allow, and a ramp from the start (and to the end, once
    /// read).
    fn first_guess(&self, stretch: &Stretch, s: f64, here: &Local) -> f64 {
        // A motion continued (not at rest at the start) is as far into its ramp as its speed.
        let lead = self.ramp_length(stretch.start_speed);
        let v = self.speed_bound(here).min(self.ramp(lead + s));
        if stretch.open {
            v
        } else {
            v.min(self.ramp(stretch.length - s))
        }
    }

    /// Plans one rest-to-rest stretch: passes, a second grid, more passes, then sampled and
    /// checked, tightened where samples ran over.
    fn plan_stretch(
        &self,
        curves: &PathCurves,
        stretch: &Stretch,
        before: Option<PathPoint>,
        check: &mut Check,
    ) -> Result<StretchPlan, ReachError> {
        let o = self.options;
        let first_guess = |s: f64, here: &Local| self.first_guess(stretch, s, here);
        let mut grid = Grid::build(curves, stretch, &self.caps, &o.grid, &first_guess);
        if grid.len() < 3 {
            // Too short for a start, a piece and a stop: lay it again finer.
            let mut finer = o.grid;
            finer.longest = stretch.length / 4.0;
            finer.shortest = finer.shortest.min(stretch.length / 8.0);
            grid = Grid::build(curves, stretch, &self.caps, &finer, &first_guess);
        }
        if grid.len() < 3 {
            return Err(ReachError::Plan(format!(
                "a stretch of {:.3e} mm is too short to plan",
                stretch.length
            )));
        }
        let mut lin = Linearisation::from_speed(&grid, &first_guess);
        let mut tight = vec![1.0 - o.margin; grid.len()];
        let mut floors: Option<Linearisation> = None;
        let mut best: Option<(Grid, Motion, Linearisation)> = None;
        let mut passes = 0;
        let (least, most) = (o.iterations.max(1), o.most_iterations.max(o.iterations).max(1));
        let mut last_pass = least == 1;
        for it in 0.. {
            let motion = self
                .passes(&grid, &lin, floors.as_ref(), &tight, Start::default(), &mut passes)
                .map_err(|e| self.describe(&grid, 0, e))?;
            let best_time = best.as_ref().map_or(f64::INFINITY, |(_, m, _)| m.time());
            let better = motion.time() < best_time;
            if last_pass {
                if better {
                    best = Some((grid, motion, lin));
                }
                break;
            }
            // One more pass linearised close to the plan ends the search once the passes
            // stop gaining (or at the most); until then the next linearisation lies above
            // the plan, so that the next plan may rise further.
            let gaining = motion.time() < (1.0 - o.gain) * best_time;
            last_pass = it + 2 >= most || (it + 2 >= least && !gaining);
            let scale = if last_pass { o.scale_last } else { o.scale_early };
            let plan = PlanSpeed {
                grid: &grid,
                motion: &motion,
            };
            let next = if it + 1 == o.regrid_after {
                // Lay the grid again from the planned speed.
                let vmax = motion.a.iter().fold(0.0f64, |m, a| m.max(*a)).sqrt();
                let speed = |s: f64, here: &Local| {
                    plan.a_at(s)
                        .sqrt()
                        .max(1e-3 * vmax)
                        .min(self.speed_bound(here).max(1e-3 * vmax))
                };
                let new_grid = Grid::build(curves, stretch, &self.caps, &o.grid, &speed);
                (new_grid.len() >= 3).then(|| {
                    let lin = Linearisation::from_plan(&new_grid, &plan);
                    (new_grid, lin)
                })
            } else {
                None
            };
            let (next_grid, next_lin) = match next {
                Some((g, l)) => (Some(g), l),
                None => (None, Linearisation::from_plan(&grid, &plan)),
            };
            let next_lin = next_lin.scaled(scale);
            floors = (o.floor > 0.0).then(|| next_lin.scaled(o.floor));
            if better {
                best = Some((grid.clone(), motion, lin));
            }
            if let Some(g) = next_grid {
                grid = g;
                tight = vec![1.0 - o.margin; grid.len()];
            }
            lin = next_lin;
        }
        let Some((grid, mut motion, lin)) = best else {
            return Err(ReachError::Plan("no pass succeeded".into()));
        };
        // Sample, check, tighten where over, plan again.
        let mut tight = vec![1.0 - o.margin; grid.len()];
        let mut repairs = 0;
        let inverses = inverse::Inverses::default();
        loop {
            let mut trial = check.clone();
            let sampled = sampler::sample(
                curves,
                &inverses,
                &grid,
                &motion,
                &self.limits,
                self.caps.axes,
                before,
                &mut trial,
                1e-9,
                sampler::Span {
                    first: self.period,
                    at_rest: true,
                },
            );
            if sampled.over.is_empty() {
                *check = trial;
                return Ok(StretchPlan {
                    passes,
                    repairs,
                    points: sampled.points,
                    grid,
                    lin,
                    tight,
                    motion,
                });
            }
            self.tighten(&mut tight, &motion, &sampled.over, &mut repairs)?;
            let floors = (o.floor > 0.0).then(|| lin.scaled(o.floor));
            motion = self
                .passes(&grid, &lin, floors.as_ref(), &tight, Start::default(), &mut passes)
                .map_err(|e| self.describe(&grid, 0, e))?;
        }
    }

    /// One backward and one forward pass (again without floors where they leave no plan).
    fn passes(
        &self,
        grid: &Grid,
        lin: &Linearisation,
        floors: Option<&Linearisation>,
        tight: &[f64],
        start: Start,
        count: &mut usize,
    ) -> Result<Motion, PassError> {
        *count += 1;
        match self.pass(grid, lin, floors, tight, start) {
            Ok(m) => Ok(m),
            Err(_) if floors.is_some() => {
                *count += 1;
                self.pass(grid, lin, None, tight, start)
            }
            Err(e) => Err(e),
        }
    }

    /// One backward and one forward pass.
    fn pass(
        &self,
        grid: &Grid,
        lin: &Linearisation,
        floors: Option<&Linearisation>,
        tight: &[f64],
        start: Start,
    ) -> Result<Motion, PassError> {
        let p = Passes {
            grid,
            limits: self.axis,
            period: self.period,
            lin_stations: &lin.stations,
            lin_points: &lin.points,
            floors: floors.map(|f| (&f.stations[..], &f.points[..])),
            tight,
            max_vertices: self.options.max_vertices,
            jerk: true,
            start,
        };
        let sets = p.backward()?;
        p.forward(&sets)
    }

    /// What a failed pass means, at the station of `grid` `offset` stations before the one
    /// it names.
    fn describe(&self, grid: &Grid, offset: usize, e: PassError) -> ReachError {
        let (k, what) = match e {
            PassError::Empty { station } => (station, "no state there can keep the limits and still stop"),
            PassError::Stalls { interval } => (interval, "the motion would stand still there"),
        };
        let last = grid.stations.len() - 1;
        let st = &grid.stations[(offset + k).min(last)];
        let why = format!(
            "{what} (element {}, u = {:.9}, curvature {:.3e} 1/mm): the path's geometry leaves no speed to plan with",
            st.element,
            st.u,
            st.right.curvature()
        );
        match e {
            PassError::Stalls { .. } => {
                let next = &grid.stations[(offset + k + 1).min(last)];
                ReachError::Stands {
                    from: (st.element, st.u),
                    to: (next.element, next.u),
                    why,
                }
            }
            PassError::Empty { .. } => ReachError::Plan(why),
        }
    }

    /// Tightens the limits of the intervals (of `tight`, which `motion` runs over) whose
    /// motion the finite differences that ran `over` saw; counts the try, refuses beyond
    /// [`ReachOptions::repairs`].
    fn tighten(
        &self,
        tight: &mut [f64],
        motion: &Motion,
        over: &[(f64, f64)],
        tries: &mut usize,
    ) -> Result<(), ReachError> {
        if *tries >= self.options.repairs {
            let (t, r) = over[0];
            return Err(ReachError::Plan(format!(
                "the samples still run over a limit (ratio {r:.9} at {t:.4} s into a stretch) after {tries} re-plans"
            )));
        }
        *tries += 1;
        let mut starts = Vec::with_capacity(motion.durations.len() + 1);
        let mut t = 0.0;
        for d in &motion.durations {
            starts.push(t);
            t += d;
        }
        starts.push(t);
        for &(t_over, ratio) in over {
            let (from, to) = (t_over - 3.5 * self.period, t_over + 0.5 * self.period);
            for k in 0..tight.len().min(motion.durations.len()) {
                if starts[k + 1] >= from && starts[k] <= to {
                    tight[k] = tight[k].min(tight[k] / ratio * (1.0 - 1e-4));
                }
            }
        }
        Ok(())
    }
}

/// A rest-to-rest stretch planned whole: the passes and re-plans it took, its checked samples,
/// and its motion with what it was planned with (the stops along it branch off that).
struct StretchPlan {
    passes: usize,
    repairs: usize,
    points: Vec<PathPoint>,
    grid: Grid,
    lin: Linearisation,
    tight: Vec<f64>,
    motion: Motion,
}

/// Values of a at every station and collocation point of a grid.
#[derive(Clone, Debug)]
struct Linearisation {
    stations: Vec<f64>,
    points: Vec<[f64; NC]>,
}

impl Linearisation {
    fn from_speed(grid: &Grid, speed: &dyn Fn(f64, &Local) -> f64) -> Self {
        Self::from_a(grid, &|s, here| speed(s, here).powi(2))
    }

    fn from_plan(grid: &Grid, plan: &PlanSpeed) -> Self {
        Self::from_a(grid, &|s, _| plan.a_at(s))
    }

    /// `a(s, here)` at every station and collocation point.
    fn from_a(grid: &Grid, a: &dyn Fn(f64, &Local) -> f64) -> Self {
        let stations = grid.stations.iter().map(|st| a(st.s, &st.right)).collect();
        let points = grid
            .intervals
            .iter()
            .zip(&grid.stations)
            .map(|(iv, st)| {
                let mut p = [0.0; NC];
                for (x, (theta, local)) in p.iter_mut().zip(&iv.points) {
                    *x = a(st.s + theta, local);
                }
                p
            })
            .collect();
        Linearisation { stations, points }
    }

    fn scaled(&self, f: f64) -> Self {
        Linearisation {
            stations: self.stations.iter().map(|a| a * f).collect(),
            points: self.points.iter().map(|p| p.map(|a| a * f)).collect(),
        }
    }
}

/// A motion's a = ṡ² at any arc length of its grid.
struct PlanSpeed<'a> {
    grid: &'a Grid,
    motion: &'a Motion,
}

impl PlanSpeed<'_> {
    fn a_at(&self, s: f64) -> f64 {
        let st = &self.grid.stations;
        let k = st.partition_point(|x| x.s <= s).clamp(1, self.grid.len()) - 1;
        let length = self.grid.intervals[k].length;
        self.motion.pieces[k].a_at((s - st[k].s).clamp(0.0, length), length)
    }
}
