//! The two passes over a grid: backward, the controllable set of every station (the states
//! (a, b) from which some sequence of controls keeps every constraint and ends at rest);
//! forward, the largest control c whose successor stays in the next station's set.
//!
//! Each controllable set is the projection onto (a, b) of the interval's rows in (a, b, c)
//! together with the next set carried back through the exact dynamics. A row with γ > 0 bounds
//! c from above, one with γ < 0 from below; the projection is where the highest lower bound
//! stays below the lowest upper bound. It is built lazily: a polygon holding the state rows is
//! cut, at its worst vertex, by the one pair of rows that binds there, until every vertex
//! qualifies; a cut creates at most two vertices, and only those are evaluated again
//! (O(vertices × rows) per cut). Every cut and the vertex cap ([`Passes::max_vertices`]) only
//! shrink the set, so every accepted state can still stop.

use super::grid::{Axes, Grid, Station, COLLOCATION, TIP};
use super::pieces::Piece;
use super::polygon::{HalfPlane, Polygon};
use super::rows::{point_rows, successor_row, AxisLimits, Point, Row};

/// Collocation points per interval.
const NC: usize = COLLOCATION.len();

/// Everything the passes read: the grid, the limits, the linearisation points, the floors
/// and the per-interval tightening.
pub struct Passes<'a> {
    pub grid: &'a Grid,
    pub limits: AxisLimits,
    pub period: f64,
    /// Linearisation point per station, and per interval at its collocation points.
    pub lin_stations: &'a [f64],
    pub lin_points: &'a [[f64; NC]],
    /// Lowest a per station and collocation point (a floor that keeps the greedy forward pass
    /// from nearly stopping), or none.
    pub floors: Option<(&'a [f64], &'a [[f64; NC]])>,
    /// Factor (≤ 1) on the limits of every interval: where a sampled plan ran over a limit.
    pub tight: &'a [f64],
    /// Most vertices a controllable set keeps.
    pub max_vertices: usize,
    /// Whether the axis jerk is a constraint (without it: the second-order problem, a quick
    /// upper estimate of the feed).
    pub jerk: bool,
    /// Where the motion starts.
    pub start: Start<'a>,
}

/// Where a motion starts: at rest, or already under way (a window of a stretch).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Start<'a> {
    /// The state (a, b) at station 0; `None`: at rest.
    pub state: Option<(f64, f64)>,
    /// Whether the rest at the grid's end is a window's artificial one (whose stop is never
    /// run as planned unless checked): a state off the stop line there (rounding near rest)
    /// ends with the stop from its speed instead of failing.
    pub artificial_end: bool,
    /// States (a, b) from station 0 on that the sets keep where they hold them: the
    /// continuation an earlier window accepted the start state with (the sets' simplification
    /// must not cut it off).
    pub through: &'a [(f64, f64)],
    /// Whether `through` is a motion to rest at the grid's end under these very rows (the
    /// stops along a plan): then the sets keep its states even where the projection's rounding
    /// leaves them just outside (a set is convex, so the hull stays within it).
    pub through_rests: bool,
}

/// The linearisation points of the jerk rows of one interval: at its start, its collocation
/// points and its end.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageLin {
    pub start: f64,
    pub points: [f64; NC],
    pub end: f64,
}

/// The controllable sets of every station, and the linearisation each interval's rows were
/// built with (the forward pass builds the same).
pub struct Sets {
    pub sets: Vec<Polygon>,
    pub lins: Vec<StageLin>,
}

/// Why a pass found no plan.
#[derive(Clone, Debug, PartialEq)]
pub enum PassError {
    /// No state at this station can keep the constraints and stop (only with floors, or an
    /// infeasible start).
    Empty { station: usize },
    /// The motion would come to a standstill inside the stretch.
    Stalls { interval: usize },
}

