//! Path blocks (VPOp, the reachability planner): the plan's per-period positions packed into
//! blocks, the module's stop from every block end run and checked by finite differences
//! ([`choose_block_stops`]), stored stop sequences where its own stop does not pass.

use super::*;

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
    /// Path blocks only: the stop is the planner's own deceleration sequence of this many
    /// positions, stored with the geometry (0: the module's tangential stop).
    pub stored: usize,
}

impl StopChoice {
    /// The module's tangential stop with jerk `fraction` and deceleration `accel_share` of the
    /// tangential limits `(a_max, j_max)`, whose check gave `ratio`.
    fn tangential((fraction, accel_share): (f64, f64), (a_max, j_max): (f64, f64), ratio: f64) -> Self {
        StopChoice {
            fraction,
            accel_share,
            accel: fraction * accel_share * a_max,
            jerk: fraction * j_max,
            ratio,
            stored: 0,
        }
    }
}

/// Stop deceleration and jerk tried at each block end, as fractions of the tangential limits,
/// largest first: 1, 0.85, 0.85^2, ... (30 steps, down to 0.009).
pub fn fractions(max_fraction: f64) -> Vec<f64> {
    (0..30).map(|k| max_fraction * 0.85f64.powi(k)).collect()
}

/// Refuses toolpaths the module cannot run as VPOp plans: it drives the tool tip only, so a
/// path with a tool-axis (top) curve would need the machine's joint kinematics in the module.
pub fn check_tip_path(toolpath: &Toolpath) -> Result<(), String> {
    if toolpath.elements.iter().any(|e| e.curve.dim() > e.curve.tip_dim()) {
        return Err(
            "this is a 5-axis toolpath (tool tip and tool axis): the realtime module drives the \
                    tool tip only, so VPOp plans of 5-axis paths (joint positions of the machine) cannot \
                    run through it; plan 2-/3-axis tool-tip paths"
                .into(),
        );
    }
    Ok(())
}

/// Arc length of path points in the module's measure: per element from its curve start
/// (Gauss-Legendre, the measure of the stop points), except on the element of the anchor (a
/// stop point, or the last sample before a stored stop), where it is shifted so that the
/// anchor's `u` has exactly its `s`, the arc length the module holds there.
pub(super) struct ArcLengths<'a> {
    toolpath: &'a Toolpath,
    /// Each element's table, built when first needed (a 1,000-line G1 program has 2,000).
    tables: Vec<OnceCell<ArcLengthTable>>,
    /// Path length before each element, as far as asked for (summed in path order).
    before: RefCell<Vec<f64>>,
    /// The anchor's element, arc length, and Gauss-Legendre length to its parameter.
    anchor: Option<(usize, f64, f64)>,
    /// Lengths of elements to parameters asked for lately, by element and the parameter's
    /// bits (the newer and the older of two generations of at most `LENGTHS_KEPT` each): the
    /// stored stops of nearby block ends share many points (the same planned positions, often
    /// the same deceleration), and each length is an adaptive quadrature of some hundred curve
    /// evaluations.
    lengths: RefCell<[HashMap<(usize, u64), f64>; 2]>,
}

/// Lengths each generation of [`ArcLengths`]'s memory keeps (some 2 MB).
pub(super) const LENGTHS_KEPT: usize = 1 << 16;

impl<'a> ArcLengths<'a> {
    fn new(toolpath: &'a Toolpath) -> Self {
        ArcLengths {
            toolpath,
            tables: toolpath.elements.iter().map(|_| OnceCell::new()).collect(),
            before: RefCell::new(vec![0.0]),
            anchor: None,
            lengths: RefCell::new([HashMap::new(), HashMap::new()]),
        }
    }

    fn table(&self, e: usize) -> &ArcLengthTable {
        self.tables[e].get_or_init(|| ArcLengthTable::new(&self.toolpath.elements[e].curve))
    }

    /// Path length before element `e`.
    fn before(&self, e: usize) -> f64 {
        let mut before = self.before.borrow_mut();
        while before.len() <= e {
            let k = before.len() - 1;
            let next = before[k] + self.table(k).total();
            before.push(next);
        }
        before[e]
    }

    /// From now on, element `e` is measured so that `u` has arc length `s`.
    fn set_anchor(&mut self, e: usize, u: f64, s: f64) {
        self.anchor = (e < self.tables.len()).then(|| (e, s, self.length_to(e, u)));
    }

