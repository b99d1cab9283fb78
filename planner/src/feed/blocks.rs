//! Path blocks (VPOp, the reachability planner): the plan's per-period positions packed into
//! blocks as the plan hands them over, the stop from every block end chosen and checked by
//! finite differences ([`BlockBuilder`], with [`super::block_stops`]), the blocks in groups that
//! end at a checked stop; a whole plan's groups ([`block_plan`]) or a streamed one's
//! ([`spawn_reach_blocks`]).

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

/// Refuses 5-axis toolpaths (a tool-axis curve beside the tip's): the module drives the tool
/// tip's joints only, and running the tip alone would leave the rotary axes standing.
pub fn check_tip_path(toolpath: &Toolpath) -> Result<(), String> {
    if toolpath.elements.iter().any(|e| e.curve.dim() > e.curve.tip_dim()) {
        return Err(TIP_ONLY.into());
    }
    Ok(())
}

/// Why a 5-axis path is refused on the machine.
const TIP_ONLY: &str = "this is a 5-axis toolpath (tool tip and tool axis): the realtime module drives the \
     tool tip's joints only, so it would run the tip with the rotary axes standing still; 5-axis paths are \
     planned offline only (`nurbs-plan plan --planner vpop --machine ...`), here plan 2-/3-axis tool-tip paths";

/// Arc length of path points in the module's measure: per element from its curve start
/// (Gauss-Legendre, the measure of the stop points), except on the element of the anchor (a
/// stop point a re-plan starts from), where it is shifted so that the anchor's `u` has exactly
/// its `s`, the arc length the module holds there. The elements come from the `PathCurves`
/// each call is given (read as far as the points asked about); what lies behind
/// [`Self::forget_before`] is dropped.
pub(super) struct ArcLengths {
    /// Each element's table, built when first needed.
    tables: RefCell<BTreeMap<usize, ArcLengthTable>>,
    /// The first element measured, and the path length from its start to the start of each
    /// element from there on, as far as asked for (summed in path order; only differences are
    /// used).
    before: RefCell<(usize, Vec<f64>)>,
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

impl ArcLengths {
    /// Measures from element `first` on.
    fn new(first: usize) -> Self {
        ArcLengths {
            tables: RefCell::new(BTreeMap::new()),
            before: RefCell::new((first, vec![0.0])),
            anchor: None,
            lengths: RefCell::new([HashMap::new(), HashMap::new()]),
        }
    }

    fn with_table<R>(&self, curves: &PathCurves, e: usize, f: impl FnOnce(&ArcLengthTable, &Nurbs) -> R) -> R {
        let curve = &curves.element(e).curve;
        let mut tables = self.tables.borrow_mut();
        f(tables.entry(e).or_insert_with(|| ArcLengthTable::new(curve)), curve)
    }

    /// Length of element `e`.
    pub(super) fn total(&self, curves: &PathCurves, e: usize) -> f64 {
        self.with_table(curves, e, |t, _| t.total())
    }

    /// Path length before element `e` (from the first element measured).
    fn before(&self, curves: &PathCurves, e: usize) -> f64 {
        let mut before = self.before.borrow_mut();
        let first = before.0;
        let k = e.saturating_sub(first);
        while before.1.len() <= k {
            let last = before.1.len() - 1;
            let next = before.1[last] + self.total(curves, first + last);
            before.1.push(next);
        }
        before.1[k]
    }

    /// From now on, element `e` is measured so that `u` has arc length `s`.
    fn set_anchor(&mut self, curves: &PathCurves, e: usize, u: f64, s: f64) {
        self.anchor = Some((e, s, self.length_to(curves, e, u)));
    }

