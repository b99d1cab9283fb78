//! `rtapi_app_main` and `nurbs_interp.update` driven period by period through the mock HAL,
//! with a counting allocator that proves the update path allocates nothing.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Mutex;
use std::time::Duration;

use crate::channel::{Channel, SegmentRecord};
use crate::mock::{self, Value};
use crate::module::{rtapi_app_exit, rtapi_app_main};
use crate::sys;
use crate::user::{Component, StreamReader, StreamValue};

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

fn record(seq: u32) -> SegmentRecord {
    SegmentRecord {
        seq,
        s_start: seq as f64 * 0.001 + (seq as f64).sqrt() * 1e-7,
        u_start: seq as f64 / 3.0,
        feed_start: 10.0 + seq as f64,
        ..SegmentRecord::default()
    }
}

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

#[test]
fn module_creates_its_pins_and_function() {
    let _guard = MODULE.lock().unwrap_or_else(|e| e.into_inner());
    let (planner, _) = load();
    let names = mock::pin_names();
    for pin in [
        "enable",
        "pos-cmd-x",
        "pos-cmd-y",
        "pos-cmd-z",
        "active",
        "fault",
        "seq",
        "records",
        "underruns",
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

#[test]
fn update_streams_records_then_counts_underruns_without_allocating() {
    let _guard = MODULE.lock().unwrap_or_else(|e| e.into_inner());
    let (_planner, channel) = load();
    let update = mock::funct("nurbs_interp.update").unwrap();
    const N: u32 = 3000; // more than the ring holds: the test refills it as the module drains
    let mut sent = 0u32;
    let fill = |sent: &mut u32| {
        while *sent < N && channel.segments.push(&record(*sent)).is_ok() {
            *sent += 1;
        }
    };

    // Disabled: outputs hold, nothing is consumed.
    fill(&mut sent);
    unsafe { mock::call(update, PERIOD_NS as _) };
    assert!(!bit("nurbs_interp.active"));
    assert_eq!(u32_pin("nurbs_interp.records"), 0);
    assert!(mock::set_pin("nurbs_interp.enable", Value::Bit(true)));

    let mut update_allocations = 0;
    for period in 0..N + 10 {
        if period % 100 == 0 {
            fill(&mut sent);
        }
        let before = allocations();
        unsafe { mock::call(update, PERIOD_NS as _) };
        update_allocations += allocations() - before;
        if period < N {
            let expected = record(period);
            assert!(bit("nurbs_interp.active"));
            assert_eq!(u32_pin("nurbs_interp.seq"), period);
            assert_eq!(
                float("nurbs_interp.pos-cmd-x").to_bits(),
                expected.s_start.to_bits()
            );
            assert_eq!(
                float("nurbs_interp.pos-cmd-y").to_bits(),
                expected.u_start.to_bits()
            );
            assert_eq!(float("nurbs_interp.pos-cmd-z"), expected.feed_start);
        } else {
            assert!(!bit("nurbs_interp.active"));
            assert_eq!(u32_pin("nurbs_interp.underruns"), period - N + 1);
            // Outputs hold the last position.
            assert_eq!(
                float("nurbs_interp.pos-cmd-x").to_bits(),
                record(N - 1).s_start.to_bits()
            );
        }
    }
    assert_eq!(update_allocations, 0, "the update path allocated");
    assert!(allocations() > 0, "the counting allocator is not in use");
    assert_eq!(u32_pin("nurbs_interp.records"), N);
    assert!(!bit("nurbs_interp.fault"));
    unsafe { rtapi_app_exit() };
}

#[test]
fn a_sequence_gap_faults_and_holds() {
    let _guard = MODULE.lock().unwrap_or_else(|e| e.into_inner());
    let (_planner, channel) = load();
    let update = mock::funct("nurbs_interp.update").unwrap();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    channel.segments.push(&record(0)).unwrap();
    channel.segments.push(&record(2)).unwrap();
    channel.segments.push(&record(3)).unwrap();
    for _ in 0..4 {
        unsafe { mock::call(update, PERIOD_NS as _) };
    }
    assert!(bit("nurbs_interp.fault"));
    assert!(!bit("nurbs_interp.active"));
    assert_eq!(float("nurbs_interp.pos-cmd-x"), record(0).s_start);
    assert_eq!(u32_pin("nurbs_interp.records"), 1);
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
        vec![
            StreamValue::Float(x),
            StreamValue::Bit(true),
            StreamValue::U32(7)
        ]
    );
}
