//! How soon a motion can start: `cargo bench -p nurbs-planner --bench start`.
//!
//! The streamed Erwinski plan hands out its first group of records (the first records the
//! module may take, with the stop after them) long before the plan ends: criterion's median of
//! the time to that first group, on G1 programs of 200 and 2,000 lines (lab set 1), beside the
//! whole streamed plan (records, stops, hold stops) of the 200-line program, the trident and
//! the butterfly in the same process; and what `nurbs-planner --planner vpop` does before the
//! motion starts (the whole VPOp plan, then the module's stop checked at every block end) on
//! the trident and the butterfly.

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_motion::planner::presets::named;
use nurbs_motion::planner::PathCurves;
use nurbs_planner::feed::{block_plan, plan_groups, stream_plan, vpop_plan, PlanEvent, StreamStart};

#[path = "../tests/common/test_paths.rs"]
#[allow(dead_code)]
mod test_paths;

fn bench_start(c: &mut Criterion) {
    let limits = named("lab1").on(2);
    let mut g = c.benchmark_group("start");
    g.sample_size(10);
    for lines in [200, 2000] {
        let toolpath = test_paths::g1_zigzag(lines);
        g.bench_function(format!("first group ({lines} lines)"), |b| {
            b.iter(|| {
                let mut first = None;
                let open = || Ok(PathCurves::new(&toolpath));
                stream_plan(&open, &limits, StreamStart::Rest(None), 1.0, &mut |e| {
                    if let PlanEvent::Group(group) = e {
                        first = Some(group.slots.len());
                    }
                    first.is_none()
                });
                first.expect("a first group")
            })
        });
    }
    let toolpath = test_paths::g1_zigzag(200);
    g.bench_function("whole plan (200 lines)", |b| {
        b.iter(|| plan_groups(&toolpath, &limits, None).unwrap().len())
    });
    let toolpath = test_paths::dense_arc(2000);
    g.bench_function("whole plan (dense G1, 2000 lines)", |b| {
        b.iter(|| plan_groups(&toolpath, &limits, None).unwrap().len())
    });
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    for name in ["trident.json", "butterfly.json"] {
        let toolpath = nurbs_motion::readers::read_toolpath(&examples.join(name)).unwrap();
        g.bench_function(format!("whole plan ({name})"), |b| {
            b.iter(|| plan_groups(&toolpath, &limits, None).unwrap().len())
        });
    }
    g.finish();
    let mut g = c.benchmark_group("vpop start");
    g.sample_size(10);
    for name in ["trident.json", "butterfly.json"] {
        let toolpath = nurbs_motion::readers::read_toolpath(&examples.join(name)).unwrap();
        g.bench_function(format!("plan ({name})"), |b| {
            b.iter(|| vpop_plan(&toolpath, &limits, None).unwrap().points.len())
        });
        g.bench_function(format!("block stops ({name})"), |b| {
            // Planned here: a run filtered to other benchmarks does not plan it.
            let plan = vpop_plan(&toolpath, &limits, None).unwrap();
            b.iter(|| {
                block_plan(&toolpath, (&plan.points, &plan.limits), None, 1.0)
                    .unwrap()
                    .blocks()
                    .count()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_start);
criterion_main!(benches);