    /// Length of element `e` from its start to parameter `u`.
    fn length_to(&self, curves: &PathCurves, e: usize, u: f64) -> f64 {
        let key = (e, u.to_bits());
        let known = {
            let lengths = self.lengths.borrow();
            lengths[0].get(&key).or_else(|| lengths[1].get(&key)).copied()
        };
        if let Some(length) = known {
            return length;
        }
        let length = self.with_table(curves, e, |table, curve| table.length_to(curve, u));
        let mut lengths = self.lengths.borrow_mut();
        if lengths[0].len() >= LENGTHS_KEPT {
            lengths[1] = std::mem::take(&mut lengths[0]);
        }
        lengths[0].insert(key, length);
        length
    }

    /// Arc length of `p` in the measure of element `e` (negative before it).
    pub(super) fn s(&self, curves: &PathCurves, p: &PathPoint, e: usize) -> f64 {
        let own = self.length_to(curves, p.element, p.u);
        if p.element == e {
            match self.anchor {
                // Exactly the anchor's arc length at its parameter (the difference is 0 there).
                Some((a, s, length)) if a == e => s + (own - length),
                _ => own,
            }
        } else {
            // An earlier element: minus the path length from `p` to the start of `e`.
            (self.before(curves, p.element) + own) - self.before(curves, e)
        }
    }

