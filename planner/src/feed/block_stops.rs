//! The stop after a path block: VPOp's deceleration sequence from the plan's states, stored with
//! the geometry, or the module's tangential stop with the largest limits that pass; each checked
//! by finite differences as the module plays it.

use super::*;

/// Deceleration shares of the module's stop tried at each jerk fraction, largest first (for
/// segment records and path blocks alike).
pub(super) const SHARES: [f64; 4] = [1.0, 0.5, 0.25, 0.1];

/// The search for a block end's stop: `simulate(fraction, share, bound)` checks one (see
/// [`BlockBuilder`]); the least violating stop tried so far is kept.
pub(super) struct StopSearch<'s> {
    pub(super) simulate: &'s dyn Fn(f64, f64, f64) -> StopChoice,
    pub(super) fractions: &'s [f64],
    pub(super) best: Option<StopChoice>,
}

impl StopSearch<'_> {
    /// Whether the stop with `fractions[k]` and `SHARES[share]` stays within the limits.
    fn passes(&mut self, k: usize, share: usize) -> bool {
        let bound = self.best.map_or(f64::INFINITY, |c| c.ratio.max(1.0 + SLACK));
        let c = (self.simulate)(self.fractions[k], SHARES[share], bound);
        if self.best.is_none_or(|b| c.ratio < b.ratio) {
            self.best = Some(c);
        }
        c.ratio <= 1.0 + SLACK
    }

    /// The first (fraction, share) that passes, largest fraction first, then largest share,
    /// trying each in turn.
    pub(super) fn exhaustive(&mut self) -> Option<(usize, usize)> {
        (0..self.fractions.len()).find_map(|k| self.first_share(k).map(|share| (k, share)))
    }

    /// The largest share that passes with `fractions[k]` (a gentler deceleration is a longer
    /// stop, which can reach a tighter bend: it may fail where a steeper one passes).
    fn first_share(&mut self, k: usize) -> Option<usize> {
        (0..SHARES.len()).find(|&share| self.passes(k, share))
    }

    /// The (fraction, share) of [`Self::exhaustive`], searched from fraction index `warm`, taking a
    /// fraction that passes to pass at every smaller one too: upwards from `warm` while the
    /// fractions pass, else downwards from it, and only if none passes there, the larger ones.
    pub(super) fn starting_at(&mut self, warm: usize) -> Option<(usize, usize)> {
        let warm = warm.min(self.fractions.len() - 1);
        if let Some(share) = self.first_share(warm) {
            let mut found = (warm, share);
            for k in (0..warm).rev() {
                match self.first_share(k) {
                    Some(share) => found = (k, share),
                    None => break,
                }
            }
            return Some(found);
        }
        let n = self.fractions.len();
        (warm + 1..n)
            .chain(0..warm)
            .find_map(|k| self.first_share(k).map(|share| (k, share)))
    }

    /// The stop of fraction index `k` and `share`, which passes, refined towards the next
    /// larger fraction (bisection, 5 steps: the tangential limits hold for the direction at
    /// the block end only, so the largest stop that passes is often just below them).
    pub(super) fn refine(&mut self, k: usize, share: usize) -> StopChoice {
        let mut good = (self.simulate)(self.fractions[k], SHARES[share], 1.0 + SLACK);
        if k > 0 {
            let mut bad = self.fractions[k - 1];
            for _ in 0..5 {
                let mid = 0.5 * (good.fraction + bad);
                let c = (self.simulate)(mid, SHARES[share], 1.0 + SLACK);
                if c.ratio <= 1.0 + SLACK {
                    good = c;
                } else {
                    bad = mid;
                }
            }
        }
        good
    }
}

/// The stop after the first `end` of the planned positions `point(0..count)` (VPOp's, or the
/// interpolator's samples of segment records): VPOp's deceleration sequence from there, or,
/// where that does not reach rest (VPOp checks its deceleration only where it has to, so not
/// every planned state has one), the plan's own next positions up to the first state whose
/// deceleration sequence does. Every step is a planned or a braking step, so all pass VPOp's
/// constraints; the sequence may cross element joins (only onwards). The search for that state
/// starts at position `resume_at` (or at the stop's start); `Err(resume_at)` if the `count`
/// positions known end first (call again from there with more, or the plan ends there).
pub(super) fn planned_then_brake(
    path: &JointPath,
    limits: &Limits,
    (point, count): (&dyn Fn(usize) -> Option<PathPoint>, usize),
    (end, resume_at): (usize, usize),
    memo: &mut BrakeMemo,
) -> Result<Vec<PathPoint>, usize> {
    // The deceleration is chosen within the limits themselves, as VPOp's plan is: the module
    // plays its positions from its own (de Boor) evaluation of the curve, which differs from
    // VPOp's power basis by rounding, and the check of the played positions allows that
    // ([`SLACK`]). A margin inside the limits would make the plan's own states, which ride
    // them, unsafe to brake from: with 1e-5 the search walked on along the plan for a state
    // that brakes, and the stops took 2.5 times as long to find.
    let first = resume_at.max(end.max(1) - 1);
    let mut i = first;
    while i < count.saturating_sub(1) {
        // What an earlier search (from an earlier end) found out about position i.
        if memo.failed.contains(&i) {
            i = memo.failed.end;
            continue;
        }
        let brake = match &memo.found {
            Some((at, brake)) if *at == i => Some(brake.clone()),
            _ => {
                let last = [point(i.saturating_sub(2)), point(i.saturating_sub(1)), point(i)];
                match last {
                    [Some(a), Some(b), Some(c)] => brake_points(path, limits, SearchOptions::default(), [a, b, c])
                        .ok()
                        .flatten(),
                    _ => None,
                }
            }
        };
        if let Some(brake) = brake {
            let Some(planned) = (end..=i).map(point).collect::<Option<Vec<PathPoint>>>() else {
                // Not a failure of position i: nothing to remember from this search.
                return Err(first.max(count.saturating_sub(1)));
            };
            memo.remember(first..i, Some((i, brake.clone())));
            return Ok(planned.into_iter().chain(brake).collect());
        }
        i += 1;
    }
    memo.remember(first..i.max(first), None);
    Err(first.max(count.saturating_sub(1)))
}

