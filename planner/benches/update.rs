//! Per-period cost of `nurbs_interp.update`: `cargo bench -p nurbs-planner --bench update`.
//!
//! The module runs on the in-process mock HAL (pins are plain memory there, as in HAL), fed by
//! the planner's own streamer with the streamed Erwinski plans of the trident and the butterfly
//! (segment records: RK2-PC every period) and the trident's VPOp plan (path blocks: a curve
//! point every period); every measured call is one servo period of the running motion (a
//! finished motion is restarted outside the measurement). Also what checking the curves of
//! the geometry stream costs per period.

use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use nurbs_hal::channel::{check_curve, trusted_curve, valid_curve, CurveDesc};
use nurbs_hal::mock::{self, Value};
use nurbs_hal::module::{rtapi_app_exit, rtapi_app_main, VALIDATION_VALUES_PER_PERIOD};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::presets::named;
use nurbs_motion::readers::read_toolpath;
use nurbs_planner::feed::{block_plan, plan_groups, vpop_plan, Source, Streamer};
use nurbs_planner::hal_user::Component;

#[path = "../tests/common/test_paths.rs"]
#[allow(dead_code)] // each benchmark uses some of the paths
mod test_paths;

const PERIOD_NS: i64 = 250_000;

fn done() -> bool {
    matches!(mock::pin("nurbs_interp.done"), Some(Value::Bit(true)))
}

fn bench_update(c: &mut Criterion) {
    for (name, blocks) in [("trident", false), ("butterfly", false), ("trident", true)] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../examples")
            .join(format!("{name}.json"));
        let toolpath = read_toolpath(&path).unwrap();
        let limits = named("lab1").on(toolpath.tip_dim());
        let label = if blocks {
            format!("update/{name} (VPOp blocks)")
        } else {
            format!("update/{name}")
        };
        let groups = (!blocks).then(|| plan_groups(&toolpath, &limits, None).unwrap());
        let vpop = blocks.then(|| vpop_plan(&toolpath, &limits, None).unwrap());
        let source = || match (&groups, &vpop) {
            (Some(g), _) => Source::groups(g.clone(), limits.period),
            (_, Some(p)) => Source::blocks(block_plan(&toolpath, (&p.points, &p.limits), None, 1.0).unwrap()),
            _ => unreachable!(),
        };

        mock::reset();
        // SAFETY: the mock HAL stands in for rtapi_app.
        assert_eq!(unsafe { rtapi_app_main() }, 0);
        let planner = Component::new("nurbs-planner").unwrap();
        let channel = planner.attach_channel(Duration::ZERO).unwrap();
        mock::set_pin("nurbs_interp.enable", Value::Bit(true));
        let update = mock::funct("nurbs_interp.update").unwrap();
        let start = |toolpath: &'static Toolpath| {
            Streamer::new(channel, toolpath.tip_dim(), source(), 0, f64::INFINITY, Instant::now()).unwrap()
        };
        let toolpath: &'static Toolpath = Box::leak(Box::new(toolpath.clone()));
        let mut streamer = start(toolpath);
        c.bench_function(&label, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    if done() {
                        // A new geometry stream restarts the motion from its first record.
                        streamer = start(toolpath);
                    }
                    streamer.fill().unwrap();
                    let t = Instant::now();
                    // SAFETY: the exported function with its instance.
                    unsafe { mock::call(update, PERIOD_NS as _) };
                    total += t.elapsed();
                }
                total
            })
        });
        drop(streamer);
        drop(planner);
        // SAFETY: loaded above.
        unsafe { rtapi_app_exit() };
    }
}

/// The curves of `toolpath` as the arena holds them, with their descriptors.
fn arena_of(toolpath: &Toolpath) -> (Vec<f64>, Vec<CurveDesc>) {
    let (mut values, mut descs) = (Vec::new(), Vec::new());
    for (i, e) in toolpath.elements.iter().enumerate() {
        let c = &e.curve;
        let at = values.len() as u32;
        let (k, p, w) = (
            c.knots().len() as u32,
            c.points().len() as u32,
            c.weights().len() as u32,
        );
        values.extend(c.knots().iter().chain(c.points()).chain(c.weights()));
        descs.push(CurveDesc {
            index: i as u32,
            degree: c.degree() as u32,
            dim: c.dim() as u32,
            knots_offset: at,
            knots_len: k,
            points_offset: at + k,
            points_len: p,
            weights_offset: at + k + p,
            weights_len: w,
            reserved: 0,
        });
    }
    (values, descs)
}

/// One period's slice of the curve checks (`VALIDATION_VALUES_PER_PERIOD` values) of a
/// 1,000-line G1 program's curves, against all of its curves at once; and the view of a
/// 3,000-point curve at a change of curve on the servo thread, trusted (as the module takes it)
/// against checked in full.
fn bench_validation(c: &mut Criterion) {
    let (values, descs) = arena_of(&test_paths::g1_zigzag(1000));
    let slice = |budget: usize| {
        let (mut left, mut k, mut cursor) = (budget, 0, 0);
        while left > 0 && k < descs.len() {
            let (used, next) = check_curve(&descs[k], &values, 2, cursor, left).unwrap();
            left = left.saturating_sub(used);
            match next {
                Some(c) => cursor = c,
                None => (k, cursor) = (k + 1, 0),
            }
        }
        k
    };
    c.bench_function(&format!("validate/all curves ({})", descs.len()), |b| {
        b.iter(|| slice(std::hint::black_box(usize::MAX)))
    });
    c.bench_function("validate/one period's slice", |b| {
        b.iter(|| slice(std::hint::black_box(VALIDATION_VALUES_PER_PERIOD)))
    });
    let (long, long_desc) = arena_of(&test_paths::long_spline(3_000));
    c.bench_function("validate/curve view, checked in full (3,000 points)", |b| {
        b.iter(|| valid_curve(std::hint::black_box(&long_desc[0]), &long, 2).unwrap())
    });
    c.bench_function("validate/curve view, trusted (3,000 points)", |b| {
        b.iter(|| trusted_curve(std::hint::black_box(&long_desc[0]), &long, 2).unwrap())
    });
}

criterion_group!(benches, bench_update, bench_validation);
criterion_main!(benches);
