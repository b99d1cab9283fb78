//! The realtime module and its planner on the mock HAL: `rtapi_app_main` and
//! `nurbs_interp.update` driven period by period, fed by the planner's own [`Streamer`], with a
//! counting allocator that proves the update path allocates nothing. Shared by the test files.
#![allow(dead_code)] // each test file uses a different subset

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use nurbs_cli::corners::{prepare, RoundCorners};
use nurbs_cli::LimitArgs;
use nurbs_hal::channel::{Channel, StopPoint};
use nurbs_hal::mock::{self, Value};
use nurbs_hal::module::{rtapi_app_exit, rtapi_app_main};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::simulate::setpoints;
use nurbs_motion::planner::verify::{verify, Row};
use nurbs_motion::planner::{Limits, PathCurves};
use nurbs_planner::feed::{plan_groups, SegmentGroup, Source, Streamer};
use nurbs_planner::hal_user::Component;
use nurbs_planner::shared_path::SharedPath;
use nurbs_rtcore::interpolator::Sample;

pub mod test_paths;

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

pub fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// The module keeps its component id in process-wide statics (as a loaded .so does): one
/// module test at a time.
static MODULE: Mutex<()> = Mutex::new(());

/// The module statics for this test alone, also after another test panicked.
pub fn lock_module() -> MutexGuard<'static, ()> {
    MODULE.lock().unwrap_or_else(|e| e.into_inner())
}

pub const PERIOD_NS: i64 = 250_000;
pub const PERIOD: f64 = 0.00025;

pub fn float(name: &str) -> f64 {
    match mock::pin(name) {
        Some(Value::Float(v)) => v,
        other => panic!("{name}: {other:?}"),
    }
}

pub fn u32_pin(name: &str) -> u32 {
    match mock::pin(name) {
        Some(Value::U32(v)) => v,
        other => panic!("{name}: {other:?}"),
    }
}

pub fn bit(name: &str) -> bool {
    match mock::pin(name) {
        Some(Value::Bit(v)) => v,
        other => panic!("{name}: {other:?}"),
    }
}

pub fn set_bit(name: &str, v: bool) {
    assert!(mock::set_pin(name, Value::Bit(v)), "{name}");
}

/// The module loaded, with a planner component attached to its channel.
pub struct Loaded {
    pub planner: Component,
    pub channel: &'static Channel,
}

impl Drop for Loaded {
    fn drop(&mut self) {
        // SAFETY: loaded by `load`; the test does not use the module afterwards.
        unsafe { rtapi_app_exit() };
    }
}

/// Loads the module, enables it and attaches a planner component to its channel.
pub fn load() -> Loaded {
    mock::reset();
    // SAFETY: the mock HAL stands in for rtapi_app; one module test at a time (lock_module).
    assert_eq!(unsafe { rtapi_app_main() }, 0, "{:?}", mock::messages());
    assert_eq!(mock::component_ready("nurbs_interp"), Some(true));
    let planner = Component::new("nurbs-planner").unwrap();
    let channel = planner.attach_channel(Duration::ZERO).unwrap();
    set_bit("nurbs_interp.enable", true);
    Loaded { planner, channel }
}

/// One period of the module; returns whether it allocated.
pub fn period() -> bool {
    let update = mock::funct("nurbs_interp.update").unwrap();
    let before = allocations();
    // SAFETY: the exported function with its instance, called as a servo thread would.
    unsafe { mock::call(update, PERIOD_NS as _) };
    allocations() != before
}

/// What the module outputs in a period: the tip position, feed, u and curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Out {
    pub q: [f64; 3],
    pub feed: f64,
    pub u: f64,
    pub curve: usize,
}

pub fn out() -> Out {
    Out {
        q: [
            float("nurbs_interp.pos-cmd-x"),
            float("nurbs_interp.pos-cmd-y"),
            float("nurbs_interp.pos-cmd-z"),
        ],
        feed: float("nurbs_interp.feed"),
        u: float("nurbs_interp.u"),
        curve: u32_pin("nurbs_interp.curve") as usize,
    }
}

pub fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// A toolpath as `nurbs-planner` prepares it (G1 corners rounded within the chord tolerance),
/// its streamed plan at lab set 1 in groups, and the offline setpoints of that plan (what
/// `nurbs-plan plan --stream --out` writes).
pub struct Job {
    pub toolpath: Toolpath,
    pub limits: Limits,
    pub groups: Vec<SegmentGroup>,
    pub samples: Vec<Sample>,
}

pub fn lab1(tip: usize) -> Limits {
    let limits = nurbs_motion::planner::presets::named("lab1").on(tip);
    assert_eq!(limits.period, PERIOD, "the module's tests run at lab set 1's period");
    limits
}

