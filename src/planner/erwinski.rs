//! The feedrate planner of paper 000 (Erwinski, Wawrzak, Paprocki 2022, section III, Fig. 3),
//! made strict: every segment is interpolated with the realtime interpolator itself and checked
//! by finite differences; a segment that still violates after the golden-section searches of
//! jerk and acceleration (steps 1-7) gets a lower end feed (step 8) and, failing that, a lower
//! start feed by re-planning the previous segment (step 9). Nothing that violates is emitted.

use super::axial::FiniteDifferences;
use super::flf::{critical_points, flf, CriticalPoint, FlfScan};
use super::quick_check::{estimate, ArcGrid, Estimate};
use super::scurve_fit::{fit_ramps, reachable_feed, Ramp};
use super::simulate::{run_segment, SimState};
use super::{Limits, LimitsError, PathCurves};
use crate::geometry::{ArcLengthTable, Toolpath};
use nurbs_rtcore::executor::CurveSet;
use nurbs_rtcore::math::{dot, norm};
use nurbs_rtcore::records::{CURVE_SHIFT, FLAG_LAST};
use nurbs_rtcore::scurve::SCurve;
use nurbs_rtcore::SegmentRecord;
use std::fmt;
use std::time::Instant;

/// Tuning of the planner (the paper's values by default).
#[derive(Clone, Debug)]
pub struct PlanOptions {
    /// FLF samples per control point (step 1).
    pub samples_per_control_point: usize,
    /// Fraction of the FLF acceleration and jerk caps used as segment end feeds, leaving room
    /// for the tangential acceleration terms.
    pub flf_margin: f64,
    /// Plan the rest of the path from rest at this point instead of the whole path (resuming
    /// after a stop); `None`: from the start of the first element.
    pub start: Option<PlanStart>,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            samples_per_control_point: 500,
            flf_margin: 0.95,
            start: None,
        }
    }
}

/// A point on the path to plan from, at rest: element `curve`, parameter `u`, taken to be at
/// arc length `s` from the element's start (the first record gets exactly these `u_start`,
/// `s_start`, so an interpolator standing there continues without a jump).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanStart {
    pub curve: usize,
    pub u: f64,
    pub s: f64,
}

/// A finished plan.
#[derive(Clone, Debug)]
pub struct Plan {
    pub records: Vec<SegmentRecord>,
    /// Critical points per curve (after refinement), as (curve, point).
    pub critical_points: Vec<(usize, CriticalPoint)>,
    pub motion_time: f64,
    /// Wall time spent planning (s) and until the first record was ready (s).
    pub plan_time: f64,
    pub first_record_time: f64,
    /// Limits as used (one value per axis).
    pub limits: Limits,
}

#[derive(Clone, Debug, PartialEq)]
pub enum PlanError {
    Limits(LimitsError),
    EmptyPath,
    MixedDimensions,
    /// No feed profile within the limits could be found (should not happen; reported rather
    /// than emitting a violating plan).
    Infeasible {
        curve: usize,
        u: f64,
        reason: String,
    },
}

impl fmt::Display for PlanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlanError::Limits(e) => write!(f, "{e}"),
            PlanError::EmptyPath => write!(f, "the toolpath has no elements"),
            PlanError::MixedDimensions => write!(f, "the toolpath mixes 2-D and 3-D elements"),
            PlanError::Infeasible { curve, u, reason } => {
                write!(
                    f,
                    "no feed profile within the limits near curve {curve}, u = {u}: {reason}"
                )
            }
        }
    }
}
impl std::error::Error for PlanError {}

impl From<LimitsError> for PlanError {
    fn from(e: LimitsError) -> Self {
        PlanError::Limits(e)
    }
}

/// A segment boundary: where the previous segment ends and the next begins (the same point;
/// at a join of two path elements the curve changes).
#[derive(Clone, Copy, Debug)]
struct Node {
    /// Curve and parameter of the segment ending here.
    #[allow(dead_code)]
    end_curve: usize,
    end_u: f64,
    end_s: f64,
    /// Curve and parameter of the segment starting here.
    start_curve: usize,
    start_u: f64,
    start_s: f64,
    /// Feed cap at this point.
    cap: f64,
    /// Path start/end, element joins and corners: never merged away.
    hard: bool,
}

