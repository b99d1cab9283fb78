//! `coarse-greedy`: an experiment toward one planner that plans fast and well. VPOp's greedy
//! search (go as fast as a stop stays possible) in continuous time on a coarse step: the
//! tangential jerk is constant over each step of `--step` servo periods, the axis velocity,
//! acceleration and jerk (arc-length derivatives of the tool tip, tabulated) are held at
//! sub-points of every step with a relative `--margin`, and a state is safe when one of VPOp's
//! deceleration settings brings it to rest on the path. Every accepted state is safe, so the
//! search never dead-ends and never goes back (it would stream as it goes). The motion is
//! sampled at the servo period and written in the columns of `nurbs-plan plan`, for
//! `nurbs-plan verify` to judge.
//!
//! Usage: coarse-greedy CURVE.json --limits PRESET [--step K] [--sub N] [--margin M]
//!        [--table N] [--bisections N] [--probe-settings N] [--adaptive-release] --out SETPOINTS.csv
//!
//! `--bisections`: probes between the stop's own step and the largest step (default 4);
//! `--probe-settings`: deceleration settings a probe between them tries (default all five; the
//! largest step is always tried with all); `--adaptive-release`: a stop releases its deceleration
//! with the share of the tangential jerk the axes have left after the curvature terms at each
//! state, instead of a share of the whole.

use nurbs_motion::geometry::{ArcLengthTable, Nurbs};
use nurbs_motion::planner::erwinski::flf::{arc_derivatives, flf_of};
use nurbs_motion::planner::presets::preset;
use nurbs_motion::planner::vpop::{BrakeSetting, BRAKES as VPOP_BRAKES};
use nurbs_motion::planner::Limits;
use nurbs_motion::readers::read_toolpath;
use std::error::Error;
use std::io::Write;
use std::time::Instant;

const MAX_AXES: usize = 3;

/// Arc-length derivatives of the tip (first, second, third) and the speed cap (feed, axis
/// velocity, chord error) on a uniform grid of arc length.
struct Jets {
    ds: f64,
    n: usize,
    rows: Vec<[f64; 3 * MAX_AXES + 1]>,
}

impl Jets {
    fn build(curve: &Nurbs, table: &ArcLengthTable, dim: usize, limits: &Limits, n: usize) -> Self {
        let len = table.total();
        let ds = len / n as f64;
        let view = curve.view();
        let breaks = curve.breakpoints();
        let (u_end, speed) = (breaks[breaks.len() - 1], |u: f64| view.speed(u, dim));
        // Arc length of [a, b] by 3-point Gauss-Legendre (the steps are short).
        let arc = |a: f64, b: f64| {
            let (m, h) = (0.5 * (a + b), 0.5 * (b - a));
            let k = h * (0.6f64).sqrt();
            h * (5.0 * speed(m - k) + 8.0 * speed(m) + 5.0 * speed(m + k)) / 9.0
        };
        // March along the curve: each row's parameter from the last by one Newton step on the
        // arc length (the rows need not sit exactly at k ds: they only bound the constraints).
        let (mut u, mut rows) = (breaks[0], Vec::with_capacity(n + 1));
        for k in 0..=n {
            if k > 0 {
                let guess = (u + ds / speed(u).max(1e-12)).min(u_end);
                let short = ds - arc(u, guess);
                u = (guess + short / speed(guess).max(1e-12)).clamp(u, u_end);
            }
            let x = arc_derivatives(&view, dim, u);
            let f = flf_of(&x, dim, limits);
            let mut r = [0.0; 3 * MAX_AXES + 1];
            for i in 0..dim {
                r[i] = x[1][i];
                r[MAX_AXES + i] = x[2][i];
                r[2 * MAX_AXES + i] = x[3][i];
            }
            r[3 * MAX_AXES] = f.feed.min(f.chord);
            rows.push(r);
        }
        Jets { ds, n, rows }
    }

    /// Linear interpolation of the derivatives; the lower of the two neighbours' speed caps.
    #[inline]
    fn at(&self, s: f64) -> [f64; 3 * MAX_AXES + 1] {
        let x = (s / self.ds).clamp(0.0, self.n as f64);
        let k = (x as usize).min(self.n - 1);
        let f = x - k as f64;
        let (a, b) = (&self.rows[k], &self.rows[k + 1]);
        let mut r = [0.0; 3 * MAX_AXES + 1];
        for i in 0..3 * MAX_AXES {
            r[i] = a[i] + f * (b[i] - a[i]);
        }
        r[3 * MAX_AXES] = a[3 * MAX_AXES].min(b[3 * MAX_AXES]);
        r
    }
}

