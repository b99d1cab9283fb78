//! Planning time of the Erwinski planner per bundled curve at lab set 1; the motion time of
//! each plan is printed so plan time / motion time can be read off.

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_motion::planner::{plan, Limits, PlanOptions};
use nurbs_motion::readers::read_toolpath;
use std::path::Path;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("plan (lab set 1)");
    g.sample_size(10);
    for name in ["trident", "butterfly", "fan"] {
        let tp = read_toolpath(&Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("examples/{name}.json"))).unwrap();
        let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, 0.00025);
        let p = plan(&tp, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
        println!("{name}: motion time {:.4} s", p.motion_time);
        g.bench_function(name, |b| {
            b.iter(|| plan(&tp, &limits, &PlanOptions::default(), &mut |_| {}).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
