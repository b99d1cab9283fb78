//! A long stretch planned window by window, so that its first points leave long before the
//! whole stretch is planned and the work held stays bounded by the window (streaming).
//!
//! A window runs from the committed state at station `m` to an artificial rest at station `e`,
//! a few stopping distances further. Its passes, re-linearised (and its stations laid again) as
//! a whole stretch's are, settle the linearisation of its rows. Then the rows up to `f` (one
//! margin before `e`) are frozen: no later window changes them. A last backward pass from rest
//! at `f` and a forward pass from the state at `m` give the motion that is committed as far as
//! `m'` (one margin before `f`, where the artificial rest does not yet slow it). Every committed
//! state can stop before `f` under frozen rows, so it lies in the first set of the next window,
//! which starts at `m'` with the same rows up to `f` and more behind them. That is why the
//! linearisation must be the same in every window that sees a station: a row linearised again
//! at a new plan could exclude a state an earlier window accepted. The sets keep the frozen
//! continuation through their simplification; where rounding still leaves the start state
//! outside, the motion runs the last window's stop to `f` and starts again from rest there.

use super::*;

/// How the windows are laid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowOptions {
    /// The margins between the committed end and the frozen end and between the frozen end and
    /// the window's end, in straight-line stopping distances from the highest speed expected
    /// on the window (a stop along a bend takes longer).
    pub margin: f64,
    /// What a window commits, in margins.
    pub commit: f64,
    /// What the first window of a stretch commits, in margins (the motion starts once it is
    /// planned).
    pub first_commit: f64,
}

impl Default for WindowOptions {
    fn default() -> Self {
        WindowOptions {
            margin: 2.0,
            commit: 8.0,
            first_commit: 1.0,
        }
    }
}

/// What a windowed stretch took.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct WindowRun {
    pub stations: usize,
    pub passes: usize,
    pub repairs: usize,
    pub windows: usize,
    /// Windows whose start state fell outside their first set: the last window's stop was run
    /// and the motion started again from rest.
    pub restarts: usize,
    pub last: Option<PathPoint>,
    /// Where the stretch ended.
    pub to: (usize, f64),
}

impl Grid {
    /// Stations `from..=to` and the intervals between them (arc lengths kept).
    pub(super) fn slice(&self, from: usize, to: usize) -> Grid {
        Grid {
            stations: self.stations[from..=to].to_vec(),
            intervals: self.intervals[from..to].to_vec(),
        }
    }
}

impl Linearisation {
    fn slice(&self, from: usize, to: usize) -> Linearisation {
        Linearisation {
            stations: self.stations[from..=to].to_vec(),
            points: self.points[from..to].to_vec(),
        }
    }

    /// Writes `sub` (a slice from station `from`) back.
    fn assign(&mut self, from: usize, sub: &Linearisation) {
        self.stations[from..from + sub.stations.len()].copy_from_slice(&sub.stations);
        self.points[from..from + sub.points.len()].copy_from_slice(&sub.points);
    }

    /// Keeps the first `frozen` intervals (and their stations) of `old`.
    fn keep_frozen(&mut self, old: &Linearisation, frozen: usize) {
        if frozen > 0 {
            self.stations[..=frozen].copy_from_slice(&old.stations[..=frozen]);
            self.points[..frozen].copy_from_slice(&old.points[..frozen]);
        }
    }

    /// Keeps stations `..=k` and the intervals between them.
    fn truncate(&mut self, k: usize) {
        self.stations.truncate(k + 1);
        self.points.truncate(k);
    }

    /// Appends the values of `part` (a slice whose first station is the last here).
    fn append(&mut self, part: Linearisation) {
        self.stations.extend_from_slice(&part.stations[1..]);
        self.points.extend(part.points);
    }
}

impl Motion {
    /// The first `k` intervals.
    fn truncated(&self, k: usize) -> Motion {
        Motion {
            a: self.a[..=k].to_vec(),
            b: self.b[..=k].to_vec(),
            pieces: self.pieces[..k].to_vec(),
            durations: self.durations[..k].to_vec(),
            off_range: 0,
            cut_short: false,
        }
    }