impl Node {
    /// A hard node inside curve `c` at parameter `u`, arc length `s`, with feed cap `cap`.
    fn within(c: usize, u: f64, s: f64, cap: f64) -> Node {
        Node {
            end_curve: c,
            end_u: u,
            end_s: s,
            start_curve: c,
            start_u: u,
            start_s: s,
            cap,
            hard: true,
        }
    }
}

/// Plans `toolpath` under `limits`; every record is passed to `on_record` as soon as it is final.
pub fn plan(
    toolpath: &Toolpath,
    limits: &Limits,
    options: &PlanOptions,
    on_record: &mut dyn FnMut(&SegmentRecord),
) -> Result<Plan, PlanError> {
    let started = Instant::now();
    if toolpath.elements.is_empty() {
        return Err(PlanError::EmptyPath);
    }
    let tip = toolpath.tip_dim();
    if toolpath.elements.iter().any(|e| e.curve.tip_dim() != tip) {
        return Err(PlanError::MixedDimensions);
    }
    let limits = limits.for_axes(tip)?;
    // Feed caps a hair below the programmed feed: the sampled path speed (chord / period) then
    // stays below it through rounding, with no retry of the segment.
    let planning = Limits {
        feed: limits.feed * (1.0 - FEED_HEADROOM),
        ..limits.clone()
    };
    let curves = PathCurves::new(toolpath);
    let tables: Vec<ArcLengthTable> = toolpath
        .elements
        .iter()
        .map(|e| ArcLengthTable::new(&e.curve))
        .collect();

    // Steps 1-3 per curve: FLF scan and refined minima; a programmed feed lowers the cap.
    let mut scans = Vec::new();
    let mut criticals = Vec::new();
    let mut nodes: Vec<Node> = Vec::new();
    let start = options.start.unwrap_or(PlanStart {
        curve: 0,
        u: curves.view(0).u_min(),
        s: 0.0,
    });
    let start_ok = start.curve < toolpath.elements.len() && {
        let view = curves.view(start.curve);
        start.u >= view.u_min() && start.u < view.u_max() && start.s.is_finite() && start.s >= 0.0
    };
    if !start_ok {
        return Err(PlanError::Infeasible {
            curve: start.curve,
            u: start.u,
            reason: "the start point is not on the path (or at its end)".into(),
        });
    }
    for (c, element) in toolpath.elements.iter().enumerate() {
        let mut lim = planning.clone();
        if let Some(f) = element.feed {
            lim.feed = lim.feed.min(f * (1.0 - FEED_HEADROOM));
        }
        let view = curves.view(c);
        let scan = FlfScan::new(view, tip, &lim, options.samples_per_control_point);
        if c < start.curve {
            // Before the start point: only the scan is kept (indexed by curve).
            scans.push(scan);
            continue;
        }
        let points = critical_points(view, tip, &lim, &scan);
        let cap_of = |p: &CriticalPoint| {
            let v = flf(view, tip, &lim, p.u);
            v.speed_cap().min(options.flf_margin * v.accel.min(v.jerk))
        };
        let (u0, u1) = (view.u_min(), view.u_max());
        let start_cap = if c == 0 { 0.0 } else { join_cap(&curves, &planning, c) };
        match nodes.last_mut() {
            Some(last) => {
                last.start_curve = c;
                last.start_u = u0;
                last.start_s = 0.0;
                last.cap = last.cap.min(start_cap);
                last.hard = true;
            }
            None => nodes.push(Node {
                end_curve: c,
                end_u: start.u,
                end_s: start.s,
                start_curve: c,
                start_u: start.u,
                start_s: start.s,
                cap: 0.0,
                hard: true,
            }),
        }
        // Interior knots where the curve is only C0 or C1: corners stop, curvature jumps cap.
        let mut stops: Vec<CriticalPoint> = interior_breaks(view, tip, &lim)
            .into_iter()
            .map(|(u, cap)| CriticalPoint { u, flf: cap })
            .collect();
        let mut all: Vec<(CriticalPoint, Option<f64>)> = points.iter().map(|p| (*p, None)).collect();
        // Critical points too close to a break are superseded by it.
        all.retain(|(p, _)| stops.iter().all(|b| (b.u - p.u).abs() > 1e-9 * (u1 - u0)));
        all.extend(stops.drain(..).map(|b| (b, Some(b.flf))));
        all.sort_by(|a, b| a.0.u.total_cmp(&b.0.u));
        if c == start.curve {
            // Only what lies ahead of the start point (which is a stop itself).
            all.retain(|(p, _)| p.u > start.u + 1e-9 * (u1 - u0));
        }
        for (p, fixed_cap) in &all {
            let p = &p;
            let s = tables[c].length_to(&element.curve, p.u);
            let cap = fixed_cap.unwrap_or_else(|| cap_of(p));
            nodes.push(Node {
                end_curve: c,
                end_u: p.u,
                end_s: s,
                start_curve: c,
                start_u: p.u,
                start_s: s,
                cap,
                hard: fixed_cap.is_some(),
            });
            criticals.push((c, **p));
        }
        let s1 = tables[c].total();
        let end_cap = if c + 1 == toolpath.elements.len() {
            0.0
        } else {
            join_cap(&curves, &planning, c + 1)
        };
        nodes.push(Node {
            end_curve: c,
            end_u: u1,
            end_s: s1,
            start_curve: c,
            start_u: u1,
            start_s: s1,
            cap: end_cap,
            hard: true,
        });
        // Feed cap inside every segment of this curve: no interior point may need less than the
        // segment's ends (insert the dip as a node otherwise).
        scans.push(scan);
    }
    // Peak caps (feed, chord, axial velocity) inside each segment, inserting nodes at dips.
    let mut k = 0;
    while k + 1 < nodes.len() {
        let (a, b) = (nodes[k], nodes[k + 1]);
        let scan = &scans[a.start_curve];
        let dip = scan.min_speed_cap_between(a.start_u, b.end_u);
        match dip {
            // A dip below both end caps gets a node; any other dip is left to the exact check
            // of the segment, which splits it there if the profile passes it too fast.
            Some((m, u)) if m < a.cap.min(b.cap) && u > a.start_u && u < b.end_u => {
                let c = a.start_curve;
                let s = tables[c].length_to(&toolpath.elements[c].curve, u);
                nodes.insert(k + 1, Node::within(c, u, s, m));
            }
            _ => k += 1,
        }
    }
    let grids: Vec<ArcGrid> = scans
        .iter()
        .enumerate()
        .map(|(c, scan)| ArcGrid::new(curves.view(c), tip, &scan.u))
        .collect();
    let (acc, jerk) = (limits.min_accel(), limits.min_jerk());
    // Look-ahead, and step 4: a critical point whose feed is bound by reachability (the segments
    // around it are too short to reach its cap) is dropped and its segments merged, so the
    // acceleration need not return to zero there. Hard nodes (ends, joins, corners) stay.
    let (mut lengths, feeds) = loop {
        let lengths: Vec<f64> = nodes.windows(2).map(|w| (w[1].end_s - w[0].start_s).max(0.0)).collect();
        let feeds = look_ahead(&nodes, &lengths, acc, jerk);
        let before = nodes.len();
        let mut k = 0;
        nodes.retain(|n| {
            let keep = n.hard || feeds[k] >= MERGE_TOLERANCE * n.cap;
            k += 1;
            keep
        });
        if nodes.len() == before {
            break (lengths, feeds);
        }
    };
    let mut peak_caps: Vec<f64> = nodes
        .windows(2)
        .map(|w| {
            let programmed = toolpath.elements[w[0].start_curve].feed.unwrap_or(f64::INFINITY);
            planning.feed.min(programmed * (1.0 - FEED_HEADROOM))
        })
        .collect();
    let mut feeds = feeds;

    // Segment by segment with axial checks and back-tracking.
    let mut nseg = lengths.len();
    let mut splits = 0usize;
    let mut records: Vec<SegmentRecord> = Vec::with_capacity(nseg);
    let mut states: Vec<SimState> = vec![SimState::start(tip, limits.period)];
    let mut start_feeds: Vec<f64> = vec![0.0];
    let check_limits = strict(&limits);
    let mut k = 0;
    let mut backtracks = 0usize;
    while k < nseg {
        let ctx = SegmentContext {
            curves: &curves,
            limits: &check_limits,
            node_start: nodes[k],
            node_end: nodes[k + 1],
            length: lengths[k],
            peak_cap: peak_caps[k],
            grid: &grids[nodes[k].start_curve],
            last: k + 1 == nseg,
            seq: k as u32,
            accel: acc,
            jerk,
        };
        let outcome = solve_segment(&ctx, start_feeds[k], feeds[k + 1], &states[k]);
        match outcome {
            Ok((record, state)) => {
                records.truncate(k);
                records.push(record);
                states.truncate(k + 1);
                states.push(state);
                start_feeds.truncate(k + 1);
                // Rounding can leave -1e-14 at a stop; a record never starts below zero.
                let end_v = record.profile().table().end().v.max(0.0);
                start_feeds.push(end_v);
                k += 1;
            }
            Err(SegmentFailure::Split { u, cap }) if splits < MAX_SPLITS => {
                // Step 4 in reverse: a point inside the segment needs a lower feed than the
                // profile gives it (a speed cap between FLF samples, or the fall towards a
                // cusp outrunning its chord cap): it becomes a node of its own.
                splits += 1;
                let c = nodes[k].start_curve;
                let s = tables[c].length_to(&toolpath.elements[c].curve, u);
                let end_s = nodes[k + 1].end_s;
                nodes.insert(k + 1, Node::within(c, u, s, cap));
                lengths[k] = s - nodes[k].start_s;
                lengths.insert(k + 1, end_s - s);
                feeds.insert(k + 1, cap);
                peak_caps.insert(k + 1, peak_caps[k]);
                nseg += 1;
                let reachable = reachable_feed(cap, lengths[k], acc, jerk, start_feeds[k]);
                if reachable < start_feeds[k] && k > 0 {
                    feeds[k] = reachable;
                    k -= 1;
                }
            }
            Err(failure) => {
                let start_max = match failure {
                    SegmentFailure::StartTooFast(v) => v,
                    SegmentFailure::Split { .. } => START_FEED_STEP * start_feeds[k],
                };
                backtracks += 1;
                if k == 0 || backtracks > 50 * nseg + 100 {
                    return Err(PlanError::Infeasible {
                        curve: nodes[k].start_curve,
                        u: nodes[k].start_u,
                        reason: "segment violates the axis limits even from its lowest start feed".into(),
                    });
                }
                // Step 9: the previous segment must end slower.
                feeds[k] = start_max.min(feeds[k]);
                k -= 1;
            }
        }
    }
    let first_record_time = started.elapsed().as_secs_f64();
    for r in &records {
        on_record(r);
    }
    // From the first setpoint to the last: the profiles plus the part-period waits at stops.
    let samples = states.last().map_or(0, |s| s.samples);
    let motion_time = samples.saturating_sub(1) as f64 * limits.period;
    Ok(Plan {
        records,
        critical_points: criticals,
        motion_time,
        plan_time: started.elapsed().as_secs_f64(),
        first_record_time,
        limits,
    })
}