/// Motion state along the path: arc length, speed, tangential acceleration.
#[derive(Clone, Copy, Debug)]
struct St {
    s: f64,
    v: f64,
    a: f64,
}

/// Whether `[lo, hi]` holds a value (false where either is NaN).
fn spans(lo: f64, hi: f64) -> bool {
    lo <= hi
}

#[inline]
fn adv(x: St, u: f64, t: f64) -> St {
    St {
        s: x.s + x.v * t + 0.5 * x.a * t * t + u * t * t * t / 6.0,
        v: x.v + x.a * t + 0.5 * u * t * t,
        a: x.a + u * t,
    }
}

/// One piece of the motion: constant tangential jerk `u` for `dur` from `start`.
#[derive(Clone, Copy, Debug)]
struct Piece {
    start: St,
    u: f64,
    dur: f64,
}

/// VPOp's deceleration settings that release with a share of the whole jerk (its first five;
/// `--adaptive-release` plays the part of the others here).
const BRAKES: &[BrakeSetting] = VPOP_BRAKES.split_at(5).0;

struct Planner<'j> {
    jets: &'j Jets,
    dim: usize,
    len: f64,
    vmax: [f64; MAX_AXES],
    amax: [f64; MAX_AXES],
    jmax: [f64; MAX_AXES],
    h: f64,
    sub: usize,
    bisections: usize,
    probe_settings: usize,
    adaptive_release: bool,
    evals: u64,
    brake_runs: u64,
    brake_steps: u64,
}

