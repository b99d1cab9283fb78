//! Table I of Erwinski et al. 2022: per-step arc-length error and per-step cost of RK2-PC, SOT, TOT and
//! FCP on the butterfly at lab set 1 (F 2500, A 1e4, J 6e4, eps 0.001, dt 0.25 ms), run in one
//! process so the costs are comparable as ratios.
// The small dense solve below indexes rows and columns like the textbook algorithm.
#![allow(clippy::needless_range_loop)]
//!
//! The error table is printed first (deterministic); criterion then times 1,000 steps of each
//! method along the same stretch of the planned motion.

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_motion::geometry::{ArcLengthTable, Nurbs};
use nurbs_motion::planner::presets::named;
use nurbs_motion::planner::simulate::fit_fcp;
use nurbs_motion::planner::{plan, PathCurves, PlanOptions};
use nurbs_motion::readers::read_toolpath;
use nurbs_rtcore::interpolator::{Interpolator, Step};
use nurbs_rtcore::step_methods::{fcp_eval, rk2pc_step, sot_step, tot_step, PathCursor};
use nurbs_rtcore::{CachedCurve, SpanCache};
use std::hint::black_box;
use std::path::Path;

/// Absolute arc-length targets of every period of the planned butterfly motion.
fn targets() -> (Nurbs, Vec<f64>) {
    let tp = read_toolpath(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/butterfly.json")).unwrap();
    let limits = named("lab1").on(2);
    let p = plan(&tp, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
    let curves = PathCurves::new(&tp);
    let mut interp = Interpolator::new();
    let mut queue = p.records.clone().into_iter();
    let mut s = Vec::new();
    while let Step::Sample(x) = interp.step(&curves, limits.period, &mut || queue.next()) {
        s.push(x.s);
    }
    (tp.elements[0].curve.clone(), s)
}

fn error_table(curve: &Nurbs, s: &[f64]) {
    let table = ArcLengthTable::new(curve);
    let view = curve.view();
    let exact = |u0: f64, u1: f64| table.length_to(curve, u1) - table.length_to(curve, u0);
    let report = |name: &str, us: &[f64]| {
        let (mut sq, mut acc) = (0.0, 0.0);
        for j in 1..us.len() {
            let e = exact(us[j - 1], us[j]) - (s[j] - s[j - 1]);
            sq += e * e;
            acc += e.abs();
        }
        let n = (us.len() - 1) as f64;
        println!("| {name} | {:.3e} | {:.3e} |", sq / n, acc);
    };
    println!("| method | mean squared error per step (mm^2) | accumulated error, sum of abs (mm) |\n|---|---|---|");
    let mut spans = SpanCache::new();
    let cached = &mut CachedCurve::new(view, &mut spans);
    let start = PathCursor::at(cached, 2, curve.u_min(), 0.0);
    let mut cur = start;
    let mut us = vec![cur.u];
    for &t in &s[1..] {
        cur = rk2pc_step(cached, 2, &cur, t);
        us.push(cur.u);
    }
    report("RK2-PC", &us);
    for (name, third) in [("SOT", false), ("TOT", true)] {
        let mut cur = start;
        let mut us = vec![cur.u];
        for j in 1..s.len() {
            cur = if third {
                tot_step(cached, 2, &cur, s[j] - s[j - 1])
            } else {
                sot_step(cached, 2, &cur, s[j] - s[j - 1])
            };
            us.push(cur.u);
        }
        report(name, &us);
    }
    // FCP: one degree-7 polynomial per 2 mm of arc length.
    let total = table.total();
    let pieces = (total / 2.0).ceil() as usize;
    let fits: Vec<[f64; 8]> = (0..pieces)
        .map(|k| {
            fit_fcp(
                curve,
                &table,
                total * k as f64 / pieces as f64,
                total * (k + 1) as f64 / pieces as f64,
            )
        })
        .collect();
    let us: Vec<f64> = s
        .iter()
        .map(|&x| {
            let k = ((x / total * pieces as f64) as usize).min(pieces - 1);
            let local = x / total * pieces as f64 - k as f64;
            fcp_eval(&fits[k], local)
        })
        .collect();
    report("FCP", &us);
}

fn bench(c: &mut Criterion) {
    let (curve, s) = targets();
    error_table(&curve, &s);
    let view = curve.view();
    // A stretch through the butterfly's high-curvature region.
    let first = s.len() / 4;
    let stretch = &s[first..first + 1000];
    let table = ArcLengthTable::new(&curve);
    // Each method keeps its span cache across iterations, as the servo thread does.
    let mut spans = SpanCache::new();
    let start = PathCursor::at(
        &mut CachedCurve::new(view, &mut spans),
        2,
        table.parameter_at(&curve, stretch[0]),
        stretch[0],
    );
    let mut g = c.benchmark_group("interpolation step (1000 steps)");
    g.bench_function("RK2-PC", |b| {
        b.iter(|| {
            let curve = &mut CachedCurve::new(view, &mut spans);
            let mut cur = start;
            for &t in &stretch[1..] {
                cur = rk2pc_step(curve, 2, &cur, t);
            }
            black_box(cur)
        })
    });
    g.bench_function("SOT", |b| {
        b.iter(|| {
            let curve = &mut CachedCurve::new(view, &mut spans);
            let mut cur = start;
            for w in stretch.windows(2) {
                cur = sot_step(curve, 2, &cur, w[1] - w[0]);
            }
            black_box(cur)
        })
    });
    g.bench_function("TOT", |b| {
        b.iter(|| {
            let curve = &mut CachedCurve::new(view, &mut spans);
            let mut cur = start;
            for w in stretch.windows(2) {
                cur = tot_step(curve, 2, &cur, w[1] - w[0]);
            }
            black_box(cur)
        })
    });
    let coeffs = fit_fcp(&curve, &table, stretch[0], stretch[999]);
    g.bench_function("FCP", |b| {
        b.iter(|| {
            let curve = &mut CachedCurve::new(view, &mut spans);
            let mut acc = 0.0;
            for &t in stretch {
                let u = fcp_eval(&coeffs, (t - stretch[0]) / (stretch[999] - stretch[0]));
                acc += curve.point(u)[0];
            }
            black_box(acc)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