/// Nodes inserted at most by segment splits (each one makes a segment shorter).
const MAX_SPLITS: usize = 10_000;

/// Why a segment could not be planned.
enum SegmentFailure {
    /// Not from this start feed: retry with the previous segment ending at most this fast.
    StartTooFast(f64),
    /// A point inside must be passed at most at feed `cap`: make it a node.
    Split { u: f64, cap: f64 },
}

/// Relative headroom of the planned feed below the programmed feed.
const FEED_HEADROOM: f64 = 1e-7;

/// A node is kept when the look-ahead reaches at least this fraction of its cap.
const MERGE_TOLERANCE: f64 = 0.999;

/// Forward and backward reachability of node feeds with the nominal tangential limits.
fn look_ahead(nodes: &[Node], lengths: &[f64], acc: f64, jerk: f64) -> Vec<f64> {
    let mut feeds: Vec<f64> = nodes.iter().map(|n| n.cap).collect();
    for k in (0..lengths.len()).rev() {
        feeds[k] = feeds[k].min(reachable_feed(feeds[k + 1], lengths[k], acc, jerk, feeds[k]));
    }
    for k in 0..lengths.len() {
        feeds[k + 1] = feeds[k + 1].min(reachable_feed(feeds[k], lengths[k], acc, jerk, feeds[k + 1]));
    }
    feeds
}