/// The plan over a grid: the state at every station, the control of every interval, each
/// interval as a piece in time with its duration.
#[derive(Clone, Debug, Default)]
pub struct Motion {
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub pieces: Vec<Piece>,
    pub durations: Vec<f64>,
    /// Stages where the chosen control left the rows' range by more than rounding.
    pub off_range: usize,
    /// Whether the motion stops short of a window's artificial rest with a stop the limits
    /// do not hold (never to be run).
    pub cut_short: bool,
}

impl Motion {
    pub fn time(&self) -> f64 {
        self.durations.iter().sum()
    }

    /// Appends the quadratic `piece` (from the last state, control `c`) over an interval of
    /// length `d` taking `duration`; the state at its end.
    fn advance(&mut self, piece: Piece, duration: f64, c: f64, d: f64) -> (f64, f64) {
        let (a, b) = (self.a[self.a.len() - 1], self.b[self.b.len() - 1]);
        let next = ((a + 2.0 * b * d + c * d * d).max(0.0), b + c * d);
        self.pieces.push(piece);
        self.durations.push(duration);
        self.a.push(next.0);
        self.b.push(next.1);
        next
    }
}

/// Jump of q'' at a station (a join where the curvature changes), if any.
fn jump(st: &Station) -> Option<Axes> {
    if st.left.q2 == st.right.q2 {
        return None;
    }
    let mut d = [0.0; TIP];
    for i in 0..TIP {
        d[i] = st.right.q2[i] - st.left.q2[i];
    }
    Some(d)
}