impl Planner<'_> {
    /// The constraints at state `y` with tangential jerk `u`.
    #[inline]
    fn ok_at(&mut self, y: St, u: f64) -> bool {
        self.evals += 1;
        if y.v < 0.0 || y.s > self.len {
            return false;
        }
        let e = self.jets.at(y.s);
        if y.v > e[3 * MAX_AXES] {
            return false;
        }
        for i in 0..self.dim {
            let (q1, q2, q3) = (e[i], e[MAX_AXES + i], e[2 * MAX_AXES + i]);
            let vi = q1 * y.v;
            let ai = q2 * y.v * y.v + q1 * y.a;
            let ji = q3 * y.v * y.v * y.v + 3.0 * q2 * y.v * y.a + q1 * u;
            if vi.abs() > self.vmax[i] || ai.abs() > self.amax[i] || ji.abs() > self.jmax[i] {
                return false;
            }
        }
        true
    }

    /// Constant jerk `u` for `t` from `x`: the constraints at the step's sub-points.
    fn feasible(&mut self, x: St, u: f64, t: f64) -> bool {
        (0..=self.sub).all(|j| self.ok_at(adv(x, u, t * j as f64 / self.sub as f64), u))
    }

    /// Interval of `u` where the constraints linearised at `ug` hold at the sub-points.
    fn bounds_lin(&mut self, x: St, t: f64, ug: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        let clip = |g: f64, dg: f64, lim: f64, lo: &mut f64, hi: &mut f64| {
            if dg.abs() > 1e-300 {
                let (a, b) = ((-lim - g) / dg, (lim - g) / dg);
                *lo = lo.max(ug + a.min(b));
                *hi = hi.min(ug + a.max(b));
            } else if g.abs() > lim {
                *lo = f64::INFINITY;
            }
        };
        for j in 0..=self.sub {
            let tau = t * j as f64 / self.sub as f64;
            let y = adv(x, ug, tau);
            self.evals += 1;
            let e = self.jets.at(y.s.min(self.len));
            let (dv, da) = (0.5 * tau * tau, tau);
            if dv > 0.0 {
                hi = hi.min(ug + (e[3 * MAX_AXES] - y.v) / dv);
                lo = lo.max(ug - y.v / dv);
                // Not past the path end.
                hi = hi.min(ug + (self.len - y.s) / (dv * tau / 3.0));
            }
            for i in 0..self.dim {
                let (q1, q2, q3) = (e[i], e[MAX_AXES + i], e[2 * MAX_AXES + i]);
                clip(q1 * y.v, q1 * dv, self.vmax[i], &mut lo, &mut hi);
                clip(
                    q2 * y.v * y.v + q1 * y.a,
                    2.0 * q2 * y.v * dv + q1 * da,
                    self.amax[i],
                    &mut lo,
                    &mut hi,
                );
                let g = q3 * y.v * y.v * y.v + 3.0 * q2 * y.v * y.a + q1 * ug;
                let dg = 3.0 * q3 * y.v * y.v * dv + 3.0 * q2 * (dv * y.a + y.v * da) + q1;
                clip(g, dg, self.jmax[i], &mut lo, &mut hi);
            }
        }
        (lo, hi)
    }

    /// Largest (`upper`) or smallest feasible jerk for a step of `t` from `x`.
    fn edge(&mut self, x: St, t: f64, upper: bool) -> Option<f64> {
        let (lo, hi) = self.bounds_lin(x, t, 0.0);
        if !spans(lo, hi) {
            return None;
        }
        let mut ug = if upper { hi } else { lo };
        for _ in 0..2 {
            let (l, h) = self.bounds_lin(x, t, ug);
            if !spans(l, h) {
                break;
            }
            ug = if upper { h } else { l };
        }
        if self.feasible(x, ug, t) {
            return Some(ug);
        }
        // A feasible point inside, then bisect towards the edge.
        let mut inside = None;
        for f in [0.5, 0.25, 0.75, 0.1, 0.9] {
            let c = lo + f * (hi - lo);
            if self.feasible(x, c, t) {
                inside = Some(c);
                break;
            }
        }
        let mut good = inside?;
        let mut bad = ug;
        for _ in 0..30 {
            let mid = 0.5 * (good + bad);
            if self.feasible(x, mid, t) {
                good = mid;
            } else {
                bad = mid;
            }
        }
        Some(good)
    }

    /// The braking jerk of setting `b` at `x` for a step of `t`: the strongest deceleration
    /// (within `bf` of the tangential limits the axes allow here) after which releasing it with
    /// `rf` of the tangential jerk still stops before the speed crosses zero.
    fn brake_u(&mut self, x: St, b: usize, t: f64) -> f64 {
        let BrakeSetting {
            brake_fraction: bf,
            switch_fraction: rf,
            ..
        } = BRAKES[b];
        let e = self.jets.at(x.s);
        let (mut jw, mut aw) = (f64::INFINITY, f64::INFINITY);
        for ((q1, jmax), amax) in e[..self.dim].iter().zip(&self.jmax).zip(&self.amax) {
            let d = q1.abs();
            if d > 0.0 {
                jw = jw.min(jmax / d);
                aw = aw.min(amax / d);
            }
        }
        let jr = if self.adaptive_release {
            // The tangential jerk the axes have left after the curvature terms at this state.
            let mut left = f64::INFINITY;
            for i in 0..self.dim {
                let (q1, q2, q3) = (e[i], e[MAX_AXES + i], e[2 * MAX_AXES + i]);
                if q1.abs() > 0.0 {
                    let used = (q3 * x.v * x.v * x.v + 3.0 * q2 * x.v * x.a).abs();
                    left = left.min((self.jmax[i] - used).max(0.0) / q1.abs());
                }
            }
            rf * left.max(0.05 * jw)
        } else {
            rf * jw
        };
        let (jw, aw) = (bf * jw, bf * aw);
        let ok = |u: f64| {
            let y = adv(x, u, t);
            y.v >= 0.0 && (y.a >= 0.0 || y.v >= y.a * y.a / (2.0 * jr))
        };
        let hi = jw;
        let lo = (-jw).max((-aw - x.a) / t).min(hi);
        if ok(lo) || !ok(hi) {
            return if ok(lo) { lo } else { hi };
        }
        let (mut bad, mut good) = (lo, hi);
        for _ in 0..40 {
            let mid = 0.5 * (bad + good);
            if ok(mid) {
                good = mid;
            } else {
                bad = mid;
            }
        }
        good
    }

    /// The last piece of a stop from `x` (decelerating): constant jerk bringing speed and
    /// acceleration to zero together within one step, if it passes.
    fn finish(&mut self, x: St) -> Option<Piece> {
        if x.v == 0.0 && x.a == 0.0 {
            return Some(Piece {
                start: x,
                u: 0.0,
                dur: 0.0,
            });
        }
        if !(x.a < 0.0 && x.v > 0.0) {
            return None;
        }
        let dur = -2.0 * x.v / x.a;
        let u = x.a * x.a / (2.0 * x.v);
        (dur <= self.h && self.feasible(x, u, dur)).then_some(Piece { start: x, u, dur })
    }

    /// One step of the deceleration sequence of setting `b` (the finishing piece where it
    /// fits); `None` where it does not pass.
    fn brake_step(&mut self, x: St, b: usize) -> Option<Piece> {
        if let Some(p) = self.finish(x) {
            return Some(p);
        }
        let u = self.brake_u(x, b, self.h);
        let (lo, hi) = self.bounds_lin(x, self.h, u);
        if !spans(lo, hi) {
            return None;
        }
        let u = u.clamp(lo, hi);
        self.feasible(x, u, self.h).then_some(Piece {
            start: x,
            u,
            dur: self.h,
        })
    }

    /// Does the deceleration sequence of setting `b` bring `x` to rest?
    fn brakes_with(&mut self, mut x: St, b: usize) -> bool {
        self.brake_runs += 1;
        for _ in 0..100_000 {
            self.brake_steps += 1;
            let Some(p) = self.brake_step(x, b) else {
                return false;
            };
            if p.dur < self.h {
                return true;
            }
            x = adv(x, p.u, p.dur);
        }
        false
    }

    /// The first setting (from `first` on, round) whose sequence brings `x` to rest.
    fn safe(&mut self, x: St, first: usize) -> Option<usize> {
        self.safe_among(x, first, BRAKES.len())
    }

    /// [`Self::safe`] trying only `count` settings.
    fn safe_among(&mut self, x: St, first: usize, count: usize) -> Option<usize> {
        (0..count)
            .map(|k| (first + k) % BRAKES.len())
            .find(|&b| self.brakes_with(x, b))
    }

    fn plan(&mut self) -> Result<Vec<Piece>, String> {
        let mut x = St { s: 0.0, v: 0.0, a: 0.0 };
        let mut pieces = Vec::new();
        let mut safe_b = 0;
        for _ in 0..50_000_000 {
            if x.v == 0.0 && x.a == 0.0 && self.len - x.s < 5e-8 {
                return Ok(pieces);
            }
            // The deceleration sequence that makes `x` safe goes on: its step is the fallback.
            let p = self
                .brake_step(x, safe_b)
                .ok_or_else(|| format!("the stop that made s = {} safe does not pass", x.s))?;
            let hi = self.edge(x, self.h, true).filter(|&hi| p.dur == 0.0 || hi > p.u);
            if let Some(hi) = hi {
                let y = adv(x, hi, self.h);
                if let Some(b) = self.safe(y, safe_b) {
                    safe_b = b;
                    pieces.push(Piece {
                        start: x,
                        u: hi,
                        dur: self.h,
                    });
                    x = y;
                    continue;
                }
            }
            let at_rest = p.dur == 0.0;
            let p = if at_rest {
                // At rest: staying is the stop.
                Piece {
                    start: x,
                    u: 0.0,
                    dur: self.h,
                }
            } else {
                p
            };
            if p.dur < self.h {
                // At rest after it (short of the end: start again from there).
                let y = adv(x, p.u, p.dur);
                pieces.push(p);
                x = St { s: y.s, v: 0.0, a: 0.0 };
                continue;
            }
            let Some(hi) = hi else {
                if at_rest && self.len - x.s < 1e-6 {
                    eprintln!("ends {} mm short of the path end", self.len - x.s);
                    return Ok(pieces);
                }
                if at_rest {
                    return Err(format!("no step from rest at s = {} of {}", x.s, self.len));
                }
                pieces.push(p);
                x = adv(x, p.u, p.dur);
                continue;
            };
            let (mut good, mut bad, mut good_b) = (p.u, hi, safe_b);
            // From rest the search may have to creep to the path end: far finer then.
            let bisections = if at_rest { 60 } else { self.bisections };
            for _ in 0..bisections {
                let mid = 0.5 * (good + bad);
                let ok = if self.feasible(x, mid, self.h) {
                    self.safe_among(adv(x, mid, self.h), good_b, self.probe_settings)
                } else {
                    None
                };
                match ok {
                    Some(b) => {
                        good = mid;
                        good_b = b;
                    }
                    None => bad = mid,
                }
            }
            safe_b = good_b;
            if x.v == 0.0 && x.a == 0.0 && good == 0.0 {
                return Err(format!("stuck at rest at s = {} of {}", x.s, self.len));
            }
            pieces.push(Piece {
                start: x,
                u: good,
                dur: self.h,
            });
            x = adv(x, good, self.h);
        }
        Err("too many steps".into())
    }
}