/// Limits a hair below the user's, so that the check has headroom for the last rounding.
fn strict(limits: &Limits) -> Limits {
    let shrink = |v: &Vec<f64>| v.iter().map(|x| x * (1.0 - 1e-9)).collect();
    Limits {
        velocity: shrink(&limits.velocity),
        acceleration: shrink(&limits.acceleration),
        jerk: shrink(&limits.jerk),
        ..limits.clone()
    }
}

/// Interior knots of multiplicity >= degree - 1 (continuity C1 or less) with the feed cap
/// there: zero where the tangent turns, else the curvature-jump cap of [`jump_cap`].
fn interior_breaks(view: &nurbs_rtcore::CurveView, tip: usize, limits: &Limits) -> Vec<(f64, f64)> {
    let p = view.degree();
    let knots = view.knots();
    let n = view.control_point_count();
    let mut out = Vec::new();
    let mut i = p + 1;
    while i < n {
        let mut m = 1;
        while i + m < n && knots[i + m] == knots[i] {
            m += 1;
        }
        if m + 1 >= p {
            let u = knots[i];
            let left = view.derivatives_left(u, 3);
            let right = view.derivatives(u, 3);
            out.push((u, jump_cap(&left, &right, tip, limits)));
        }
        i += m;
    }
    out
}