impl Passes<'_> {
    fn floor_station(&self, k: usize) -> f64 {
        self.floors.map_or(0.0, |(s, _)| s[k])
    }

    /// The linearisation points given for interval `k`.
    fn stage_lin(&self, k: usize) -> StageLin {
        StageLin {
            start: self.lin_stations[k],
            points: self.lin_points[k],
            end: self.lin_stations[k + 1],
        }
    }

    /// The rows of interval `k` without the successor set.
    pub fn stage_rows(&self, k: usize, lin: &StageLin, out: &mut Vec<Row>) {
        out.clear();
        let g = self.grid;
        let (st0, st1, iv) = (&g.stations[k], &g.stations[k + 1], &g.intervals[k]);
        let f = self.tight[k];
        let lim = self.limits.scaled(f);
        let cap = f * f;
        let j0 = jump(st0);
        let j1 = jump(st1);
        // a(σ) = a + 2bσ + cσ² lies between the least and the largest of its Bernstein
        // coefficients a, a + b·D, a(D) over the interval: the middle one is a row of its own
        // (the others are rows at the two ends). Without it the motion could stop and turn
        // back between collocation points.
        let floor_mid = self.floor_station(k).min(self.floor_station(k + 1));
        out.push(Row {
            a: -1.0,
            b: -iv.length,
            c: 0.0,
            d: -floor_mid,
        });
        // The same from above: a(σ) stays below the interval's lowest cap between its points.
        let cap_mid = iv
            .points
            .iter()
            .fold(st0.right.cap.min(st1.left.cap), |m, (_, p)| m.min(p.cap));
        out.push(Row {
            a: 1.0,
            b: iv.length,
            c: 0.0,
            d: cap_mid * cap,
        });
        point_rows(
            out,
            &Point {
                theta: 0.0,
                local: &st0.right,
                a_lin: lin.start,
                state: true,
                jerk: self.jerk,
                jump: j0.as_ref(),
                floor: self.floor_station(k),
                jerk_cap: !self.jerk,
            },
            &lim,
            cap,
            self.period,
        );
        for (j, (theta, local)) in iv.points.iter().enumerate() {
            point_rows(
                out,
                &Point {
                    theta: *theta,
                    local,
                    a_lin: lin.points[j],
                    state: true,
                    jerk: self.jerk,
                    jump: None,
                    floor: self.floors.map_or(0.0, |(_, p)| p[k][j]),
                    jerk_cap: !self.jerk,
                },
                &lim,
                cap,
                self.period,
            );
        }
        point_rows(
            out,
            &Point {
                theta: iv.length,
                local: &st1.left,
                a_lin: lin.end,
                state: j1.is_some() || st1.left.cap != st1.right.cap,
                jerk: self.jerk,
                jump: j1.as_ref(),
                floor: self.floor_station(k + 1),
                jerk_cap: !self.jerk,
            },
            &lim,
            cap,
            self.period,
        );
    }

    /// The largest tangential jerk over interval `k` (no curvature terms): what a
    /// constant-jerk start or stop there may use.
    fn piece_jerk(&self, k: usize) -> f64 {
        let g = self.grid;
        let lim = self.limits.scaled(self.tight[k]);
        let mut jt = lim
            .tangential_jerk(&g.stations[k].right.q1)
            .min(lim.tangential_jerk(&g.stations[k + 1].left.q1));
        for (_, p) in &g.intervals[k].points {
            jt = jt.min(lim.tangential_jerk(&p.q1));
        }
        jt
    }

    /// The state rows of station `k` alone (θ = 0 of interval `k`, or the end station).
    fn station_rows(&self, k: usize, rows: &mut Vec<Row>) {
        rows.clear();
        let g = self.grid;
        let f = self.tight[k.min(g.len() - 1)];
        point_rows(
            rows,
            &Point {
                theta: 0.0,
                local: &g.stations[k].right,
                a_lin: self.lin_stations[k],
                state: true,
                jerk: false,
                jump: None,
                floor: self.floor_station(k),
                jerk_cap: !self.jerk,
            },
            &self.limits.scaled(f),
            f * f,
            self.period,
        );
    }

    /// `poly` clipped by the state rows of station `k`.
    fn station_polygon(&self, k: usize, mut poly: Polygon, rows: &mut Vec<Row>) -> Polygon {
        self.station_rows(k, rows);
        for r in rows.iter() {
            poly.clip(HalfPlane {
                na: r.a,
                nb: r.b,
                d: r.d,
            });
        }
        poly
    }

    /// Whether the state `(a, b)` keeps the state rows of station `k` (to rounding).
    fn station_holds(&self, k: usize, (a, b): (f64, f64), rows: &mut Vec<Row>) -> bool {
        self.station_rows(k, rows);
        rows.iter()
            .all(|r| r.a * a + r.b * b <= r.d + 1e-9 * (r.d.abs() + (r.a * a).abs() + (r.b * b).abs()))
    }

    /// The controllable sets from rest at the end of the grid back to station 0.
    pub fn backward(&self) -> Result<Sets, PassError> {
        let g = self.grid;
        let n = g.len();
        let mut sets = vec![Polygon::default(); n + 1];
        let mut rows = Vec::new();
        // A box every feasible state lies in: |q'_i·b| ≤ A_i + |q''_i|·a with a's cap keeping
        // |q''|·a ≤ A and some |q'_i| ≥ 1/√3, so |b| ≤ 2√3·A; ten times that. (A box far
        // larger would set the polygons' rounding tolerances above a short stretch's states.)
        let a_max = self.limits.acceleration[..self.limits.axes]
            .iter()
            .fold(0.0f64, |m, a| m.max(*a));
        let big = 10.0 * 2.0 * 3f64.sqrt() * a_max;
        // The set the last c-piece must end in: a constant-jerk stop over the last interval,
        // a = −1.5·D·b, |b| ≤ b_e.
        let last = n - 1;
        {
            let d = g.intervals[last].length;
            let jt = self.piece_jerk(last);
            let be = (2.0 * jt * (1.5 * d).sqrt()).powf(2.0 / 3.0);
            let tol = 1e-9 * 1.5 * d * be;
            let mut p = Polygon::rectangle(0.0, 1.5 * d * be * (1.0 + 1e-9), -be, 0.0);
            p.clip(HalfPlane {
                na: 1.0,
                nb: 1.5 * d,
                d: tol,
            });
            p.clip(HalfPlane {
                na: -1.0,
                nb: -1.5 * d,
                d: tol,
            });
            sets[last] = self.station_polygon(last, p, &mut rows);
        }
        if sets[last].is_empty() {
            return Err(PassError::Empty { station: last });
        }
        let mut projector = Projector::default();
        let mut hp = Vec::new();
        let mut lins = vec![StageLin::default(); n];
        for k in (0..last).rev() {
            sets[k + 1].half_planes(&mut hp);
            let d = g.intervals[k].length;
            let cap = g.stations[k].right.cap * self.tight[k] * self.tight[k];
            let lin = self.stage_lin(k);
            self.stage_rows(k, &lin, &mut rows);
            rows.extend(hp.iter().map(|h| successor_row(h.na, h.nb, h.d, d)));
            let mut poly = projector.project(&rows, Polygon::rectangle(0.0, cap.max(0.0), -big, big));
            if poly.is_empty() {
                return Err(PassError::Empty { station: k });
            }
            // The continuation an earlier window accepted stays in the set where the exact
            // projection holds it (the simplification alone could cut it off).
            let keep =
                (self.start.through.get(k)).filter(|&&(a, b)| self.start.through_rests || poly.contains(a, b, 1e-12));
            poly.simplify(self.max_vertices);
            if let Some(&(a, b)) = keep {
                if !poly.contains(a, b, 1e-12) {
                    poly.include([a, b]);
                }
            }
            sets[k] = poly;
            lins[k] = lin;
        }
        Ok(Sets { sets, lins })
    }

    /// The greedy forward pass from rest at station 0 (the first interval a constant-jerk
    /// start), or from the state [`Passes::start`] there, through the sets to rest at the end
    /// of the grid (the last interval a constant-jerk stop).
    pub fn forward(&self, sets: &Sets) -> Result<Motion, PassError> {
        let g = self.grid;
        let n = g.len();
        let mut m = Motion::default();
        let mut rows = Vec::new();
        let mut hp = Vec::new();
        let under_way = self.start.state.filter(|&(a, _)| a > 0.0);
        if let Some((a, b)) = under_way {
            // A state the first set does not hold has no continuation that keeps the rows.
            if !sets.sets[0].contains(a, b, 1e-9) {
                return Err(PassError::Empty { station: 0 });
            }
            m.a.push(a);
            m.b.push(b);
        }
        let first = if under_way.is_some() { 0 } else { 1 };
        // The largest b1 on the start line (1.5·D·b1, b1) inside the set of station 1.
        let (mut a, mut b) = if let Some(state) = under_way {
            state
        } else {
            let d = g.intervals[0].length;
            let jt = self.piece_jerk(0);
            let bmax = (2.0 * jt * (1.5 * d).sqrt()).powf(2.0 / 3.0);
            let (pa, pb) = (1.5 * d * bmax, bmax);
            sets.sets[1].half_planes(&mut hp);
            let mut t: f64 = 1.0;
            for h in &hp {
                let along = h.na * pa + h.nb * pb;
                if along > 0.0 {
                    t = t.min(h.d / along);
                }
            }
            let t = t.max(0.0);
            let (a1, b1) = (t * pa, t * pb);
            let Some((piece, duration)) = Piece::start(a1, b1) else {
                return Err(PassError::Stalls { interval: 0 });
            };
            m.a.extend([0.0, a1]);
            m.b.extend([0.0, b1]);
            m.pieces.push(piece);
            m.durations.push(duration);
            (a1, b1)
        };
        for k in first..n - 1 {
            self.stage_rows(k, &sets.lins[k], &mut rows);
            sets.sets[k + 1].half_planes(&mut hp);
            let d = g.intervals[k].length;
            rows.extend(hp.iter().map(|h| successor_row(h.na, h.nb, h.d, d)));
            let (lo, hi) = c_range(&rows, a, b);
            let c = if lo <= hi {
                if hi.is_finite() {
                    hi
                } else {
                    lo
                }
            } else {
                if lo - hi > 1e-7 * (lo.abs() + hi.abs()) {
                    m.off_range += 1;
                }
                0.5 * (lo + hi)
            };
            // Where the sets leave only a near-stop (a successor at rest, reached with the
            // speed's minimum inside the interval), the rounding of c may let a(θ) dip below
            // zero: take the least c that keeps it positive (the speed then passes a tiny
            // minimum, in finite time) and let the checks judge the rest.
            let c = c.max(no_dip(a, b, d));
            let piece = Piece::quadratic(a, b, c);
            let Some(duration) = piece.duration(d) else {
                if self.start.artificial_end && a > 0.0 {
                    // Short of a window's artificial rest: stop here and stay (what follows is
                    // never run as planned).
                    return Ok(Self::stop_here(m, a, d, n - k));
                }
                return Err(PassError::Stalls { interval: k });
            };
            (a, b) = m.advance(piece, duration, c, d);
        }
        // The constant-jerk stop over the last interval (the state lies on its line up to the
        // set's rounding).
        match Piece::stop(a, b) {
            Some((piece, duration, _)) => {
                m.pieces.push(piece);
                m.durations.push(duration);
            }
            None if a <= 1e-18 => {
                m.pieces.push(Piece::Start { jerk: 0.0 });
                m.durations.push(0.0);
            }
            None if self.start.artificial_end && a > 0.0 => {
                return Ok(Self::stop_here(m, a, g.intervals[n - 1].length, 1))
            }
            None => return Err(PassError::Stalls { interval: n - 1 }),
        }
        m.a.push(0.0);
        m.b.push(0.0);
        Ok(m)
    }

    /// The quickest stop the sets allow from the state `(a, b)` at station `from`: the least
    /// control whose successor stays in the next set, until a successor on the stop line of the
    /// interval after it is in the rows' range (a constant-jerk stop over that interval within
    /// its jerk and the station's rows); then that control and that stop. Every state of the
    /// sets can stop, so this needs no simulation: it is the forward pass with the other bound.
    /// Where the speed would reach zero inside an interval (the least control keeps it only
    /// just above: a crawl), a constant-jerk stop within the interval's jerk ends the motion
    /// there instead. The motion from `from`, the station after its last interval, and where
    /// that interval is cut short, its length to the rest; `None` where the state lies
    /// outside its set or rounding leaves no control.
    pub fn brake(&self, sets: &Sets, from: usize, (mut a, mut b): (f64, f64)) -> Option<(Motion, usize, Option<f64>)> {
        let g = self.grid;
        let n = g.len();
        // A state the set does not quite hold (the forward pass crosses the sets' rounding where
        // the rows leave no range, as here) still brakes as far as the rows allow; the sampled
        // check judges the stop.
        if a.is_nan() || a <= 0.0 || from + 1 >= n || !sets.sets[from].contains(a, b, BRAKE_OUTSIDE) {
            return None;
        }
        let mut m = Motion {
            a: vec![a],
            b: vec![b],
            ..Motion::default()
        };
        let (mut rows, mut hp, mut station) = (Vec::new(), Vec::new(), Vec::new());
        for k in from..n - 1 {
            let d = g.intervals[k].length;
            // A stop inside this interval.
            if let Some((stop, duration, length)) = Piece::stop(a, b) {
                if length <= d {
                    if let Piece::Stop { jerk, .. } = stop {
                        if jerk <= self.piece_jerk(k) {
                            m.pieces.push(stop);
                            m.durations.push(duration);
                            m.a.push(0.0);
                            m.b.push(0.0);
                            return Some((m, k + 1, Some(length)));
                        }
                    }
                }
            }
            self.stage_rows(k, &sets.lins[k], &mut rows);
            // A successor on the next interval's stop line: a1 + 1.5·d1·b1 = 0.
            let d1 = g.intervals[k + 1].length;
            let c_stop = -(a + 2.0 * b * d + 1.5 * d1 * b) / (d * d + 1.5 * d1 * d);
            let (lo, hi) = c_range(&rows, a, b);
            if c_stop >= lo && c_stop <= hi {
                let (a1, b1) = (a + 2.0 * b * d + c_stop * d * d, b + c_stop * d);
                let be = (2.0 * self.piece_jerk(k + 1) * (1.5 * d1).sqrt()).powf(2.0 / 3.0);
                let piece = Piece::quadratic(a, b, c_stop);
                let stop = Piece::stop(a1, b1);
                if let (Some(duration), Some((stop, stop_duration, _)), true) = (
                    piece.duration(d),
                    stop,
                    -b1 <= be && self.station_holds(k + 1, (a1, b1), &mut station),
                ) {
                    m.pieces.extend([piece, stop]);
                    m.durations.extend([duration, stop_duration]);
                    m.a.extend([a1, 0.0]);
                    m.b.extend([b1, 0.0]);
                    return Some((m, k + 2, None));
                }
            }
            sets.sets[k + 1].half_planes(&mut hp);
            rows.extend(hp.iter().map(|h| successor_row(h.na, h.nb, h.d, d)));
            let (lo, hi) = c_range(&rows, a, b);
            if !lo.is_finite() {
                return None;
            }
            // Where the rows leave no range (rounding, or a state just outside its set), the
            // middle, as the forward pass takes it.
            let c = if lo <= hi { lo } else { 0.5 * (lo + hi) };
            let c = c.max(no_dip(a, b, d));
            let piece = Piece::quadratic(a, b, c);
            let duration = piece.duration(d)?;
            (a, b) = m.advance(piece, duration, c, d);
        }
        let (piece, duration, _) = Piece::stop(a, b)?;
        m.pieces.push(piece);
        m.durations.push(duration);
        m.a.push(0.0);
        m.b.push(0.0);
        Some((m, n, None))
    }

    /// Ends `m` (at state a) with a constant-jerk stop over the next interval (length `d`)
    /// whatever its tangential acceleration, at rest for the `left - 1` intervals after it.
    fn stop_here(mut m: Motion, a: f64, d: f64, left: usize) -> Motion {
        let (piece, duration) = match Piece::stop(a, -a / (1.5 * d)) {
            Some((piece, duration, _)) => (piece, duration),
            None => (Piece::Start { jerk: 0.0 }, 0.0),
        };
        m.off_range += 1;
        m.cut_short = true;
        m.pieces.push(piece);
        m.durations.push(duration);
        for _ in 1..left {
            m.pieces.push(Piece::Start { jerk: 0.0 });
            m.durations.push(0.0);
            m.a.push(0.0);
            m.b.push(0.0);
        }
        m.a.push(0.0);
        m.b.push(0.0);
        m
    }
}

