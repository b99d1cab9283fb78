//! `rtapi_app_main` and `nurbs_interp.update` driven period by period through the mock HAL,
//! with a counting allocator that proves the update path allocates nothing.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::simulate::setpoints;
use nurbs_motion::planner::{plan, Limits, PathCurves, Plan, PlanOptions};
use nurbs_motion::readers::read_toolpath;
use nurbs_rtcore::executor::Sample;

use crate::channel::{Channel, Record, RecordStop, SegmentRecord, Slot};
use crate::mock::{self, Value};
use crate::module::{rtapi_app_exit, rtapi_app_main, FaultCode};
use crate::plan_geometry::StopChoice;
use crate::sys;
use crate::test_paths::{g1_zigzag, long_spline, rounded_polyline};
use crate::user::{Component, GeometryBuilder, StreamReader, StreamValue};

/// Counts this thread's allocations (thread-local, so parallel tests do not disturb each other).
struct CountingAlloc;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    // try_with: no panic during thread teardown.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

// SAFETY: forwards to System; counting has no effect on the returned memory.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// The module keeps its component id in process-wide statics (as a loaded .so does): one
/// module test at a time.
static MODULE: Mutex<()> = Mutex::new(());

const PERIOD_NS: i64 = 250_000;
const PERIOD: f64 = 0.00025;

fn float(name: &str) -> f64 {
    match mock::pin(name) {
        Some(Value::Float(v)) => v,
        other => panic!("{name}: {other:?}"),
    }
}

fn u32_pin(name: &str) -> u32 {
    match mock::pin(name) {
        Some(Value::U32(v)) => v,
        other => panic!("{name}: {other:?}"),
    }
}

fn bit(name: &str) -> bool {
    match mock::pin(name) {
        Some(Value::Bit(v)) => v,
        other => panic!("{name}: {other:?}"),
    }
}

/// Load the module and attach a planner component to its channel.
fn load() -> (Component, &'static Channel) {
    mock::reset();
    assert_eq!(unsafe { rtapi_app_main() }, 0, "{:?}", mock::messages());
    assert_eq!(mock::component_ready("nurbs_interp"), Some(true));
    let planner = Component::new("nurbs-planner").unwrap();
    let channel = planner.attach_channel(Duration::ZERO).unwrap();
    (planner, channel)
}

/// Load the module, enable it and publish the geometry of `job`: ready for its records.
fn load_enabled(job: &Job) -> (Component, &'static Channel) {
    let (planner, channel) = load();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    geometry(job).publish(channel).unwrap();
    (planner, channel)
}

/// The module statics for this test alone (see `MODULE`), also after another test panicked.
/// The module's output of this period: x, y, feed, u, curve.
fn sample_pins() -> [f64; 5] {
    [
        float("nurbs_interp.pos-cmd-x"),
        float("nurbs_interp.pos-cmd-y"),
        float("nurbs_interp.feed"),
        float("nurbs_interp.u"),
        u32_pin("nurbs_interp.curve") as f64,
    ]
}

fn lock_module() -> MutexGuard<'static, ()> {
    MODULE.lock().unwrap_or_else(|e| e.into_inner())
}

/// A toolpath, its plan, the offline setpoints (what `nurbs-plan plan --out` writes) and what
/// nurbs-planner sends for it: the geometry and the records as slots with their checked stops
/// (default stop fraction 1).
struct Job {
    toolpath: Toolpath,
    plan: Plan,
    limits: Limits,
    records: Vec<SegmentRecord>,
    samples: Vec<Sample>,
    geometry: GeometryBuilder,
    slots: Vec<Slot>,
    choices: Vec<StopChoice>,
}

fn job(name: &str) -> Job {
    job_at(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../examples")
            .join(name),
    )
}

fn job_at(path: &std::path::Path) -> Job {
    job_of(read_toolpath(path).unwrap())
}

/// `toolpath` planned at lab set 1.
fn job_of(toolpath: Toolpath) -> Job {
    let limits = Limits::uniform(toolpath.tip_dim(), 2500.0, 1e4, 6e4, 0.001, PERIOD);
    let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
    let samples = setpoints(&PathCurves::new(&toolpath), &plan.limits, &plan.records);
    let (geometry, slots, choices) = crate::plan_geometry::geometry(&toolpath, &plan, 1.0).unwrap();
    Job {
        limits: plan.limits.clone(),
        records: plan.records.clone(),
        plan,
        samples,
        toolpath,
        geometry,
        slots,
        choices,
    }
}

/// What nurbs-planner publishes.
fn geometry(job: &Job) -> &GeometryBuilder {
    &job.geometry
}

/// Push slots from `from` while the ring has room; returns the next index.
fn fill(channel: &Channel, slots: &[Slot], mut from: usize) -> usize {
    while let Some(r) = slots.get(from) {
        if channel.segments.push(r).is_err() {
            break;
        }
        from += 1;
    }
    from
}

#[test]
fn module_creates_its_pins_and_function() {
    let _guard = lock_module();
    let (planner, _) = load();
    let names = mock::pin_names();
    for pin in [
        "enable",
        "pos-cmd-x",
        "pos-cmd-y",
        "pos-cmd-z",
        "feed",
        "u",
        "curve",
        "active",
        "done",
        "fault",
        "fault-code",
        "underrun",
        "underruns",
        "records",
        "seq",
        "buffered",
        "hold",
        "abort",
        "resume",
        "resume-ready",
        "held",
    ] {
        assert!(
            names.contains(&format!("nurbs_interp.{pin}")),
            "missing {pin}: {names:?}"
        );
    }
    assert_eq!(mock::pin_dir("nurbs_interp.enable"), Some(sys::HAL_IN));
    assert_eq!(mock::pin_dir("nurbs_interp.pos-cmd-x"), Some(sys::HAL_OUT));
    assert!(mock::funct("nurbs_interp.update").is_some());
    drop(planner);
    unsafe { rtapi_app_exit() };
    assert!(mock::funct("nurbs_interp.update").is_none());
    assert_eq!(mock::component_ready("nurbs_interp"), None);
}

/// Runs `job` through the module, the records streamed in small batches; returns the samples
/// (x, y, feed, u, curve) of the periods with `active` set and the allocation count of all
/// update calls.
fn run_module(channel: &Channel, job: &Job, batch: usize, periods: usize) -> (Vec<[f64; 5]>, u64) {
    let update = mock::funct("nurbs_interp.update").unwrap();
    let mut sent = 0;
    let mut out = Vec::with_capacity(periods);
    let mut update_allocations = 0;
    for _ in 0..periods {
        if channel.segments.len() < batch {
            sent = fill(channel, &job.slots[..(sent + batch).min(job.slots.len())], sent);
        }
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        update_allocations += allocations() - before;
        if bit("nurbs_interp.active") {
            out.push(sample_pins());
        }
    }
    (out, update_allocations)
}