/// Feed cap across a point where the derivatives jump from `left` to `right` (parameter
/// derivatives; converted to arc length here): zero at a tangent break, otherwise the axial
/// acceleration jump at feed v, |dx''| v^2, must stay within one period's jerk.
fn jump_cap(
    left: &nurbs_rtcore::executor::Derivs,
    right: &nurbs_rtcore::executor::Derivs,
    tip: usize,
    limits: &Limits,
) -> f64 {
    let to_arc = |d: &nurbs_rtcore::executor::Derivs| {
        let g2 = dot(&d[1], &d[1], tip);
        let g = g2.sqrt();
        let mut x1 = [0.0; nurbs_rtcore::MAX_DIM];
        let mut x2 = [0.0; nurbs_rtcore::MAX_DIM];
        if g > 0.0 {
            let c12 = dot(&d[1], &d[2], tip);
            for i in 0..tip {
                x1[i] = d[1][i] / g;
                x2[i] = d[2][i] / g2 - d[1][i] * c12 / (g2 * g2);
            }
        }
        (x1, x2, g)
    };
    let (l1, l2, gl) = to_arc(left);
    let (r1, r2, gr) = to_arc(right);
    let gap = norm(&nurbs_rtcore::math::sub(&left[0], &right[0]), tip);
    if gap > 1e-9 || gl == 0.0 || gr == 0.0 || dot(&l1, &r1, tip) < 1.0 - 1e-12 {
        return 0.0;
    }
    let mut cap = limits.feed;
    for i in 0..tip {
        let jump = (l2[i] - r2[i]).abs();
        if jump > 0.0 {
            cap = cap.min(0.5 * (limits.jerk[i] * limits.period / jump).sqrt());
        }
    }
    cap
}

/// Feed cap where curve `c - 1` joins curve `c`: zero at a tangent break; otherwise the axial
/// acceleration jump between the two curves must not exceed one period's jerk.
fn join_cap(curves: &PathCurves, limits: &Limits, c: usize) -> f64 {
    let (a, b) = (curves.view(c - 1), curves.view(c));
    jump_cap(
        &a.derivatives(a.u_max(), 3),
        &b.derivatives(b.u_min(), 3),
        limits.velocity.len(),
        limits,
    )
}

#[derive(Clone, Copy)]
struct SegmentContext<'a> {
    curves: &'a PathCurves<'a>,
    limits: &'a Limits,
    node_start: Node,
    node_end: Node,
    length: f64,
    peak_cap: f64,
    grid: &'a ArcGrid,
    last: bool,
    seq: u32,
    accel: f64,
    jerk: f64,
}