/// The range of c the rows leave at the state `(a, b)`: (highest lower bound, lowest upper).
fn c_range(rows: &[Row], a: f64, b: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for r in rows {
        let rest = r.d - r.a * a - r.b * b;
        if r.c > 0.0 {
            hi = hi.min(rest / r.c);
        } else if r.c < 0.0 {
            lo = lo.max(rest / r.c);
        }
    }
    (lo, hi)
}

/// The least c that keeps a(θ) = a + 2bθ + cθ² ≥ 0 over [0, d].
fn no_dip(a: f64, b: f64, d: f64) -> f64 {
    // The end: a + 2bd + cd² ≥ 0.
    let end = -(a + 2.0 * b * d) / (d * d);
    // Decelerating with the minimum at θ = −b/c inside the interval: a − b²/c ≥ 0 too.
    let c = if b >= 0.0 || end < -b / d {
        end
    } else if a > 0.0 {
        (b * b / a).max(-b / d)
    } else {
        f64::INFINITY
    };
    // A hair above, so that the rounded minimum stays above zero.
    c + 1e-9 * c.abs()
}

/// How far (relative) outside its set a state may lie and still brake from the sets.
const BRAKE_OUTSIDE: f64 = 1e-3;

/// Relative gap between the bounds on c that a vertex of a projection may keep (rounding).
const PROJECTION_SLACK: f64 = 1e-3;

