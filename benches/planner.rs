//! Planning time of the Erwinski planner per bundled curve at lab set 1: the time until the
//! first record is final (the streaming planner's latency) and the time of the whole plan, in
//! the same run. The motion time of each plan is printed so plan time / motion time can be
//! read off, and a median of each time with their ratio. As a baseline run in the same process,
//! the time to replay the plan's records through the RK2-PC interpolator (the setpoints the
//! machine gets): plan time / replay time does not drift with this shared machine's speed.

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::presets::named;
use nurbs_motion::planner::simulate::setpoints;
use nurbs_motion::planner::{plan, Limits, PathCurves, PlanOptions, Planner};
use nurbs_motion::readers::read_toolpath;
use std::path::Path;
use std::time::Instant;

fn first_record(tp: &Toolpath, limits: &Limits) {
    let mut planner = Planner::new(
        tp,
        limits,
        &PlanOptions {
            stream: true,
            ..PlanOptions::default()
        },
    )
    .unwrap();
    planner.next().unwrap().unwrap();
}

fn median_ms(runs: usize, f: &dyn Fn()) -> f64 {
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[runs / 2]
}

fn bench(c: &mut Criterion) {
    let curves = ["trident", "butterfly", "fan"];
    let paths: Vec<Toolpath> = curves
        .iter()
        .map(|name| {
            read_toolpath(&Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/{name}.json"))).unwrap()
        })
        .collect();
    let limits = named("lab1").on(2);
    for (name, tp) in curves.iter().zip(&paths) {
        let p = plan(tp, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
        let first = median_ms(11, &|| first_record(tp, &limits));
        let full = median_ms(11, &|| {
            plan(tp, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
        });
        let replay = median_ms(11, &|| {
            setpoints(&PathCurves::new(tp), &limits, &p.records);
        });
        println!(
            "{name}: motion time {:.4} s; median of 11: first record {first:.2} ms, whole plan {full:.2} ms, \
             first / whole {:.1} %, replay {replay:.2} ms, whole plan / replay {:.2}",
            p.motion_time,
            100.0 * first / full,
            full / replay
        );
    }
    let mut g = c.benchmark_group("first record (lab set 1)");
    g.sample_size(10);
    for (name, tp) in curves.iter().zip(&paths) {
        g.bench_function(*name, |b| b.iter(|| first_record(tp, &limits)));
    }
    g.finish();
    let mut g = c.benchmark_group("plan (lab set 1)");
    g.sample_size(10);
    for (name, tp) in curves.iter().zip(&paths) {
        g.bench_function(*name, |b| {
            b.iter(|| plan(tp, &limits, &PlanOptions::default(), &mut |_| {}).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