    /// Length of element `e` from its start to parameter `u`.
    fn length_to(&self, e: usize, u: f64) -> f64 {
        let key = (e, u.to_bits());
        let mut lengths = self.lengths.borrow_mut();
        if let Some(&length) = lengths[0].get(&key).or_else(|| lengths[1].get(&key)) {
            return length;
        }
        let length = self.table(e).length_to(&self.toolpath.elements[e].curve, u);
        if lengths[0].len() >= LENGTHS_KEPT {
            lengths[1] = std::mem::take(&mut lengths[0]);
        }
        lengths[0].insert(key, length);
        length
    }

    /// Arc length of `p` in the measure of element `e` (negative before it).
    fn s(&self, p: &PathPoint, e: usize) -> f64 {
        let own = self.length_to(p.element, p.u);
        if p.element == e {
            match self.anchor {
                // Exactly the anchor's arc length at its parameter (the difference is 0 there).
                Some((a, s, length)) if a == e => s + (own - length),
                _ => own,
            }
        } else {
            // An earlier element: minus the path length from `p` to the start of `e`.
            (self.before(p.element) + own) - self.before(e)
        }
    }
}

/// Packs the points of a VPOp plan into path blocks: runs of at most [`BLOCK_SAMPLES`] points
/// on one element (a new block at every element change), each with the arc lengths of its
/// points and of the two points before it, the last flagged. `anchor`: the stop point a
/// re-plan starts from (its arc length is kept exactly). Stop limits are left at zero
/// ([`choose_block_stops`] sets them).
pub(super) fn pack_blocks(arcs: &ArcLengths, points: &[PathPoint]) -> Vec<PathBlock> {
    let mut blocks: Vec<PathBlock> = Vec::new();
    let mut i = 0;
    while i < points.len() {
        let e = points[i].element;
        let before = |k: usize| arcs.s(&points[i.saturating_sub(k)], e);
        let mut b = PathBlock {
            seq: blocks.len() as u32,
            curve: e as u32,
            s_before: [before(2), before(1)],
            ..PathBlock::default()
        };
        let mut n = 0;
        while n < BLOCK_SAMPLES && i < points.len() && points[i].element == e {
            b.u[n] = points[i].u;
            b.s[n] = arcs.s(&points[i], e);
            n += 1;
            i += 1;
        }
        b.count = n as u32;
        blocks.push(b);
    }
    if let Some(last) = blocks.last_mut() {
        last.flags |= FLAG_LAST;
    }
    blocks
}

/// A stop sequence chosen after a block: its positions (path points, from the period after
/// `from`) and the choice it makes.
#[derive(Clone, Debug)]
pub struct StoredStop {
    pub from: PathPoint,
    pub points: Vec<PathPoint>,
    pub choice: StopChoice,
}