    /// Forgets the tables of the elements before `e` (no point before it is asked about again).
    fn forget_before(&self, e: usize) {
        let mut tables = self.tables.borrow_mut();
        *tables = tables.split_off(&e);
        let mut before = self.before.borrow_mut();
        let drop = e.saturating_sub(before.0).min(before.1.len() - 1);
        if drop > 0 {
            before.1.drain(..drop);
            before.0 += drop;
        }
    }
}

/// A stop sequence chosen after a block: its positions (path points, from the period after
/// `from`) and the choice it makes.
#[derive(Clone, Debug)]
pub struct StoredStop {
    pub from: PathPoint,
    pub points: Vec<PathPoint>,
    pub choice: StopChoice,
}

/// Path blocks that go into the ring together: the module takes them only whole and stops
/// only after the last, with the stop the planner checked there; with the arena data that
/// stop needs, and the curves the group is the first to need.
#[derive(Clone, Debug)]
pub struct BlockGroup {
    /// Group fields and stop limits set; the last block's arena offsets are the streamer's to
    /// fill in.
    pub blocks: Vec<PathBlock>,
    /// The stop choice after each block (only the last one's is a stop the module runs).
    pub choices: Vec<StopChoice>,
    /// The stop after the last block: the planner's stored deceleration as arena values
    /// ([`StopRun`]s), or `None`: the module's tangential stop.
    pub stored: Option<Vec<f64>>,
    /// The stop points that tangential stop respects: `(s, feed cap)` pairs on the last block's
    /// curve ahead of it (every feed minimum of the plan known there, and the curve end at rest).
    pub points: Vec<f64>,
    /// The curves this group is the first to need, from curve `first_curve` on.
    pub curves: Vec<Nurbs>,
    pub first_curve: u32,
    /// Motion time (s).
    pub time: f64,
}

/// What a streamed block plan's thread hands out.
pub type BlockEvent = PlanEvent<BlockGroup>;

/// Turns a plan of one point per period (VPOp's or the reachability planner's), handed over
/// as it is planned, into path blocks in groups, each group ending where the module's stop is
/// checked within the limits.
///
/// Blocks are runs of at most [`BLOCK_SAMPLES`] points on one element (a new block at every
/// element change), each with the arc lengths of its points and of the two points before it;
/// the path's last is flagged. At every block end, VPOp's own deceleration sequence from there
/// ([`brake_points`], after the plan's next positions where the block end's state has none)
/// is checked as the module plays it, by finite differences continuing the motion; it is
/// stored with the geometry. Where it does not pass (or cannot be stored: the last block), the
/// module's tangential stop ([`block_stop`]) with jerk fractions of the tangential limits there
/// and deceleration shares 1, 1/2, 1/4, 1/10 of each, looking for the largest fraction with a
/// share that stays within the axis limits by finite differences, then bisecting towards the
/// next larger fraction (the tangential limits hold for the direction at the block end only,
/// so the largest stop that passes is often just below them); that search starts at the
/// fraction that passed at the last block end that had one ([`StopSearch::starting_at`]; the
/// first searches from the largest). A block whose stop passes ends its group; one whose stop
/// does not joins the next block's group (keeping the least violating limits tried).
///
/// The sequence first, because it is the cheaper to find and check: VPOp's plan checks most
/// of its states safe to brake from, with the same sequences. Measured (`cargo bench -p
/// nurbs-planner --features linuxcnc --bench start -- "vpop start"`, lab set 1), the trident's
/// 192 block ends and the butterfly's 848: 0.35 s and 2.0 s with the tangential stop first
/// (128 and 784 stored), against 0.24 s and 1.3 s with the sequence first (all stored; the
/// arena they take, 20 % and 3 % more values, is the price).
///
/// A plan that offers stops of its own ([`Self::offer_stop`]: the reachability planner's, the
/// quickest stop its controllable sets allow from a station's state) needs no deceleration
/// search: a block ends where an offered stop branches off inside it, and its stored stop is
/// the plan's positions to the first offered stop at or after its end, then that stop, checked
/// the same way; the tangential stop where it does not pass.
///
/// The tangential stop respects the plan's feed minima ahead on the block's curve (a cap of
/// that feed: the path needs it there, e.g. at a sharp turn) and the curve end, at rest: those
/// known when the block is decided. A block is decided once the points after it settle its
/// stored stop, so a plan handed over whole ([`block_plan`]) knows them all, and a streamed one
/// those planned so far (the check decides with exactly the list the module gets).
pub struct BlockBuilder {
    limits: Limits,
    fractions: Vec<f64>,
    /// The path as the module evaluates it, and as VPOp's deceleration search does.
    curves: PathCurves,
    path: JointPath,
    arcs: ArcLengths,
    /// Points received and still needed, the first being point number `base`.
    points: VecDeque<PathPoint>,
    base: usize,
    /// The plan has handed over its last point.
    ended: bool,
    /// The first point not yet in a decided block.
    packed: usize,
    seq: u32,
    /// Finite differences of the motion through the last decided block.
    fd: FiniteDifferences,
    /// Whether a tangential search has run, and the fraction index of the last that passed.
    searched: bool,
    last_passed: usize,
    brakes: BrakeMemo,
    /// Stops the plan offers (the reachability planner's, from its controllable sets), by the
    /// number of the point they follow: where it offers them, they replace VPOp's deceleration
    /// search, and blocks end where they branch off.
    offered: BTreeMap<usize, Vec<PathPoint>>,
    offers: bool,
    /// Per curve, the plan's feed minima `(s, feed)` found so far, and the last two points'
    /// `(curve, s, feed)` (the feed over the step into each).
    minima: BTreeMap<usize, Vec<(f64, f64)>>,
    recent: [Option<(usize, f64, f64)>; 2],
    /// The undecided group's blocks so far.
    group: Vec<(PathBlock, StopChoice)>,
    /// The next curve to hand out with a group.
    next_curve: usize,
    /// Block ends with a stop within the limits, stored sequences among them, and the worst
    /// ratio of those stops to an axis limit.
    pub ends: usize,
    pub stored: usize,
    pub worst: f64,
}

impl BlockBuilder {
    /// Blocks of a plan along `curves` (`path` reads the same elements) within `limits`, with
    /// stop jerk fractions up to `max_fraction`; from the path start, or from rest at `anchor`
    /// (a stop point: its arc length is kept exactly).
    pub fn new(
        mut curves: PathCurves,
        path: JointPath,
        limits: &Limits,
        anchor: Option<&StopPoint>,
        max_fraction: f64,
    ) -> Result<Self, String> {
        if !(max_fraction > 0.0 && max_fraction <= 1.0) {
            return Err(format!("stop fraction {max_fraction} must be in (0, 1]"));
        }
        let limits = limits.for_axes(curves.tip_dim()).map_err(|e| e.to_string())?;
        let first = match anchor {
            Some(a) => plan_start(&mut curves, a).curve,
            None => curves.first(),
        };
        if !curves.load(first) {
            return Err(format!("no path element {first} to plan from"));
        }
        let mut arcs = ArcLengths::new(first);
        if let Some(a) = anchor {
            let start = plan_start(&mut curves, a);
            arcs.set_anchor(&curves, start.curve, start.u, start.s);
        }
        let tip = limits.velocity.len();
        Ok(BlockBuilder {
            fd: FiniteDifferences::new(tip, limits.period),
            fractions: fractions(max_fraction),
            limits,
            curves,
            path,
            arcs,
            points: VecDeque::new(),
            base: 0,
            ended: false,
            packed: 0,
            seq: 0,
            searched: false,
            last_passed: 0,
            brakes: BrakeMemo::default(),
            offered: BTreeMap::new(),
            offers: false,
            minima: BTreeMap::new(),
            recent: [None, None],
            group: Vec::new(),
            next_curve: first,
            ends: 0,
            stored: 0,
            worst: 0.0,
        })
    }