/// Limit flags with only the chord tolerance (what the path's preparation needs).
pub fn chord_tolerance(tolerance: f64) -> LimitArgs {
    LimitArgs {
        chord_tol: Some(tolerance),
        ..LimitArgs::default()
    }
}

/// The job of a bundled example.
pub fn job(name: &str) -> Job {
    job_at(&examples().join(name))
}

/// [`job`] of a file anywhere.
pub fn job_at(path: &Path) -> Job {
    job_of(prepared(path))
}

/// The toolpath of a file as `nurbs-plan` prepares it by default (`--round-corners auto`:
/// corners rounded, runs of short lines fitted).
pub fn prepared(path: &Path) -> Toolpath {
    prepare(path, Some(RoundCorners::Auto), &chord_tolerance(0.001))
        .unwrap()
        .toolpath
}

/// [`job_at`] with the corners only rounded, each on its own (`--round-corners round`).
pub fn job_rounded(path: &Path) -> Job {
    let prepared = prepare(path, Some(RoundCorners::Round), &chord_tolerance(0.001)).unwrap();
    job_of(prepared.toolpath)
}

/// A dense CAM-like G1 program of `lines` lines of 0.02 mm (`scripts/dense-g1.py`), written
/// to `dir`.
pub fn dense_g1(lines: usize, dir: &Path) -> PathBuf {
    let out = std::process::Command::new("python3")
        .arg(examples().join("../scripts/dense-g1.py"))
        .args(["--lines", &lines.to_string()])
        .output()
        .expect("python3 runs scripts/dense-g1.py");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let path = dir.join(format!("dense-{lines}.ngc"));
    std::fs::write(&path, out.stdout).unwrap();
    path
}

/// Planned at lab set 1; with the environment's `HOLD_RESERVE` where it is set (measurement
/// runs of the hold and feed-override tests with a hold reserve, `--hold-reserve`).
pub fn job_of(toolpath: Toolpath) -> Job {
    let mut limits = lab1(toolpath.tip_dim()).for_axes(toolpath.tip_dim()).unwrap();
    if let Some(r) = std::env::var("HOLD_RESERVE").ok().and_then(|v| v.parse().ok()) {
        limits.hold_reserve = r;
    }
    job_within(toolpath, limits)
}

/// [`job_of`] with other limits.
pub fn job_within(toolpath: Toolpath, limits: Limits) -> Job {
    let groups = plan_groups(&toolpath, &limits, None).unwrap();
    let records: Vec<_> = groups.iter().flat_map(|g| g.slots.iter().map(|s| s.record)).collect();
    let samples = setpoints(&PathCurves::new(&toolpath), &limits, &records);
    Job {
        toolpath,
        limits,
        groups,
        samples,
    }
}

/// A streamer for `groups` of `job` into the loaded module's channel (margin: everything the
/// ring takes), from curve `first`.
pub fn streamer<'a>(l: &'a Loaded, toolpath: &'a Toolpath, groups: Vec<SegmentGroup>, first: usize) -> Streamer<'a> {
    Streamer::new(
        l.channel,
        toolpath.tip_dim(),
        Source::groups(groups, PERIOD),
        first,
        f64::INFINITY,
        Instant::now(),
    )
    .unwrap()
}

/// Runs periods (filling from `s` before each, calling `control(period)`) until `stop(period)`
/// or `limit` periods; returns the output of every period with a sample. Asserts that the
/// update path never allocated.
pub fn run(
    s: &mut Streamer,
    limit: usize,
    control: &mut dyn FnMut(usize),
    stop: &mut dyn FnMut(usize) -> bool,
) -> Vec<Out> {
    let mut got = Vec::new();
    for k in 0..limit {
        s.fill().unwrap();
        control(k);
        assert!(!period(), "the update path allocated (period {k})");
        if bit("nurbs_interp.active") {
            got.push(out());
        }
        if stop(k) {
            break;
        }
    }
    got
}

/// Runs until the module is done, faults or holds (or `limit` periods).
pub fn run_to_rest(s: &mut Streamer, limit: usize) -> Vec<Out> {
    run(s, limit, &mut |_| {}, &mut |_| {
        bit("nurbs_interp.done") || bit("nurbs_interp.fault") || bit("nurbs_interp.held")
    })
}

/// The module's samples equal the offline ones, bit for bit.
pub fn assert_exact(name: &str, got: &[Out], expected: &[Sample], tip: usize) {
    assert_eq!(got.len(), expected.len(), "{name}: sample count");
    for (k, (g, e)) in got.iter().zip(expected).enumerate() {
        let z = if tip >= 3 { e.point[2] } else { 0.0 };
        let want = [e.point[0], e.point[1], z, e.feed, e.u, e.curve as f64];
        let have = [g.q[0], g.q[1], g.q[2], g.feed, g.u, g.curve as f64];
        assert_eq!(
            have.map(f64::to_bits),
            want.map(f64::to_bits),
            "{name}: sample {k}: {have:?} != {want:?}"
        );
    }
}

