//! How long a long G1 program waits before the motion starts, three ways, in one process
//! (`cargo bench -p nurbs-hal --features mock-hal --bench start`): a 200-line zigzag of 2 mm lines
//! (corners rounded within 0.001 mm, 399 elements, lab set 1) until the stops of the first 2 s of
//! motion (`nurbs-planner`'s default margin) are checked, as `nurbs-planner` does:
//!
//! - `all stops`: the whole plan, then every record's stop (what the motion waited for before
//!   records carried their stops);
//! - `plan, then stops`: the whole plan, then the stops record by record (the default);
//! - `streamed`: the planner streaming in a thread, stops checked as records come (`--stream`).

use std::collections::VecDeque;
use std::sync::{mpsc, Arc};
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_motion::planner::{plan, Limits, PlanOptions};

#[path = "../src/plan_geometry.rs"]
#[allow(dead_code)]
mod plan_geometry;
#[path = "../src/test_paths.rs"]
#[allow(dead_code)] // each benchmark uses some of the paths
mod test_paths;
use plan_geometry::{Next, Records};

const LINES: usize = 200;
const MARGIN: f64 = 2.0;

/// Checks stops until `MARGIN` seconds of motion are ready (taking a streamed plan's events from
/// `events` as they come); returns the records ready.
fn first_margin(records: &mut Records, events: Option<&mpsc::Receiver<plan_geometry::PlanEvent>>) -> usize {
    let (mut ready, mut count) = (0.0, 0);
    while ready < MARGIN {
        if let Some(events) = events {
            while let Ok(event) = events.try_recv() {
                records.take(event).unwrap();
            }
        }
        match records.next(&mut |_| Some(0)).unwrap() {
            Next::Slot(_, time, _) => (ready, count) = (ready + time, count + 1),
            Next::Waiting => std::thread::sleep(Duration::from_micros(50)),
            Next::Working => {}
            Next::Done => break,
        }
    }
    count
}

fn bench_start(c: &mut Criterion) {
    let toolpath = Arc::new(test_paths::g1_zigzag(LINES));
    let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, 0.00025);
    let mut g = c.benchmark_group(format!("start/{LINES}-line G1 program"));
    g.sample_size(10);
    g.bench_function("all stops", |b| {
        b.iter(|| {
            let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
            plan_geometry::geometry(&toolpath, &plan, 1.0).unwrap().1.len()
        })
    });
    g.bench_function("plan, then stops", |b| {
        b.iter(|| {
            let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
            let mut records = Records::Segments {
                records: plan.records.iter().copied().collect::<VecDeque<_>>(),
                chooser: Box::new(plan_geometry::segment_chooser(&toolpath, &plan, 1.0).unwrap()),
                complete: true,
            };
            first_margin(&mut records, None)
        })
    });
    g.bench_function("streamed", |b| {
        b.iter(|| {
            let (sender, receiver) = mpsc::channel();
            let (path, plan_limits) = (Arc::clone(&toolpath), limits.clone());
            let planner = std::thread::spawn(move || {
                plan_geometry::stream_plan(&path, &plan_limits, None, &mut |e| sender.send(e).is_ok())
            });
            let mut motion = plan_geometry::streamed_motion(&toolpath, &limits, 1.0).unwrap();
            let count = first_margin(&mut motion.records, Some(&receiver));
            drop(receiver);
            planner.join().unwrap();
            count
        })
    });
    g.finish();
}

criterion_group!(benches, bench_start);
criterion_main!(benches);
