//! The stops the planner offers along its plan ([`ReachOptions::stops_every`]): what the
//! machine brakes with on a hold. From the state at a station, the quicker of two:
//! - the stop the controllable sets allow ([`Passes::brake`]): every state the forward pass
//!   accepts lies in its set, so it can stop without a simulation, but at speeds far below the
//!   plan's the rows linearised at the plan let the deceleration fall with the speed (on a
//!   straight line at lab set 1 a stop took 4-7 times the S-curve's time);
//! - the S-curve stop the module also runs ([`stop_from`]: constant-jerk phases in time) with
//!   the tangential limits over the distance it covers, less what the path's curvature there takes at the highest speed on the way
//!   (nothing is left of them in tight bends).
//!
//! Where the stations lie further apart than two offers, S-curve stops also branch off at
//! samples inside the interval. Each is sampled at the servo period from the period after its
//! start and checked by finite differences continuing the three samples before it (the other
//! where the quicker runs over); the plan itself is unchanged.

use super::grid::{arc_derivatives, Interval, Local};
use super::inverse::Inverses;
use super::pieces::Piece;
use super::*;
use nurbs_rtcore::scurve::{stop_from, SCurveState, SCurveTable, PHASES};

/// Speed (mm/s) below which no stop branches off: from there the least control creeps (a
/// speed of 1e-5 mm/s took 800 s to rest on `3D_Chips.ngc`).
const SLOWEST_BRANCH: f64 = 1e-3;
/// Longest stop offered (s): each is stored sample by sample (the slowest measured on
/// `3D_Chips.ngc`, from 2 mm/s, take 0.9 s).
const LONGEST_STOP: f64 = 2.0;

/// Points per interval where the S-curve stop's limits also look at the path (the curvature
/// peaks of fitted corners lie between collocation points), and the share of the limits it
/// leaves for what they still miss.
const DENSER: usize = 6;
const STOP_MARGIN: f64 = 0.02;

/// The points of each interval of a grid the S-curve stops' limits look at (its stations,
/// collocation points and [`DENSER`] more), each with the interval's tightening and
/// [`STOP_MARGIN`]: found once per interval, as every stop within reach of it looks there.
struct LookedAt {
    intervals: Vec<Option<Vec<(Local, f64)>>>,
}

impl LookedAt {
    fn new(grid: &Grid) -> Self {
        LookedAt {
            intervals: vec![None; grid.len()],
        }
    }

    fn interval(&mut self, curves: &PathCurves, grid: &Grid, tight: &[f64], axes: usize, j: usize) -> &[(Local, f64)] {
        self.intervals[j].get_or_insert_with(|| {
            let f = tight[j.min(tight.len() - 1)] * (1.0 - STOP_MARGIN);
            let (st, next) = (&grid.stations[j], &grid.stations[j + 1]);
            let mut locals = Vec::with_capacity(grid.intervals[j].points.len() + 2 + DENSER);
            locals.push((st.right, f));
            locals.extend(grid.intervals[j].points.iter().map(|(_, l)| (*l, f)));
            locals.push((next.left, f));
            let view = curves.view(st.element);
            let u_end = if next.element == st.element {
                next.u
            } else {
                view.u_max()
            };
            for m in 1..=DENSER {
                let u = st.u + (u_end - st.u) * m as f64 / (DENSER + 1) as f64;
                let (_, q1, q2, q3) = arc_derivatives(&view, u, axes, false);
                locals.push((Local { q1, q2, q3, cap: 0.0 }, f));
            }
            locals
        })
    }
}

/// Where the stops branching off a motion's samples go as they are found, in path order: each
/// after the motion's first `n` samples, its samples from the next period to rest, and where
/// it branches off.
pub(super) type Branches<'a> = dyn FnMut(usize, Vec<PathPoint>, Branch) -> Result<(), ReachError> + 'a;

/// What finds the stops branching off a motion's samples, handing each to the sink it is given.
pub(super) type FindStops<'a> = dyn Fn(&[PathPoint], &mut Branches<'_>) -> Result<(), ReachError> + 'a;