    /// The intervals from `k` on.
    fn tail(&self, k: usize) -> Motion {
        Motion {
            a: self.a[k..].to_vec(),
            b: self.b[k..].to_vec(),
            pieces: self.pieces[k..].to_vec(),
            durations: self.durations[k..].to_vec(),
            off_range: 0,
            cut_short: self.cut_short,
        }
    }
}

/// A motion a windowed stretch continues ([`Begin::Moving`]).
#[derive(Clone, Copy)]
pub(super) struct Continued<'a> {
    /// (a, b) at the stretch's start, and the time from there to the first sample.
    pub state: (f64, f64),
    pub next: f64,
    /// The rows it was planned on; none: the stretch is laid afresh from the branch.
    pub fork: Option<&'a Forked>,
}

/// A value at arc length s where the path is `here` (a speed, a linearisation point).
type AlongPath<'a> = dyn Fn(f64, &Local) -> f64 + 'a;

/// What sampling a motion gave: the last sample and the time from the motion's end to the
/// next (all passed the check and left), or the (time, ratio) of the samples that ran over.
type Committed = Result<(Option<PathPoint>, f64), Vec<(f64, f64)>>;

/// Passes of the first window of a plan that continues a motion (an override change waits for
/// it), on the stations its fork laid: 4-8 passes and a new grid took a median 62 ms to its
/// first points (144 re-plans over the bundled curves, `tests/reach.rs`), 2 on the fork's
/// stations 28-30 ms; the windows after it are planned as ever.
const QUICK_PASSES: usize = 2;

/// Share of the limits the stop after a window's committed part leaves unused.
const STOP_RESERVE: f64 = 0.01;
/// Intervals before a window's committed end that keep the reserve.
const JUNCTION: usize = 3;

/// The last station at or before arc length `s` (at least `least`).
fn station_before(grid: &Grid, s: f64, least: usize) -> usize {
    let k = grid.stations.partition_point(|st| st.s <= s);
    k.saturating_sub(1).max(least)
}

/// The stations of a stretch laid so far (from the station before the last window's start),
/// and what the windows keep per station.
struct Laid {
    /// The stretch as far as it was read.
    stretch: Stretch,
    grid: Grid,
    /// The jerk rows' linearisation at every station and collocation point.
    lin: Linearisation,
    /// Factor on the limits of every interval (tightened where samples ran over).
    tight: Vec<f64>,
    /// Per station, a speed no plan exceeds much: the first guess, and below it what a
    /// jerk-limited ramp allows after every earlier station (what sizes the windows).
    expected: Vec<f64>,
    /// Whether the stations reach the stretch's end.
    complete: bool,
}

impl Laid {
    /// Forgets the stations before `k` (committed and no longer needed).
    fn forget(&mut self, k: usize) {
        self.grid.stations.drain(..k);
        self.grid.intervals.drain(..k);
        self.lin.stations.drain(..k);
        self.lin.points.drain(..k);
        self.tight.drain(..k);
        self.expected.drain(..k);
    }
}

