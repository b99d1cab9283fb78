//! Realtime core of the NURBS motion product.
//!
//! Plain data and pure functions that run on the servo thread: NURBS evaluation, the S-curve
//! feed of one planned segment, and the per-period interpolation step that turns a feed into a
//! curve parameter. The crate is `no_std` and does not link `alloc`, so nothing here can
//! allocate; it knows nothing of HAL, files or the planner.
#![cfg_attr(not(test), no_std)]
// Safe Rust only: what the servo thread runs has no unsafe of its own (the HAL glue is in nurbs-hal).
#![forbid(unsafe_code)]
// No unwrap, expect or explicit panic on the servo thread's code (the tests may). Indexing is
// not denied here as it is in the module's own code: the numerical loops index fixed-size
// arrays and validated curves by the published algorithms' subscripts, bounded by MAX_ORDER
// and the checks `CurveView::new` makes (tested, and fuzzed through the module's validation).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used, clippy::panic))]
// The numerical loops mirror the indices of the published algorithms (P&T A2.3, A4.2).
#![allow(clippy::needless_range_loop)]

pub mod block_stop;
pub mod handover;
pub mod interpolator;
pub mod kinematics;
pub mod math;
pub mod nurbs;
pub mod records;
pub mod scurve;
pub mod span_cache;
pub mod step_methods;

pub use math::Vector;
pub use nurbs::{
    basis_functions, CurveView, GeometryError, Homogeneous, ValuesChecked, MAX_DEGREE, MAX_DERIV, MAX_DIM,
};
pub use records::{PathBlock, RecordError, SegmentRecord, StopRun, BLOCK_SAMPLES};
pub use scurve::{SCurve, SCurveState};
pub use span_cache::{CachedCurve, SpanCache};
