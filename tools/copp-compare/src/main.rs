//! `copp-compare`: the public `copp` crate's third-order time-optimal path parameterization
//! (Wang, Hu, Li et al., IJMTM 2026: TOPP3 as a sequence of second-order cone programs, Clarabel
//! inside) run on one of our curves with one of our limit sets, and written as a setpoint CSV in
//! the columns of `nurbs-plan plan`, so that `nurbs-plan verify` judges it exactly as it judges
//! our planners (finite differences at the servo period, chord error, feed, end points).
//!
//! What goes in: the tool-tip curve parameterised by arc length on a station grid (uniform,
//! refined where the curve turns: at most `--turn` radians per interval), its derivatives up to
//! the third by arc length (the FLF scan's `arc_derivatives`), the axis velocity, acceleration
//! and jerk limits, and the FLF's feed, axis-velocity and chord-error caps (eq. 10 of Erwinski
//! et al.) as a bound on the path speed at every station. copp enforces the
//! limits at the stations only; between them the sampled motion may exceed them, which is what
//! the verifier measures. `--margin m` scales the axis limits and the speed cap by (1 - m)
//! before solving.
//!
//! The sampled motion: copp's `t(s)` and `s(t)`, sampled at `k t_f / n` with n = ceil(t_f / T)
//! (a uniform stretch of at most one period, so that the last sample is the path end at rest)
//! and written at `k T`.
//!
//! Usage: copp-compare CURVE.json --limits PRESET [--intervals N] [--turn RAD] [--margin M]
//!        [--iterations K] [--method socp|lp] --out SETPOINTS.csv [--summary S.json]

use copp::diag::PathError;
use copp::path::{Path as CoppPath, PathEvaluator2nd, PathEvaluator3rd};
use copp::robot::Robot;
use copp::solver::topp2_ra::{topp2_ra, ReachSet2OptionsBuilder, Topp2ProblemBuilder};
use copp::solver::{topp3_lp, topp3_socp};
use copp::InterpolationMode;
use nurbs_motion::geometry::{ArcLengthTable, Nurbs};
use nurbs_motion::planner::erwinski::flf::{arc_derivatives, flf_of};
use nurbs_motion::planner::presets::preset;
use nurbs_motion::planner::Limits;
use nurbs_motion::readers::read_toolpath;
use nurbs_rtcore::Vector;
use std::error::Error;
use std::io::Write;
use std::sync::Arc;
use std::time::Instant;

/// The tool-tip curve by arc length: position and derivatives with respect to s.
struct ArcLengthCurve {
    curve: Nurbs,
    table: ArcLengthTable,
    dim: usize,
}

impl ArcLengthCurve {
    fn new(curve: Nurbs) -> Self {
        let table = ArcLengthTable::new(&curve);
        let dim = curve.tip_dim();
        ArcLengthCurve { curve, table, dim }
    }

    fn length(&self) -> f64 {
        self.table.total()
    }

    fn parameter(&self, s: f64) -> f64 {
        self.table.parameter_at(&self.curve, s)
    }

    fn curvature(&self, s: f64) -> f64 {
        self.curve.curvature(self.parameter(s))
    }

    /// q and its first three derivatives by arc length at `s` (the FLF scan's own).
    fn jet(&self, s: f64) -> [Vector; 4] {
        arc_derivatives(&self.curve.view(), self.dim, self.parameter(s))
    }

    fn fill(&self, s: &[f64], bufs: &mut [&mut [f64]]) {
        let n = self.dim;
        for (k, &sk) in s.iter().enumerate() {
            let jet = self.jet(sk);
            for (order, buf) in bufs.iter_mut().enumerate() {
                buf[k * n..(k + 1) * n].copy_from_slice(&jet[order][..n]);
            }
        }
    }
}

impl PathEvaluator2nd for ArcLengthCurve {
    fn dim(&self) -> usize {
        self.dim
    }
    fn evaluate_up_to_2nd(&self, s: &[f64], q: &mut [f64], dq: &mut [f64], ddq: &mut [f64]) -> Result<(), PathError> {
        self.fill(s, &mut [q, dq, ddq]);
        Ok(())
    }
}

impl PathEvaluator3rd for ArcLengthCurve {
    fn evaluate_up_to_3rd(
        &self,
        s: &[f64],
        q: &mut [f64],
        dq: &mut [f64],
        ddq: &mut [f64],
        dddq: &mut [f64],
    ) -> Result<(), PathError> {
        self.fill(s, &mut [q, dq, ddq, dddq]);
        Ok(())
    }
}