impl Planner<'_> {
    /// Length of a stop from speed `v` along a straight line with the smallest axis
    /// acceleration and jerk (constant jerk to the deceleration, held, and back).
    fn stop_distance(&self, v: f64) -> f64 {
        let (a, j) = self.least_limits();
        if v * j <= a * a {
            v * (v / j).sqrt()
        } else {
            0.5 * v * (v / a + a / j)
        }
    }

    /// Lays the stations of `laid` on from its last (or the stretch start) until arc length
    /// `until`, reading the path ahead as far as needed, spaced by `speed` and linearised at
    /// `lin_a` (a at arc length s; both the first guess where `None`).
    fn lay(
        &self,
        curves: &mut PathCurves,
        laid: &mut Laid,
        until: f64,
        speed: Option<&AlongPath<'_>>,
        lin_a: Option<&AlongPath<'_>>,
    ) {
        loop {
            // The path read a chunk past `until`, so that a rest within it is known before the
            // stations near it are laid.
            let s_last = laid.grid.stations.last().map_or(0.0, |st| st.s);
            let ahead = if until.is_finite() {
                until + (until - s_last).max(1.0)
            } else {
                f64::INFINITY
            };
            let more = ahead - laid.stretch.length;
            if more > 0.0 {
                read_on(curves, &mut laid.stretch, more, &self.rests.borrow());
            }
            let from = laid
                .grid
                .stations
                .last()
                .map_or((laid.stretch.from, 0.0), |st| ((st.element, st.u), st.s));
            let stretch = &laid.stretch;
            let guess = |s: f64, here: &Local| self.first_guess(stretch, s, here);
            let guess_a = |s: f64, here: &Local| guess(s, here).powi(2);
            let (part, reached) = Grid::build_part(
                curves,
                stretch,
                from,
                until,
                &self.caps,
                &self.options.grid,
                speed.unwrap_or(&guess),
            );
            if part.stations.is_empty() {
                // Nothing left to lay before the end read so far (a fork's stations may reach
                // it).
                if laid.stretch.open {
                    continue;
                }
                laid.complete = true;
                return;
            }
            let lin = Linearisation::from_a(&part, lin_a.unwrap_or(&guess_a));
            let old = laid.grid.stations.len();
            if old == 0 {
                laid.lin = lin;
            } else {
                laid.lin.append(lin);
            }
            laid.grid.append(part);
            self.cap_across_slow_down(curves, &mut laid.grid);
            laid.tight.resize(laid.grid.len(), 1.0 - self.options.margin);
            // The ramp envelope from the station before on (its far side may be new).
            self.expect(laid, old.saturating_sub(1));
            laid.complete = reached && !laid.stretch.open;
            if laid.complete || !reached {
                return;
            }
        }
    }

    /// The speeds expected at the stations of `laid` from `from` on: the first guess, and below
    /// it what a jerk-limited ramp allows after every earlier station.
    fn expect(&self, laid: &mut Laid, from: usize) {
        laid.expected.truncate(from);
        for k in laid.expected.len()..laid.grid.stations.len() {
            let st = &laid.grid.stations[k];
            let mut d = self.ramp_length(self.first_guess(&laid.stretch, st.s, &st.right));
            if k > 0 {
                let before = self.ramp_length(laid.expected[k - 1]) + st.s - laid.grid.stations[k - 1].s;
                d = d.min(before);
            }
            laid.expected.push(self.ramp(d));
        }
    }

    /// The stations of `fork` from its station `k` on, as a stretch's first, with the caps of
    /// this planner (its feed override) and the fork's motion's speeds expected at least.
    fn laid_from(&self, curves: &PathCurves, fork: &Fork, k: usize) -> Laid {
        let mut grid = fork.grid.slice(k, fork.grid.len());
        let caps = &self.caps;
        let feed = |e: usize| curves.programmed_feed(e);
        for j in 0..grid.stations.len() {
            let left_element = if j > 0 {
                grid.stations[j - 1].element
            } else {
                grid.stations[j].element
            };
            let st = &mut grid.stations[j];
            st.left.cap = caps.at(st.s, &st.left.q1, &st.left.q2, feed(left_element));
            st.right.cap = caps.at(st.s, &st.right.q1, &st.right.q2, feed(st.element));
            if j < grid.intervals.len() {
                let (s, element) = (st.s, st.element);
                for (theta, local) in &mut grid.intervals[j].points {
                    local.cap = caps.at(s + *theta, &local.q1, &local.q2, feed(element));
                }
            }
        }
        self.cap_across_slow_down(curves, &mut grid);
        let mut laid = Laid {
            stretch: fork.stretch,
            grid,
            lin: fork.lin.slice(k, fork.grid.len()),
            tight: fork.tight[k..].to_vec(),
            expected: Vec::new(),
            complete: false,
        };
        self.expect(&mut laid, 0);
        for (x, a) in laid.expected.iter_mut().zip(&fork.motion.a[k..]) {
            *x = x.max(a.sqrt());
        }
        laid
    }

    /// The interval of `grid` across the arc length where a lower feed override takes over
    /// ([`Caps::slow_down`]) takes its caps from its start on: the cap rows hold at points, and
    /// between the last one before and the first one after, the plan could run over the new
    /// feed.
    fn cap_across_slow_down(&self, curves: &PathCurves, grid: &mut Grid) {
        let Some(slow) = self.caps.slow_down else {
            return;
        };
        let j = grid.stations.partition_point(|st| st.s < slow.from);
        if j == 0 || j >= grid.stations.len() {
            return;
        }
        let (k, at) = (j - 1, slow.from);
        let feed = curves.programmed_feed(grid.stations[k].element);
        let st = &mut grid.stations[k];
        st.right.cap = self.caps.at(at, &st.right.q1, &st.right.q2, feed);
        for (_, local) in &mut grid.intervals[k].points {
            local.cap = self.caps.at(at, &local.q1, &local.q2, feed);
        }
    }

    /// Drops the stations of `laid` past `k`.
    fn unlay(laid: &mut Laid, k: usize) {
        laid.grid.truncate(k);
        laid.lin.truncate(k);
        laid.tight.truncate(k);
        laid.expected.truncate(k + 1);
        laid.complete = false;
    }

    /// Plans `stretch` (read as far as it goes) window by window, handing out each window's
    /// points once they passed the check; the stretch read to its end, unplanned, where it is
    /// shorter than a window. From rest, or continuing a motion `moving` (then in windows
    /// however short, and never handed back unplanned: a plan from rest would not continue the
    /// motion; on its fork's stretch and rows where it has one).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn plan_stretch_windowed(
        &self,
        curves: &mut PathCurves,
        stretch: Stretch,
        before: Option<PathPoint>,
        check: &mut Check,
        window: &WindowOptions,
        moving: Option<Continued<'_>>,
        emit: &mut Emit<'_>,
    ) -> Result<Result<WindowRun, Stretch>, ReachError> {
        let mut laid = match moving.and_then(|m| m.fork) {
            Some(forked) => self.laid_from(curves, &forked.fork, forked.station),
            None => Laid {
                stretch,
                grid: Grid::default(),
                lin: Linearisation {
                    stations: Vec::new(),
                    points: Vec::new(),
                },
                tight: Vec::new(),
                expected: Vec::new(),
                complete: false,
            },
        };
        let mut emitted = false;
        let mut counted = |p: Planned<'_>| {
            emitted = true;
            emit(p)
        };
        let mut trial = check.clone();
        match self.windows(curves, &mut laid, before, &mut trial, window, moving, &mut counted) {
            Ok(Some(run)) => {
                *check = trial;
                Ok(Ok(run))
            }
            Err(e) if moving.is_some() => Err(e),
            // Shorter than a window, or no window planned before the first points: the
            // stretch is planned whole.
            Ok(None) => Ok(Err(laid.stretch)),
            Err(ReachError::Plan(_) | ReachError::Stands { .. }) if !emitted => Ok(Err(laid.stretch)),
            Err(e) => Err(e),
        }
    }

    /// [`Planner::plan_stretch_windowed`] on `laid`; `None` where the stretch is shorter than
    /// a window (and starts at rest).
    #[allow(clippy::too_many_arguments)]
    fn windows(
        &self,
        curves: &mut PathCurves,
        laid: &mut Laid,
        before: Option<PathPoint>,
        check: &mut Check,
        window: &WindowOptions,
        moving: Option<Continued<'_>>,
        emit: &mut Emit<'_>,
    ) -> Result<Option<WindowRun>, ReachError> {
        let gap_at = |v: f64| window.margin * self.stop_distance(v);
        let mut run = WindowRun {
            last: before,
            ..WindowRun::default()
        };
        // The committed station, the state there (None: at rest), the end of the frozen rows,
        // the time from there to the next sample, and the last window's stop: its first
        // station and its motion to rest at `frozen`.
        let mut m = 0;
        let mut state: Option<(f64, f64)> = moving.map(|m| m.state);
        let mut first_sample = moving.map_or(self.period, |m| m.next);
        // A fork's rows are frozen as far as its stop, the continuation of the state.
        let (mut frozen, mut last_stop) = match moving.and_then(|m| m.fork) {
            Some(forked) => {
                let stop = Motion {
                    a: forked.stop.iter().map(|s| s.0).collect(),
                    b: forked.stop.iter().map(|s| s.1).collect(),
                    ..Motion::default()
                };
                (forked.stop.len() - 1, Some((0, stop)))
            }
            None => (0, None),
        };
        loop {
            // The window reaches (commit + 2) margins past `m`, each from the highest speed
            // expected on it; stations are laid as far as that.
            let s_m = laid.grid.stations.get(m).map_or(0.0, |st| st.s);
            let commit = if run.windows == 0 {
                window.first_commit
            } else {
                window.commit
            };
            let long_enough = |laid: &Laid, e: usize, v: f64| {
                laid.grid.stations[e].s - s_m >= (commit + 2.0) * gap_at(v) && e >= m + 3 && e > frozen + 2
            };
            let (mut e, mut v) = (m, 0.0f64);
            let gap = loop {
                let mut long = false;
                while !long && e + 1 < laid.grid.stations.len() {
                    e += 1;
                    v = v.max(laid.expected[e]);
                    long = long_enough(laid, e, v);
                }
                if long || laid.complete {
                    break gap_at(v);
                }
                let end = laid.grid.stations.last().map_or(0.0, |st| st.s);
                self.lay(curves, laid, end + gap_at(v).max(1.0), None, None);
            };
            if run.windows == 0 && moving.is_none() && laid.complete && laid.grid.length() < (commit + 2.0) * gap {
                // Shorter than a window: planned whole.
                return Ok(None);
            }
            run.windows += 1;
            // The rest of the stretch when what is left past the window is short.
            if laid.complete && laid.grid.length() - laid.grid.stations[e].s < gap {
                e = laid.grid.len();
            }
            if laid.grid.len() < 3 {
                return Err(ReachError::Plan(format!(
                    "a stretch of {:.3e} mm is too short to plan",
                    laid.stretch.length
                )));
            }
            // The last window's continuation from `m` to its rest at `frozen`.
            let through: Vec<(f64, f64)> = match (&last_stop, state) {
                (Some((from, stop)), Some(_)) => (m - from..=frozen - from).map(|k| (stop.a[k], stop.b[k])).collect(),
                _ => Vec::new(),
            };
            let start = Start {
                state,
                through: &through,
                artificial_end: !(laid.complete && e == laid.grid.len()),
                through_rests: false,
            };
            // The committed motion (to rest at `f`) and its ends, or none where the start state
            // lies outside the window's first set.
            let committed = 'window: {
                // The first window of a motion continued is what an override change waits for.
                let quick = moving.is_some() && run.windows == 1;
                let planned = self.window_passes(curves, laid, (m, &mut e), frozen, start, &mut run.passes, gap, quick);
                let motion = match planned {
                    Ok(motion) => motion,
                    Err(PassError::Empty { station: 0 }) if state.is_some() => break 'window None,
                    Err(err) => return Err(self.describe(&laid.grid, m, err)),
                };
                if laid.complete && e == laid.grid.len() {
                    // The last window: all of it, to rest at the stretch's end.
                    let start = Start {
                        artificial_end: false,
                        ..start
                    };
                    let sub = laid.grid.slice(m, e);
                    let lin_sub = laid.lin.slice(m, e);
                    let floors = (self.options.floor > 0.0).then(|| lin_sub.scaled(self.options.floor));
                    let mut motion = motion;
                    let mut tries = 0;
                    loop {
                        let span = sampler::Span {
                            first: first_sample,
                            at_rest: true,
                        };
                        let along = Along {
                            grid: &sub,
                            lin: &lin_sub,
                            tight: &laid.tight[m..e],
                            start,
                            motion: &motion,
                            stretch: Some(&laid.stretch),
                        };
                        let stops = |samples: &[PathPoint], found: &mut Branches<'_>| {
                            self.branch_stops(curves, &along, sub.len(), first_sample, samples, found)
                        };
                        match self.commit(curves, &sub, &motion, run.last, check, span, &stops, emit)? {
                            Ok((last, _)) => {
                                run.last = last.or(run.last);
                                run.repairs += tries;
                                run.stations += laid.grid.stations.len();
                                run.to = laid.stretch.to;
                                return Ok(Some(run));
                            }
                            Err(over) => {
                                self.tighten(&mut laid.tight[m..e], &motion, &over, &mut tries)?;
                                motion = self
                                    .passes(
                                        &sub,
                                        &lin_sub,
                                        floors.as_ref(),
                                        &laid.tight[m..e],
                                        start,
                                        &mut run.passes,
                                    )
                                    .map_err(|err| self.describe(&laid.grid, m, err))?;
                            }
                        }
                    }
                }
                // Freeze the rows to `f`, commit to `m2`: the motion from the state at `m` to rest
                // at `f`. The rows past the window plan's last speed maximum are linearised at its
                // artificial stop: `f` lies before it. A plateau (a plan held at its cap) ends at
                // that maximum: frozen only to its start, a window at a low feed was too short to
                // stop in.
                let mut decel = motion.a.len() - 1;
                while decel > 0 && (motion.a[decel - 1] > motion.a[decel] || motion.a[decel] <= 0.0) {
                    decel -= 1;
                }
                let grid = &laid.grid;
                let f = station_before(grid, grid.stations[e].s - gap, m + 2).min((m + decel).max(m + 2));
                let mut m2 = station_before(grid, grid.stations[f].s - gap, m + 1).min(f - 1) - m;
                let sub = grid.slice(m, f);
                let lin_sub = laid.lin.slice(m, f);
                let mut tries = 0;
                let committed = loop {
                    // The stop is planned with a reserve on the limits past the committed end: the
                    // next window may tighten those rows by as much (samples that ran over) and
                    // still hold the committed state. The last intervals before it keep the
                    // reserve too: the finite differences across the junction see both windows'
                    // motions, and only the next one's can still be tightened.
                    let mut reserved = laid.tight[m..f].to_vec();
                    for t in &mut reserved[m2.saturating_sub(JUNCTION)..] {
                        *t *= 1.0 - STOP_RESERVE;
                    }
                    let stop = match self.proof(&sub, &lin_sub, &reserved, start, &mut m2, &mut run.passes) {
                        Ok(stop) => stop,
                        Err(PassError::Empty { station: 0 }) if state.is_some() => break None,
                        Err(err) => return Err(self.describe(&laid.grid, m, err)),
                    };
                    let part = stop.truncated(m2);
                    let span = sampler::Span {
                        first: first_sample,
                        at_rest: false,
                    };
                    let along = Along {
                        grid: &sub,
                        lin: &lin_sub,
                        tight: &reserved,
                        start,
                        motion: &stop,
                        stretch: Some(&laid.stretch),
                    };
                    let stops = |samples: &[PathPoint], found: &mut Branches<'_>| {
                        self.branch_stops(curves, &along, m2, first_sample, samples, found)
                    };
                    let committed = laid.grid.slice(m, m + m2);
                    match self.commit(curves, &committed, &part, run.last, check, span, &stops, emit)? {
                        Ok((last, next)) => {
                            run.last = last.or(run.last);
                            first_sample = next;
                            break Some(stop);
                        }
                        Err(over) => self.tighten(&mut laid.tight[m..m + m2], &part, &over, &mut tries)?,
                    }
                };
                run.repairs += tries;
                committed.map(|stop| (stop, m2, f))
            };
            match committed {
                Some((stop, m2, f)) => {
                    // Past the frozen rows the window's linearisation is its artificial stop's:
                    // the next window starts from the first guess there.
                    let stretch = &laid.stretch;
                    let guess_a = |s: f64, here: &Local| self.first_guess(stretch, s, here).powi(2);
                    for k in f + 1..laid.grid.stations.len() {
                        let st = &laid.grid.stations[k];
                        laid.lin.stations[k] = guess_a(st.s, &st.right);
                    }
                    for k in f..laid.grid.len() {
                        let (st, iv) = (&laid.grid.stations[k], &laid.grid.intervals[k]);
                        for (x, (theta, local)) in laid.lin.points[k].iter_mut().zip(&iv.points) {
                            *x = guess_a(st.s + theta, local);
                        }
                    }
                    state = Some((stop.a[m2], stop.b[m2]));
                    // What lies before this window's start is no longer needed (a restart runs
                    // its stop from the next one's start).
                    laid.forget(m);
                    run.stations += m;
                    last_stop = Some((0, stop));
                    (m, frozen) = (m2, f - m);
                    curves.release_before(laid.grid.stations[0].element);
                }
                None if moving.is_some() && run.windows == 1 => {
                    return Err(ReachError::Plan(
                        "the motion continued lies outside the new plan's first set".into(),
                    ))
                }
                None => {
                    m = self.restart(
                        curves,
                        &laid.grid,
                        &mut last_stop,
                        m,
                        first_sample,
                        check,
                        &mut run,
                        emit,
                    )?;
                    (frozen, state, first_sample) = (m, None, self.period);
                }
            }
        }
    }

    /// The passes of the window from station `m` to `e`, re-linearised as a whole stretch's
    /// are, except on the intervals before `frozen`; after the first, the stations past the
    /// frozen ones are laid again from the planned speed (`e` moves with them). The
    /// linearisation of the best pass is written back. `quick`: [`QUICK_PASSES`] on the
    /// stations as laid.
    #[allow(clippy::too_many_arguments)]
    fn window_passes(
        &self,
        curves: &mut PathCurves,
        laid: &mut Laid,
        (m, e): (usize, &mut usize),
        frozen: usize,
        start: Start,
        count: &mut usize,
        gap: f64,
        quick: bool,
    ) -> Result<Motion, PassError> {
        let mut start = start;
        let o = if quick {
            &ReachOptions {
                iterations: QUICK_PASSES,
                most_iterations: QUICK_PASSES,
                regrid_after: 0,
                ..*self.options
            }
        } else {
            self.options
        };
        let fz = frozen.saturating_sub(m);
        let mut sub = laid.grid.slice(m, *e);
        let mut current = laid.lin.slice(m, *e);
        let mut floors: Option<Linearisation> = None;
        let mut best: Option<(Motion, Linearisation)> = None;
        let (least, most) = (o.iterations.max(1), o.most_iterations.max(o.iterations).max(1));
        let mut last_pass = least == 1;
        for it in 0.. {
            // The passes before the stations are laid again only guide that: they may end
            // short of the stretch's end as a window's artificial rest may.
            let pass_start = if it < o.regrid_after {
                Start {
                    artificial_end: true,
                    ..start
                }
            } else {
                start
            };
            let motion = self.passes(&sub, &current, floors.as_ref(), &laid.tight[m..*e], pass_start, count);
            let motion = motion?;
            let best_time = best.as_ref().map_or(f64::INFINITY, |(m, _)| m.time());
            let better = motion.time() < best_time;
            if last_pass {
                if better {
                    best = Some((motion, current));
                }
                break;
            }
            let gaining = motion.time() < (1.0 - o.gain) * best_time;
            last_pass = it + 2 >= most || (it + 2 >= least && !gaining);
            let scale = if last_pass { o.scale_last } else { o.scale_early };
            let plan = PlanSpeed {
                grid: &sub,
                motion: &motion,
            };
            let (mut next, new_sub) = if it + 1 == o.regrid_after {
                // Lay the stations past the frozen ones again from the planned speed, as far as
                // the window reached (or to the stretch's end).
                let keep = m + fz;
                let until = if laid.complete && *e == laid.grid.len() {
                    f64::INFINITY
                } else {
                    sub.length()
                };
                let vmax = motion.a.iter().fold(0.0f64, |m, a| m.max(*a)).sqrt();
                // The window's artificial stop (its last margin) keeps the spacing of the
                // speed before it: stations there are laid again by the next window, and
                // stations a fraction of a micrometre apart near its rest leave states too
                // small for the stop piece's rounding.
                let tail = sub.length() - gap;
                let v_tail = plan.a_at(tail).sqrt();
                let speed = |s: f64, here: &Local| {
                    let v = plan.a_at(s).sqrt();
                    let v = if s > tail && until.is_finite() {
                        v.max(v_tail)
                    } else {
                        v
                    };
                    v.max(1e-3 * vmax).min(self.speed_bound(here).max(1e-3 * vmax))
                };
                let plan_a = |s: f64, _: &Local| plan.a_at(s);
                Self::unlay(laid, keep);
                self.lay(curves, laid, until, Some(&speed), Some(&plan_a));
                *e = laid.grid.len();
                if *e < m + 3 {
                    return Err(PassError::Stalls { interval: 0 });
                }
                let new_sub = laid.grid.slice(m, *e);
                start.artificial_end = !laid.complete;
                (Linearisation::from_plan(&new_sub, &plan).scaled(scale), Some(new_sub))
            } else {
                (Linearisation::from_plan(&sub, &plan).scaled(scale), None)
            };
            next.keep_frozen(&current, fz);
            floors = (o.floor > 0.0).then(|| next.scaled(o.floor));
            match new_sub {
                // A pass on the stations laid before no longer fits them: it is forgotten.
                Some(new_sub) => {
                    sub = new_sub;
                    best = None;
                }
                None if better => best = Some((motion, current)),
                None => {}
            }
            current = next;
        }
        let (motion, best_lin) = best.ok_or(PassError::Stalls { interval: 0 })?;
        laid.lin.assign(m, &best_lin);
        Ok(motion)
    }

    /// The motion from the window's start state to rest at the end of `sub` (the rows about
    /// to be frozen), with floors as the window's passes had them as far as the committed end
    /// `m2` (a station of `sub`) and none past it, where the stop goes below them. Where the
    /// floors leave no stop, the committed end moves back towards the start (at most three
    /// times), then the floors go.
    fn proof(
        &self,
        sub: &Grid,
        lin_sub: &Linearisation,
        tight: &[f64],
        start: Start,
        m2: &mut usize,
        count: &mut usize,
    ) -> Result<Motion, PassError> {
        if self.options.floor > 0.0 {
            for _ in 0..3 {
                let mut floors = lin_sub.scaled(self.options.floor);
                floors.stations[*m2..].fill(0.0);
                floors.points[*m2..].fill([0.0; NC]);
                *count += 1;
                match self.pass(sub, lin_sub, Some(&floors), tight, start) {
                    Ok(motion) if !motion.cut_short || *m2 == 1 => return Ok(motion),
                    // A stop cut short (that the limits do not hold) cannot be run after a
                    // restart: commit less.
                    Ok(_) => *m2 = (*m2 / 2).max(1),
                    Err(PassError::Empty { station }) if station > 0 && station <= *m2 => *m2 = (station / 2).max(1),
                    Err(_) => break,
                }
            }
        }
        self.passes(sub, lin_sub, None, tight, start, count)
    }

    /// Samples `motion` over `grid` and checks the samples; if none runs over, hands them out
    /// with the stops `stops` branches off them, and gives the last and the time from the
    /// motion's end to the next sample; if some do, where.
    #[allow(clippy::too_many_arguments)]
    fn commit(
        &self,
        curves: &PathCurves,
        grid: &Grid,
        motion: &Motion,
        before: Option<PathPoint>,
        check: &mut Check,
        span: sampler::Span,
        stops: &FindStops<'_>,
        emit: &mut Emit<'_>,
    ) -> Result<Committed, ReachError> {
        let mut trial = check.clone();
        let sampled = sampler::sample(
            curves,
            &inverse::Inverses::default(),
            grid,
            motion,
            &self.limits,
            self.caps.axes,
            before,
            &mut trial,
            1e-9,
            span,
        );
        if !sampled.over.is_empty() {
            return Ok(Err(sampled.over));
        }
        *check = trial;
        hand_out(&sampled.points, &|found| stops(&sampled.points, found), emit)?;
        Ok(Ok((sampled.points.last().copied(), sampled.next)))
    }

    /// The motion runs the last window's stop from station `m` to rest at `frozen` (its rows
    /// unchanged, its states accepted): the station where it rests, where the next window
    /// starts.
    #[allow(clippy::too_many_arguments)]
    fn restart(
        &self,
        curves: &PathCurves,
        grid: &Grid,
        last_stop: &mut Option<(usize, Motion)>,
        m: usize,
        first: f64,
        check: &mut Check,
        run: &mut WindowRun,
        emit: &mut Emit<'_>,
    ) -> Result<usize, ReachError> {
        let Some((from, stop)) = last_stop.take() else {
            return Err(ReachError::Plan("a window's start state has no continuation".into()));
        };
        if stop.cut_short {
            return Err(ReachError::Plan(
                "a window's start state has no continuation, and the last window's stop is cut short".into(),
            ));
        }
        let tail = stop.tail(m - from);
        let rest = tail.durations.len();
        let span = sampler::Span { first, at_rest: true };
        let no_stops = |_: &[PathPoint], _: &mut Branches<'_>| Ok(());
        match self.commit(
            curves,
            &grid.slice(m, m + rest),
            &tail,
            run.last,
            check,
            span,
            &no_stops,
            emit,
        )? {
            Ok((last, _)) => {
                run.last = last.or(run.last);
                run.restarts += 1;
                Ok(m + rest)
            }
            Err(over) => Err(ReachError::Plan(format!(
                "a window's stop runs over a limit (ratio {:.9})",
                over[0].1
            ))),
        }
    }
}
