//! Per-period cost of `nurbs_interp.update`: `cargo bench -p nurbs-hal --features mock-hal`.
//!
//! The module runs on the in-process mock HAL (pins are plain memory there, as in HAL), fed with
//! the Erwinski plans of the trident and the butterfly (segment records: RK2-PC every period)
//! and the trident's VPOp plan (path blocks: a curve point every period); every measured call
//! is one servo period of the running motion (a finished motion is restarted outside the
//! measurement). Also what validating a newly published geometry costs per period.

use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_hal::channel::Channel;
use nurbs_hal::mock::{self, Value};
use nurbs_hal::module::{rtapi_app_exit, rtapi_app_main};
use nurbs_hal::record::Slot;
use nurbs_hal::user::Component;
use nurbs_motion::planner::{plan, Limits, PlanOptions};
use nurbs_motion::readers::read_toolpath;

#[path = "../src/plan_geometry.rs"]
#[allow(dead_code)]
mod plan_geometry;
#[path = "../src/test_paths.rs"]
#[allow(dead_code)] // each benchmark uses some of the paths
mod test_paths;

const PERIOD_NS: i64 = 250_000;

fn fill(channel: &Channel, slots: &[Slot], mut from: usize) -> usize {
    while let Some(r) = slots.get(from) {
        if channel.segments.push(r).is_err() {
            break;
        }
        from += 1;
    }
    from
}

fn done() -> bool {
    matches!(mock::pin("nurbs_interp.done"), Some(Value::Bit(true)))
}

fn bench_update(c: &mut Criterion) {
    for (name, blocks) in [("trident", false), ("butterfly", false), ("trident", true)] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../examples")
            .join(format!("{name}.json"));
        let toolpath = read_toolpath(&path).unwrap();
        let limits = Limits::uniform(toolpath.tip_dim(), 2500.0, 1e4, 6e4, 0.001, 0.00025);
        let (geometry, slots, label) = if blocks {
            let plan = plan_geometry::vpop_plan(&toolpath, &limits, None).unwrap();
            let (geometry, blocks, _) = plan_geometry::block_geometry(&toolpath, &plan, None, 1.0).unwrap();
            let slots: Vec<Slot> = blocks.iter().map(Slot::block).collect();
            (geometry, slots, format!("update/{name} (VPOp blocks)"))
        } else {
            let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
            let (geometry, slots, _) = plan_geometry::geometry(&toolpath, &plan, 1.0).unwrap();
            (geometry, slots, format!("update/{name}"))
        };

        mock::reset();
        assert_eq!(unsafe { rtapi_app_main() }, 0);
        let planner = Component::new("nurbs-planner").unwrap();
        let channel = planner.attach_channel(Duration::ZERO).unwrap();
        mock::set_pin("nurbs_interp.enable", Value::Bit(true));
        let update = mock::funct("nurbs_interp.update").unwrap();
        let mut sent = 0;
        let restart = |sent: &mut usize| {
            // A new geometry generation restarts the motion from the first record.
            while channel.segments.pop().ok().flatten().is_some() {}
            geometry.publish(channel).unwrap();
            unsafe { mock::call(update, PERIOD_NS as _) }; // takes the geometry
            *sent = 0;
        };
        restart(&mut sent);
        c.bench_function(&label, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    if done() {
                        restart(&mut sent);
                    }
                    if channel.segments.len() < 64 {
                        sent = fill(channel, &slots, sent);
                    }
                    let t = Instant::now();
                    unsafe { mock::call(update, PERIOD_NS as _) };
                    total += t.elapsed();
                }
                total
            })
        });
        drop(planner);
        unsafe { rtapi_app_exit() };
    }
}

/// What the module spends on a newly published geometry: one period's slice of the checks
/// (`VALIDATION_VALUES_PER_PERIOD` values), against the whole geometry of a 1,000-line G1
/// program checked at once (as the module did before it sliced them).
fn bench_validation(c: &mut Criterion) {
    use nurbs_hal::channel::{validate_curves, validate_geometry, CurvesChecked, CurvesCursor};
    use nurbs_hal::module::VALIDATION_VALUES_PER_PERIOD;
    let toolpath = test_paths::g1_zigzag(1000);
    let geometry = plan_geometry::curves_geometry(&toolpath).unwrap();
    let layout = geometry.layout();
    let curves = layout.header.curve_count;
    let slice = validate_curves(&layout, CurvesCursor::default(), VALIDATION_VALUES_PER_PERIOD).unwrap();
    assert!(
        matches!(slice, CurvesChecked::UpTo(_)),
        "the geometry needs more than one slice"
    );
    c.bench_function(&format!("validate/whole geometry ({curves} curves)"), |b| {
        b.iter(|| validate_geometry(std::hint::black_box(&layout)).unwrap())
    });
    c.bench_function("validate/one period's slice", |b| {
        b.iter(|| {
            validate_curves(
                std::hint::black_box(&layout),
                CurvesCursor::default(),
                VALIDATION_VALUES_PER_PERIOD,
            )
            .unwrap()
        })
    });
    // A curve change on the servo thread: the view of a 3,000-point curve, trusted (as the
    // module takes it) against checked again in full (as it did before).
    let long = plan_geometry::curves_geometry(&test_paths::long_spline(3_000)).unwrap();
    let long = long.layout();
    c.bench_function("validate/curve view, checked in full (3,000 points)", |b| {
        b.iter(|| nurbs_hal::channel::valid_curve(std::hint::black_box(&long), 0).unwrap())
    });
    c.bench_function("validate/curve view, trusted (3,000 points)", |b| {
        b.iter(|| nurbs_hal::channel::trusted_curve(std::hint::black_box(&long), 0).unwrap())
    });
}

criterion_group!(benches, bench_update, bench_validation);
criterion_main!(benches);
