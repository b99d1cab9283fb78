//! Planner side of the geometry: what `nurbs-planner` publishes besides the curves, and the
//! check behind it. Compiled into the `nurbs-planner` binary and into the tests (never into
//! the realtime module's library: it needs the planner crate).
//!
//! The module's underrun stop starts at a segment boundary and is deterministic (the same
//! [`underrun_stop`] and interpolator on the same geometry and period), so the planner can run
//! it offline from every boundary and pick, per boundary, the largest stop deceleration and jerk
//! whose stop stays within the axis limits by finite differences (the `nurbs-plan verify`
//! check). That choice goes to the module as the per-record stop table.

use nurbs_hal::channel::{validate_geometry, CurveViews, StopPoint, MAX_CURVES};
use nurbs_hal::module::underrun_stop;
use nurbs_hal::user::GeometryBuilder;
use nurbs_motion::geometry::{ArcLengthTable, Toolpath};
use nurbs_motion::planner::axial::FiniteDifferences;
use nurbs_motion::planner::erwinski::PlanStart;
use nurbs_motion::planner::{plan, Limits, PathCurves, Plan, PlanOptions};
use nurbs_rtcore::executor::{Interpolator, Step};

/// Stop deceleration and jerk tried at each boundary, as fractions of the smallest axis
/// acceleration and jerk, largest first: 1, 0.85, 0.85^2, ... (30 steps, down to 0.009).
pub fn fractions(max_fraction: f64) -> Vec<f64> {
    (0..30).map(|k| max_fraction * 0.85f64.powi(k)).collect()
}

/// Per curve, the `(s, feed cap)` points the module's underrun stop must respect: the plan's
/// critical points (FLF minima, corners) at the planner's FLF margin, and the curve end at rest.
pub fn stop_points(toolpath: &Toolpath, plan: &Plan) -> Vec<Vec<(f64, f64)>> {
    let margin = PlanOptions::default().flf_margin;
    toolpath
        .elements
        .iter()
        .enumerate()
        .map(|(c, e)| {
            let table = ArcLengthTable::new(&e.curve);
            let mut stops: Vec<(f64, f64)> = plan
                .critical_points
                .iter()
                .filter(|(curve, _)| *curve == c)
                .map(|(_, p)| (table.length_to(&e.curve, p.u), margin * p.flf.max(0.0)))
                .collect();
            stops.push((table.total(), 0.0));
            stops.sort_by(|a, b| a.0.total_cmp(&b.0));
            stops
        })
        .collect()
}

/// The stop chosen after one record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopChoice {
    /// Stop jerk as a fraction of the smallest axis jerk.
    pub fraction: f64,
    /// Stop deceleration as a share of the same fraction of the smallest axis acceleration.
    pub accel_share: f64,
    pub accel: f64,
    pub jerk: f64,
    /// Worst ratio of an axial velocity, acceleration or jerk to its limit, from three samples
    /// before the stop to rest (<= 1: within the limits).
    pub ratio: f64,
}

/// Runs the plan through the interpolator and, at every segment boundary, the module's stop
/// with each jerk fraction in `fractions` (largest first) and deceleration shares 1, 1/2, 1/4,
/// 1/10 of it, until one stays within the limits; returns the choice per record (the least
/// violating one where none does).
pub fn choose_stops(toolpath: &Toolpath, plan: &Plan, valid: &CurveViews, fractions: &[f64]) -> Vec<StopChoice> {
    let curves = PathCurves::new(toolpath);
    let limits = &plan.limits;
    let tip = limits.velocity.len();
    let (a_max, j_max) = (limits.min_accel(), limits.min_jerk());
    let mut interp = Interpolator::new();
    let mut fd = FiniteDifferences::new(tip, limits.period);
    let mut choices = Vec::with_capacity(plan.records.len());
    for record in &plan.records {
        let mut pending = Some(*record);
        while let Step::Sample(s) = interp.step(&curves, limits.period, &mut || pending.take()) {
            fd.push(&s.point[..tip], limits);
        }
        let Some(last) = interp.record().copied() else {
            break;
        };
        let mut best: Option<StopChoice> = None;
        for (fraction, accel_share) in fractions
            .iter()
            .flat_map(|&f| [1.0, 0.5, 0.25, 0.1].map(|share| (f, share)))
        {
            let (accel, jerk) = (fraction * accel_share * a_max, fraction * j_max);
            let curve = valid.get(last.curve()).copied().flatten();
            let mut stop = Some(underrun_stop(curve, &last, accel, jerk));
            let (mut i, mut f) = (interp, fd);
            f.reset_peaks();
            while let Step::Sample(s) = i.step(&curves, limits.period, &mut || stop.take()) {
                f.push(&s.point[..tip], limits);
            }
            f.finish(limits);
            let choice = StopChoice {
                fraction,
                accel_share,
                accel,
                jerk,
                ratio: f.worst_ratio(limits),
            };
            if best.is_none_or(|b| choice.ratio < b.ratio) {
                best = Some(choice);
            }
            if choice.ratio <= 1.0 {
                best = Some(choice);
                break;
            }
        }
        if let Some(b) = best {
            choices.push(b);
        }
    }
    choices
}

/// The geometry `nurbs-planner` publishes for `plan`: the curves with their stop points, the
/// default stop (`max_fraction` of the smallest axis limits) and the per-record stop table
/// (fractions up to `max_fraction`). Also returns the choices.
pub fn geometry(
    toolpath: &Toolpath,
    plan: &Plan,
    max_fraction: f64,
) -> Result<(GeometryBuilder, Vec<StopChoice>), String> {
    if !(max_fraction > 0.0 && max_fraction <= 1.0) {
        return Err(format!("stop fraction {max_fraction} must be in (0, 1]"));
    }
    let limits = &plan.limits;
    let mut g = GeometryBuilder::new(
        toolpath.tip_dim(),
        max_fraction * limits.min_accel(),
        max_fraction * limits.min_jerk(),
    );
    for (e, stops) in toolpath.elements.iter().zip(stop_points(toolpath, plan)) {
        let c = &e.curve;
        g.add_curve(c.degree(), c.dim(), c.knots(), c.points(), c.weights(), &stops)?;
    }
    let fractions = fractions(max_fraction);
    let choices = {
        let mut valid: CurveViews = [None; MAX_CURVES];
        validate_geometry(g.header(), g.values(), &mut valid).map_err(|e| format!("geometry refused: {e:?}"))?;
        choose_stops(toolpath, plan, &valid, &fractions)
    };
    let table: Vec<(f64, f64)> = choices.iter().map(|c| (c.accel, c.jerk)).collect();
    g.set_stop_table(&table)?;
    Ok((g, choices))
}

/// The plan of the rest of the path from where the module stopped after an underrun (at rest,
/// its first record starting at exactly the published element, parameter and arc length).
pub fn plan_from_stop(toolpath: &Toolpath, limits: &Limits, stop: &StopPoint) -> Result<Plan, String> {
    let options = PlanOptions {
        start: Some(PlanStart {
            curve: stop.curve as usize,
            u: stop.u,
            s: stop.s,
        }),
        ..PlanOptions::default()
    };
    plan(toolpath, limits, &options, &mut |_| {}).map_err(|e| format!("re-plan from the stop point: {e}"))
}