    /// The limits as used (for the path's axes).
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Points received so far.
    fn received(&self) -> usize {
        self.base + self.points.len()
    }

    fn point(&self, i: usize) -> Option<PathPoint> {
        i.checked_sub(self.base).and_then(|k| self.points.get(k)).copied()
    }

    /// Takes the plan's next point.
    pub fn push(&mut self, p: PathPoint) -> Result<(), String> {
        if !self.curves.load(p.element) {
            return Err(format!(
                "a planned point on path element {}, beyond the path",
                p.element
            ));
        }
        let curve = &self.curves.element(p.element).curve;
        if curve.dim() > curve.tip_dim() {
            return Err(TIP_ONLY.into());
        }
        // The feed over the step into it, and whether the point before was a feed minimum.
        let e = p.element;
        let s = self.arcs.s(&self.curves, &p, e);
        let before = self.points.back().map_or(s, |q| self.arcs.s(&self.curves, q, e));
        let feed = (s - before) / self.limits.period;
        if let [Some(a), Some((c, s1, f1))] = self.recent {
            if f1 > 0.0 && f1 < a.2 && f1 <= feed {
                self.minima.entry(c).or_default().push((s1, f1));
            }
        }
        self.recent = [self.recent[1], Some((e, s, feed))];
        self.points.push_back(p);
        Ok(())
    }

    /// The plan offers its own stops ([`Self::offer_stop`]): only they and the module's
    /// tangential stop are tried, never VPOp's deceleration search.
    pub fn expect_offered_stops(&mut self) {
        self.offers = true;
    }

    /// Takes a stop the plan offers after the last point pushed (its positions from the next
    /// period on, to rest).
    pub fn offer_stop(&mut self, points: &[PathPoint]) {
        if let Some(last) = self.received().checked_sub(1) {
            self.offered.insert(last, points.to_vec());
        }
    }

    /// The stop after position `end - 1` from the offered ones: the plan's positions from `end`
    /// to the first that has an offered stop, then that stop. `Err` where none is known yet.
    fn planned_then_offered(&self, end: usize) -> Result<Vec<PathPoint>, ()> {
        let (&i, stop) = self.offered.range(end.saturating_sub(1)..).next().ok_or(())?;
        let planned = (end..=i).map(|k| self.point(k)).collect::<Option<Vec<_>>>().ok_or(())?;
        Ok(planned.into_iter().chain(stop.iter().copied()).collect())
    }

    /// Decides the blocks the points received settle, handing each group out as it closes
    /// (`out` returns false when nobody takes them any more: then false).
    pub fn advance(&mut self, out: &mut dyn FnMut(BlockGroup) -> bool) -> bool {
        while let Some(decided) = self.decide_next() {
            if let Some(group) = decided {
                if !out(group) {
                    return false;
                }
            }
        }
        true
    }