struct Args {
    curve: String,
    limits: Limits,
    limits_name: String,
    intervals: usize,
    turn: f64,
    margin: f64,
    iterations: usize,
    lp: bool,
    out: String,
    summary: Option<String>,
}

fn parse() -> Result<Args, Box<dyn Error>> {
    let mut it = std::env::args().skip(1);
    let (mut curve, mut limits_name, mut out, mut summary) = (None, None, None, None);
    let (mut intervals, mut turn, mut margin, mut iterations, mut lp) = (2000usize, 0.02f64, 0.0f64, 2usize, false);
    while let Some(a) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--limits" => limits_name = Some(value()?),
            "--intervals" => intervals = value()?.parse()?,
            "--turn" => turn = value()?.parse()?,
            "--margin" => margin = value()?.parse()?,
            "--iterations" => iterations = value()?.parse()?,
            "--method" => lp = value()? == "lp",
            "--out" => out = Some(value()?),
            "--summary" => summary = Some(value()?),
            _ if !a.starts_with("--") && curve.is_none() => curve = Some(a),
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    let limits_name = limits_name.ok_or("--limits PRESET is needed")?;
    let preset = preset(&limits_name).ok_or_else(|| format!("no limit preset {limits_name}"))?;
    Ok(Args {
        curve: curve.ok_or("a curve file is needed")?,
        limits: preset.limits(),
        limits_name,
        intervals,
        turn,
        margin,
        iterations: iterations.max(1),
        lp,
        out: out.ok_or("--out FILE is needed")?,
        summary,
    })
}

/// Stations from 0 to the curve length: at most `length / intervals` apart and turning at most
/// `turn` radians between two (curvature sampled at both ends of each interval).
fn stations(path: &ArcLengthCurve, intervals: usize, turn: f64) -> Vec<f64> {
    let length = path.length();
    let h_max = length / intervals as f64;
    let mut s = vec![0.0];
    let mut at = 0.0;
    while at < length {
        let mut h = h_max.min(turn / path.curvature(at).max(1e-12));
        while h > 1e-9 && path.curvature((at + h).min(length)) * h > turn {
            h *= 0.7;
        }
        at = (at + h).min(length);
        if length - at < 0.2 * h {
            at = length;
        }
        s.push(at);
    }
    s
}