/// One candidate profile, interpolated and measured.
struct Trial {
    record: SegmentRecord,
    state: SimState,
    /// Worst peak / limit ratio (> 1 is a violation), eq. 22-23 sums, duration.
    ratio: f64,
    /// How far the speed caps (feed, axial velocity, chord error) are exceeded, as a factor on
    /// the feed: lower jerk or acceleration cannot cure that, a lower peak feed can. Above 1
    /// only through interpolation error or an FLF dip between scan samples.
    speed_ratio: f64,
    /// Curve parameter where the speed caps are exceeded most.
    speed_u: f64,
    /// Sampled path speed there.
    speed_at: f64,
    /// Within the first or last periods of the segment, or between.
    speed_where: Where,
    acc_violation: f64,
    jerk_violation: f64,
    duration: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Where {
    Start,
    Inside,
    End,
}

/// What the golden-section search compares.
trait Candidate {
    fn ok(&self) -> bool;
    fn duration(&self) -> f64;
}

impl Candidate for Trial {
    fn ok(&self) -> bool {
        self.ratio <= 1.0
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

/// A candidate judged by the fast estimate only.
struct Quick {
    estimate: Estimate,
    duration: f64,
}

impl Candidate for Quick {
    fn ok(&self) -> bool {
        self.estimate.ratio <= 1.0
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

fn make_record(ctx: &SegmentContext, profile: &SCurve) -> SegmentRecord {
    let mut flags = (ctx.node_start.start_curve as u32) << CURVE_SHIFT;
    if ctx.last {
        flags |= FLAG_LAST;
    }
    SegmentRecord {
        seq: ctx.seq,
        flags,
        u_start: ctx.node_start.start_u,
        u_end: ctx.node_end.end_u,
        s_start: ctx.node_start.start_s,
        length: profile.table().length(),
        feed_start: profile.feed_start,
        durations: profile.durations,
        jerks: profile.jerks,
    }
}

fn trial(ctx: &SegmentContext, from: &SimState, v0: f64, v1: f64, up: Ramp, down: Ramp) -> Option<Trial> {
    let profile = fit_ramps(v0, v1, ctx.length, ctx.peak_cap, up, down).ok()?;
    let record = make_record(ctx, &profile);
    let mut state = *from;
    state.check.reset_peaks();
    // Chord error between consecutive samples, measured at the middle parameter (where the
    // sagitta of a smooth arc peaks), with 10 % kept for the exact check.
    let mut chord_ratio: f64 = 0.0;
    let tip = ctx.limits.velocity.len();
    let mut prev: Option<nurbs_rtcore::executor::Sample> = from.last_sample;
    let mut last_sample = from.last_sample;
    let eps = super::flf::CHORD_MARGIN * ctx.limits.chord_tolerance;
    let (period, feed) = (ctx.limits.period, ctx.limits.feed);
    let mut worst_speed = (0.0f64, ctx.node_start.start_u, 0.0, 0usize);
    let mut count = 0usize;
    let sink = &mut |s: &nurbs_rtcore::executor::Sample| {
        if let Some(p) = prev {
            let mut ratio = 0.0f64;
            let mut step2 = 0.0;
            for i in 0..tip {
                let d = s.point[i] - p.point[i];
                step2 += d * d;
                ratio = ratio.max(d.abs() / period / ctx.limits.velocity[i]);
            }
            ratio = ratio.max(step2.sqrt() / period / feed);
            if p.curve == s.curve && s.u > p.u {
                if let Some(view) = ctx.curves.curve(s.curve) {
                    let r = sagitta(&view, tip, &p, s, eps) / eps;
                    chord_ratio = chord_ratio.max(r);
                    ratio = ratio.max(r.sqrt());
                }
            }
            if ratio > worst_speed.0 {
                worst_speed = (ratio, s.u, step2.sqrt() / period, count);
            }
        }
        count += 1;
        prev = Some(*s);
        last_sample = Some(*s);
    };
    if !run_segment(ctx.curves, ctx.limits, &mut state, record, sink) {
        return None;
    }
    let check: &FiniteDifferences = &state.check;
    let ratio = check
        .worst_ratio(ctx.limits)
        .max(chord_ratio)
        .max(check.peaks.feed / feed);
    state.last_sample = last_sample;
    let n = check.peaks.samples.max(1) as f64;
    Some(Trial {
        record,
        state,
        ratio,
        speed_ratio: worst_speed.0,
        speed_u: worst_speed.1,
        speed_at: worst_speed.2,
        speed_where: match worst_speed.3 {
            i if i <= 2 => Where::Start,
            i if i + 3 >= count => Where::End,
            _ => Where::Inside,
        },
        acc_violation: check.peaks.acc_violation / n,
        jerk_violation: check.peaks.jerk_violation / n,
        duration: profile.total_time(),
    })
}

/// Margin of the estimate: the searches aim this far inside the limits, so that the exact check
/// of their choice usually passes.
const ESTIMATE_MARGIN: f64 = 0.995;
/// An estimated ratio above this after the searches means: lower the end feed straight away.
const HOPELESS_ESTIMATE: f64 = 1.05;

fn quick(ctx: &SegmentContext, from: &SimState, v0: f64, v1: f64, up: Ramp, down: Ramp) -> Option<Quick> {
    let profile = fit_ramps(v0, v1, ctx.length, ctx.peak_cap, up, down).ok()?;
    // Local time of the segment's first sample (0 from rest at a stop, see the executor).
    let t_first = match from.interp.record() {
        Some(_) if !from.interp.ends_at_rest() => ctx.limits.period - from.interp.time_left_in_segment(),
        _ => 0.0,
    };
    let table = profile.table();
    let estimate = estimate(
        ctx.grid,
        ctx.limits,
        ESTIMATE_MARGIN,
        &table,
        ctx.node_start.start_s,
        t_first,
    );
    Some(Quick {
        estimate,
        duration: table.total_time(),
    })
}

/// Largest distance from the curve between two samples to the chord between them.
///
/// Three probes (quarter, middle, three quarters of the parameter step) find the sagitta where
/// the parametrisation is uneven across the step (near-repeated control points); where they
/// come near the tolerance `eps`, the step is measured as `verify` measures it.
fn sagitta(
    view: &nurbs_rtcore::CurveView,
    tip: usize,
    a: &nurbs_rtcore::executor::Sample,
    b: &nurbs_rtcore::executor::Sample,
    eps: f64,
) -> f64 {
    let probe = |f: f64| super::verify::distance_to_chord(&view.point(a.u + f * (b.u - a.u)), &a.point, &b.point, tip);
    let probed = probe(0.5).max(probe(0.25)).max(probe(0.75));
    if probed > EXACT_CHORD_ABOVE * eps {
        super::verify::chord_error(view, tip, a.u, b.u, &a.point, &b.point)
    } else {
        probed
    }
}

/// Fraction of the planning tolerance above which a step's chord error is measured exactly.
const EXACT_CHORD_ABOVE: f64 = 0.3;

/// Golden-section search (eq. 24-27) over `x in (0, upper]` for the better profile by the
/// paper's rules: violating vs violating, the smaller violation; both fine, the shorter; else
/// the one without violation.
fn golden<T: Candidate>(
    upper: f64,
    eval: &dyn Fn(f64) -> Option<T>,
    violation: &dyn Fn(&T) -> f64,
) -> Option<(f64, T)> {
    let g = (5f64.sqrt() + 1.0) / 2.0;
    let better = |a: &Option<T>, b: &Option<T>| -> bool {
        match (a, b) {
            (Some(x), Some(y)) => match (x.ok(), y.ok()) {
                (true, true) => x.duration() <= y.duration(),
                (false, false) => violation(x) <= violation(y),
                (ok, _) => ok,
            },
            (Some(_), None) => true,
            (None, _) => false,
        }
    };
    let (mut a, mut b) = (0.0, upper);
    let mut xl = b - (b - a) / g;
    let mut xr = a + (b - a) / g;
    let (mut fl, mut fr) = (eval(xl), eval(xr));
    // Terminate at 0.1 % of the range (the paper's absolute 0.1 would take 30 steps at 2e5).
    while b - a > 1e-3 * upper {
        if better(&fl, &fr) {
            b = xr;
            xr = xl;
            fr = fl;
            xl = b - (b - a) / g;
            fl = eval(xl);
        } else {
            a = xl;
            xl = xr;
            fl = fr;
            xr = a + (b - a) / g;
            fr = eval(xr);
        }
    }
    if better(&fl, &fr) {
        fl.map(|t| (xl, t))
    } else {
        fr.map(|t| (xr, t))
    }
}

/// Factor applied to the end feed when a segment cannot be made to fit (step 8), and to the
/// start feed asked of the previous segment when even that fails (step 9).
const END_FEED_STEP: f64 = 0.8;
const START_FEED_STEP: f64 = 0.9;

/// Plans one segment from feed `v0` (fixed: the previous segment ends there) towards `v1`.
/// Returns the record and the state after it, or the highest start feed worth retrying with.
///
/// The golden-section searches (jerk, then acceleration) first run on the fast estimate, and
/// their choice is checked exactly; only if that fails do they run again on exact trials.
fn solve_segment(
    ctx: &SegmentContext,
    v0: f64,
    v1_target: f64,
    from: &SimState,
) -> Result<(SegmentRecord, SimState), SegmentFailure> {
    let both = |accel: f64, jerk: f64| Ramp { accel, jerk };
    let mut local = *ctx;
    let ctx = &mut local;
    let mut v1 = v1_target.min(reachable_feed(v0, ctx.length, ctx.accel, ctx.jerk, v1_target));
    for _attempt in 0..40 {
        let nominal = both(ctx.accel, ctx.jerk);
        if let Some(t) = trial(ctx, from, v0, v1, nominal, nominal) {
            if t.ok() {
                return Ok((t.record, t.state));
            }
            if t.speed_ratio > 1.0 {
                // A speed cap (feed, axial velocity, chord error) is exceeded; lower jerk or
                // acceleration would not help. Lower the feed where it happens: the start feed
                // (previous segment), the end feed, a new node inside, or the peak.
                let factor = (1.0 - 1e-6) / t.speed_ratio;
                // At an end whose feed is well below the sampled speed, the profile rises or
                // falls within a period or two there: the cure is a lower peak, not end feed.
                let near = |v: f64| v >= 0.5 * t.speed_at;
                match t.speed_where {
                    Where::Start if near(v0) => return Err(SegmentFailure::StartTooFast(v0 * factor)),
                    Where::End if near(v1) => v1 *= factor,
                    Where::Inside if t.speed_at < ctx.peak_cap * SPLIT_BELOW_PEAK => {
                        let cap = (1.0 - 1e-3) * t.speed_at * factor;
                        return Err(SegmentFailure::Split { u: t.speed_u, cap });
                    }
                    _ => {
                        ctx.peak_cap = ctx.peak_cap.min(t.speed_at) * factor;
                        if v0 > ctx.peak_cap {
                            return Err(SegmentFailure::StartTooFast(ctx.peak_cap));
                        }
                        v1 = v1.min(ctx.peak_cap);
                    }
                }
                // Then on to the searches with the new feeds (an axial excess may remain).
            }
        }
        // Steps 3-7 on the estimate.
        let by_jerk = golden(
            ctx.jerk,
            &|j| quick(ctx, from, v0, v1, both(ctx.accel, j), both(ctx.accel, j)),
            &|q| q.estimate.jerk_violation + q.estimate.acc_violation,
        );
        let j = by_jerk.as_ref().map_or(ctx.jerk, |(j, _)| *j);
        let (a, estimated_ratio) = match by_jerk {
            Some((_, q)) if q.ok() => (ctx.accel, q.estimate.ratio),
            _ => golden(ctx.accel, &|a| quick(ctx, from, v0, v1, both(a, j), both(a, j)), &|q| {
                q.estimate.acc_violation + q.estimate.jerk_violation
            })
            .map_or((ctx.accel, f64::INFINITY), |(a, q)| (a, q.estimate.ratio)),
        };
        if let Some(t) = trial(ctx, from, v0, v1, both(a, j), both(a, j)) {
            if t.ok() {
                return Ok((t.record, t.state));
            }
        }
        // The estimate was not enough: the same searches on exact trials, unless the estimate
        // already shows this end feed to be out of reach (they agree to about 1 %).
        if estimated_ratio > HOPELESS_ESTIMATE {
            v1 = if v1 < 1e-3 { 0.0 } else { END_FEED_STEP * v1 };
            continue;
        }
        let by_jerk = golden(
            ctx.jerk,
            &|j| trial(ctx, from, v0, v1, both(ctx.accel, j), both(ctx.accel, j)),
            &|t| t.jerk_violation + t.acc_violation,
        );
        let j = by_jerk.as_ref().map_or(ctx.jerk, |(j, _)| *j);
        if let Some((_, t)) = by_jerk {
            if t.ok() {
                return Ok((t.record, t.state));
            }
        }
        let by_acc = golden(ctx.accel, &|a| trial(ctx, from, v0, v1, both(a, j), both(a, j)), &|t| {
            t.acc_violation + t.jerk_violation
        });
        if let Some((_, t)) = by_acc {
            if t.ok() {
                return Ok((t.record, t.state));
            }
        }
        // Step 8: a lower end feed.
        if v1 <= 1e-6 {
            break;
        }
        v1 = if v1 < 1e-3 { 0.0 } else { END_FEED_STEP * v1 };
    }
    Err(SegmentFailure::StartTooFast(START_FEED_STEP * v0))
}

/// A speed excess inside a segment is split off as a node when the profile there is below this
/// fraction of the peak (at the peak, lowering the peak is the cure).
const SPLIT_BELOW_PEAK: f64 = 0.99;