    /// The plan has ended: decides the rest.
    pub fn finish(&mut self, out: &mut dyn FnMut(BlockGroup) -> bool) -> bool {
        self.ended = true;
        self.advance(out)
    }

    /// Decides the next block, if the points received settle it: `Some(Some(group))` where
    /// it closes a group.
    fn decide_next(&mut self) -> Option<Option<BlockGroup>> {
        let start = self.packed;
        let e = self.point(start)?.element;
        // The block: up to BLOCK_SAMPLES points on element e, complete once a point after it
        // is known (or the plan has ended).
        let mut end = start;
        while end < self.received() && end - start < BLOCK_SAMPLES && self.point(end)?.element == e {
            end += 1;
        }
        // An offered stop inside the block ends it there.
        if let Some((&i, _)) = self.offered.range(start..end.saturating_sub(1)).next_back() {
            end = i + 1;
        }
        let last = self.ended && end == self.received();
        if !(last || end < self.received()) {
            return None;
        }
        let mut b = PathBlock {
            seq: self.seq,
            curve: e as u32,
            count: (end - start) as u32,
            ..PathBlock::default()
        };
        let at = |k: usize| self.point(k).map(|q| self.arcs.s(&self.curves, &q, e));
        b.s_before = [at(start.saturating_sub(2))?, at(start.saturating_sub(1))?];
        for (n, k) in (start..end).enumerate() {
            b.u[n] = self.point(k)?.u;
            b.s[n] = at(k)?;
        }
        if last {
            b.flags |= FLAG_LAST;
        }
        let mut fd = self.fd;
        let mut spans = SpanCache::new();
        {
            let curve = &mut CachedCurve::new(self.curves.view(e), &mut spans);
            let tip = self.limits.velocity.len();
            for &u in &b.u[..b.len()] {
                fd.push(&curve.point(u)[..tip], &self.limits);
            }
        }
        let (a_max, j_max) = tangential_limits(&self.curves, &self.limits, &b);
        let points = self.stop_points(e, b.s[b.len() - 1]);
        // VPOp's own deceleration first (VPOp's own plan's states mostly brake at once; from the
        // reachability planner's, it walks on along the plan some 8 positions), the module's
        // tangential stop where it does not pass.
        let from = self.point(end - 1)?;
        let sequence = if last {
            None
        } else if self.offers {
            match self.planned_then_offered(end) {
                Ok(points) => Some(points),
                Err(()) if !self.ended => return None, // wait for more of the plan
                Err(()) => None,
            }
        } else {
            let count = self.received();
            let (points, base) = (&self.points, self.base);
            let point = |i: usize| i.checked_sub(base).and_then(|k| points.get(k)).copied();
            match planned_then_brake(&self.path, &self.limits, (&point, count), (end, 0), &mut self.brakes) {
                Ok(points) => Some(points),
                Err(_) if !self.ended => return None, // wait for more of the plan
                Err(_) => None,
            }
        };
        let stored = sequence.and_then(|points| {
            let reach = points.iter().map(|p| p.element).max().unwrap_or(e);
            (self.curves.load(reach)).then_some(())?;
            check_stored(&self.curves, &self.limits, fd, from, points)
        });
        let stored = stored.filter(|s| s.ratio <= 1.0 + SLACK).map(|s| StoredStop {
            // The block keeps the tangential limits there (the module's stop, were it to
            // need one) and the stored sequence's ratio.
            choice: StopChoice {
                stored: s.points.len(),
                ..StopChoice::tangential((1.0, 1.0), (a_max, j_max), s.ratio)
            },
            from: s.from,
            points: s.points,
        });
        let choice = match &stored {
            Some(s) => s.choice,
            None => self.tangential_stop(&b, &points, fd, (a_max, j_max)),
        };
        b.stop_accel = choice.accel;
        b.stop_jerk = choice.jerk;
        // Decided: the block joins the group.
        self.fd = fd;
        self.packed = end;
        self.seq += 1;
        self.group.push((b, choice));
        let passes = choice.ratio <= 1.0 + SLACK;
        let group = (passes || last).then(|| self.close_group(stored, points));
        self.forget_behind();
        Some(group)
    }