/// A motion and what it was planned with.
pub(super) struct Along<'a> {
    pub grid: &'a Grid,
    pub lin: &'a Linearisation,
    pub tight: &'a [f64],
    pub start: Start<'a>,
    pub motion: &'a Motion,
    /// The stretch a plan in windows lays: its stations' branches take the rows over
    /// ([`Fork`]).
    pub stretch: Option<&'a Stretch>,
}

/// The branch at `(element, u)` with speed and acceleration `state`, `next` before the sample
/// after the first `n` of `samples`.
fn branch(
    (element, u): (usize, f64),
    (speed, acceleration): (f64, f64),
    next: f64,
    samples: &[PathPoint],
    n: usize,
    fork: Option<Forked>,
) -> Branch {
    Branch {
        element,
        u,
        speed,
        acceleration,
        next,
        before: [samples[n - 3], samples[n - 2], samples[n - 1]],
        fork,
    }
}

/// Hands `points` to `emit`, each stop `stops` finds after the points before it, as it finds
/// them (the first points leave once the first stop is found, not all).
pub(super) fn hand_out(
    points: &[PathPoint],
    stops: &dyn Fn(&mut Branches<'_>) -> Result<(), ReachError>,
    emit: &mut Emit<'_>,
) -> Result<(), ReachError> {
    let mut sent = 0;
    stops(&mut |n, stop, branch| {
        for p in &points[sent..n] {
            emit(Planned::Point(p)).map_err(ReachError::Plan)?;
        }
        sent = n;
        emit(Planned::Stop(&stop, &branch)).map_err(ReachError::Plan)
    })?;
    for p in &points[sent..] {
        emit(Planned::Point(p)).map_err(ReachError::Plan)?;
    }
    Ok(())
}

impl Planner<'_> {
    /// The stops of [`ReachOptions::stops_every`] branching off `along.motion` at its stations up
    /// to `upto`, about that often, handed to `found` as they are found: each with the number of
    /// `samples` (the motion's, the first `first` into it) before it, sampled from the next
    /// period, and checked by finite differences continuing the three samples before it: the
    /// quicker of the two stops (see the module), the other where it runs over, none where both
    /// do (the block builder has others).
    pub(super) fn branch_stops(
        &self,
        curves: &PathCurves,
        along: &Along<'_>,
        upto: usize,
        first: f64,
        samples: &[PathPoint],
        found: &mut Branches<'_>,
    ) -> Result<(), ReachError> {
        let Some(every) = self.options.stops_every else {
            return Ok(());
        };
        let grid = along.grid;
        // The sets of the rows the motion was planned with, without floors (a stop goes below
        // them); they keep the motion's own states through their simplification (the motion
        // rides the boundary of sets built with floors, simplified otherwise).
        let through: Vec<(f64, f64)> = along
            .motion
            .a
            .iter()
            .copied()
            .zip(along.motion.b.iter().copied())
            .collect();
        let p = Passes {
            grid,
            limits: self.axis,
            period: self.period,
            lin_stations: &along.lin.stations,
            lin_points: &along.lin.points,
            floors: None,
            tight: along.tight,
            max_vertices: self.options.max_vertices,
            jerk: true,
            start: Start {
                through: &through,
                through_rests: true,
                ..along.start
            },
        };
        let sets = p.backward().ok();
        let motion = along.motion;
        let mut looked = LookedAt::new(grid);
        let inverses = Inverses::default();
        // The rows the branches at stations take over, once one is found.
        let fork = std::cell::OnceCell::new();
        let (mut t, mut last) = (0.0, f64::NEG_INFINITY);
        for k in 1..upto.min(grid.len() - 1) {
            let t0 = t;
            t += motion.durations[k - 1];
            // Where the stations lie further apart than the stops should (the grid was laid
            // from a faster pass), S-curve stops from samples inside the interval before.
            while last.is_finite() && t - last > 2.0 * every {
                let at_time = (last + every).max(first);
                let n = ((at_time - first) / self.period).floor() as usize + 1;
                let at_time = first + (n - 1) as f64 * self.period;
                last += every;
                if at_time <= t0 || n < 3 || n > samples.len() {
                    continue;
                }
                let (sigma, v, acc) = motion.pieces[k - 1].state_at(at_time - t0);
                if v < SLOWEST_BRANCH {
                    continue;
                }
                let candidate = self.s_curve_stop(curves, grid, along.tight, &mut looked, (k - 1, sigma), (v * v, acc));
                if let Some(points) =
                    self.first_passing(curves, &inverses, candidate.into_iter(), samples, n, self.period)
                {
                    // The branch is the n-th sample itself.
                    let at = (grid.stations[k - 1].element, self.u_at(curves, grid, k - 1, sigma));
                    found(n, points, branch(at, (v, acc), self.period, samples, n, None))?;
                    last = at_time;
                }
            }
            if t - last < every || t < first {
                continue;
            }
            // Samples at or before the station.
            let n = ((t - first) / self.period).floor() as usize + 1;
            let state = (motion.a[k], motion.b[k]);
            if n < 3 || n > samples.len() || state.0 < SLOWEST_BRANCH * SLOWEST_BRANCH {
                continue;
            }
            // The candidates, quicker first.
            let mut candidates: Vec<(Grid, Motion)> = Vec::with_capacity(2);
            candidates.extend(self.s_curve_stop(curves, grid, along.tight, &mut looked, (k, 0.0), state));
            let mut brake_states = None;
            if let Some((stop, end, cut)) = sets.as_ref().and_then(|sets| p.brake(sets, k, state)) {
                brake_states = Some(stop.a.iter().copied().zip(stop.b.iter().copied()).collect::<Vec<_>>());
                candidates.push((self.cut_grid(curves, grid.slice(k, end), cut), stop));
            }
            candidates.sort_by(|x, y| x.1.time().total_cmp(&y.1.time()));
            let next = first + n as f64 * self.period - t;
            if let Some(points) = self.first_passing(curves, &inverses, candidates.into_iter(), samples, n, next) {
                let at = (grid.stations[k].element, grid.stations[k].u);
                let forked = along.stretch.zip(brake_states).map(|(stretch, stop)| Forked {
                    stop,
                    fork: fork
                        .get_or_init(|| {
                            std::sync::Arc::new(Fork {
                                stretch: *stretch,
                                grid: grid.clone(),
                                lin: along.lin.clone(),
                                tight: along.tight.to_vec(),
                                motion: motion.clone(),
                            })
                        })
                        .clone(),
                    station: k,
                });
                found(
                    n,
                    points,
                    branch(at, (state.0.sqrt(), state.1), next, samples, n, forked),
                )?;
                last = t;
            }
        }
        Ok(())
    }

    /// The samples of the first of `candidates` (stops, each over a grid of its own) that passes
    /// the check continuing the three `samples` before the `n`-th, its first sample `next` after
    /// its start; none longer than [`LONGEST_STOP`].
    fn first_passing(
        &self,
        curves: &PathCurves,
        inverses: &Inverses,
        candidates: impl Iterator<Item = (Grid, Motion)>,
        samples: &[PathPoint],
        n: usize,
        next: f64,
    ) -> Option<Vec<PathPoint>> {
        for (sub, stop) in candidates.filter(|(_, m)| m.time() <= LONGEST_STOP) {
            let mut check = Check::new(&self.limits, self.caps.axes);
            for q in &samples[n - 3..n] {
                check.push(&q.tip);
            }
            let span = sampler::Span {
                first: next,
                at_rest: true,
            };
            let sampled = sampler::sample(
                curves,
                inverses,
                &sub,
                &stop,
                &self.limits,
                self.caps.axes,
                Some(samples[n - 1]),
                &mut check,
                1e-9,
                span,
            );
            if sampled.over.is_empty() {
                return Some(sampled.points);
            }
        }
        None
    }

    /// `sub` with its last interval ending `cut` (its length) into it, where a stop rests there.
    fn cut_grid(&self, curves: &PathCurves, mut sub: Grid, cut: Option<f64>) -> Grid {
        if let Some(length) = cut {
            let last = sub.len() - 1;
            let u = self.u_at(curves, &sub, last, length);
            let (element, s) = (sub.stations[last].element, sub.stations[last].s + length);
            let end = &mut sub.stations[last + 1];
            (end.element, end.u, end.s) = (element, u, s);
            sub.intervals[last].length = length;
        }
        sub
    }

    /// The curve parameter `sigma` into interval `k` of `grid`.
    fn u_at(&self, curves: &PathCurves, grid: &Grid, k: usize, sigma: f64) -> f64 {
        let (st, next) = (&grid.stations[k], &grid.stations[k + 1]);
        let view = curves.view(st.element);
        let u_end = if next.element == st.element {
            next.u
        } else {
            view.u_max()
        };
        sampler::invert(&view, st.u, 0.0, sigma, st.u, u_end, self.caps.axes, None).0
    }

    /// The S-curve stop from the state `(a, b)` at `sigma0` into interval `k` of `grid` (see the
    /// module), as a grid of its own (a station where it starts, the grid's from there on, more
    /// where its phases change inside an interval, the last where it rests) and its motion;
    /// `None` where the limits leave it nothing or it would run past the grid.
    fn s_curve_stop(
        &self,
        curves: &PathCurves,
        grid: &Grid,
        tight: &[f64],
        looked: &mut LookedAt,
        (k, sigma0): (usize, f64),
        (a, b): (f64, f64),
    ) -> Option<(Grid, Motion)> {
        let v0 = a.sqrt();
        let s0 = grid.stations[k].s + sigma0;
        // The limits over the distance the stop covers, until that distance settles (the
        // module's stop profile: jerk down, hold, jerk up to rest).
        let (mut reach, mut settled): (f64, Option<SCurveTable>) = (0.0, None);
        for _ in 0..4 {
            let (accel, jerk) = self.limits_along(curves, grid, tight, looked, k, s0 + reach, v0, b)?;
            let table = stop_from(v0, b, accel, jerk).table_from(b);
            if table.length() <= reach {
                settled = Some(table);
                break;
            }
            reach = table.length() * 1.05;
        }
        let table = settled?;
        let length = table.length();
        if length.is_nan() || length <= 0.0 || s0 + length >= grid.stations[grid.len()].s {
            return None;
        }
        let phases: Vec<usize> = (0..PHASES).filter(|&p| table.profile.durations[p] > 0.0).collect();
        let eps = 1e-12 * (1.0 + length);
        // The bounds of the stop's intervals: the grid's stations before its rest (Some) and
        // where a phase starts inside an interval (None), in path order, then the rest.
        let mut bounds: Vec<(f64, Option<usize>)> = vec![(0.0, (sigma0 == 0.0).then_some(k))];
        bounds.extend(
            (k + 1..=grid.len())
                .map(|j| (grid.stations[j].s - s0, Some(j)))
                .take_while(|&(dj, _)| dj < length - eps),
        );
        for &p in phases.iter().skip(1) {
            let ds = table.states[p].s;
            if ds > eps && ds < length - eps && bounds.iter().all(|(x, _)| (x - ds).abs() > eps) {
                bounds.push((ds, None));
            }
        }
        bounds.sort_by(|x, y| x.0.total_cmp(&y.0));
        bounds.push((length, None));
        let mut sub = Grid::default();
        let mut motion = Motion::default();
        let mut before: Option<(f64, f64, usize)> = None; // distance, time, grid interval
        for (n, &(dist, station)) in bounds.iter().enumerate() {
            // The grid interval the bound lies in (or starts).
            let g = station.unwrap_or_else(|| grid.stations[..grid.len()].partition_point(|st| st.s - s0 <= dist) - 1);
            let mut st = grid.stations[g];
            if station.is_none() {
                st.u = self.u_at(curves, grid, g, dist - (grid.stations[g].s - s0));
                st.s = s0 + dist;
            }
            // The phase there (the last one starting at or before it), and the state.
            let phase = phases
                .iter()
                .rev()
                .copied()
                .find(|&p| table.states[p].s <= dist + eps)
                .unwrap_or(0);
            let (start, jerk) = (table.states[phase], table.profile.jerks[phase]);
            let last = n + 1 == bounds.len();
            let (time, here) = if last {
                (table.total_time(), SCurveState::default())
            } else {
                let phase_piece = Piece::Jerk {
                    v: start.v,
                    b: start.a,
                    jerk,
                };
                let tau = phase_piece.time_to(dist - start.s, table.profile.durations[phase]);
                (table.starts[phase] + tau, start.advance(jerk, tau))
            };
            let (vd, ad) = (here.v.max(0.0), here.a);
            if let Some((d0, t0, g0)) = before {
                sub.intervals.push(Interval {
                    length: dist - d0,
                    ..grid.intervals[g0]
                });
                motion.durations.push(time - t0);
            }
            sub.stations.push(st);
            motion.a.push(vd * vd);
            motion.b.push(ad);
            if !last {
                motion.pieces.push(Piece::Jerk { v: vd, b: ad, jerk });
            }
            before = Some((dist, time, g));
        }
        (motion.pieces.len() == sub.intervals.len() && !sub.intervals.is_empty()).then_some((sub, motion))
    }

    /// The tangential deceleration and jerk the axes allow from station `k` to arc length
    /// `until` (the points [`LookedAt`] in each interval), less what the curvature takes at
    /// the highest speed on the way (from `v0`, accelerating at `a0`): |q'ᵢ|·A + |q''ᵢ|·v² ≤ Aᵢ
    /// and |q'ᵢ|·J + 3|q''ᵢ|·A·v + |q'''ᵢ|·v³ ≤ Jᵢ. `None` where nothing is left.
    #[allow(clippy::too_many_arguments)]
    fn limits_along(
        &self,
        curves: &PathCurves,
        grid: &Grid,
        tight: &[f64],
        looked: &mut LookedAt,
        k: usize,
        until: f64,
        v0: f64,
        a0: f64,
    ) -> Option<(f64, f64)> {
        let axes = self.caps.axes;
        // The intervals up to the one `until` lies in.
        let mut last = k;
        while last + 1 < grid.len() && grid.stations[last + 1].s < until {
            last += 1;
        }
        for j in k..=last {
            looked.interval(curves, grid, tight, axes, j);
        }
        let locals = || looked.intervals[k..=last].iter().flatten().flatten();
        // The highest speed on the way: a rising acceleration first falls to zero (at the
        // jerk found the round before; twice the speed before any).
        let (mut accel, mut jerk) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..2 {
            let v = match (a0 > 0.0, jerk.is_finite()) {
                (false, _) => v0,
                (true, true) => v0 + 0.5 * a0 * a0 / jerk,
                (true, false) => 2.0 * v0,
            };
            let mut acc = f64::INFINITY;
            for (l, f) in locals() {
                for i in (0..axes).filter(|&i| l.q1[i].abs() > 1e-12) {
                    acc = acc.min((self.axis.acceleration[i] * f - l.q2[i].abs() * v * v) / l.q1[i].abs());
                }
            }
            if acc.is_nan() || acc <= 0.0 {
                return None;
            }
            let used = acc.max(a0.abs());
            let mut jk = f64::INFINITY;
            for (l, f) in locals() {
                for i in (0..axes).filter(|&i| l.q1[i].abs() > 1e-12) {
                    let room = self.axis.jerk[i] * f - 3.0 * l.q2[i].abs() * used * v - l.q3[i].abs() * v * v * v;
                    jk = jk.min(room / l.q1[i].abs());
                }
            }
            if jk.is_nan() || jk <= 0.0 {
                return None;
            }
            (accel, jerk) = (acc, jk);
        }
        Some((accel, jerk))
    }
}