fn main() -> Result<(), Box<dyn Error>> {
    let args = parse()?;
    let toolpath = read_toolpath(std::path::Path::new(&args.curve))?;
    if toolpath.elements.len() != 1 {
        return Err(format!(
            "{}: {} elements; this comparison takes one smooth curve",
            args.curve,
            toolpath.elements.len()
        )
        .into());
    }
    let curve = toolpath.elements[0].curve.clone();
    let path = Arc::new(ArcLengthCurve::new(curve));
    let dim = path.dim;
    let limits = args.limits.for_axes(dim).map_err(|e| e.0)?;
    let scale = 1.0 - args.margin;
    let started = Instant::now();

    let s = stations(&path, args.intervals, args.turn);
    let n = s.len();
    // Feed, axis velocity and chord error (the FLF's own caps, eq. 10 of Erwinski et al.): a
    // bound on the path speed at every station.
    let speed_cap: Vec<f64> = s
        .iter()
        .map(|&sk| {
            let caps = flf_of(&path.jet(sk), dim, &limits);
            let v = scale * caps.feed.min(caps.chord);
            v * v
        })
        .collect();
    let copp_path = CoppPath::from_shared_evaluator_3rd(path.clone(), 0.0, path.length())?;
    let per_axis = |v: &[f64], sign: f64| -> Vec<f64> { v.iter().map(|x| sign * x * scale).collect() };
    let (v_max, v_min) = (per_axis(&limits.velocity, 1.0), per_axis(&limits.velocity, -1.0));
    let (a_max, a_min) = (
        per_axis(&limits.acceleration, 1.0),
        per_axis(&limits.acceleration, -1.0),
    );
    let (j_max, j_min) = (per_axis(&limits.jerk, 1.0), per_axis(&limits.jerk, -1.0));
    let mut robot = Robot::with_capacity(dim, n);
    robot
        .with_s(s.as_slice())?
        .with_q_from_path_3rd(&copp_path, 0, n)?
        .with_axial_velocity((v_max.as_slice(), n), (v_min.as_slice(), n), 0)?
        .with_axial_acceleration((a_max.as_slice(), n), (a_min.as_slice(), n), 0)?
        .with_axial_jerk((j_max.as_slice(), n), (j_min.as_slice(), n), 0)?;
    robot.constraints.with_constraint_1order(speed_cap.as_slice(), 0)?;

    // Second order first (no jerk): the linearisation point of the third-order problem.
    let a_ra = {
        let problem = Topp2ProblemBuilder::new(&robot, (0, n - 1), (0.0, 0.0)).build()?;
        topp2_ra(&problem, &ReachSet2OptionsBuilder::new().build()?)?
    };
    robot.constraints.amax_substitute(&a_ra, 0)?;
    let mut linearization = a_ra;
    let mut profile = None;
    let mut solved = 0;
    for _ in 0..args.iterations {
        let next: Result<_, Box<dyn Error>> = (|| {
            Ok(if args.lp {
                let problem = topp3_lp::Topp3ProblemBuilder::new(&mut robot, 0, &linearization, (0.0, 0.0), (0.0, 0.0))
                    .build_with_linearization()?;
                let options = topp3_lp::ClarabelOptionsBuilder::new()
                    .allow_almost_solved(true)
                    .build()?;
                topp3_lp::topp3_lp(&problem, &options)?
            } else {
                let problem =
                    topp3_socp::Topp3ProblemBuilder::new(&mut robot, 0, &linearization, (0.0, 0.0), (0.0, 0.0))
                        .build_with_linearization()?;
                let options = topp3_socp::ClarabelOptionsBuilder::new()
                    .allow_almost_solved(true)
                    .build()?;
                topp3_socp::topp3_socp(&problem, &options)?
            })
        })();
        // Every iterate is feasible (the jerk rows are an inner linearisation): where a later
        // one fails, the last one solved stands.
        let next = match next {
            Ok(next) => next,
            Err(e) if profile.is_some() => {
                eprintln!(
                    "iteration {} failed ({e}); the result of iteration {solved} stands",
                    solved + 1
                );
                break;
            }
            Err(e) => return Err(e),
        };
        linearization = next.a.clone();
        profile = Some(next);
        solved += 1;
    }
    let profile = profile.ok_or("no iteration ran")?;
    let (t_final, t_s) = topp3_socp::s_to_t_topp3(&s, profile.as_parts(), 0.0)?;
    let solve_time = started.elapsed().as_secs_f64();

    // Samples at k t_f / n, written at k T: the last one at the path end.
    let periods = (t_final / limits.period).ceil() as usize;
    let times: Vec<f64> = (0..=periods).map(|k| k as f64 * t_final / periods as f64).collect();
    let s_t = topp3_socp::t_to_s_topp3(
        &s,
        profile.as_parts(),
        &t_s,
        InterpolationMode::NonUniformTimeGrid(&times),
    )?;
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args.out)?);
    writeln!(out, "t,u,{},feed,element", ["x", "y", "z"][..dim].join(","))?;
    let mut prev: Option<[f64; 3]> = None;
    for (k, &sk) in s_t.iter().enumerate() {
        let sk = if k == periods {
            path.length()
        } else {
            sk.clamp(0.0, path.length())
        };
        let u = path.parameter(sk);
        let p = path.curve.point(u);
        let q = [p[0], p[1], if dim > 2 { p[2] } else { 0.0 }];
        let feed = prev.map_or(0.0, |a| {
            (0..dim).map(|i| (q[i] - a[i]).powi(2)).sum::<f64>().sqrt() / limits.period
        });
        write!(out, "{:?},{:?}", k as f64 * limits.period, u)?;
        for c in &q[..dim] {
            write!(out, ",{c:?}")?;
        }
        writeln!(out, ",{feed:?},0")?;
        prev = Some(q);
    }
    out.flush()?;
    let motion_time = periods as f64 * limits.period;
    eprintln!(
        "copp TOPP3-{} ({} of {} iterations, {} stations, margin {}): t_f {:.6} s, motion {:.6} s at {} s, solve {:.1} ms",
        if args.lp { "LP" } else { "SOCP" },
        solved,
        args.iterations,
        n,
        args.margin,
        t_final,
        motion_time,
        limits.period,
        solve_time * 1e3
    );
    if let Some(summary) = args.summary {
        let json = serde_json::json!({
            "curve": args.curve,
            "limits": args.limits_name,
            "method": if args.lp { "topp3-lp" } else { "topp3-socp" },
            "iterations": args.iterations,
            "iterations_solved": solved,
            "stations": n,
            "turn_rad": args.turn,
            "margin": args.margin,
            "t_final_s": t_final,
            "motion_time_s": motion_time,
            "plan_time_s": solve_time,
        });
        std::fs::write(summary, serde_json::to_string_pretty(&json)?)?;
    }
    Ok(())
}