    /// The stop points a tangential stop after a block on curve `e` ending at arc length `s0`
    /// respects, as `(s, cap)` pairs: the feed minima known ahead, and the curve end at rest.
    fn stop_points(&self, e: usize, s0: f64) -> Vec<f64> {
        let ahead = self.minima.get(&e).into_iter().flatten().filter(|(s, _)| *s > s0);
        let end = (self.arcs.total(&self.curves, e), 0.0);
        ahead
            .chain(std::iter::once(&end))
            .flat_map(|&(s, cap)| [s, cap])
            .collect()
    }

    /// The module's tangential stop after `b`, the largest that passes (see [`BlockBuilder`]),
    /// else the least violating one tried.
    fn tangential_stop(
        &mut self,
        b: &PathBlock,
        points: &[f64],
        fd: FiniteDifferences,
        (a_max, j_max): (f64, f64),
    ) -> StopChoice {
        let (curves, limits, dt) = (&self.curves, &self.limits, self.limits.period);
        // The module's stop with these limits, checked by finite differences; abandoned as soon
        // as it is worse than `bound` (it cannot be the choice then).
        let simulate = |fraction: f64, accel_share: f64, bound: f64| -> StopChoice {
            let untried = StopChoice::tangential((fraction, accel_share), (a_max, j_max), 0.0);
            let mut trial = *b;
            trial.stop_accel = untried.accel;
            trial.stop_jerk = untried.jerk;
            let (stop, a0) = block_stop(points, &trial, dt);
            let mut interp = Interpolator::new();
            let started = interp.start_profile(curves, stop, stop.profile().table_from(a0));
            let mut step = || {
                if started {
                    interp.step(curves, dt, &mut || None)
                } else {
                    Step::Finished
                }
            };
            let ratio = stop_ratio(limits, fd, bound, &mut step);
            StopChoice { ratio, ..untried }
        };
        let mut search = StopSearch {
            simulate: &simulate,
            fractions: &self.fractions,
            best: None,
        };
        // From the last fraction that passed: 4 ms later the state is nearly the same.
        let found = if self.searched {
            search.starting_at(self.last_passed)
        } else {
            search.exhaustive()
        };
        let best = match found {
            Some((k, share)) => Some(search.refine(k, share)),
            None => search.best,
        };
        self.searched = true;
        if let Some((k, _)) = found {
            self.last_passed = k;
        }
        // `simulate` always gives a choice; the first fraction tried is the fallback.
        best.unwrap_or_else(|| StopChoice::tangential((self.fractions[0], 1.0), (a_max, j_max), f64::INFINITY))
    }

    /// Closes the group with its last block's stop: `stored` (the planner's sequence) or the
    /// tangential one with stop `points`.
    fn close_group(&mut self, stored: Option<StoredStop>, points: Vec<f64>) -> BlockGroup {
        let mut group = std::mem::take(&mut self.group);
        let n = group.len();
        let (last, choice) = group[n - 1];
        let mut needed = last.curve();
        let values = stored.map(|s| {
            needed = needed.max(s.points.iter().map(|p| p.element).max().unwrap_or(needed));
            group[n - 1].0.stop_len = s.points.len() as u32;
            stop_runs(&self.arcs, &self.curves, s.from, &s.points)
        });
        if choice.ratio <= 1.0 + SLACK && !last.is_last() {
            self.ends += 1;
            self.stored += usize::from(values.is_some());
            self.worst = self.worst.max(choice.ratio);
        }
        for (k, (b, _)) in group.iter_mut().enumerate() {
            b.group_left = (n - k) as u32;
            b.curve_needed = needed as u32;
        }
        let first_curve = self.next_curve;
        let curves = (first_curve..=needed)
            .map(|c| self.curves.element(c).curve.clone())
            .collect();
        self.next_curve = self.next_curve.max(needed + 1);
        let samples: usize = group.iter().map(|(b, _)| b.len()).sum();
        // A stored stop needs no stop points.
        let points = if values.is_some() { Vec::new() } else { points };
        BlockGroup {
            time: samples as f64 * self.limits.period,
            choices: group.iter().map(|(_, c)| *c).collect(),
            blocks: group.into_iter().map(|(b, _)| b).collect(),
            stored: values,
            points,
            curves,
            first_curve: first_curve as u32,
        }
    }