/// Rows bounding c from one side, as c ≤ d − a·A − b·B (upper) or c ≥ a·A + b·B − d (lower),
/// kept column by column so that evaluating them all at a vertex vectorises.
#[derive(Default)]
struct Bounds {
    a: Vec<f64>,
    b: Vec<f64>,
    d: Vec<f64>,
}

impl Bounds {
    fn clear(&mut self) {
        self.a.clear();
        self.b.clear();
        self.d.clear();
    }

    fn push(&mut self, a: f64, b: f64, d: f64) {
        self.a.push(a);
        self.b.push(b);
        self.d.push(d);
    }

    fn is_empty(&self) -> bool {
        self.a.is_empty()
    }

    /// The largest a·A + b·B − d over the rows at `v`.
    fn max_at(&self, v: [f64; 2]) -> f64 {
        let mut m = f64::NEG_INFINITY;
        for ((a, b), d) in self.a.iter().zip(&self.b).zip(&self.d) {
            m = m.max(a * v[0] + b * v[1] - d);
        }
        m
    }

    /// The first row where a·A + b·B − d takes the value `x` at `v`.
    fn row_of(&self, v: [f64; 2], x: f64) -> usize {
        (0..self.a.len())
            .find(|&i| self.a[i] * v[0] + self.b[i] * v[1] - self.d[i] == x)
            .unwrap_or(0)
    }
}