/// What the searches of [`planned_then_brake`] found out, kept for the next one (the block or
/// record ends come in path order, 4 ms apart, and a search from one end often runs past the
/// next): the positions in `failed` have no deceleration to rest, `found` has one. The results
/// are the same as without it (each position's deceleration depends on it alone).
#[derive(Default)]
pub(super) struct BrakeMemo {
    failed: std::ops::Range<usize>,
    found: Option<(usize, Vec<PathPoint>)>,
}

impl BrakeMemo {
    /// A search tried `failed` in vain (positions where no deceleration was tried count too:
    /// they are missing or not on the path) and ended at `found`, if anywhere.
    fn remember(&mut self, failed: std::ops::Range<usize>, found: Option<(usize, Vec<PathPoint>)>) {
        // Join the failures when the new run starts inside or right after the old one.
        self.failed = if self.failed.contains(&failed.start) || self.failed.end == failed.start {
            self.failed.start..self.failed.end.max(failed.end)
        } else {
            failed
        };
        if found.is_some() {
            self.found = found;
        }
    }
}

/// The stop sequence `points` (from [`planned_then_brake`]) after `from`, the last position
/// before it, checked as the module runs it (each position the curve point at its `u`) by
/// finite differences continuing `fd` (the motion up to `from`): its positions and worst ratio
/// to an axis limit, `None` where it would step back over an element. `curves` holds every
/// element the sequence reaches.
pub(super) fn check_stored(
    curves: &PathCurves,
    limits: &Limits,
    fd: FiniteDifferences,
    from: PathPoint,
    points: Vec<PathPoint>,
) -> Option<CheckedStop> {
    // Elements only onwards, one at a time (the module checks each step).
    let onwards = points.iter().try_fold(from.element, |e, p| {
        (p.element == e || p.element == e + 1).then_some(p.element)
    });
    if points.is_empty() || onwards.is_none() {
        return None;
    }
    let tip = limits.velocity.len();
    let mut f = fd;
    f.reset_peaks();
    let mut spans = SpanCache::new();
    for p in &points {
        let point = CachedCurve::new(curves.view(p.element), &mut spans).point(p.u);
        f.push(&point[..tip], limits);
    }
    f.finish(limits);
    Some(CheckedStop {
        from,
        points,
        ratio: f.worst_ratio(limits),
    })
}

/// A stored stop sequence as [`check_stored`] checked it.
pub(super) struct CheckedStop {
    pub(super) from: PathPoint,
    pub(super) points: Vec<PathPoint>,
    pub(super) ratio: f64,
}

/// The arena values of the stored stop `points` that follow `from`: a [`StopRun`] per element,
/// each position as `(u, s)` in its element's measure. The arc length of a run's first step
/// is exact (from the curve's start), each later step adds its chord, which the module checks
/// against it (a chord within 1e-9 of its step, and an arc of one period differs from its
/// chord by far less; exact lengths cost an adaptive quadrature per position).
pub(super) fn stop_runs(arcs: &ArcLengths, curves: &PathCurves, from: PathPoint, points: &[PathPoint]) -> Vec<f64> {
    let tip = curves.tip_dim();
    let mut spans = SpanCache::new();
    let mut position = |p: &PathPoint| CachedCurve::new(curves.view(p.element), &mut spans).point(p.u);
    let mut values = Vec::with_capacity(2 * points.len() + StopRun::VALUES);
    let mut before = (from, position(&from));
    for run in points.chunk_by(|a, b| a.element == b.element) {
        let e = run[0].element;
        let mut s = arcs.s(curves, &before.0, e);
        values.extend(
            StopRun {
                curve: e,
                count: run.len(),
                s_before: s,
            }
            .to_values(),
        );
        for p in run {
            let here = position(p);
            s += (0..tip).map(|i| (here[i] - before.1[i]).powi(2)).sum::<f64>().sqrt();
            values.extend([p.u, s]);
            before = (*p, here);
        }
    }
    values
}

/// Worst ratio to an axis limit of a stop whose samples `step` yields, by finite differences
/// continuing `fd` (the motion before it) and at rest after it; abandoned (a value above
/// `bound`) as soon as it is worse than `bound`, as it cannot be the choice then.
pub(super) fn stop_ratio(limits: &Limits, fd: FiniteDifferences, bound: f64, step: &mut dyn FnMut() -> Step) -> f64 {
    let tip = limits.velocity.len();
    let mut f = fd;
    f.reset_peaks();
    while let Step::Sample(s) = step() {
        f.push(&s.point[..tip], limits);
        let ratio = f.worst_ratio(limits);
        if ratio > bound {
            return ratio;
        }
    }
    f.finish(limits);
    f.worst_ratio(limits)
}

/// Tangential deceleration and jerk the axes allow at the end of `b`: min over the axes of the
/// limit over the axis' share of the unit tangent.
pub(super) fn tangential_limits(curves: &PathCurves, limits: &Limits, b: &PathBlock) -> (f64, f64) {
    crate::hold_stops::tangential_limits(curves, limits, b.curve(), b.u[b.len().saturating_sub(1)])
}