    /// Forgets the points, minima and elements no later block can ask about: a block needs the
    /// two points before it, a stored stop's search the three before its block's end.
    fn forget_behind(&mut self) {
        self.offered = self.offered.split_off(&self.packed);
        let keep = self.packed.saturating_sub(3);
        while self.base < keep && self.points.pop_front().is_some() {
            self.base += 1;
        }
        let Some(oldest) = self.points.front().map(|p| p.element) else {
            return;
        };
        let e = oldest.min(self.next_curve);
        self.minima = self.minima.split_off(&e);
        self.arcs.forget_before(e);
        self.curves.release_before(e);
        self.path.release_before(e as f64);
    }
}

/// A whole plan's blocks in groups ([`block_plan`]).
#[derive(Clone)]
pub struct BlockPlan {
    pub groups: Vec<BlockGroup>,
    /// Motion time of one block sample (s).
    pub period: f64,
    pub stops: StopCounts,
}

/// Block ends with a stop within the limits, stored sequences among them, and the worst ratio
/// of those stops to an axis limit.
pub type StopCounts = (usize, usize, f64);

impl BlockPlan {
    /// The blocks in path order.
    pub fn blocks(&self) -> impl Iterator<Item = &PathBlock> {
        self.groups.iter().flat_map(|g| &g.blocks)
    }