/// Runs the blocks as the module does (each sample the curve point at its parameter) and, at
/// every block end, VPOp's own deceleration sequence from there ([`brake_points`], after the
/// plan's next positions where the block end's state has none), checked as the module plays
/// it by finite differences continuing the motion; it is stored with the geometry. Where it
/// does not pass (or cannot be stored: the last block), the module's tangential stop
/// ([`block_stop`]) with jerk fractions of the tangential limits there and deceleration shares
/// 1, 1/2, 1/4, 1/10 of each, looking for the largest fraction with a share that stays within
/// the axis limits by finite differences, as [`StopChooser`] does for segment records, then
/// bisecting towards the next larger fraction (the tangential limits hold for the direction at
/// the block end only, so the largest stop that passes is often just below them); that search
/// starts at the fraction that passed at the last block end that had one
/// ([`StopSearch::starting_at`]; the first searches from the largest). Stores the limits in
/// each block (the least violating ones where none passes) and returns the choices.
///
/// The sequence first, because it is the cheaper to find and check: VPOp's plan checks most
/// of its states safe to brake from, with the same sequences. Measured (`cargo bench -p
/// nurbs-planner --features linuxcnc --bench start -- "vpop start"`, lab set 1), the trident's
/// 192 block ends and the butterfly's 848: 0.35 s and 2.0 s with the tangential stop first
/// (128 and 784 stored), against 0.24 s and 1.3 s with the sequence first (all stored; the
/// arena they take, 20 % and 3 % more values, is the price).
pub fn choose_block_stops(
    toolpath: &Toolpath,
    limits: &Limits,
    blocks: &mut [PathBlock],
    stop_points: &[Vec<f64>],
    fractions: &[f64],
    points: &[PathPoint],
) -> (Vec<StopChoice>, Vec<Option<StoredStop>>) {
    let curves = PathCurves::new(toolpath);
    let path = JointPath::tip(toolpath);
    let mut sequences = Vec::with_capacity(blocks.len());
    let mut end = 0;
    let tip = limits.velocity.len();
    let dt = limits.period;
    let mut fd = FiniteDifferences::new(tip, dt);
    let mut choices = Vec::with_capacity(blocks.len());
    // Whether a search has run (the next starts from `last_passed`, the fraction index of the
    // last tangential stop that passed).
    let mut searched = false;
    let mut last_passed = 0;
    let mut brakes = BrakeMemo::default();
    // The module's evaluation of a block's points (see `Interpolator::point_at`).
    let mut spans = SpanCache::new();
    for b in blocks.iter_mut() {
        let view = curves.view(b.curve());
        let curve = &mut CachedCurve::new(view, &mut spans);
        for &u in &b.u[..b.len()] {
            fd.push(&curve.point(u)[..tip], limits);
        }
        end += b.len();
        let curve_points = stop_points.get(b.curve()).map_or(&[][..], Vec::as_slice);
        // Tangential limits at the block end: what the axes allow along the path direction
        // there (each axis limit over its share of the unit tangent; at least the smallest axis
        // limit). The fractions scale them down where the path turns during the stop.
        let (a_max, j_max) = tangential_limits(&curves, limits, b);
        // The module's stop with these limits, checked by finite differences; abandoned as soon
        // as it is worse than `bound` (it cannot be the choice then).
        let simulate = |fraction: f64, accel_share: f64, bound: f64| -> StopChoice {
            let untried = StopChoice::tangential((fraction, accel_share), (a_max, j_max), 0.0);
            let mut trial = *b;
            trial.stop_accel = untried.accel;
            trial.stop_jerk = untried.jerk;
            let (stop, a0) = block_stop(curve_points, &trial, dt);
            let mut interp = Interpolator::new();
            let started = interp.start_profile(&curves, stop, stop.profile().table_from(a0));
            let mut step = || {
                if started {
                    interp.step(&curves, dt, &mut || None)
                } else {
                    Step::Finished
                }
            };
            let ratio = stop_ratio(limits, fd, bound, &mut step);
            StopChoice { ratio, ..untried }
        };
        let mut search = StopSearch {
            simulate: &simulate,
            fractions,
            best: None,
        };
        let point = |i: usize| points.get(i).copied();
        let can_store = !b.is_last() && end >= 1;
        // VPOp's own deceleration first (the plan's states mostly brake at once: one sequence
        // and its check), the module's tangential stop where it does not pass.
        let stored = can_store
            .then(|| {
                let from = (end, points[end - 1], 0);
                stored_stop(&path, &curves, limits, (fd, &point, points.len()), from, &mut brakes)
            })
            .and_then(Result::ok)
            .flatten()
            .filter(|s| s.ratio <= 1.0 + SLACK)
            .map(|s| StoredStop {
                // The block keeps the tangential limits there (the module's stop, were it to
                // need one) and the stored sequence's ratio.
                choice: StopChoice {
                    stored: s.points.len(),
                    ..StopChoice::tangential((1.0, 1.0), (a_max, j_max), s.ratio)
                },
                from: s.from,
                points: s.points,
            });
        let (best, sequence) = match stored {
            Some(stored) => (Some(stored.choice), Some(stored)),
            None => {
                // From the last fraction that passed: 4 ms later the state is nearly the same.
                let found = if searched {
                    search.starting_at(last_passed)
                } else {
                    search.exhaustive()
                };
                searched = true;
                if let Some((k, _)) = found {
                    last_passed = k;
                }
                let best = match found {
                    Some((k, share)) => Some(search.refine(k, share)),
                    None => search.best,
                };
                (best, None)
            }
        };
        sequences.push(sequence);
        if let Some(c) = best {
            b.stop_accel = c.accel;
            b.stop_jerk = c.jerk;
            choices.push(c);
        }
    }
    (choices, sequences)
}

/// Deceleration shares of the module's stop tried at each jerk fraction, largest first (for
/// segment records and path blocks alike).
pub(super) const SHARES: [f64; 4] = [1.0, 0.5, 0.25, 0.1];