/// The lazy projection, with its buffers.
#[derive(Default)]
struct Projector {
    /// c ≤ u.d − u.a·A − u.b·B, stored negated: c ≤ −(a·A + b·B − d).
    upper: Bounds,
    lower: Bounds,
    cache: Vec<Eval>,
    next_cache: Vec<Eval>,
    before: Vec<[f64; 2]>,
    used: Vec<(usize, usize)>,
}

/// A vertex's worst pair: how far its lowest upper bound on c lies below its highest lower
/// bound (`gap` > 0: the vertex does not qualify), and the two bounds.
#[derive(Clone, Copy, Debug)]
struct Eval {
    gap: f64,
    scale: f64,
    lo: f64,
    hi: f64,
}

impl Projector {
    fn eval(&self, v: [f64; 2]) -> Eval {
        let lo = self.lower.max_at(v);
        let hi = -self.upper.max_at(v);
        Eval {
            gap: lo - hi,
            scale: lo.abs().max(hi.abs()),
            lo,
            hi,
        }
    }

    /// Where lower bound `l` on c stays below upper bound `u`: (l.a + u.a)·A + (l.b + u.b)·B ≤
    /// l.d + u.d.
    fn pair(&self, l: usize, u: usize) -> HalfPlane {
        HalfPlane {
            na: self.lower.a[l] + self.upper.a[u],
            nb: self.lower.b[l] + self.upper.b[u],
            d: self.lower.d[l] + self.upper.d[u],
        }
    }