struct Args {
    curve: String,
    limits: Limits,
    step: usize,
    sub: usize,
    margin: f64,
    table: usize,
    bisections: usize,
    probe_settings: usize,
    adaptive_release: bool,
    out: String,
}

fn parse() -> Result<Args, Box<dyn Error>> {
    let mut it = std::env::args().skip(1);
    let (mut curve, mut limits_name, mut out) = (None, None, None);
    let (mut step, mut sub, mut margin, mut table, mut bisections) = (8usize, 4usize, 0.005f64, 20_000usize, 4usize);
    let mut probe_settings = BRAKES.len();
    let mut adaptive_release = false;
    while let Some(a) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--limits" => limits_name = Some(value()?),
            "--step" => step = value()?.parse()?,
            "--sub" => sub = value()?.parse()?,
            "--margin" => margin = value()?.parse()?,
            "--table" => table = value()?.parse()?,
            "--bisections" => bisections = value()?.parse()?,
            "--probe-settings" => probe_settings = value()?.parse()?,
            "--adaptive-release" => adaptive_release = true,
            "--out" => out = Some(value()?),
            _ if !a.starts_with("--") && curve.is_none() => curve = Some(a),
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    let limits_name = limits_name.ok_or("--limits PRESET is needed")?;
    let preset = preset(&limits_name).ok_or_else(|| format!("no limit preset {limits_name}"))?;
    Ok(Args {
        curve: curve.ok_or("a curve file is needed")?,
        limits: preset.limits(),
        step,
        sub,
        margin,
        table,
        bisections,
        probe_settings,
        adaptive_release,
        out: out.ok_or("--out FILE is needed")?,
    })
}

