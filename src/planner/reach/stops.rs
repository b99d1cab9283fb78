//! The stops the planner offers along its plan ([`ReachOptions::stops_every`]): what the
//! machine brakes with on a hold. Every state the forward pass accepts lies in its
//! controllable set, so from the state at a station the set-based stop ([`Passes::brake`])
//! needs no simulation. Each is sampled at the servo period from the period after its station
//! and checked by finite differences continuing the three samples before it; the plan itself
//! is unchanged.

use super::*;

/// Speed (mm/s) below which no stop branches off: from there the least control creeps (a
/// speed of 1e-5 mm/s took 800 s to rest on `3D_Chips.ngc`).
const SLOWEST_BRANCH: f64 = 1e-3;
/// Longest stop offered (s): each is stored sample by sample (the slowest measured on
/// `3D_Chips.ngc`, from 2 mm/s, take 0.9 s).
const LONGEST_STOP: f64 = 2.0;

/// A stop branching off a motion after its first `.0` samples: its samples from the next
/// period to rest.
pub(super) type Branch = (usize, Vec<PathPoint>);

/// A motion and what it was planned with.
pub(super) struct Along<'a> {
    pub grid: &'a Grid,
    pub lin: &'a Linearisation,
    pub tight: &'a [f64],
    pub start: Start<'a>,
    pub motion: &'a Motion,
}

/// Hands `points` to `emit`, each stop of `stops` after the points before it.
pub(super) fn hand_out(points: &[PathPoint], stops: &[Branch], emit: &mut Emit<'_>) -> Result<(), ReachError> {
    let mut stops = stops.iter().peekable();
    for (i, p) in points.iter().enumerate() {
        emit(Planned::Point(p)).map_err(ReachError::Plan)?;
        while let Some((_, stop)) = stops.next_if(|(n, _)| *n == i + 1) {
            emit(Planned::Stop(stop)).map_err(ReachError::Plan)?;
        }
    }
    Ok(())
}

impl Planner<'_> {
    /// The stops of [`ReachOptions::stops_every`] branching off `along.motion` at its stations up
    /// to `upto`, about that often: each with the number of `samples` (the motion's, the first
    /// `first` into it) before it, sampled from the next period, and checked by finite
    /// differences continuing the three samples before it (one that runs over is left out: the
    /// block builder has others).
    pub(super) fn branch_stops(
        &self,
        curves: &PathCurves,
        along: &Along<'_>,
        upto: usize,
        first: f64,
        samples: &[PathPoint],
    ) -> Vec<Branch> {
        let Some(every) = self.options.stops_every else {
            return Vec::new();
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
                ..along.start
            },
        };
        let sets = p.backward().ok();
        let mut stops = Vec::new();
        let (mut t, mut last) = (0.0, f64::NEG_INFINITY);
        for k in 1..upto.min(grid.len() - 1) {
            t += along.motion.durations[k - 1];
            if t - last < every || t < first {
                continue;
            }
            // Samples at or before the station.
            let n = ((t - first) / self.period).floor() as usize + 1;
            let state = (along.motion.a[k], along.motion.b[k]);
            if n < 3 || n > samples.len() || state.0 < SLOWEST_BRANCH * SLOWEST_BRANCH {
                continue;
            }
            let Some((motion, end, cut)) = sets.as_ref().and_then(|sets| p.brake(sets, k, state)) else {
                continue;
            };
            if motion.time() > LONGEST_STOP {
                continue;
            }
            let sub = self.cut_grid(curves, grid.slice(k, end), cut);
            let mut check = Check::new(&self.limits, self.caps.axes);
            for q in &samples[n - 3..n] {
                check.push(&q.tip);
            }
            let span = sampler::Span {
                first: first + n as f64 * self.period - t,
                at_rest: true,
            };
            let sampled = sampler::sample(
                curves,
                &sub,
                &motion,
                &self.limits,
                self.caps.axes,
                Some(samples[n - 1]),
                &mut check,
                1e-9,
                span,
            );
            if sampled.over.is_empty() {
                stops.push((n, sampled.points));
                last = t;
            }
        }
        stops
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
        sampler::invert(&view, st.u, 0.0, sigma, st.u, u_end, self.caps.axes)
    }
}