/// The search for a block end's stop: `simulate(fraction, share, bound)` checks one (see
/// [`choose_block_stops`]); the least violating stop tried so far is kept.
pub(super) struct StopSearch<'s> {
    simulate: &'s dyn Fn(f64, f64, f64) -> StopChoice,
    fractions: &'s [f64],
    best: Option<StopChoice>,
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
    fn exhaustive(&mut self) -> Option<(usize, usize)> {
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
    fn starting_at(&mut self, warm: usize) -> Option<(usize, usize)> {
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
    fn refine(&mut self, k: usize, share: usize) -> StopChoice {
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

/// [`planned_then_brake`] after the first `end` of the `count` planned positions known
/// (searching from `resume_at`), checked as the module runs it (each position the curve point
/// at its `u`) by finite differences continuing `fd` (the motion up to `from`, the last
/// position before the stop): its positions and worst ratio to an axis limit, `None` where it
/// would step back over an element; `Err` as from [`planned_then_brake`].
pub(super) fn stored_stop(
    path: &JointPath,
    curves: &PathCurves,
    limits: &Limits,
    (fd, point, count): (FiniteDifferences, &dyn Fn(usize) -> Option<PathPoint>, usize),
    (end, from, resume_at): (usize, PathPoint, usize),
    memo: &mut BrakeMemo,
) -> Result<Option<CheckedStop>, usize> {
    let points = planned_then_brake(path, limits, (point, count), (end, resume_at), memo)?;
    // Elements only onwards, one at a time (the module checks each step).
    let onwards = points.iter().try_fold(from.element, |e, p| {
        (p.element == e || p.element == e + 1).then_some(p.element)
    });
    if points.is_empty() || onwards.is_none() {
        return Ok(None);
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
    Ok(Some(CheckedStop {
        from,
        points,
        ratio: f.worst_ratio(limits),
    }))
}

/// A stored stop sequence as [`stored_stop`] checked it.
pub(super) struct CheckedStop {
    from: PathPoint,
    points: Vec<PathPoint>,
    ratio: f64,
}

/// The arena values of the stored stop `points` that follow `from`: a [`StopRun`] per element,
/// each position as `(u, s)` in its element's measure.
pub(super) fn stop_runs(arcs: &ArcLengths, from: PathPoint, points: &[PathPoint]) -> Vec<f64> {
    let mut values = Vec::with_capacity(2 * points.len() + StopRun::VALUES);
    let mut before = from;
    for run in points.chunk_by(|a, b| a.element == b.element) {
        let e = run[0].element;
        let header = StopRun {
            curve: e,
            count: run.len(),
            s_before: arcs.s(&before, e),
        };
        values.extend(header.to_values());
        values.extend(run.iter().flat_map(|p| [p.u, arcs.s(p, e)]));
        before = run[run.len() - 1];
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

/// Per curve, the points the module's stop after a path block must respect: where the VPOp plan
/// itself passes slowest (every local minimum of its feed, as a cap of that feed: the path
/// needs it there, e.g. at a sharp turn) and the curve end, at rest. The stop is compressed to
/// pass them no faster; the simulation check decides whether that stays within the limits.
pub fn block_stop_points(toolpath: &Toolpath, blocks: &[PathBlock], period: f64) -> Vec<Vec<(f64, f64)>> {
    let mut stops: Vec<Vec<(f64, f64)>> = toolpath
        .elements
        .iter()
        .map(|e| vec![(ArcLengthTable::new(&e.curve).total(), 0.0)])
        .collect();
    // (curve, s, feed) of every sample, the feed over the step into it.
    let samples: Vec<(usize, f64, f64)> = blocks
        .iter()
        .flat_map(|b| (0..b.len()).map(move |k| (b.curve(), b.s[k], (b.s[k] - b.s_history(k + 1)) / period)))
        .collect();
    for w in samples.windows(3) {
        let (c, s, f) = w[1];
        if f > 0.0 && f < w[0].2 && f <= w[2].2 {
            if let Some(list) = stops.get_mut(c) {
                list.push((s, f));
            }
        }
    }
    for list in &mut stops {
        list.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    stops
}

/// A VPOp plan ready for the channel: its blocks in groups (a block whose stop the planner
/// could not bring within the limits joins the next block's group), and the arena data their
/// stops need, which the streamer writes before the block goes out and whose offsets it
/// fills in: per block its stored stop sequence ([`StopRun`]s), per curve its stop points.
#[derive(Clone)]
pub struct BlockPlan {
    pub blocks: Vec<PathBlock>,
    /// The stored stop sequence after each block, as arena values (a group's last block only).
    pub stored: Vec<Option<Vec<f64>>>,
    /// Per curve, its stop points as `(s, feed cap)` pairs.
    pub points: Vec<Vec<f64>>,
    /// The stop choice of each block.
    pub choices: Vec<StopChoice>,
    /// Motion time of one block sample (s).
    pub period: f64,
    /// The path's curves, for the geometry stream.
    pub curves: Vec<Nurbs>,
}

impl BlockPlan {
    /// Motion time of block `k`.
    pub fn time(&self, k: usize) -> f64 {
        self.blocks.get(k).map_or(0.0, |b| b.len() as f64 * self.period)
    }

    /// Block ends with a stop within the limits, stored sequences among them, and the worst
    /// ratio of those stops to an axis limit.
    pub fn stops(&self) -> (usize, usize, f64) {
        let ends = self.blocks.iter().filter(|b| b.group_left == 1 && !b.is_last()).count();
        let stored = self.stored.iter().filter(|s| s.is_some()).count();
        let worst = self
            .blocks
            .iter()
            .zip(&self.choices)
            .filter(|(b, _)| b.group_left == 1 && !b.is_last())
            .map(|(_, c)| c.ratio)
            .fold(0.0, f64::max);
        (ends, stored, worst)
    }
}

/// The blocks of a plan of one point per period (`points`, planned within `limits`: VPOp's or
/// the reachability planner's) with their checked stops (jerk fractions up to
/// `max_fraction`), in groups, and the data their stops need. `anchor`: the stop point a
/// re-plan starts from (its arc length is kept exactly).
pub fn block_plan(
    toolpath: &Toolpath,
    (points, limits): (&[PathPoint], &Limits),
    anchor: Option<&StopPoint>,
    max_fraction: f64,
) -> Result<BlockPlan, String> {
    check_tip_path(toolpath)?;
    if !(max_fraction > 0.0 && max_fraction <= 1.0) {
        return Err(format!("stop fraction {max_fraction} must be in (0, 1]"));
    }
    let mut arcs = ArcLengths::new(toolpath);
    if let Some(a) = anchor {
        let start = plan_start(&mut PathCurves::new(toolpath), a);
        arcs.set_anchor(start.curve, start.u, start.s);
    }
    let mut blocks = pack_blocks(&arcs, points);
    let stop_points: Vec<Vec<f64>> = block_stop_points(toolpath, &blocks, limits.period)
        .iter()
        .map(|list| list.iter().flat_map(|&(s, cap)| [s, cap]).collect())
        .collect();
    let (choices, sequences) = choose_block_stops(
        toolpath,
        limits,
        &mut blocks,
        &stop_points,
        &fractions(max_fraction),
        points,
    );
    // From the last block back: a block ends its group where its stop passed (or at the path
    // end); the group's curves reach as far as the stored stop at its end.
    let mut stored = vec![None; blocks.len()];
    let (mut group_left, mut needed) = (0u32, 0u32);
    for (k, (b, sequence)) in blocks.iter_mut().zip(sequences).enumerate().rev() {
        let passes = choices.get(k).is_some_and(|c| c.ratio <= 1.0 + SLACK);
        if passes || b.is_last() {
            group_left = 1;
            needed = b.curve;
            if let Some(seq) = sequence.filter(|_| passes) {
                needed = needed.max(seq.points.last().map_or(0, |p| p.element as u32));
                stored[k] = Some(stop_runs(&arcs, seq.from, &seq.points));
                b.stop_len = seq.points.len() as u32;
            }
        } else {
            group_left += 1;
            needed = needed.max(b.curve);
        }
        b.group_left = group_left;
        b.curve_needed = needed;
    }
    Ok(BlockPlan {
        blocks,
        stored,
        points: stop_points,
        choices,
        period: limits.period,
        curves: toolpath.elements.iter().map(|e| e.curve.clone()).collect(),
    })
}

/// The VPOp plan of `toolpath` (tool tip), from its start or from rest at the stop point `from`.
pub fn vpop_plan(toolpath: &Toolpath, limits: &Limits, from: Option<&StopPoint>) -> Result<VpopPlan, String> {
    check_tip_path(toolpath)?;
    let options = SearchOptions {
        start: from.map(|p| {
            let start = plan_start(&mut PathCurves::new(toolpath), p);
            (start.curve, start.u)
        }),
        ..SearchOptions::default()
    };
    plan_tip(toolpath, limits, options).map_err(|e| match from {
        None => e.to_string(),
        Some(_) => format!("re-plan from the stop point: {e}"),
    })
}

/// The reachability plan of `toolpath` (tool tip), from its start or from rest at the stop
/// point `from`.
pub fn reach_plan(toolpath: &Toolpath, limits: &Limits, from: Option<&StopPoint>) -> Result<ReachPlan, String> {
    check_tip_path(toolpath)?;
    let start = from.map(|p| {
        let start = plan_start(&mut PathCurves::new(toolpath), p);
        (start.curve, start.u)
    });
    reach::plan_tip(toolpath, limits, &ReachOptions::default(), start).map_err(|e| match from {
        None => e.to_string(),
        Some(_) => format!("re-plan from the stop point: {e}"),
    })
}