    /// The states of `init` (clipped by the rows without c) for which some c keeps every row.
    fn project(&mut self, rows: &[Row], mut poly: Polygon) -> Polygon {
        self.upper.clear();
        self.lower.clear();
        for r in rows {
            if r.c > 0.0 {
                // c ≤ (d − a·A − b·B)/γ, kept as a·A + b·B − d over γ (negated bound).
                self.upper.push(r.a / r.c, r.b / r.c, r.d / r.c);
            } else if r.c < 0.0 {
                // c ≥ (a·A + b·B − d)/(−γ)
                let g = -r.c;
                self.lower.push(r.a / g, r.b / g, r.d / g);
            } else {
                poly.clip(HalfPlane {
                    na: r.a,
                    nb: r.b,
                    d: r.d,
                });
            }
        }
        if poly.is_empty() || self.lower.is_empty() || self.upper.is_empty() {
            return poly;
        }
        self.cache.clear();
        for v in &poly.vertices {
            let e = self.eval(*v);
            self.cache.push(e);
        }
        self.used.clear();
        // Whether every vertex qualified before the cuts ran out, and whether a vertex was
        // given up on beyond rounding on the way.
        let outside = |e: &Eval| e.gap > PROJECTION_SLACK * e.scale.max(1.0);
        let (mut settled, mut escaped) = (false, false);
        for _ in 0..4 * (rows.len() + 8) {
            let Some((m, worst)) = self
                .cache
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.gap.total_cmp(&y.1.gap))
                .map(|(m, e)| (m, *e))
            else {
                break;
            };
            if worst.gap <= 1e-12 * worst.scale {
                settled = true;
                break;
            }
            let v = poly.vertices[m];
            let pair = (self.lower.row_of(v, worst.lo), self.upper.row_of(v, -worst.hi));
            if self.used.contains(&pair) {
                // Cut by this pair already: what is left over is rounding.
                escaped |= outside(&worst);
                self.cache[m].gap = f64::NEG_INFINITY;
                continue;
            }
            self.used.push(pair);
            let (l, u) = pair;
            let h = self.pair(l, u);
            self.before.clear();
            self.before.extend_from_slice(&poly.vertices);
            if !poly.clip(h) {
                escaped |= outside(&worst);
                self.cache[m].gap = f64::NEG_INFINITY;
                continue;
            }
            if poly.is_empty() {
                return poly;
            }
            // Keep the evaluations of the vertices that survived; evaluate the new ones.
            self.next_cache.clear();
            for v in &poly.vertices {
                let e = match self.before.iter().position(|p| p == v) {
                    Some(i) => self.cache[i],
                    None => self.eval(*v),
                };
                self.next_cache.push(e);
            }
            std::mem::swap(&mut self.cache, &mut self.next_cache);
        }
        // The cuts above give up on a vertex where a cut leaves it (rounding, or rows whose c
        // coefficient is tiny beside the others, whose bounds on c are huge): where one is
        // still outside, cut by every pair of a lower and an upper bound (the exact projection
        // the lazy one saves; on a few stations of long programs).
        if (!settled || escaped) && poly.vertices.iter().any(|v| outside(&self.eval(*v))) {
            for l in 0..self.lower.a.len() {
                for u in 0..self.upper.a.len() {
                    poly.clip(self.pair(l, u));
                    if poly.is_empty() {
                        return poly;
                    }
                }
            }
        }
        poly
    }
}

#[cfg(test)]
mod tests {
    use super::no_dip;

    /// The least c keeping a(θ) ≥ 0 on [0, d]: with it a stays non-negative, with a little
    /// less it dips below zero somewhere.
    #[test]
    fn no_dip_is_the_least_c_that_keeps_the_speed_real() {
        for &(a, b, d) in &[
            (0.158, -66.5, 2.38e-3),   // the minimum inside the interval
            (1.0, -0.1, 1.0),          // the minimum past the end: the end decides
            (1.0, 2.0, 0.5),           // accelerating: the end decides
            (5.1e-11, 1.7e-7, 9.2e-5), // near rest
        ] {
            let c = no_dip(a, b, d);
            let at = |c: f64, th: f64| a + 2.0 * b * th + c * th * th;
            let lowest = |c: f64| {
                (0..=10_000)
                    .map(|i| at(c, d * i as f64 / 1e4))
                    .fold(f64::INFINITY, f64::min)
            };
            assert!(lowest(c) >= 0.0, "({a}, {b}, {d}): c = {c} dips to {}", lowest(c));
            let less = c - 1e-4 * c.abs().max(1e-12);
            assert!(lowest(less) < 0.0, "({a}, {b}, {d}): c = {c} is not the least");
        }
    }
}