/// The project's check (`nurbs-plan verify`'s) on a sampled run: the violations it reports,
/// besides not reaching the path end when `to_end` is false.
pub fn violations(job: &Job, run: &[Out], to_end: bool) -> Vec<String> {
    let tip = job.toolpath.tip_dim();
    let rows: Vec<Row> = run
        .iter()
        .enumerate()
        .map(|(k, o)| Row {
            t: k as f64 * PERIOD,
            curve: o.curve,
            u: o.u,
            q: o.q[..tip].to_vec(),
        })
        .collect();
    let report = verify(&mut PathCurves::new(&job.toolpath), &job.limits, &rows);
    report
        .violations
        .into_iter()
        .filter(|v| to_end || v != "the last setpoint is not the end of the path")
        .collect()
}

/// The machine held still between a stop and the resumed motion (at least three periods, as
/// the module waits for the command): what a sampler that records only moving periods leaves
/// out, put back in.
pub fn hold_position(run: &mut Vec<Out>) {
    if let Some(&last) = run.last() {
        run.extend([Out { feed: 0.0, ..last }; 3]);
    }
}

/// The stop point the module published, if any.
pub fn stop_point(channel: &Channel) -> Option<StopPoint> {
    channel.stop.read()
}

/// Paces the mock module's periods: at most `speed` times the servo thread's real pace, and
/// never faster to catch up after a slow period.
pub struct Pace {
    began: Instant,
    next: f64,
    step: f64,
}

impl Pace {
    pub fn new(began: Instant, speed: f64) -> Pace {
        Pace {
            began,
            next: 0.0,
            step: PERIOD / speed,
        }
    }

    /// Waits until the next period is due.
    pub fn wait(&mut self) {
        let now = self.began.elapsed().as_secs_f64();
        if now < self.next {
            std::thread::sleep(std::time::Duration::from_secs_f64(self.next - now));
        }
        self.next = self.began.elapsed().as_secs_f64().max(self.next) + self.step;
    }
}

/// Streams a plan of `toolpath` (the planner's own streaming source, as `nurbs-planner` runs
/// it) into the loaded module `l`, whose periods run at most `speed` times the servo's real
/// pace ([`Pace`]) for at most `periods`, until the motion is done, faults or holds.
/// `control` is called before each period with the streamer and the samples so far (to change
/// the feed override). Returns the module's samples while active, and the streamer.
pub fn paced_run<'a>(
    l: &'a Loaded,
    toolpath: &Toolpath,
    limits: &Limits,
    speed: f64,
    periods: usize,
    mut control: impl FnMut(&mut Streamer<'a>, usize),
) -> (Vec<Out>, Streamer<'a>) {
    let source = Source::streamed(SharedPath::whole(toolpath), limits.clone(), None, 1.0);
    paced_source_run(l, toolpath.tip_dim(), source, speed, periods, &mut control)
}

/// [`paced_run`] of any source of a `tip`-axis path.
pub fn paced_source_run<'a>(
    l: &'a Loaded,
    tip: usize,
    source: Source,
    speed: f64,
    periods: usize,
    control: &mut dyn FnMut(&mut Streamer<'a>, usize),
) -> (Vec<Out>, Streamer<'a>) {
    let began = Instant::now();
    let mut s = Streamer::new(l.channel, tip, source, 0, 0.25, began).unwrap();
    let mut got: Vec<Out> = Vec::new();
    let mut pace = Pace::new(began, speed);
    for k in 0..periods {
        s.fill().unwrap();
        control(&mut s, got.len());
        pace.wait();
        assert!(!period(), "the update path allocated (period {k})");
        if bit("nurbs_interp.active") {
            got.push(out());
        }
        if bit("nurbs_interp.done") || bit("nurbs_interp.fault") || bit("nurbs_interp.held") {
            break;
        }
    }
    (got, s)
}

/// Instants at random samples of a motion (a seeded xorshift: the same run every time).
pub struct Instants(u64);

impl Instants {
    pub fn new(seed: u64) -> Instants {
        Instants(seed)
    }

    /// A sample in `1..=below`.
    pub fn next(&mut self, below: usize) -> usize {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        1 + (self.0 % below as u64) as usize
    }
}

/// The `p` quantile of sorted latencies (0 if there are none).
pub fn quantile(sorted: &[usize], p: f64) -> usize {
    sorted
        .get(((sorted.len() as f64 - 1.0) * p) as usize)
        .copied()
        .unwrap_or(0)
}
