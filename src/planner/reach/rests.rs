//! Rests the planner adds where a pass would stand still: near-cusps (two control points a few
//! nanometres apart make a turn of 1e7-1e10 1/mm that only a standing motion follows) and
//! micro-geometry at a stretch's end. The stretch then ends at rest there and the next starts
//! from rest, as at a tangent break. A stretch too short for the grid, a step of at most the
//! chord tolerance, is crossed in one servo period where the finite differences allow it.

use super::grid::{arc_derivatives, Local};
use super::sampler::Check;
use super::*;

/// Most rests added to one stretch before the planner refuses it.
pub(super) const MOST_RESTS: usize = 16;
/// Points per interval where the rest's curvature peak is looked for.
const LOOKS: usize = 64;
/// Periods at rest before and after a one-period step (the finite differences of the samples
/// before settle, and the next stretch starts from samples at rest).
const SETTLE: usize = 3;

/// The rests added so far, in path order.
#[derive(Debug, Default)]
pub(super) struct Rests(Vec<(usize, f64)>);

impl Rests {
    /// Adds `at`; false where it is there already.
    pub(super) fn add(&mut self, at: (usize, f64)) -> bool {
        match self.0.binary_search_by(|r| r.0.cmp(&at.0).then(r.1.total_cmp(&at.1))) {
            Ok(_) => false,
            Err(i) => {
                self.0.insert(i, at);
                true
            }
        }
    }

    /// The first rest on element `e` after parameter `u`.
    pub(super) fn after(&self, e: usize, u: f64) -> Option<f64> {
        let i = self.0.partition_point(|r| r.0 < e || (r.0 == e && r.1 <= u));
        self.0.get(i).filter(|r| r.0 == e).map(|r| r.1)
    }
}

/// Where in the interval from `from` to `to` (element, parameter) the motion should rest: the
/// peak of the curvature there (on the element `from` is on, up to its end).
pub(super) fn rest_in(curves: &PathCurves, from: (usize, f64), to: (usize, f64), axes: usize) -> (usize, f64) {
    let view = curves.view(from.0);
    let end = if to.0 == from.0 { to.1 } else { view.u_max() };
    let mut best = (f64::NEG_INFINITY, end);
    for i in 1..LOOKS {
        let u = from.1 + (end - from.1) * i as f64 / LOOKS as f64;
        let (_, q1, q2, q3) = arc_derivatives(&view, u, axes, false);
        let kappa = Local { q1, q2, q3, cap: 0.0 }.curvature();
        if kappa.is_finite() && kappa > best.0 {
            best = (kappa, u);
        }
    }
    (from.0, best.1)
}

/// The point at rest at `(element, u)`.
pub(super) fn point_at(curves: &PathCurves, (element, u): (usize, f64), axes: usize) -> PathPoint {
    sampler::path_point(&curves.view(element), element, u, axes)
}

impl Planner<'_> {
    /// `stretch` (closed, at rest at both ends, no longer than the chord tolerance) crossed in
    /// one period between samples at rest, where the finite differences continuing `check`
    /// allow it (its feed too, the programmed one as the samples' check takes it; the curve
    /// between lies within its length of the chord); the samples, `check` advanced over them.
    pub(super) fn one_step(&self, curves: &PathCurves, stretch: &Stretch, check: &mut Check) -> Option<Vec<PathPoint>> {
        let axes = self.caps.axes;
        let feed = sampler::step_feed(curves, &self.limits, stretch.from.0, stretch.to.0);
        if stretch.open || stretch.length > self.limits.chord_tolerance || stretch.length / self.period > feed {
            return None;
        }
        let (from, to) = (point_at(curves, stretch.from, axes), point_at(curves, stretch.to, axes));
        let mut trial = check.clone();
        let mut points = Vec::with_capacity(2 * SETTLE + 1);
        points.extend(std::iter::repeat_n(from, SETTLE));
        points.extend(std::iter::repeat_n(to, SETTLE + 1));
        for p in &points {
            if trial.push(&p.tip) > 1.0 + 1e-9 {
                return None;
            }
        }
        *check = trial;
        Some(points)
    }
}

/// What a whole stretch came to ([`Planner::plan_resting`]).
pub(super) enum Resting {
    Planned(Box<StretchPlan>),
    /// Crossed in one step: its samples.
    Stepped(Vec<PathPoint>),
}

impl Planner<'_> {
    /// `stretch` planned whole ([`Planner::plan_stretch`]). Where a pass would stand still,
    /// the stretch ends at rest at the curvature peak of the interval there and is planned
    /// again, at most [`MOST_RESTS`] times; a stretch too short to plan is crossed in one step
    /// ([`Planner::one_step`]). `stretch` is left as planned (its end may have moved back to a
    /// rest).
    pub(super) fn plan_resting(
        &self,
        curves: &mut PathCurves,
        stretch: &mut Stretch,
        before: Option<PathPoint>,
        check: &mut Check,
    ) -> Result<Resting, ReachError> {
        for _ in 0..=MOST_RESTS {
            let err = match self.plan_stretch(curves, stretch, before, check) {
                Ok(plan) => return Ok(Resting::Planned(Box::new(plan))),
                Err(e) => e,
            };
            if let Some(points) = self.one_step(curves, stretch, check) {
                return Ok(Resting::Stepped(points));
            }
            let ReachError::Stands { from, to, .. } = &err else {
                return Err(err);
            };
            let inside = |x: (usize, f64), y: (usize, f64)| x.0 < y.0 || (x.0 == y.0 && x.1 < y.1);
            let at = rest_in(curves, *from, *to, self.caps.axes);
            if !inside(stretch.from, at) || !self.rests.borrow_mut().add(at) {
                return Err(err);
            }
            // The stretch read again from its start, up to the new rest.
            let mut again = Stretch {
                to: stretch.from,
                rest_at_end: false,
                length: 0.0,
                open: true,
                ..*stretch
            };
            read_on(curves, &mut again, f64::INFINITY, &self.rests.borrow());
            *stretch = again;
        }
        Err(ReachError::Plan(format!("more than {MOST_RESTS} rests in one stretch")))
    }
}