#[test]
fn trident_runs_exactly_the_offline_setpoints_without_allocating() {
    let _guard = lock_module();
    let job = job("trident.json");
    let (_planner, channel) = load();
    let update = mock::funct("nurbs_interp.update").unwrap();

    // Disabled, and enabled without geometry: nothing moves, nothing is consumed.
    fill(channel, &job.slots, 0);
    unsafe { mock::call(update, PERIOD_NS as _) };
    assert!(mock::set_pin("nurbs_interp.enable", Value::Bit(true)));
    unsafe { mock::call(update, PERIOD_NS as _) };
    assert!(!bit("nurbs_interp.active"));
    assert_eq!(u32_pin("nurbs_interp.records"), 0);
    while channel.segments.pop().unwrap().is_some() {}

    geometry(&job).publish(channel).unwrap();
    channel.set_planned_time(job.records.iter().map(|r| r.profile().total_time()).sum());
    let n = job.samples.len();
    let (got, update_allocations) = run_module(channel, &job, 8, n + 50);
    assert_eq!(update_allocations, 0, "the update path allocated");
    assert!(allocations() > 0, "the counting allocator is not in use");
    assert_eq!(got.len(), n, "sample count");
    for (k, (g, e)) in got.iter().zip(&job.samples).enumerate() {
        let expected = [e.point[0], e.point[1], e.feed, e.u, e.curve as f64];
        assert_eq!(
            g.map(f64::to_bits),
            expected.map(f64::to_bits),
            "sample {k}: {g:?} != {expected:?}"
        );
    }
    let end = job.toolpath.elements[0].curve.point(1.0);
    assert_eq!(
        (float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")),
        (end[0], end[1])
    );
    assert!(bit("nurbs_interp.done"));
    assert!(!bit("nurbs_interp.fault"));
    assert!(!bit("nurbs_interp.underrun"));
    assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
    assert_eq!(u32_pin("nurbs_interp.records") as usize, job.records.len());
    assert_eq!(float("nurbs_interp.buffered"), 0.0);
    unsafe { rtapi_app_exit() };
}

/// A path of several elements (line, NURBS, line: the curve index changes between records), a
/// 5-axis path (3 tip axes, 6-D curve) and a G1 program of 150 lines with its corners rounded
/// (299 elements; the channel held 64 before): the module's x, y, z, feed, u and curve equal the offline setpoints bit for
/// bit.
#[test]
fn multi_element_and_3d_paths_run_exactly_the_offline_setpoints() {
    let _guard = lock_module();
    let dir = std::env::temp_dir().join(format!("nurbs-hal-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ngc = dir.join("line-trident-line.ngc");
    std::fs::write(
        &ngc,
        "G21 G17 G90 G64\nG0 X0 Y0\nF60000\nG1 X10 Y0\nG5.2 X20 Y27 P1 L4\nX12 Y8 P1\nX10 Y20 P1\n\
         X8 Y8 P1\nX0 Y27 P1\nX10 Y0 P1\nG5.3\nG1 X0 Y0\nM2\n",
    )
    .unwrap();
    let pocket = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/open_pocket.json");
    let zigzag = g1_zigzag(150);
    assert_eq!(zigzag.elements.len(), 299);
    let jobs = [
        ("line-trident-line", job_at(&ngc)),
        ("open_pocket", job_at(&pocket)),
        ("G1 zigzag", job_of(zigzag)),
    ];
    for (name, job) in jobs {
        let tip = job.toolpath.tip_dim();
        let (_planner, channel) = load_enabled(&job);
        let update = mock::funct("nurbs_interp.update").unwrap();
        let (mut sent, mut got) = (0, Vec::new());
        let mut allocated = 0;
        for _ in 0..job.samples.len() + 50 {
            sent = fill(channel, &job.slots, sent);
            let before = allocations();
            unsafe { mock::call(update, PERIOD_NS as _) };
            allocated += allocations() - before;
            if bit("nurbs_interp.active") {
                got.push([
                    float("nurbs_interp.pos-cmd-x"),
                    float("nurbs_interp.pos-cmd-y"),
                    float("nurbs_interp.pos-cmd-z"),
                    float("nurbs_interp.feed"),
                    float("nurbs_interp.u"),
                    u32_pin("nurbs_interp.curve") as f64,
                ]);
            }
        }
        assert_eq!(allocated, 0);
        let curves: std::collections::BTreeSet<u64> = got.iter().map(|g| g[5] as u64).collect();
        println!("{name}: {} samples, {} curves, {tip} tip axes", got.len(), curves.len());
        assert_eq!(
            curves.len(),
            job.toolpath.elements.len(),
            "{name}: every element is run"
        );
        assert_eq!(
            got.len(),
            job.samples.len(),
            "{name}: fault {} underrun {} records {}/{} done {}",
            u32_pin("nurbs_interp.fault-code"),
            u32_pin("nurbs_interp.underruns"),
            u32_pin("nurbs_interp.records"),
            job.records.len(),
            bit("nurbs_interp.done")
        );
        for (k, (g, e)) in got.iter().zip(&job.samples).enumerate() {
            let z = if tip >= 3 { e.point[2] } else { 0.0 };
            let expected = [e.point[0], e.point[1], z, e.feed, e.u, e.curve as f64];
            assert_eq!(g.map(f64::to_bits), expected.map(f64::to_bits), "{name}: sample {k}");
        }
        // And what ran is within the limits (the project's check on the sampled positions).
        let rows = verify_rows(&got, |g| (&g[..tip], g[4], g[5]));
        let report = nurbs_motion::planner::verify::verify(&PathCurves::new(&job.toolpath), &job.limits, &rows);
        assert!(report.violations.is_empty(), "{name}: {:?}", report.violations);
        assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault"));
        unsafe { rtapi_app_exit() };
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_underrun_stops_along_the_path_without_a_jump() {
    let _guard = lock_module();
    let job = job("butterfly.json");
    let (_planner, channel) = load_enabled(&job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    // Only the first records arrive, one whose end feed is well above zero is the last.
    let end_feed = |i: usize| job.records[i - 1].profile().table().end().v;
    let cut = (3..job.records.len() - 1)
        .max_by(|&a, &b| end_feed(a).total_cmp(&end_feed(b)))
        .unwrap();
    assert!(end_feed(cut) > 10.0, "end feed {}", end_feed(cut));
    fill(channel, &job.slots[..cut], 0);
    let mut xs: Vec<[f64; 3]> = Vec::new();
    let mut allocated = 0;
    for _ in 0..job.samples.len() {
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        allocated += allocations() - before;
        if bit("nurbs_interp.active") {
            xs.push([
                float("nurbs_interp.pos-cmd-x"),
                float("nurbs_interp.pos-cmd-y"),
                float("nurbs_interp.feed"),
            ]);
        }
    }
    assert_eq!(allocated, 0);
    assert!(bit("nurbs_interp.underrun"));
    assert!(!bit("nurbs_interp.fault"));
    assert!(u32_pin("nurbs_interp.underruns") > 0);
    assert!(!bit("nurbs_interp.done"));
    // Up to the cut the samples are the plan's; then the stop ramps the feed down to zero.
    let planned = xs
        .iter()
        .zip(&job.samples)
        .take_while(|(g, e)| g[0] == e.point[0] && g[1] == e.point[1])
        .count();
    assert!(planned > 10 && planned < xs.len(), "{planned} of {}", xs.len());
    let stop = &xs[planned..];
    assert!(
        stop.windows(2).all(|w| w[1][2] <= w[0][2] + 1e-9),
        "feed not decreasing"
    );
    // The last sample of the stop lies within one period of its end: feed below J dt^2 / 2.
    let last_feed = stop.last().unwrap()[2];
    let rest = job.limits.min_jerk() * PERIOD * PERIOD / 2.0;
    assert!(last_feed.abs() <= rest, "not at rest: {last_feed} mm/s");
    // Axis velocity, acceleration and jerk by finite differences: within (tangential) limits
    // plus the curvature share, and above all no jump.
    let v: Vec<f64> = xs
        .windows(2)
        .map(|w| ((w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])) / PERIOD)
        .collect();
    let vmax = v.iter().copied().fold(0.0, f64::max);
    assert!(vmax <= job.limits.feed * 1.0001, "jump: {vmax} mm/s");
    let a_max = v
        .windows(2)
        .skip(planned.saturating_sub(2))
        .map(|w| (w[1] - w[0]).abs() / PERIOD)
        .fold(0.0, f64::max);
    assert!(
        a_max <= job.limits.min_accel() * 1.01,
        "stop decelerates at {a_max} mm/s^2"
    );
    // Holding: no further samples, the position stays.
    let held = (float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y"));
    unsafe { mock::call(update, PERIOD_NS as _) };
    assert_eq!(held, (float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")));
    assert!(!bit("nurbs_interp.active"));
    unsafe { rtapi_app_exit() };
}

/// Underrun, resume: the module stops on the path, publishes where it stands; the plan of the
/// rest of the path from there (at rest) is published; nothing moves until the resume command;
/// then the motion continues to the end of the path. The whole sampled run (the stop's samples
/// followed directly by the resumed ones, as a sampler records it) passes the finite-difference
/// check, with no jump, and the update path allocates nothing.
#[test]
fn an_underrun_resumes_from_the_stop_point_on_command() {
    let _guard = lock_module();
    for name in ["trident.json", "butterfly.json"] {
        let job = job(name);
        let end_feed = |i: usize| job.records[i - 1].profile().table().end().v;
        let cut = (3..job.records.len() - 1)
            .max_by(|&a, &b| end_feed(a).total_cmp(&end_feed(b)))
            .unwrap();
        underrun_and_resume(name, &job, cut);
    }
}

/// Only the first `cut` records of `job` arrive: the module stops after them, publishes the stop
/// point, waits for the plan from there and the resume command, and runs it to the path end.
/// Returns the sampled run (x, y, feed, u, curve) and the samples up to the stop.
fn underrun_and_resume(name: &str, job: &Job, cut: usize) -> (Vec<[f64; 5]>, usize) {
    let (_planner, channel) = load_enabled(job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    fill(channel, &job.slots[..cut], 0);
    let mut samples: Vec<[f64; 5]> = Vec::new();
    let mut allocated = 0;
    let mut period = |samples: &mut Vec<[f64; 5]>| {
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        allocated += allocations() - before;
        if bit("nurbs_interp.active") {
            samples.push(sample_pins());
        }
    };
    let mut stop = None;
    for _ in 0..job.samples.len() {
        period(&mut samples);
        stop = channel.stop.read();
        if stop.is_some() {
            break;
        }
    }
    let stop = stop.expect("no stop point published");
    let held = [float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")];
    assert_eq!([stop.point[0], stop.point[1]], held);
    assert_eq!(stop.u, float("nurbs_interp.u"));
    assert_eq!(stop.seq as usize, cut - 1);
    assert!(bit("nurbs_interp.underrun") && !bit("nurbs_interp.fault"));
    // A resume command without data does nothing.
    mock::set_pin("nurbs_interp.resume", Value::Bit(true));
    let n_stopped = samples.len();
    for _ in 0..100 {
        period(&mut samples);
    }
    mock::set_pin("nurbs_interp.resume", Value::Bit(false));
    assert_eq!(samples.len(), n_stopped);
    assert!(!bit("nurbs_interp.resume-ready"));
    // The planner re-plans the rest from rest at the stop point and publishes it.
    let plan2 = crate::plan_geometry::plan_from_stop(&job.toolpath, &job.limits, &stop).unwrap();
    assert_eq!((plan2.records[0].u_start, plan2.records[0].s_start), (stop.u, stop.s));
    for _ in 0..10 {
        period(&mut samples); // the module empties the ring of the stopped motion
    }
    assert!(channel.segments.is_empty());
    let (g2, slots2, _) = crate::plan_geometry::geometry(&job.toolpath, &plan2, 1.0).unwrap();
    g2.publish(channel).unwrap();
    let mut sent = fill(channel, &slots2, 0);
    // Data but no command: the machine stays.
    for _ in 0..400 {
        period(&mut samples);
    }
    assert_eq!(samples.len(), n_stopped);
    assert!(bit("nurbs_interp.resume-ready") && bit("nurbs_interp.underrun"));
    assert_eq!([float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")], held);
    assert!(channel.stop.read().is_some());
    mock::set_pin("nurbs_interp.resume", Value::Bit(true));
    let periods = job.samples.len() + 20_000;
    for _ in 0..periods {
        sent = fill(channel, &slots2, sent);
        period(&mut samples);
        if bit("nurbs_interp.done") {
            break;
        }
    }
    mock::set_pin("nurbs_interp.resume", Value::Bit(false));
    assert_eq!(allocated, 0, "the update path allocated");
    assert!(bit("nurbs_interp.done"), "{name}: did not resume to the end");
    assert!(!bit("nurbs_interp.fault") && !bit("nurbs_interp.underrun"));
    assert!(channel.stop.read().is_none());
    // The resumed motion starts where the machine stood and ends at C(1) at rest.
    assert_eq!([samples[n_stopped][0], samples[n_stopped][1]], held);
    let end = job.samples.last().unwrap().point;
    let last = samples.last().unwrap();
    assert_eq!([last[0], last[1]], [end[0], end[1]], "{name}");
    assert_eq!(last[2], 0.0);
    let report =
        nurbs_motion::planner::verify::verify(&PathCurves::new(&job.toolpath), &job.limits, &rows_of(&samples));
    println!(
        "{name}: {} samples to the stop, {} resumed; peaks {:?}",
        n_stopped,
        samples.len() - n_stopped,
        report.peaks
    );
    assert!(report.violations.is_empty(), "{name}: {:?}", report.violations);
    unsafe { rtapi_app_exit() };
    (samples, n_stopped)
}

/// After an underrun stop, a plan that does not start where the machine stands (here: the
/// whole path again, from C(0)) is refused with a fault and the position is held.
#[test]
fn a_resume_from_elsewhere_is_refused() {
    let _guard = lock_module();
    let job = job("trident.json");
    let (_planner, channel) = load_enabled(&job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    fill(channel, &job.slots[..job.slots.len() / 2], 0);
    for _ in 0..job.samples.len() {
        unsafe { mock::call(update, PERIOD_NS as _) };
    }
    assert!(channel.stop.read().is_some());
    let held = [float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")];
    geometry(&job).publish(channel).unwrap();
    fill(channel, &job.slots, 0);
    mock::set_pin("nurbs_interp.resume", Value::Bit(true));
    for _ in 0..100 {
        unsafe { mock::call(update, PERIOD_NS as _) };
        assert!(!bit("nurbs_interp.active"));
    }
    assert!(bit("nurbs_interp.fault"));
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::ResumePoint as u32);
    assert_eq!([float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")], held);
    unsafe { rtapi_app_exit() };
}

/// Runs a few periods and returns the fault code.
fn fault_after(channel: &Channel, slots: &[Slot]) -> u32 {
    let update = mock::funct("nurbs_interp.update").unwrap();
    fill(channel, slots, 0);
    for _ in 0..100_000 {
        unsafe { mock::call(update, PERIOD_NS as _) };
        if bit("nurbs_interp.fault") {
            break;
        }
    }
    u32_pin("nurbs_interp.fault-code")
}

#[test]
fn malformed_records_fault_and_hold() {
    let _guard = lock_module();
    let job = job("trident.json");
    type Tamper = fn(&mut SegmentRecord, &mut RecordStop);
    let cases: [(Tamper, FaultCode); 8] = [
        (|r, _| r.seq += 1, FaultCode::Sequence),
        (|r, _| r.durations[3] = f64::NAN, FaultCode::Record),
        (|r, _| r.length *= 2.0, FaultCode::Record),
        (|r, _| r.flags |= 7 << 16, FaultCode::BadRecord),
        (|_, stop| stop.jerk = f64::NAN, FaultCode::Record),
        (|_, stop| stop.accel = 0.0, FaultCode::Record),
        (|_, stop| stop.points_len = u32::MAX, FaultCode::Record),
        (
            |_, stop| stop.points_offset = (crate::channel::GEOMETRY_VALUES - 1) as u32,
            FaultCode::Record,
        ),
    ];
    for (tamper, code) in cases {
        let (_planner, channel) = load_enabled(&job);
        let mut slots = job.slots.clone();
        let k = slots.len() / 2;
        let Some(Record::Segment(mut record, mut stop)) = slots[k].decode() else {
            panic!("not a segment slot");
        };
        tamper(&mut record, &mut stop);
        slots[k] = Slot::segment(&record, &stop);
        assert_eq!(fault_after(channel, &slots[..=k]), code as u32);
        assert!(bit("nurbs_interp.fault"));
        assert!(!bit("nurbs_interp.active"));
        // A record the interpolator refuses has been taken; the others are refused on arrival.
        let taken = k + usize::from(code == FaultCode::BadRecord);
        assert_eq!(u32_pin("nurbs_interp.records") as usize, taken);
        let held = float("nurbs_interp.pos-cmd-x");
        fill(channel, &job.slots[k + 1..], 0);
        fault_after(channel, &[]);
        assert_eq!(float("nurbs_interp.pos-cmd-x"), held, "moved after a fault");
        unsafe { rtapi_app_exit() };
    }
}

#[test]
fn invalid_geometry_is_refused() {
    let _guard = lock_module();
    let job = job("trident.json");
    let g = geometry(&job);
    let mut values = g.values().to_vec();
    values[g.curves()[0].weights_offset as usize] = -1.0;
    let (_planner, channel) = load();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    channel.geometry.publish_unchecked(&crate::channel::GeometryRef {
        values: &values,
        ..g.layout()
    });
    assert_eq!(fault_after(channel, &job.slots), FaultCode::Geometry as u32);
    assert_eq!(u32_pin("nurbs_interp.records"), 0);
    assert_eq!(float("nurbs_interp.pos-cmd-x"), 0.0);
    unsafe { rtapi_app_exit() };

    // A geometry re-published in the middle of a motion is refused too.
    let (_planner, channel) = load();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    g.publish(channel).unwrap();
    let update = mock::funct("nurbs_interp.update").unwrap();
    fill(channel, &job.slots, 0);
    for _ in 0..100 {
        unsafe { mock::call(update, PERIOD_NS as _) };
    }
    assert!(bit("nurbs_interp.active"));
    g.publish(channel).unwrap();
    assert_eq!(fault_after(channel, &[]), FaultCode::GeometryChanged as u32);
    unsafe { rtapi_app_exit() };
}

/// A geometry of many curves (a 150-line G1 program: 299 elements) is validated a slice per
/// period, so that no period runs long: [`VALIDATION_VALUES_PER_PERIOD`] value checks per
/// period.
/// The motion starts in the period the last slice passes; a bad curve in the last slice faults
/// only there, before anything moved; a geometry re-published half-way is validated again from
/// its first curve.
#[test]
fn a_large_geometry_is_validated_a_slice_per_period() {
    validated_a_slice_per_period(&job_of(g1_zigzag(150)));
}

/// One curve larger than a period's slice (3,000 control points) is validated over several
/// periods as well, a slice of its values at a time.
#[test]
fn a_single_large_curve_is_validated_a_slice_per_period() {
    let job = job_of(long_spline(3_000));
    assert_eq!(job.geometry.curves().len(), 1);
    validated_a_slice_per_period(&job);
}

fn validated_a_slice_per_period(job: &Job) {
    use crate::module::VALIDATION_VALUES_PER_PERIOD as BUDGET;
    let _guard = lock_module();
    let g = geometry(job);
    // Every value is checked once, and the interior knots once more (their multiplicity).
    let total: usize = g
        .curves()
        .iter()
        .map(|d| (d.knots_len + d.points_len + 2 * d.weights_len - d.degree - 1) as usize)
        .sum();
    let periods = total.div_ceil(BUDGET);
    assert!(periods >= 2, "{total} values: too few for this test");
    let periods_to_first_record = |channel: &Channel| {
        let update = mock::funct("nurbs_interp.update").unwrap();
        fill(channel, &job.slots, 0);
        (1..=periods + 5)
            .find(|_| {
                unsafe { mock::call(update, PERIOD_NS as _) };
                u32_pin("nurbs_interp.records") > 0
            })
            .unwrap()
    };

    let (_planner, channel) = load_enabled(job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    assert_eq!(periods_to_first_record(channel), periods, "{total} values");
    // The motion that follows is the offline plan's.
    let mut got = vec![sample_pins()];
    for _ in 0..job.samples.len() + 10 {
        fill(
            channel,
            &job.slots,
            u32_pin("nurbs_interp.records") as usize + channel.segments.len(),
        );
        unsafe { mock::call(update, PERIOD_NS as _) };
        if bit("nurbs_interp.active") {
            got.push(sample_pins());
        }
    }
    assert!(!bit("nurbs_interp.fault") && bit("nurbs_interp.done"));
    assert_eq!(got.len(), job.samples.len());
    for (k, (row, want)) in got.iter().zip(&job.samples).enumerate() {
        assert_eq!([row[0], row[1]], [want.point[0], want.point[1]], "sample {k}");
    }
    let report = nurbs_motion::planner::verify::verify(&PathCurves::new(&job.toolpath), &job.limits, &rows_of(&got));
    assert!(report.violations.is_empty(), "{:?}", report.violations);
    unsafe { rtapi_app_exit() };

    // A bad last weight (the last value checked): found in the last slice, nothing taken before.
    let mut values = g.values().to_vec();
    let last = g.curves().last().unwrap();
    values[(last.weights_offset + last.weights_len - 1) as usize] = 0.0;
    let (_planner, channel) = load();
    let update = mock::funct("nurbs_interp.update").unwrap();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    channel.geometry.publish_unchecked(&crate::channel::GeometryRef {
        values: &values,
        ..g.layout()
    });
    fill(channel, &job.slots, 0);
    let mut faulted_at = None;
    for period in 1..=periods + 5 {
        unsafe { mock::call(update, PERIOD_NS as _) };
        if bit("nurbs_interp.fault") {
            faulted_at = Some(period);
            break;
        }
    }
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::Geometry as u32);
    assert_eq!(faulted_at, Some(periods), "the last slice finds it");
    assert_eq!(u32_pin("nurbs_interp.records"), 0);
    assert_eq!(float("nurbs_interp.pos-cmd-x"), 0.0);
    unsafe { rtapi_app_exit() };

    // Re-published after the first slice: validated from the start again.
    let (_planner, channel) = load_enabled(job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    unsafe { mock::call(update, PERIOD_NS as _) };
    assert_eq!(u32_pin("nurbs_interp.records"), 0);
    g.publish(channel).unwrap();
    assert_eq!(periods_to_first_record(channel), periods);
    unsafe { rtapi_app_exit() };
}

#[test]
fn stream_reader_reads_a_sampler_like_stream() {
    mock::reset();
    let comp = Component::new("recorder").unwrap();
    let key = 0x4853_4130;
    mock::stream_create(key, &[sys::HAL_FLOAT, sys::HAL_BIT, sys::HAL_U32]);
    let mut reader = StreamReader::attach(&comp, key).unwrap();
    assert_eq!(reader.read(), Ok(None));
    let x = 1.0 / 3.0;
    assert!(mock::stream_write(
        key,
        &[
            sys::hal_stream_data { f: x },
            sys::hal_stream_data { u: 1 },
            sys::hal_stream_data { u: 7 }
        ]
    ));
    let (n, values) = reader.read().unwrap().unwrap();
    assert_eq!(n, 1);
    assert_eq!(
        values,
        vec![StreamValue::Float(x), StreamValue::Bit(true), StreamValue::U32(7)]
    );
}

/// The underrun stop from every segment boundary of the trident and the butterfly, as
/// nurbs-planner chooses it: within the axis limits everywhere (by finite differences, the
/// `nurbs-plan verify` check), never through a corner too fast, never off its curve.
#[test]
fn underrun_stops_are_within_the_limits_at_every_boundary() {
    for name in ["trident.json", "butterfly.json"] {
        let job = job(name);
        let choices = &job.choices;
        assert_eq!(choices.len(), job.records.len());
        let worst = choices.iter().map(|c| c.ratio).fold(0.0, f64::max);
        let smallest = choices.iter().map(|c| c.fraction).fold(1.0, f64::min);
        println!("{name}: worst stop ratio {worst:.4}, smallest fraction {smallest}");
        assert!(worst <= 1.0, "{name}: {choices:?}");
    }
}

/// A G1 polyline with rounded corners is many elements, and the records end at the joins at
/// speed (into the tight corner splines). The module's tangential stop ends on its own curve, so
/// there it would have to stop at once (250 x an axis limit); the planner stores a stop sequence
/// that goes on across the join instead. Every boundary has a stop within the limits, and an
/// underrun at the fastest boundary whose stop crosses a join stops across it, resumes, and the
/// whole run verifies.
#[test]
fn underrun_stops_cross_element_joins() {
    let _guard = lock_module();
    let job = job_of(rounded_polyline());
    let choices = &job.choices;
    let worst = choices.iter().map(|c| c.ratio).fold(0.0, f64::max);
    let stored = choices.iter().filter(|c| c.stored > 0).count();
    println!(
        "{} elements, {} records, {stored} stored stops, worst stop ratio {worst:.6}",
        job.toolpath.elements.len(),
        job.records.len()
    );
    assert!(worst <= 1.0, "a stop exceeds the limits: {choices:?}");
    let values = job.geometry.values();
    let stop_of = |k: usize| match job.slots[k].decode() {
        Some(Record::Segment(_, stop)) => stop,
        _ => panic!("not a segment slot"),
    };
    let crossing: Vec<usize> = (0..job.records.len() - 1)
        .filter(|&k| {
            let s = stop_of(k);
            s.stored_len > 0 && last_run_curve(values, s.stored_offset, s.stored_len) > job.records[k].curve()
        })
        .collect();
    println!(
        "{} of {} record-end stops cross an element join",
        crossing.len(),
        job.records.len()
    );
    assert!(
        !crossing.is_empty(),
        "no stop crosses a join: the test lost its subject"
    );
    let end_feed = |k: &usize| job.records[*k].profile().table().end().v;
    let k = crossing
        .iter()
        .copied()
        .max_by(|a, b| end_feed(a).total_cmp(&end_feed(b)))
        .unwrap();
    let (samples, stopped) = underrun_and_resume("rounded polyline", &job, k + 1);
    let curve_at_stop = samples[stopped - 1][4] as usize;
    println!(
        "stop after record {k} (curve {}, end feed {:.2} mm/s) ends on curve {curve_at_stop}",
        job.records[k].curve(),
        end_feed(&k)
    );
    assert!(
        curve_at_stop > job.records[k].curve(),
        "the stop did not cross the join"
    );
}

/// Holds on a G1 program (the rounded polyline) at nine points of its motion: about half its
/// boundaries stop with a stored sequence across a join. Each hold comes to rest, the plan from
/// the stop point resumes on release to the path end, and the whole run verifies.
#[test]
fn holds_on_a_g1_program_stop_and_resume_within_the_limits() {
    let _guard = lock_module();
    let job = job_of(rounded_polyline());
    let n = job.samples.len();
    let goal = job.samples.last().unwrap().point;
    let mut crossed = 0;
    for hold_at in (1..10).map(|k| k * n / 10) {
        let (samples, rest_at, _) = hold_run(&job, hold_at, 200);
        let last = samples.last().unwrap();
        assert_eq!([last[0], last[1]], [goal[0], goal[1]], "hold at {hold_at}");
        let report =
            nurbs_motion::planner::verify::verify(&PathCurves::new(&job.toolpath), &job.limits, &rows_of(&samples));
        assert!(
            report.violations.is_empty(),
            "hold at {hold_at}: {:?}",
            report.violations
        );
        let curves = rest_at.map(|r| (samples[hold_at][4], samples[r - 1][4]));
        println!("hold at period {hold_at}: at rest at period {rest_at:?}; curve at the hold, at rest: {curves:?}");
        crossed += usize::from(curves.is_some_and(|(held, rest)| rest > held));
    }
    assert!(
        crossed > 0,
        "no hold came to rest beyond a join: the test lost its subject"
    );
}

/// When the arena has no room for a stored stop sequence, the record keeps the best tangential
/// stop (checked: its ratio is what `nurbs-planner` reports, as `EXCEEDS` above 1) and refers to
/// no stored values; the records after it still go out, in order.
#[test]
fn a_full_arena_keeps_the_tangential_stops() {
    use crate::plan_geometry::{segment_chooser, Next, Records};
    let job = job_of(rounded_polyline());
    let mut records = Records::Segments {
        records: job.records.iter().copied().collect(),
        chooser: Box::new(segment_chooser(&job.toolpath, &job.plan, 1.0).unwrap()),
        complete: true,
    };
    let mut out = Vec::new();
    loop {
        // Room for the stop points of each curve (a few pairs here), none for a stored sequence
        // (tens of positions).
        match records.next(&mut |v| (v.len() <= 32).then_some(0)).unwrap() {
            Next::Slot(slot, _, choice) => out.push((slot, choice)),
            Next::Working | Next::Waiting => {}
            Next::Done => break,
        }
    }
    assert_eq!(out.len(), job.slots.len());
    let mut kept = 0;
    for (k, (((slot, choice), full), full_choice)) in out.iter().zip(&job.slots).zip(&job.choices).enumerate() {
        let (Some(Record::Segment(r, stop)), Some(Record::Segment(r_full, stop_full))) = (slot.decode(), full.decode())
        else {
            panic!("not a segment slot");
        };
        assert_eq!((r, stop.stored_len, choice.stored), (r_full, 0, 0), "record {k}");
        assert_eq!((stop.accel, stop.jerk), (choice.accel, choice.jerk));
        if stop_full.stored_len > 0 {
            kept += 1;
            assert!(choice.ratio > 1.0, "record {k}: a stored stop was needed: {choice:?}");
        } else {
            assert_eq!(choice, full_choice);
        }
    }
    println!("{kept} records keep a tangential stop over the limits");
    assert!(kept > 0, "no stored stop in the full run: the test lost its subject");
}

/// `nurbs-planner --stream`: the planner hands out records and each curve's stop points as it
/// plans; the module starts once some records are queued and runs while the plan goes on. The
/// slots are those of the same plan checked all at once, and the module's setpoints are those
/// of `nurbs-plan plan --stream`, bit for bit, with no underrun.
#[test]
fn a_streamed_plan_runs_through_the_module_while_it_is_planned() {
    use crate::plan_geometry::{stream_plan, streamed_motion, Next, PlanEvent};
    let _guard = lock_module();
    let toolpath = g1_zigzag(30);
    let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, PERIOD);
    let mut events = Vec::new();
    stream_plan(&toolpath, &limits, None, &mut |e| {
        events.push(e);
        true
    });
    let streamed = PlanOptions {
        stream: true,
        ..PlanOptions::default()
    };
    let offline = plan(&toolpath, &limits, &streamed, &mut |_| {}).unwrap();
    let samples = setpoints(&PathCurves::new(&toolpath), &offline.limits, &offline.records);
    let (_, all_at_once, _) = crate::plan_geometry::geometry(&toolpath, &offline, 1.0).unwrap();
    let record_events = events.iter().filter(|e| matches!(e, PlanEvent::Record(_))).count();
    assert_eq!(record_events, offline.records.len());
    assert!(matches!(events.last(), Some(PlanEvent::Done(_))));

    let mut motion = streamed_motion(&toolpath, &limits, 1.0).unwrap();
    assert!(!motion.records.is_complete());
    let (_planner, channel) = load();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    let mut arena = motion.geometry.publish(channel).unwrap();
    let update = mock::funct("nurbs_interp.update").unwrap();
    let (mut slots, mut out, mut taken) = (Vec::new(), Vec::new(), 0);
    let mut started_after = None;
    let mut incoming = events.into_iter();
    for _ in 0..samples.len() + 10_000 {
        // One event of the plan per period, and a few stop checks.
        if let Some(event) = incoming.next() {
            taken += 1;
            motion.records.take(event).unwrap();
        }
        for _ in 0..4 {
            if let Next::Slot(slot, _, _) = motion.records.next(&mut |v| arena.put(v)).unwrap() {
                channel.segments.push(&slot).unwrap();
                slots.push(slot);
            }
        }
        // The module runs once 20 records are queued (nurbs-planner's margin, in short).
        if started_after.is_none() && slots.len() >= 20 {
            started_after = Some(taken);
        }
        if started_after.is_some() {
            unsafe { mock::call(update, PERIOD_NS as _) };
            if bit("nurbs_interp.active") {
                out.push(sample_pins());
            }
            if bit("nurbs_interp.done") {
                break;
            }
        }
    }
    assert!(motion.records.is_complete());
    let started_after = started_after.expect("never started");
    println!(
        "{} events; the motion started after {started_after}, {} samples",
        taken,
        out.len()
    );
    assert!(
        started_after < taken / 2,
        "the motion did not start while the plan went on"
    );
    assert_eq!(slots, all_at_once);
    assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
    assert_eq!(out.len(), samples.len());
    for (k, (g, e)) in out.iter().zip(&samples).enumerate() {
        let expected = [e.point[0], e.point[1], e.feed, e.u, e.curve as f64];
        assert_eq!(g.map(f64::to_bits), expected.map(f64::to_bits), "sample {k}");
    }
    let report = nurbs_motion::planner::verify::verify(&PathCurves::new(&toolpath), &offline.limits, &rows_of(&out));
    assert!(report.violations.is_empty(), "{:?}", report.violations);
    unsafe { rtapi_app_exit() };
}

/// When `nurbs-planner` may start the motion while it still checks stops: with the checks
/// faster than the motion (at half the measured rate), once a margin is checked; slower, once
/// the rest cannot catch up with them; always once everything is checked.
#[test]
fn the_motion_starts_once_the_stop_checks_stay_ahead() {
    use crate::plan_geometry::checked_far_enough;
    // 20 x the motion's pace (a 1,000-line G1 program): the margin is enough.
    assert!(!checked_far_enough(1.9, 120.0, 20.0, 2.0));
    assert!(checked_far_enough(2.0, 120.0, 20.0, 2.0));
    // 1.5 x, counted as 0.75 x: with c s checked, the 100 - c s left must be checked within
    // c - 2 s of motion, c >= 2 + (100 - c) / 3, so c >= 26.5.
    assert!(!checked_far_enough(26.4, 100.0, 1.5, 2.0));
    assert!(checked_far_enough(26.6, 100.0, 1.5, 2.0));
    // Simulated: the motion never catches up with the checks at the true rate.
    for rate in [0.3, 0.8, 1.5, 2.5] {
        let total = 50.0;
        let mut checked: f64 = 0.0;
        let mut t: f64 = 0.0;
        while !checked_far_enough(checked, total, rate, 2.0) {
            checked = (checked + rate * 0.01).min(total);
            t += 0.01;
        }
        // From here the motion runs (1 s per s) while the checks go on at `rate`.
        let start = t;
        while checked < total {
            checked = (checked + rate * 0.01).min(total);
            t += 0.01;
            assert!(checked >= (t - start).min(total), "rate {rate}: the motion caught up");
        }
        println!("rate {rate}: motion starts after {start:.2} s of checks");
    }
    // Nothing checked at all never starts (unless the motion is empty).
    assert!(!checked_far_enough(0.0, 10.0, 0.0, 2.0));
    assert!(checked_far_enough(0.0, 0.0, 0.0, 2.0));
}

/// The curve of the last run of the stored stop sequence of `len` positions at `offset`.
fn last_run_curve(values: &[f64], offset: u32, len: u32) -> usize {
    let (mut at, mut left, mut curve) = (offset as usize, len as usize, usize::MAX);
    while left > 0 {
        let run = nurbs_rtcore::StopRun::from_values(&values[at..]).unwrap();
        (curve, left, at) = (
            run.curve,
            left - run.count,
            at + nurbs_rtcore::StopRun::VALUES + 2 * run.count,
        );
    }
    curve
}

/// What a long G1 program costs `nurbs-planner` before the motion starts (`G1_LINES` lines,
/// default 1,000; ignored in CI, a measurement): the plan, then the stop checks of the records
/// it queues first (2 s of motion, the default margin), while the rest are checked during the
/// motion; and the stop checks of all records. Every stop stays within the limits and the
/// geometry fits the channel.
/// `cargo test --release -p nurbs-hal --features mock-hal long_g1 -- --ignored --nocapture`
#[test]
#[ignore]
fn long_g1_program_cost() {
    use crate::plan_geometry::{segment_chooser, Next, Records};
    let lines: usize = std::env::var("G1_LINES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    let toolpath = g1_zigzag(lines);
    let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, PERIOD);
    let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
    // As nurbs-planner streams: stops checked until 2 s of motion are ready.
    let t = std::time::Instant::now();
    let mut records = Records::Segments {
        records: plan.records.iter().copied().collect(),
        chooser: Box::new(segment_chooser(&toolpath, &plan, 1.0).unwrap()),
        complete: true,
    };
    let (mut ready, mut count) = (0.0, 0);
    let mut stored = Vec::new();
    while ready < 2.0 {
        let next = records.next(&mut |v| {
            stored.extend_from_slice(v);
            Some(0)
        });
        match next.unwrap() {
            Next::Slot(_, time, _) => (ready, count) = (ready + time, count + 1),
            Next::Working | Next::Waiting => {}
            Next::Done => break,
        }
    }
    let first = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let (g, _, choices) = crate::plan_geometry::geometry(&toolpath, &plan, 1.0).unwrap();
    let all = t.elapsed().as_secs_f64();
    let worst = choices.iter().map(|c| c.ratio).fold(0.0, f64::max);
    println!(
        "{lines} lines: motion {:.1} s; plan {:.2} s; stops of the first {count} records ({ready:.2} s of motion) {first:.3} s; stops of all {} records {all:.2} s ({} stored, worst ratio {worst:.7}); {} arena values",
        plan.motion_time,
        plan.plan_time,
        plan.records.len(),
        choices.iter().filter(|c| c.stored > 0).count(),
        g.values().len()
    );
    assert!(worst <= 1.0 + nurbs_motion::planner::verify::SLACK);
    assert!(ready >= 2.0 && count < plan.records.len());
    // Streamed (nurbs-planner --stream): the planner in a thread, records and stop points
    // checked as they come, until 2 s of motion are ready.
    let t = std::time::Instant::now();
    let (sender, receiver) = std::sync::mpsc::channel();
    let shared = std::sync::Arc::new(toolpath.clone());
    let path = std::sync::Arc::clone(&shared);
    let planner = std::thread::spawn(move || {
        crate::plan_geometry::stream_plan(&path, &limits, None, &mut |e| sender.send(e).is_ok())
    });
    let mut motion = crate::plan_geometry::streamed_motion(&shared, &plan.limits, 1.0).unwrap();
    let (mut ready, mut count) = (0.0, 0);
    while ready < 2.0 {
        while let Ok(event) = receiver.try_recv() {
            motion.records.take(event).unwrap();
        }
        match motion.records.next(&mut |_| Some(0)).unwrap() {
            Next::Slot(_, time, _) => (ready, count) = (ready + time, count + 1),
            Next::Waiting => std::thread::sleep(std::time::Duration::from_micros(100)),
            Next::Working => {}
            Next::Done => break,
        }
    }
    println!(
        "streamed: the first {count} records ({ready:.2} s of motion) planned and checked after {:.3} s",
        t.elapsed().as_secs_f64()
    );
    drop(receiver);
    planner.join().unwrap();
}

/// Every period's setpoint (held periods included: the machine is at rest there) as `verify`
/// rows, from the first sample to the end of the run: `fields` gives a sample's tip
/// coordinates, parameter and curve.
fn verify_rows<S>(samples: &[S], fields: impl Fn(&S) -> (&[f64], f64, f64)) -> Vec<nurbs_motion::planner::verify::Row> {
    samples
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let (q, u, curve) = fields(s);
            nurbs_motion::planner::verify::Row {
                t: k as f64 * PERIOD,
                curve: curve as usize,
                u,
                q: q.to_vec(),
            }
        })
        .collect()
}

/// [`verify_rows`] of the samples [`sample_pins`] reads (x, y, feed, u, curve).
fn rows_of(samples: &[[f64; 5]]) -> Vec<nurbs_motion::planner::verify::Row> {
    verify_rows(samples, |s| (&s[..2], s[3], s[4]))
}

/// Runs `job` with the whole plan queued, calling `control(period)` before each period;
/// records every period from the first sample on (x, y, feed, u, curve).
fn run_with(channel: &Channel, job: &Job, periods: usize, control: &mut dyn FnMut(usize)) -> Vec<[f64; 5]> {
    let update = mock::funct("nurbs_interp.update").unwrap();
    let mut sent = 0;
    let mut out = Vec::new();
    let mut allocated = 0;
    for period in 0..periods {
        sent = fill(channel, &job.slots, sent);
        control(period);
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        allocated += allocations() - before;
        if bit("nurbs_interp.active") || !out.is_empty() {
            out.push(sample_pins());
        }
    }
    assert_eq!(allocated, 0, "the update path allocated");
    out
}

/// Periods of `job`'s offline samples where an axis' finite-difference jerk and acceleration
/// peak (the hardest moments to start a hold at).
fn peak_periods(job: &Job) -> Vec<usize> {
    let p: Vec<[f64; 2]> = job.samples.iter().map(|s| [s.point[0], s.point[1]]).collect();
    let mut best = [(0.0f64, 0usize); 2];
    for (k, w) in p.windows(4).enumerate().map(|(k, w)| (k + 3, w)) {
        for (i, (jerk_limit, acc_limit)) in job.limits.jerk.iter().zip(&job.limits.acceleration).enumerate() {
            let acc = (w[3][i] - 2.0 * w[2][i] + w[1][i]).abs();
            let jerk = (w[3][i] - 3.0 * w[2][i] + 3.0 * w[1][i] - w[0][i]).abs();
            let jerk_ratio = jerk / (jerk_limit * PERIOD.powi(3));
            let acc_ratio = acc / (acc_limit * PERIOD.powi(2));
            if jerk_ratio > best[0].0 {
                best[0] = (jerk_ratio, k);
            }
            if acc_ratio > best[1].0 {
                best[1] = (acc_ratio, k);
            }
        }
    }
    println!(
        "peak jerk {:?}, peak acceleration {:?} (ratio, sample)",
        best[0], best[1]
    );
    // The sample k is produced by period k - 1 (the first period produces sample 0).
    best.iter().map(|b| b.1.saturating_sub(1)).collect()
}

/// Runs `job` with `hold` set before period `hold_at`, playing the planner: it streams the plan
/// until the module publishes its stop point, then the plan from there; `hold` is released
/// `held_for` periods after that plan is queued. Returns every period's setpoint from the first
/// sample on (x, y, feed, u, curve), the period the module came to rest (None: the hold came
/// during the last segment, which has no boundary to stop at: the motion ends at C(1)), and the
/// period the motion ended.
fn hold_run(job: &Job, hold_at: usize, held_for: usize) -> (Vec<[f64; 5]>, Option<usize>, usize) {
    let (_planner, channel) = load_enabled(job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    let mut slots = job.slots.clone();
    let (mut sent, mut out, mut allocated) = (0, Vec::new(), 0);
    let (mut rest_at, mut release_at, mut end, mut last_running) = (None, None, 0, false);
    for p in 0..job.samples.len() + 50_000 {
        if p == hold_at {
            mock::set_pin("nurbs_interp.hold", Value::Bit(true));
            last_running = u32_pin("nurbs_interp.records") as usize == job.records.len();
        }
        if rest_at.is_none() {
            if let Some(stop) = channel.stop.read() {
                // The planner sees the stop point once the module has emptied the ring.
                assert!(channel.segments.is_empty());
                assert!(bit("nurbs_interp.held") && !bit("nurbs_interp.underrun"));
                let plan2 = crate::plan_geometry::plan_from_stop(&job.toolpath, &job.limits, &stop).unwrap();
                let (g2, slots2, _) = crate::plan_geometry::geometry(&job.toolpath, &plan2, 1.0).unwrap();
                g2.publish(channel).unwrap();
                slots = slots2;
                sent = 0;
                rest_at = Some(p);
                release_at = Some(p + held_for);
            }
        }
        if Some(p) == release_at {
            assert!(bit("nurbs_interp.resume-ready") && !bit("nurbs_interp.active"));
            mock::set_pin("nurbs_interp.hold", Value::Bit(false));
        }
        sent = fill(channel, &slots, sent);
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        allocated += allocations() - before;
        if bit("nurbs_interp.active") || !out.is_empty() {
            out.push(sample_pins());
        }
        if bit("nurbs_interp.done") {
            end = p;
            break;
        }
    }
    assert_eq!(allocated, 0, "the update path allocated");
    assert!(!bit("nurbs_interp.fault") && !bit("nurbs_interp.held"));
    assert!(
        rest_at.is_some() || last_running,
        "hold at {hold_at} never came to rest"
    );
    mock::set_pin("nurbs_interp.hold", Value::Bit(false));
    unsafe { rtapi_app_exit() };
    (out, rest_at, end)
}

/// Feed hold: the module stops at the next segment boundary with the stop the planner checked
/// from that boundary, publishes its stop point, the planner re-plans the rest from there and
/// releasing `hold` runs it to the end. Holds requested anywhere, including where the plan runs
/// at its peak axial jerk and acceleration: every period's setpoint (held ones included) passes
/// the exact finite-difference check (`verify`, relative slack 1e-6), no jump, ends at C(1).
#[test]
fn hold_stops_on_the_path_and_resumes_within_the_limits() {
    let _guard = lock_module();
    for name in ["trident.json", "butterfly.json"] {
        let job = job(name);
        let n = job.samples.len();
        let mut at = vec![1, n / 7, n / 3, n / 2, 2 * n / 3, 6 * n / 7];
        at.extend(peak_periods(&job));
        let mut worst = 0.0f64;
        let mut latency = 0usize;
        for hold_at in at {
            let (samples, rest_at, end) = hold_run(&job, hold_at, 2000);
            let last = samples.last().unwrap();
            let goal = job.samples.last().unwrap().point;
            assert_eq!([last[0], last[1]], [goal[0], goal[1]], "{name}: hold at {hold_at}");
            if rest_at.is_some() {
                assert!(samples.len() > n + 2000, "{name}: hold at {hold_at}: no hold");
                let still = samples.windows(2).filter(|w| w[0][..2] == w[1][..2]).count();
                assert!(still >= 2000, "{name}: hold at {hold_at}: held {still} periods");
            }
            let report =
                nurbs_motion::planner::verify::verify(&PathCurves::new(&job.toolpath), &job.limits, &rows_of(&samples));
            assert!(
                report.violations.is_empty(),
                "{name}: hold at {hold_at}: {:?}",
                report.violations
            );
            let ratio = (0..2)
                .map(|i| {
                    (report.peaks.vel[i] / job.limits.velocity[i])
                        .max(report.peaks.acc[i] / job.limits.acceleration[i])
                        .max(report.peaks.jerk[i] / job.limits.jerk[i])
                })
                .fold(0.0, f64::max);
            worst = worst.max(ratio);
            let to_rest = rest_at.map(|r| r - hold_at);
            latency = latency.max(to_rest.unwrap_or(0));
            println!(
                "{name}: hold at period {hold_at}: at rest after {to_rest:?} periods (None: in the last segment), end at {end}, worst ratio {ratio:.9}"
            );
        }
        let durations: Vec<f64> = job.records.iter().map(|r| r.profile().total_time()).collect();
        println!(
            "{name}: worst hold/resume ratio {worst:.9}, longest hold-to-rest {:.3} s; segments: longest {:.3} s, last {:.3} s",
            latency as f64 * PERIOD,
            durations.iter().copied().fold(0.0, f64::max),
            durations.last().unwrap()
        );
    }
}

/// The commands need data: a hold released before the plan from the stop point is queued
/// keeps the machine at rest until it is, then the motion continues at once; a `resume` edge
/// under hold is ignored.
#[test]
fn commands_wait_for_the_plan_from_the_stop_point() {
    let _guard = lock_module();
    let job = job("trident.json");
    let (_planner, channel) = load_enabled(&job);
    let update = mock::funct("nurbs_interp.update").unwrap();
    let periods = |k: usize| {
        for _ in 0..k {
            unsafe { mock::call(update, PERIOD_NS as _) };
        }
    };
    fill(channel, &job.slots, 0);
    periods(job.samples.len() / 3);
    mock::set_pin("nurbs_interp.hold", Value::Bit(true));
    periods(3000);
    let stop = channel.stop.read().expect("no stop point after the hold");
    assert_eq!(stop.cause, crate::module::StopCause::Hold as u32);
    assert!(bit("nurbs_interp.held") && !bit("nurbs_interp.underrun"));
    // Released without a plan from the stop point: nothing moves.
    mock::set_pin("nurbs_interp.hold", Value::Bit(false));
    let here = [float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")];
    for _ in 0..500 {
        periods(1);
        assert!(!bit("nurbs_interp.active"));
    }
    let plan2 = crate::plan_geometry::plan_from_stop(&job.toolpath, &job.limits, &stop).unwrap();
    // Under hold again, the plan arrives; a resume edge does not start it.
    mock::set_pin("nurbs_interp.hold", Value::Bit(true));
    let (g2, slots2, _) = crate::plan_geometry::geometry(&job.toolpath, &plan2, 1.0).unwrap();
    g2.publish(channel).unwrap();
    let mut sent = fill(channel, &slots2, 0);
    mock::set_pin("nurbs_interp.resume", Value::Bit(true));
    periods(100);
    mock::set_pin("nurbs_interp.resume", Value::Bit(false));
    assert!(!bit("nurbs_interp.active") && bit("nurbs_interp.resume-ready"));
    assert_eq!([float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")], here);
    // Released: the plan from the stop point runs to the end.
    mock::set_pin("nurbs_interp.hold", Value::Bit(false));
    periods(1);
    assert!(bit("nurbs_interp.active"));
    assert_eq!([float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")], here);
    for _ in 0..job.samples.len() {
        sent = fill(channel, &slots2, sent);
        periods(1);
    }
    assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault") && !bit("nurbs_interp.held"));
    unsafe { rtapi_app_exit() };
}

/// Abort: the module stops at the next segment boundary (the checked stop), then the motion is
/// over and the queue is discarded; within the limits.
#[test]
fn abort_stops_then_discards_the_queue() {
    let _guard = lock_module();
    let job = job("butterfly.json");
    let (_planner, channel) = load_enabled(&job);
    let abort_at = job.samples.len() / 3;
    let samples = run_with(channel, &job, abort_at + 14_000, &mut |p| {
        if p == abort_at {
            mock::set_pin("nurbs_interp.abort", Value::Bit(true));
        }
        if p > abort_at + 10_000 {
            // Released: an aborted motion does not come back.
            mock::set_pin("nurbs_interp.abort", Value::Bit(false));
        }
    });
    assert!(!bit("nurbs_interp.done"));
    assert!(!bit("nurbs_interp.fault"));
    assert!(!bit("nurbs_interp.active"));
    assert!(channel.stop.read().is_none(), "an aborted motion offers no stop point");
    let rest = samples.last().unwrap();
    assert!(samples[samples.len() - 1500..].iter().all(|s| s[..2] == rest[..2]));
    let records = u32_pin("nurbs_interp.records") as usize;
    assert!(records < job.records.len());
    // The queue is being discarded: what the planner still sends is not run.
    assert!(channel.segments.is_empty());
    let report =
        nurbs_motion::planner::verify::verify(&PathCurves::new(&job.toolpath), &job.limits, &rows_of(&samples));
    let others: Vec<_> = report
        .violations
        .iter()
        .filter(|v| !v.contains("not the end of the path"))
        .collect();
    assert!(others.is_empty(), "{others:?}");
    unsafe { rtapi_app_exit() };
}

/// Per-period cost of `nurbs_interp.update` on this machine (mock HAL, so pin access is a plain
/// memory access as in HAL): `cargo test --release -p nurbs-hal -- --ignored --nocapture update_cost`.
#[test]
#[ignore = "timing; run with --ignored --nocapture"]
fn update_cost() {
    let _guard = lock_module();
    for name in ["trident.json", "butterfly.json"] {
        let job = job(name);
        let (_planner, channel) = load_enabled(&job);
        let update = mock::funct("nurbs_interp.update").unwrap();
        // Prime: the first period takes the geometry (validation, once).
        unsafe { mock::call(update, PERIOD_NS as _) };
        let mut sent = 0;
        let mut ns = Vec::with_capacity(job.samples.len());
        while !bit("nurbs_interp.done") {
            sent = fill(channel, &job.slots, sent);
            let t = std::time::Instant::now();
            unsafe { mock::call(update, PERIOD_NS as _) };
            ns.push(t.elapsed().as_nanos() as u64);
        }
        let slow: Vec<(usize, u64)> = ns.iter().copied().enumerate().filter(|(_, t)| *t > 20_000).collect();
        println!("{name}: periods over 20 us: {slow:?}");
        ns.sort_unstable();
        let q = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize];
        println!(
            "{name}: {} periods: median {} ns, p99 {} ns, max {} ns",
            ns.len(),
            q(0.5),
            q(0.99),
            ns[ns.len() - 1]
        );
        unsafe { rtapi_app_exit() };
    }
}

/// After a motion is over (finished, stopped on an underrun and aborted, aborted), the module empties the
/// ring and a new geometry starts a new motion from its first record: the trident again, exactly.
#[test]
fn a_new_geometry_starts_a_new_motion_after_done_underrun_or_abort() {
    let _guard = lock_module();
    let job = job("trident.json");
    let n = job.samples.len();
    let update = || mock::funct("nurbs_interp.update").unwrap();
    let periods = |k: usize| {
        for _ in 0..k {
            unsafe { mock::call(update(), PERIOD_NS as _) };
        }
    };
    type End = fn(&Channel, &Job);
    let endings: [(&str, End); 3] = [
        ("done", |c, job| {
            fill(c, &job.slots, 0);
        }),
        ("underrun", |c, job| {
            fill(c, &job.slots[..job.slots.len() / 2], 0);
        }),
        ("abort", |c, job| {
            fill(c, &job.slots, 0);
            mock::set_pin("nurbs_interp.abort", Value::Bit(true));
        }),
    ];
    for (what, end) in endings {
        let (_planner, channel) = load_enabled(&job);
        end(channel, &job);
        periods(n + 12_000);
        assert!(!bit("nurbs_interp.active"), "{what}");
        if what == "underrun" {
            // An underrun stop waits for a plan from the stop point; abort ends that motion.
            assert!(channel.stop.read().is_some());
            mock::set_pin("nurbs_interp.abort", Value::Bit(true));
            periods(9_000);
            assert!(channel.stop.read().is_none(), "abort keeps the stop point");
        }
        // Records of the old motion still coming are dropped, not run.
        fill(channel, &job.slots[1..], 0);
        periods(10);
        assert!(channel.segments.is_empty(), "{what}: ring not emptied");
        mock::set_pin("nurbs_interp.abort", Value::Bit(false));
        geometry(&job).publish(channel).unwrap();
        let (got, allocated) = run_module(channel, &job, 8, n + 50);
        assert_eq!(allocated, 0);
        assert_eq!(got.len(), n, "{what}: second motion");
        for (g, e) in got.iter().zip(&job.samples) {
            assert_eq!((g[0], g[1]), (e.point[0], e.point[1]), "{what}");
        }
        assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault"), "{what}");
        unsafe { rtapi_app_exit() };
    }
}

/// VPOp plans through the module as path blocks (`nurbs-planner --planner vpop`).
mod blocks {
    use super::*;
    use crate::channel::PathBlock;
    use crate::plan_geometry::{block_geometry, vpop_plan, Motion, Next};
    use crate::record::BLOCK_SAMPLES;
    use nurbs_motion::planner::verify::{verify, Row};
    use nurbs_motion::planner::vpop::VpopPlan;
    use nurbs_rtcore::StopRun;

    struct BlockJob {
        toolpath: Toolpath,
        plan: VpopPlan,
        geometry: GeometryBuilder,
        blocks: Vec<PathBlock>,
        /// Worst ratio to a limit of the checked stop after each block.
        ratios: Vec<f64>,
    }

    fn block_job(name: &str) -> BlockJob {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../examples")
            .join(name);
        block_job_for(name, read_toolpath(&path).unwrap())
    }

    /// The VPOp plan of `toolpath` at lab set 1 as blocks; every block-end stop must pass the
    /// check (the ones that do not are listed first).
    fn block_job_for(name: &str, toolpath: Toolpath) -> BlockJob {
        let limits = Limits::uniform(toolpath.tip_dim(), 2500.0, 1e4, 6e4, 0.001, PERIOD);
        let plan = vpop_plan(&toolpath, &limits, None).unwrap();
        let (geometry, blocks, choices) = block_geometry(&toolpath, &plan, None, 1.0).unwrap();
        let worst = choices.iter().map(|c| c.ratio).fold(0.0, f64::max);
        let failing = choices.iter().filter(|c| c.ratio > 1.0 + 1e-6).count();
        let stored = choices.iter().filter(|c| c.stored > 0).count();
        println!(
            "{name}: {} blocks, {stored} with a stored stop, {failing} without a stop within the limits, worst ratio {worst:.9}, {} arena values",
            blocks.len(),
            geometry.values().len()
        );
        for (k, c) in choices
            .iter()
            .enumerate()
            .filter(|(_, c)| c.ratio > 1.0 + 1e-6)
            .take(10)
        {
            let (s, v, a) = crate::module::block_end_state(&blocks[k], PERIOD);
            println!(
                "  block {k}: ratio {:.4}, stored {}, at s {s:.3} feed {v:.2} accel {a:.1}",
                c.ratio, c.stored
            );
        }
        assert_eq!(failing, 0, "a block-end stop exceeds the limits: worst ratio {worst}");
        assert_eq!(choices.len(), blocks.len());
        BlockJob {
            toolpath,
            plan,
            geometry,
            blocks,
            ratios: choices.iter().map(|c| c.ratio).collect(),
        }
    }

    fn push_blocks(channel: &Channel, blocks: &[PathBlock], mut from: usize) -> usize {
        while let Some(b) = blocks.get(from) {
            if channel.segments.push(&Slot::block(b)).is_err() {
                break;
            }
            from += 1;
        }
        from
    }

    /// One period: (x, y, feed, u, curve) if active, and the allocations of the call.
    fn period() -> (Option<[f64; 5]>, u64) {
        let update = mock::funct("nurbs_interp.update").unwrap();
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        let allocated = allocations() - before;
        let sample = bit("nurbs_interp.active").then(sample_pins);
        (sample, allocated)
    }

    fn rows(samples: &[[f64; 5]]) -> Vec<Row> {
        super::rows_of(samples)
    }

    /// The project's checker on a sampled run: no violation (axial limits by finite
    /// differences with the 1e-6 slack, feed, chord error, distance to the curve, end points).
    fn assert_verifies(job: &BlockJob, samples: &[[f64; 5]]) {
        let report = verify(&PathCurves::new(&job.toolpath), &job.plan.limits, &rows(samples));
        assert!(report.violations.is_empty(), "violations: {:?}", report.violations);
    }

    /// Publishes `job` and plays it to the end, queueing blocks as a planner would; returns the
    /// samples, after checking that no period allocated.
    fn play_all(job: &BlockJob, channel: &Channel) -> Vec<[f64; 5]> {
        mock::set_pin("nurbs_interp.enable", Value::Bit(true));
        job.geometry.publish(channel).unwrap();
        let (mut sent, mut got, mut allocated) = (0, Vec::new(), 0);
        for _ in 0..job.plan.points.len() + 50 {
            if channel.segments.len() < 4 {
                sent = push_blocks(channel, &job.blocks[..(sent + 8).min(job.blocks.len())], sent);
            }
            let (s, a) = period();
            allocated += a;
            got.extend(s);
        }
        assert_eq!(allocated, 0, "the update path allocated");
        got
    }

    /// One sample per planned period, each VPOp's parameter and (to 1e-9 mm) position; returns
    /// the largest distance.
    fn assert_exact(job: &BlockJob, got: &[[f64; 5]]) -> f64 {
        assert_eq!(got.len(), job.plan.points.len(), "one sample per planned period");
        let mut worst = 0.0f64;
        for (k, (g, p)) in got.iter().zip(&job.plan.points).enumerate() {
            assert_eq!((g[3], g[4] as usize), (p.u, p.element), "sample {k}: parameter");
            let d = (g[0] - p.tip[0]).hypot(g[1] - p.tip[1]);
            worst = worst.max(d);
            assert!(d <= 1e-9, "sample {k}: {d:e} mm from the VPOp position");
        }
        worst
    }

    #[test]
    fn vpop_blocks_run_exactly_the_planned_positions_without_allocating() {
        let _guard = lock_module();
        let job = block_job("trident.json");
        let (_planner, channel) = load();
        let got = play_all(&job, channel);
        assert!(allocations() > 0, "the counting allocator is not in use");
        assert!(
            !bit("nurbs_interp.fault"),
            "fault {}",
            u32_pin("nurbs_interp.fault-code")
        );
        let worst = assert_exact(&job, &got);
        println!("largest distance to VPOp's positions: {worst:e} mm");
        assert_verifies(&job, &got);
        assert!(bit("nurbs_interp.done"));
        assert_eq!(u32_pin("nurbs_interp.records") as usize, job.blocks.len());
        assert_eq!(float("nurbs_interp.buffered"), 0.0);
        // Done: nothing more moves.
        assert!(period().0.is_none());
        unsafe { rtapi_app_exit() };
    }

    /// A G1 polyline with its corners rounded is many elements (lines and corner splines): the
    /// blocks start anew at every element, and the module still plays exactly VPOp's positions
    /// across every join, and the run verifies. Every block end has a stop within the limits,
    /// also near a join (the stop goes on across it); an underrun at the fastest such block end
    /// stops across the join and resumes.
    #[test]
    fn vpop_blocks_cross_element_joins_exactly() {
        let _guard = lock_module();
        let toolpath = rounded_polyline();
        let elements = toolpath.elements.len();
        assert!(elements >= 9, "{elements} elements");
        let job = block_job_for("rounded polyline", toolpath);
        let curves_of_blocks: std::collections::BTreeSet<usize> = job.blocks.iter().map(|b| b.curve()).collect();
        assert_eq!(curves_of_blocks.len(), elements, "every element has blocks of its own");
        let (_planner, channel) = load();
        let got = play_all(&job, channel);
        assert!(
            !bit("nurbs_interp.fault"),
            "fault {}",
            u32_pin("nurbs_interp.fault-code")
        );
        assert_exact(&job, &got);
        assert_verifies(&job, &got);
        assert!(bit("nurbs_interp.done"));
        // Known limitation: the module's stop runs on one curve and ends at rest by its end at
        // the latest. A block ending closer to its element's end than a stop within the limits
        // needs has no such stop (it would have to cross the join): exactly those fail.
        unsafe { rtapi_app_exit() };
        // Every block end has a stop within the limits, also those closer to their element's
        // end than a stop needs: VPOp's stored deceleration sequence goes on across the join.
        // (`block_job_for` asserts it.)
        let values = job.geometry.values();
        let crossing: Vec<usize> = (0..job.blocks.len())
            .filter(|&k| {
                let b = &job.blocks[k];
                b.stop_len > 0 && super::last_run_curve(values, b.stop_offset, b.stop_len) > b.curve()
            })
            .collect();
        println!(
            "{} of {} block-end stops cross an element join",
            crossing.len(),
            job.blocks.len()
        );
        assert!(
            !crossing.is_empty(),
            "no stop crosses a join: the test lost its subject"
        );
        // The fastest of them runs in the module: an underrun there stops across the join,
        // within the limits, and the motion resumes from there.
        let end_feed = |k: &usize| crate::module::block_end_state(&job.blocks[*k], PERIOD).1;
        let fastest = crossing
            .iter()
            .copied()
            .max_by(|a, b| end_feed(a).total_cmp(&end_feed(b)));
        underrun_and_resume(&job, fastest.unwrap());
    }

    /// Only the blocks up to the one ending at the highest feed arrive: the module stops from
    /// that block's end (non-zero acceleration) along the curve, within the limits by the
    /// project's check, publishes the stop point; the VPOp plan from rest there runs on a
    /// `resume` edge to the path end. The whole sampled run passes the check, every stop sample
    /// lies on the curve, and nothing allocates. The same after the fastest block whose stop is
    /// VPOp's stored deceleration sequence (where no tangential stop stays within the limits).
    #[test]
    fn an_underrun_at_high_speed_stops_within_the_limits_and_resumes() {
        let _guard = lock_module();
        let job = block_job("trident.json");
        let end_feed = |b: &PathBlock| crate::module::block_end_state(b, PERIOD).1;
        let fastest = |stored: bool| {
            (2..job.blocks.len() - 1)
                .filter(|&k| (job.blocks[k].stop_len > 0) == stored)
                .max_by(|&a, &b| end_feed(&job.blocks[a]).total_cmp(&end_feed(&job.blocks[b])))
                .unwrap()
        };
        let peak = job.blocks.iter().map(end_feed).fold(0.0, f64::max);
        println!("peak block-end feed of the plan {peak:.1} mm/s");
        let tangential = fastest(false);
        let v = end_feed(&job.blocks[tangential]);
        assert!(v > 100.0 && v > 0.25 * peak, "not at high speed: {v}");
        underrun_and_resume(&job, tangential);
        let stored = fastest(true);
        assert!(end_feed(&job.blocks[stored]) > 50.0, "not at speed");
        underrun_and_resume(&job, stored);
    }

    fn underrun_and_resume(job: &BlockJob, cut: usize) {
        let (_planner, channel) = load();
        mock::set_pin("nurbs_interp.enable", Value::Bit(true));
        job.geometry.publish(channel).unwrap();
        let dt = PERIOD;
        let (_, v, a) = crate::module::block_end_state(&job.blocks[cut], dt);
        println!(
            "underrun after block {cut}: feed {v:.1} mm/s, acceleration {a:.1} mm/s^2, stored stop of {} periods",
            job.blocks[cut].stop_len
        );
        push_blocks(channel, &job.blocks[..=cut], 0);
        let (mut samples, mut allocated) = (Vec::new(), 0u64);
        let mut stop = None;
        for _ in 0..job.plan.points.len() {
            let (s, a) = period();
            allocated += a;
            samples.extend(s);
            stop = channel.stop.read();
            if stop.is_some() {
                break;
            }
        }
        let stop = stop.expect("no stop point published");
        assert!(bit("nurbs_interp.underrun") && !bit("nurbs_interp.fault"));
        assert_eq!(u32_pin("nurbs_interp.underruns"), 1);
        assert_eq!(stop.seq as usize, cut);
        let planned: usize = job.blocks[..=cut].iter().map(PathBlock::len).sum();
        assert!(samples.len() > planned + 3, "no stop ran: {} samples", samples.len());
        if job.blocks[cut].stop_len > 0 {
            assert_eq!(samples.len(), planned + job.blocks[cut].stop_len as usize);
        }
        for (k, (g, p)) in samples.iter().zip(&job.plan.points).take(planned).enumerate() {
            assert!((g[0] - p.tip[0]).hypot(g[1] - p.tip[1]) <= 1e-9, "sample {k}");
        }
        // The stop: along the path (every sample the point of its curve at its parameter, the
        // parameter never going back on a curve, curves only onwards one at a time) to rest.
        for w in samples[planned - 1..].windows(2) {
            let (e0, e1) = (w[0][4] as usize, w[1][4] as usize);
            assert!(e1 == e0 && w[1][3] >= w[0][3] || e1 == e0 + 1, "went back: {w:?}");
            let c = job.toolpath.elements[e1].curve.point(w[1][3]);
            assert!((w[1][0] - c[0]).hypot(w[1][1] - c[1]) <= 1e-9, "off the curve");
        }
        assert_eq!(
            [stop.point[0], stop.point[1]],
            [samples.last().unwrap()[0], samples.last().unwrap()[1]]
        );
        let stopped = samples.len();
        // The stop alone (the motion up to it, at rest after it) within the limits.
        let mut fd = nurbs_motion::planner::axial::FiniteDifferences::new(2, dt);
        for (k, s) in samples.iter().enumerate() {
            if k == planned {
                // From here the stop alone: what the planner checked for this block end.
                fd.reset_peaks();
            }
            fd.push(&s[..2], &job.plan.limits);
        }
        fd.finish(&job.plan.limits);
        let ratio = fd.worst_ratio(&job.plan.limits);
        println!(
            "stop from {v:.1} mm/s: {} periods, worst ratio {ratio:.4}",
            stopped - planned
        );
        assert!(ratio <= 1.0 + 1e-6, "the stop exceeds the limits: {ratio}");
        assert!(
            (ratio - job.ratios[cut]).abs() < 1e-9,
            "not the stop the planner checked"
        );
        // Re-plan from the stop point (VPOp from rest there), publish, resume on an edge.
        let plan2 = vpop_plan(&job.toolpath, &job.plan.limits, Some(&stop)).unwrap();
        let (g2, blocks2, _) = block_geometry(&job.toolpath, &plan2, Some(&stop), 1.0).unwrap();
        assert_eq!((blocks2[0].u[0], blocks2[0].s[0]), (stop.u, stop.s));
        for _ in 0..5 {
            samples.push(*samples.last().unwrap()); // held periods: at rest
            period();
        }
        g2.publish(channel).unwrap();
        let mut sent = push_blocks(channel, &blocks2, 0);
        for _ in 0..5 {
            let (s, _) = period();
            assert!(s.is_none(), "moved before the resume command");
            samples.push(*samples.last().unwrap());
        }
        assert!(bit("nurbs_interp.resume-ready"));
        mock::set_pin("nurbs_interp.resume", Value::Bit(true));
        for _ in 0..plan2.points.len() + 20 {
            sent = push_blocks(channel, &blocks2, sent);
            let (s, a) = period();
            allocated += a;
            samples.extend(s);
        }
        assert_eq!(allocated, 0, "the update path allocated");
        assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault") && !bit("nurbs_interp.underrun"));
        // The resumed motion's first sample is the held one (a period at rest), then VPOp's.
        assert_eq!(samples.len(), stopped + 10 + plan2.points.len());
        assert_verifies(job, &samples);
        unsafe { rtapi_app_exit() };
    }

    /// Runs `blocks` (as slots) until a fault; returns the fault code and whether the position
    /// stayed where it was at the fault.
    fn fault_of(job: &BlockJob, slots: &[Slot]) -> (u32, bool) {
        let (_planner, channel) = load();
        mock::set_pin("nurbs_interp.enable", Value::Bit(true));
        job.geometry.publish(channel).unwrap();
        let mut sent = 0;
        let mut last = None;
        let mut allocated = 0;
        for _ in 0..job.plan.points.len() {
            while let Some(s) = slots.get(sent) {
                if channel.segments.push(s).is_err() {
                    break;
                }
                sent += 1;
            }
            let (s, a) = period();
            allocated += a;
            if s.is_some() {
                last = s;
            }
            if bit("nurbs_interp.fault") {
                break;
            }
        }
        assert_eq!(allocated, 0);
        let code = u32_pin("nurbs_interp.fault-code");
        let held = [float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")];
        for _ in 0..100 {
            assert!(period().0.is_none(), "moved after a fault");
        }
        let still = held == [float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")];
        let at_last = last.is_some_and(|l| [l[0], l[1]] == held);
        unsafe { rtapi_app_exit() };
        (code, still && at_last)
    }

    /// Hold during a path-block motion: the module stops at the end of the current block with
    /// the stop checked there, publishes the stop point (cause hold); the VPOp plan from there
    /// runs when `hold` is released; the whole run (held periods included) passes `verify`.
    /// Abort: the same stop, then the queue is discarded and the stop point withdrawn.
    #[test]
    fn hold_and_abort_stop_at_the_block_end_within_the_limits() {
        let _guard = lock_module();
        let job = block_job("trident.json");
        for abort in [false, true] {
            let (_planner, channel) = load();
            mock::set_pin("nurbs_interp.enable", Value::Bit(true));
            job.geometry.publish(channel).unwrap();
            let mut sent = 0;
            let (mut samples, mut allocated) = (Vec::new(), 0u64);
            let pin = if abort {
                "nurbs_interp.abort"
            } else {
                "nurbs_interp.hold"
            };
            let mut stop = None;
            // The stop may outlast the rest of the plan (it brakes at the block's end): room
            // for it beyond the plan's periods.
            for k in 0..2 * job.plan.points.len() {
                sent = push_blocks(channel, &job.blocks, sent);
                if k == 1234 {
                    mock::set_pin(pin, Value::Bit(true)); // mid-block (1234 = 77 * 16 + 2)
                }
                let (s, a) = period();
                allocated += a;
                samples.extend(s);
                if bit("nurbs_interp.held") {
                    stop = channel.stop.read();
                    break;
                }
            }
            assert!(bit("nurbs_interp.held") && !bit("nurbs_interp.fault"));
            // The stop began at the end of the block the request came in (block 77).
            let planned: usize = job.blocks[..=77].iter().map(PathBlock::len).sum();
            for (k, (g, p)) in samples.iter().zip(&job.plan.points).take(planned).enumerate() {
                assert!((g[0] - p.tip[0]).hypot(g[1] - p.tip[1]) <= 1e-9, "sample {k}");
            }
            assert!(samples.len() > planned);
            if abort {
                assert!(stop.is_none(), "abort withdraws the stop point");
                for _ in 0..20 {
                    assert!(period().0.is_none());
                }
                assert!(channel.segments.is_empty(), "queue not discarded");
                assert!(!bit("nurbs_interp.done"));
                unsafe { rtapi_app_exit() };
                continue;
            }
            let stop = stop.expect("no stop point");
            assert_eq!((stop.cause, stop.seq), (2, 77));
            let plan2 = vpop_plan(&job.toolpath, &job.plan.limits, Some(&stop)).unwrap();
            let (g2, blocks2, _) = block_geometry(&job.toolpath, &plan2, Some(&stop), 1.0).unwrap();
            for _ in 0..5 {
                samples.push(*samples.last().unwrap());
                assert!(period().0.is_none());
            }
            g2.publish(channel).unwrap();
            let mut sent = push_blocks(channel, &blocks2, 0);
            for _ in 0..5 {
                samples.push(*samples.last().unwrap());
                assert!(period().0.is_none(), "moved under hold");
            }
            mock::set_pin("nurbs_interp.hold", Value::Bit(false));
            for _ in 0..plan2.points.len() + 20 {
                sent = push_blocks(channel, &blocks2, sent);
                let (s, a) = period();
                allocated += a;
                samples.extend(s);
            }
            assert_eq!(allocated, 0);
            assert!(bit("nurbs_interp.done") && !bit("nurbs_interp.fault"));
            assert_verifies(&job, &samples);
            unsafe { rtapi_app_exit() };
        }
    }

    /// Every block end of the butterfly's VPOp plan has a stop within the limits.
    #[test]
    fn butterfly_block_ends_all_have_a_checked_stop() {
        block_job("butterfly.json");
    }

    /// What a VPOp motion costs `nurbs-planner --planner vpop` before it starts (ignored in CI,
    /// a measurement): the VPOp plan, then the stop checks at every block end, at lab set 1.
    /// `cargo test --release -p nurbs-hal --features mock-hal vpop_start_cost -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn vpop_start_cost() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
        for name in ["trident.json", "butterfly.json"] {
            let toolpath = read_toolpath(&dir.join(name)).unwrap();
            let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, PERIOD);
            let t = std::time::Instant::now();
            let plan = vpop_plan(&toolpath, &limits, None).unwrap();
            let planned = t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            let (geometry, blocks, choices) = block_geometry(&toolpath, &plan, None, 1.0).unwrap();
            let checked = t.elapsed().as_secs_f64();
            let worst = choices.iter().map(|c| c.ratio).fold(0.0, f64::max);
            let stored = choices.iter().filter(|c| c.stored > 0).count();
            let tangential: Vec<f64> = choices.iter().filter(|c| c.stored == 0).map(|c| c.fraction).collect();
            println!(
                "{name}: motion {:.3} s; VPOp plan {planned:.2} s; stop checks at {} block ends {checked:.2} s ({:.1} ms per block of {:.1} ms of motion); worst ratio {worst:.7}; {stored} stored stops, mean jerk fraction of the others {:.4}; {} arena values",
                plan.motion_time,
                blocks.len(),
                1e3 * checked / blocks.len() as f64,
                1e3 * plan.motion_time / blocks.len() as f64,
                tangential.iter().sum::<f64>() / tangential.len().max(1) as f64,
                geometry.values().len()
            );
            assert!(worst <= 1.0 + nurbs_motion::planner::verify::SLACK);
        }
    }

    /// Every slot of a motion as `nurbs-planner` streams it, with its motion time, and the
    /// values appended to the arena behind the published geometry.
    fn drain(m: &mut Motion) -> (Vec<(Slot, f64, StopChoice)>, Vec<f64>) {
        let Motion { geometry, records, .. } = m;
        let base = geometry.values().len();
        let (mut out, mut appended) = (Vec::new(), Vec::new());
        loop {
            let mut arena = |v: &[f64]| {
                let offset = (base + appended.len()) as u32;
                appended.extend_from_slice(v);
                Some(offset)
            };
            match records.next(&mut arena).unwrap() {
                Next::Slot(slot, time, choice) => out.push((slot, time, choice)),
                Next::Working | Next::Waiting => {}
                Next::Done => return (out, appended),
            }
        }
    }

    /// What `nurbs-planner` streams: Erwinski plans as segment slots with their checked stops,
    /// the same as all at once ([`crate::plan_geometry::geometry`]), VPOp plans as block
    /// slots (one per block, their motion time one period per sample); a 5-axis toolpath is
    /// refused for VPOp with a message saying why.
    #[test]
    fn nurbs_planner_motions_of_both_kinds_and_the_5_axis_refusal() {
        use crate::plan_geometry::{motion, PlannerKind};
        use crate::record::{KIND_BLOCK, KIND_SEGMENT};
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
        let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, PERIOD);
        for toolpath in [read_toolpath(&dir.join("trident.json")).unwrap(), rounded_polyline()] {
            let job = super::job_of(toolpath.clone());
            let mut e = motion(&toolpath, &limits, PlannerKind::Erwinski, None, 1.0).unwrap();
            let (slots, appended) = drain(&mut e);
            assert!(slots.iter().all(|s| s.0.kind == KIND_SEGMENT));
            let streamed: Vec<Slot> = slots.iter().map(|s| s.0).collect();
            assert_eq!(slots.iter().map(|s| s.1).sum::<f64>(), e.motion_time);
            assert_eq!(streamed, job.slots);
            let mut values = e.geometry.values().to_vec();
            values.extend_from_slice(&appended);
            assert_eq!(values, job.geometry.values());
            let stored = slots.iter().filter(|s| s.2.stored > 0).count();
            println!("{} records streamed, {stored} with stored stops", slots.len());
        }
        let trident = read_toolpath(&dir.join("trident.json")).unwrap();
        let e = motion(&trident, &limits, PlannerKind::Erwinski, None, 1.0).unwrap();
        let mut v = motion(&trident, &limits, PlannerKind::Vpop, None, 1.0).unwrap();
        let (slots, appended) = drain(&mut v);
        assert!(appended.is_empty());
        assert!(slots.iter().all(|s| s.0.kind == KIND_BLOCK));
        assert_eq!(v.geometry.header().curve_count, 1);
        let samples: usize = slots
            .iter()
            .map(|s| s.0)
            .map(|s| match s.decode() {
                Some(crate::record::Record::Block(b)) => b.len(),
                _ => 0,
            })
            .sum();
        let time: f64 = slots.iter().map(|s| s.1).sum();
        assert_eq!(time, v.motion_time);
        assert!((time - samples as f64 * PERIOD).abs() < 1e-9);
        println!("{}; {}", e.summary, v.summary);
        let pocket = read_toolpath(&dir.join("open_pocket.json")).unwrap();
        let five = Limits::uniform(3, 2500.0, 1e4, 6e4, 0.001, PERIOD);
        let err = motion(&pocket, &five, PlannerKind::Vpop, None, 1.0)
            .err()
            .expect("5-axis accepted");
        assert!(err.contains("5-axis"), "{err}");
    }

    /// A stored stop sequence that does not fit its curve (a parameter beyond the curve, or
    /// going back, or NaN, a curve skipped or not a whole number, an arc length that does not
    /// follow on) faults when the module reaches it, with the position held.
    #[test]
    fn a_bad_stored_stop_faults_with_the_position_held() {
        let _guard = lock_module();
        let job = block_job("trident.json");
        let cut = (2..job.blocks.len() - 1)
            .find(|&k| job.blocks[k].stop_len > 10)
            .unwrap();
        let b = job.blocks[cut];
        // The trident is one curve: one run, its header (curve, count, s before) at 0..3,
        // position k's u and s at 3 + 2k and 4 + 2k. Each case faults at the given position.
        type Tamper = fn(&mut [f64]);
        let cases: [(Tamper, usize); 8] = [
            (|v| v[13] = f64::NAN, 5),
            (|v| v[13] = 1.5, 5),
            (|v| v[13] = v[9], 5),
            (|v| v[14] = v[10], 5),
            (|v| v[0] += 1.0, 0),
            (|v| v[0] = 0.5, 0),
            (|v| v[1] = 0.0, 0),
            (|v| v[2] += 1e-6, 0),
        ];
        for (tamper, at_position) in cases {
            let (_planner, channel) = load();
            mock::set_pin("nurbs_interp.enable", Value::Bit(true));
            let mut values = job.geometry.values().to_vec();
            let at = b.stop_offset as usize;
            tamper(&mut values[at..at + StopRun::VALUES + 2 * b.stop_len as usize]);
            channel
                .geometry
                .publish(&crate::channel::GeometryRef {
                    values: &values,
                    ..job.geometry.layout()
                })
                .unwrap();
            push_blocks(channel, &job.blocks[..=cut], 0);
            let mut last = None;
            let mut n = 0;
            for _ in 0..job.plan.points.len() {
                let (s, a) = period();
                assert_eq!(a, 0);
                if s.is_some() {
                    last = s;
                    n += 1;
                }
                if bit("nurbs_interp.fault") {
                    break;
                }
            }
            assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::BlockPath as u32);
            let planned: usize = job.blocks[..=cut].iter().map(PathBlock::len).sum();
            assert_eq!(n, planned + at_position, "the stop ran up to the bad position");
            for _ in 0..50 {
                assert!(period().0.is_none());
            }
            let l = last.unwrap();
            assert_eq!(
                [l[0], l[1]],
                [float("nurbs_interp.pos-cmd-x"), float("nurbs_interp.pos-cmd-y")]
            );
            unsafe { rtapi_app_exit() };
        }
    }

    #[test]
    fn bad_blocks_are_refused_with_the_position_held() {
        let _guard = lock_module();
        let job = block_job("trident.json");
        let k = job.blocks.len() / 2;
        const MID: usize = BLOCK_SAMPLES / 2;
        type Tamper = fn(&mut PathBlock);
        let cases: [(&str, Tamper, FaultCode); 10] = [
            (
                "stop points past the arena",
                |b| b.points_len = u32::MAX,
                FaultCode::Record,
            ),
            ("NaN parameter", |b| b.u[3] = f64::NAN, FaultCode::Record),
            ("infinite arc length", |b| b.s[0] = f64::INFINITY, FaultCode::Record),
            (
                "parameter beyond the curve",
                |b| b.u[b.len() - 1] = 1.5,
                FaultCode::BlockPath,
            ),
            ("sequence gap", |b| b.seq += 1, FaultCode::Sequence),
            ("parameter going back", |b| b.u[MID] = b.u[MID - 2], FaultCode::Record),
            ("arc length going back", |b| b.s[MID] = b.s[MID - 2], FaultCode::Record),
            (
                "arc lengths that do not fit the positions",
                |b| {
                    for s in &mut b.s[MID..] {
                        *s += 0.5;
                    }
                },
                FaultCode::BlockPath,
            ),
            ("no samples", |b| b.count = 0, FaultCode::Record),
            (
                "not continuing the previous block",
                |b| b.s_before[1] += 1e-6,
                FaultCode::BlockPath,
            ),
        ];
        for (what, tamper, code) in cases {
            let mut blocks = job.blocks.clone();
            tamper(&mut blocks[k]);
            let slots: Vec<Slot> = blocks[..=k].iter().map(Slot::block).collect();
            let (got, held) = fault_of(&job, &slots);
            assert_eq!(got, code as u32, "{what}");
            assert!(held, "{what}: position not held");
        }
        // Another kind within a block motion, and a slot of no known kind.
        let mut slots: Vec<Slot> = job.blocks[..k].iter().map(Slot::block).collect();
        let stop = RecordStop {
            accel: 1e4,
            jerk: 6e4,
            ..RecordStop::default()
        };
        slots.push(Slot::segment(
            &SegmentRecord {
                seq: k as u32,
                ..SegmentRecord::default()
            },
            &stop,
        ));
        assert_eq!(fault_of(&job, &slots), (FaultCode::RecordKind as u32, true));
        let mut slots: Vec<Slot> = job.blocks[..k].iter().map(Slot::block).collect();
        let mut unknown = Slot::block(&job.blocks[k]);
        unknown.kind = 77;
        slots.push(unknown);
        assert_eq!(fault_of(&job, &slots), (FaultCode::RecordKind as u32, true));
    }
}

/// Random G1 polylines (3-10 vertices, 3-300 mm), their corners rounded within a random
/// tolerance, under random limits at 0.25 and 1 ms: both planners' plans, as `nurbs-planner`
/// publishes them, have a stop within the limits at every record and block boundary (by the
/// finite-difference check, relative slack 1e-6). `STOP_CASES` (default 6) sets the number of
/// cases; the cases are the same in every run.
#[test]
fn random_polylines_have_a_stop_within_the_limits_at_every_boundary() {
    use nurbs_motion::geometry::{ElementKind, Nurbs};
    use nurbs_motion::planner::verify::SLACK;
    let mut rng = 0x2026_1122_u64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let cases: usize = std::env::var("STOP_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(6);
    let (mut records, mut blocks, mut stored) = (0, 0, 0);
    for case in 0..cases {
        let n = 3 + (next() * 8.0) as usize;
        let size = 10f64.powf(0.5 + 2.0 * next());
        let vertices: Vec<Vec<f64>> = (0..n).map(|_| vec![size * next(), size * next()]).collect();
        let mut knots = vec![0.0, 0.0];
        knots.extend((1..n - 1).map(|k| k as f64));
        knots.extend([(n - 1) as f64; 2]);
        let polyline = Toolpath::single(ElementKind::Polyline, Nurbs::new(1, knots, &vertices, None).unwrap());
        let eps = 10f64.powf(-3.0 + 2.0 * next());
        let toolpath = nurbs_motion::planner::corner::round_toolpath(&polyline, eps)
            .unwrap()
            .toolpath;
        let feed = 10f64.powf(1.0 + 2.4 * next());
        let accel = 10f64.powf(3.0 + 2.0 * next());
        let jerk = accel * 10f64.powf(0.5 + 1.5 * next());
        let dt = if next() < 0.5 { 0.00025 } else { 0.001 };
        let limits = Limits::uniform(2, feed, accel, jerk, eps, dt);
        let what = format!(
            "case {case}: {} elements, {size:.1} mm, eps {eps:.4}, F {feed:.0} A {accel:.0} J {jerk:.0} dt {dt}",
            toolpath.elements.len()
        );
        let plan = plan(&toolpath, &limits, &PlanOptions::default(), &mut |_| {}).unwrap();
        let (_, _, choices) = crate::plan_geometry::geometry(&toolpath, &plan, 1.0).unwrap();
        let vpop = crate::plan_geometry::vpop_plan(&toolpath, &limits, None).unwrap();
        let (_, b, block_choices) = crate::plan_geometry::block_geometry(&toolpath, &vpop, None, 1.0).unwrap();
        let worst = |c: &[crate::plan_geometry::StopChoice]| c.iter().map(|c| c.ratio).fold(0.0, f64::max);
        let count = |c: &[crate::plan_geometry::StopChoice]| c.iter().filter(|c| c.stored > 0).count();
        println!(
            "{what}: {} records ({} stored stops, worst {:.7}), {} blocks ({} stored, worst {:.7})",
            plan.records.len(),
            count(&choices),
            worst(&choices),
            b.len(),
            count(&block_choices),
            worst(&block_choices)
        );
        assert!(worst(&choices) <= 1.0 + SLACK, "{what}: records {choices:?}");
        assert!(worst(&block_choices) <= 1.0 + SLACK, "{what}: blocks");
        (records, blocks) = (records + plan.records.len(), blocks + b.len());
        stored += count(&choices) + count(&block_choices);
    }
    println!(
        "{cases} cases: {records} record and {blocks} block boundaries, {stored} stored stops, all within the limits"
    );
}
