//! Planning time of VPOp on the trident with the VPOp paper's limits (F 166.667 mm/s, dt 6 ms,
//! chord tolerance 0.02 mm); the motion time of the plan is printed.

// The limit sets of the test suites (only `limits.rs`: the rest of tests/common is test-only).
#[path = "../tests/common/limits.rs"]
mod limits;

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_motion::planner::vpop::{plan_tip, SearchOptions};
use nurbs_motion::readers::read_toolpath;
use std::path::Path;

fn bench(c: &mut Criterion) {
    let tp = read_toolpath(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/trident.json")).unwrap();
    let limits = limits::trident_vpop();
    let p = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    println!(
        "trident (VPOp limits): motion time {:.3} s, {} setpoints, {:?}",
        p.motion_time,
        p.points.len(),
        p.stats
    );
    let mut g = c.benchmark_group("vpop");
    g.sample_size(20);
    g.bench_function("trident VPOp limits", |b| {
        b.iter(|| plan_tip(&tp, &limits, SearchOptions::default()).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