    /// Motion time (s).
    pub fn time(&self) -> f64 {
        self.groups.iter().map(|g| g.time).sum()
    }
}

/// The blocks of a whole plan of one point per period (`points`, planned within `limits`:
/// VPOp's or the reachability planner's) of `toolpath` with their checked stops (jerk fractions
/// up to `max_fraction`), in groups, and the data their stops need. `anchor`: the stop point a
/// re-plan starts from (its arc length is kept exactly).
pub fn block_plan(
    toolpath: &Toolpath,
    (points, limits): (&[PathPoint], &Limits),
    anchor: Option<&StopPoint>,
    max_fraction: f64,
) -> Result<BlockPlan, String> {
    check_tip_path(toolpath)?;
    let curves = PathCurves::new(toolpath);
    let mut builder = BlockBuilder::new(curves, JointPath::tip(toolpath), limits, anchor, max_fraction)?;
    for p in points {
        builder.push(*p)?;
    }
    let mut groups = Vec::new();
    builder.finish(&mut |g| {
        groups.push(g);
        true
    });
    Ok(BlockPlan {
        groups,
        period: builder.limits().period,
        stops: (builder.ends, builder.stored, builder.worst),
    })
}

/// Periods between the stops the reachability planner offers on the machine, at least. A
/// hold waits for the next, and they branch off at its stations, up to some 6 ms apart where
/// the plan is fast: measured on the trident and the butterfly at lab set 1 (200 holds each),
/// every hold brakes within 3.5 ms, for stops costing 39 / 82-90 % of the motion.
const STOPS_EVERY: f64 = 8.0;

/// The reachability plan of the path `shared` (tool tip; from its start, or from rest at the
/// module's stop point `from`) in look-ahead windows, in a thread of its own that reads the path
/// as it plans, its blocks in groups handed out as they close (at most [`EVENTS_AHEAD`]
/// waiting): the same positions as `nurbs-plan plan --planner reach --stream`.
pub fn spawn_reach_blocks(
    shared: SharedPath,
    limits: Limits,
    from: Option<StopPoint>,
    max_fraction: f64,
) -> Receiver<BlockEvent> {
    let (sender, receiver) = mpsc::sync_channel(EVENTS_AHEAD);
    std::thread::spawn(move || {
        let send = |e: BlockEvent| sender.send(e).is_ok();
        match reach_blocks(&shared, &limits, from.as_ref(), max_fraction, &mut |g| {
            send(BlockEvent::Group(g))
        }) {
            Ok((line, error, _)) => send(BlockEvent::Done { line, error }),
            Err(e) => send(BlockEvent::Failed(e)),
        };
    });
    receiver
}

/// [`spawn_reach_blocks`]'s groups all at once, and its line for the log (tests, benches).
pub fn reach_block_plan(
    shared: &SharedPath,
    limits: &Limits,
    max_fraction: f64,
) -> Result<(BlockPlan, String), String> {
    let mut groups = Vec::new();
    let (line, error, stops) = reach_blocks(shared, limits, None, max_fraction, &mut |g| {
        groups.push(g);
        true
    })?;
    if let Some(e) = error {
        return Err(e);
    }
    let plan = BlockPlan {
        groups,
        period: limits.period,
        stops,
    };
    Ok((plan, line))
}

/// [`spawn_reach_blocks`]'s plan, its groups handed to `out`: a line for the log, why the file
/// could not be read to its end (the plan ends at rest before the element that failed), and
/// the block ends' stops as [`BlockPlan::stops`] counts them.
fn reach_blocks(
    shared: &SharedPath,
    limits: &Limits,
    from: Option<&StopPoint>,
    max_fraction: f64,
    out: &mut dyn FnMut(BlockGroup) -> bool,
) -> Result<(String, Option<String>, StopCounts), String> {
    let mut curves = shared.open()?;
    let start = from.map(|p| {
        let start = plan_start(&mut curves, p);
        (start.curve, start.u)
    });
    let mut builder = BlockBuilder::new(
        shared.open()?,
        JointPath::over(shared.open()?),
        limits,
        from,
        max_fraction,
    )?;
    builder.expect_offered_stops();
    let options = ReachOptions {
        window: Some(WindowOptions::default()),
        stops_every: Some(STOPS_EVERY * limits.period),
        ..ReachOptions::default()
    };
    let (mut count, mut waiting) = (0usize, 0usize);
    let (_, stats, plan_time) = reach::run(&mut curves, limits, &options, &reach::Begin::Rest(start), &mut |p| {
        let p = match p {
            Planned::Point(p) => p,
            Planned::Stop(stop, _) => {
                builder.offer_stop(stop);
                return Ok(());
            }
        };
        builder.push(*p)?;
        count += 1;
        waiting += 1;
        // A block is at most BLOCK_SAMPLES points: deciding more often finds nothing new.
        if waiting >= BLOCK_SAMPLES {
            waiting = 0;
            if !builder.advance(out) {
                return Err("the streamer stopped taking the plan".into());
            }
        }
        Ok(())
    })
    .map_err(|e| match from {
        None => e.to_string(),
        Some(_) => format!("re-plan from the stop point: {e}"),
    })?;
    if !builder.finish(out) {
        return Err("the streamer stopped taking the plan".into());
    }
    let motion = count.saturating_sub(1) as f64 * builder.limits().period;
    let line = format!(
        "Reach: {count} periods, motion {motion:.6} s, planned in {plan_time:.3} s ({} windows, first points after {:.3} s); stops within the limits at {} block ends ({} stored sequences, worst {:.4} x an axis limit)",
        stats.windows, stats.first_points_time, builder.ends, builder.stored, builder.worst
    );
    let stops = (builder.ends, builder.stored, builder.worst);
    Ok((line, curves.error().map(|e| e.to_string()), stops))
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