fn main() -> Result<(), Box<dyn Error>> {
    let args = parse()?;
    let toolpath = read_toolpath(std::path::Path::new(&args.curve))?;
    if toolpath.elements.len() != 1 {
        return Err("this experiment takes one smooth curve".into());
    }
    let curve = toolpath.elements[0].curve.clone();
    let dim = curve.tip_dim();
    let limits = args.limits.for_axes(dim).map_err(|e| e.0)?;
    let started = Instant::now();
    let table = ArcLengthTable::new(&curve);
    let jets = Jets::build(&curve, &table, dim, &limits, args.table);
    let tabulated = started.elapsed().as_secs_f64();
    let k = 1.0 - args.margin;
    let axis = |v: &[f64]| {
        let mut a = [f64::INFINITY; MAX_AXES];
        for i in 0..dim {
            a[i] = k * v[i];
        }
        a
    };
    let mut planner = Planner {
        jets: &jets,
        dim,
        len: table.total(),
        vmax: axis(&limits.velocity),
        amax: axis(&limits.acceleration),
        jmax: axis(&limits.jerk),
        h: args.step as f64 * limits.period,
        sub: args.sub,
        bisections: args.bisections,
        probe_settings: args.probe_settings.clamp(1, BRAKES.len()),
        adaptive_release: args.adaptive_release,
        evals: 0,
        brake_runs: 0,
        brake_steps: 0,
    };
    let pieces = planner.plan()?;
    let plan_time = started.elapsed().as_secs_f64();

    let total: f64 = pieces.iter().map(|p| p.dur).sum();
    let periods = (total / limits.period).ceil() as usize;
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args.out)?);
    writeln!(out, "t,u,{},feed,element", ["x", "y", "z"][..dim].join(","))?;
    let (mut k_piece, mut t0) = (0usize, 0.0f64);
    let mut prev: Option<[f64; 3]> = None;
    for n in 0..=periods {
        let t = n as f64 * limits.period;
        while k_piece + 1 < pieces.len() && t >= t0 + pieces[k_piece].dur {
            t0 += pieces[k_piece].dur;
            k_piece += 1;
        }
        let p = &pieces[k_piece];
        let s = adv(p.start, p.u, (t - t0).clamp(0.0, p.dur))
            .s
            .clamp(0.0, table.total());
        let s = if n == periods { table.total() } else { s };
        let u = table.parameter_at(&curve, s);
        let pt = curve.point(u);
        let q = [pt[0], pt[1], if dim > 2 { pt[2] } else { 0.0 }];
        let feed = prev.map_or(0.0, |a| {
            (0..dim).map(|i| (q[i] - a[i]).powi(2)).sum::<f64>().sqrt() / limits.period
        });
        write!(out, "{:?},{:?}", t, u)?;
        for c in &q[..dim] {
            write!(out, ",{c:?}")?;
        }
        writeln!(out, ",{feed:?},0")?;
        prev = Some(q);
    }
    out.flush()?;
    eprintln!(
        "coarse-greedy (step {} periods, {} sub-points, margin {}): motion {:.6} s ({} pieces), plan {:.1} ms (table {:.1} ms), {} evaluations, {} stop runs, {} stop steps",
        args.step,
        args.sub,
        args.margin,
        periods as f64 * limits.period,
        pieces.len(),
        plan_time * 1e3,
        tabulated * 1e3,
        planner.evals,
        planner.brake_runs,
        planner.brake_steps
    );
    Ok(())
}
