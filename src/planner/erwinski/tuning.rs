//! The Erwinski planner's tuning constants, in one place, each with the reason for its value
//! (measured on the bundled curves and the random-curve runs unless it says otherwise).

// Segments, trials and searches (`mod.rs`)

/// Segments accepted after an absorbing one before the records before it are final.
pub(super) const ABSORBER_LOOK_BEHIND: usize = 1;

/// Motion time (s) of records not final before a stop chain settles them.
pub(super) const CHAIN_AFTER: f64 = 0.1;

/// Segments a stop chain stays behind the planning front: back-tracking cascades on dense G1
/// programs reach some 40 short segments back, and a cascade that reaches a chain makes the
/// plan stop there.
pub(super) const CHAIN_LOOK_BEHIND: usize = 64;

/// The same before the first record: the motion waits for it.
pub(super) const FIRST_CHAIN_LOOK_BEHIND: usize = 16;

/// Motion time (s) of a plan's first records settled by chains [`FIRST_CHAIN_LOOK_BEHIND`]
/// behind the front, each once [`EARLY_CHAIN_AFTER`] of motion waits (`EARLY_RUN`).
pub(super) const EARLY_RUN: f64 = 0.1;
pub(super) const EARLY_CHAIN_AFTER: f64 = 0.025;

/// Motion time (s) from a stop to the next one offered inside a run of records settled
/// together, and between tries where one fails (most fail on dense G1 programs: a short segment
/// in a rounded corner that brakes exceeds an axis' jerk). On the dense G1 program of
/// `scripts/dense-g1.py` these stops cut the median hold from 69 to 20.5 ms (600 lines, 200
/// holds of `planner/tests/hold.rs`) for some 5-10 % more planning (2,000 lines streamed, with
/// [`INNER_STOP_ATTEMPTS`]). A 10 ms gap and a try at every boundary held sooner (14 ms
/// median) for a quarter more planning.
pub(super) const INNER_STOP_GAP: f64 = 0.02;
pub(super) const INNER_STOP_RETRY: f64 = 0.005;

/// Attempts of a segment solve (end feeds lowered, peaks lowered) before it fails.
pub(super) const SOLVE_ATTEMPTS: usize = 40;

/// The same for the segments of a stop inside a run: the next boundary is tried instead. On
/// the dense G1 program as many stops pass with 3 as with 40, at less cost.
pub(super) const INNER_STOP_ATTEMPTS: usize = 3;

/// Servo periods the trials of one such stop may simulate: the passing ones on the dense G1
/// program take a few hundred; without a bound of its own, a stop that cannot pass could take
/// the plan's whole budget (minutes, on some random curves of the property test).
pub(super) const INNER_STOP_WORK: u64 = 20_000;

/// Failed stop chains remembered (not tried again while their inputs are the same).
pub(super) const FAILED_CHAINS_KEPT: usize = 16;

/// Segments of a stop chain solved again to end slower where the next cannot start as fast.
pub(super) const CHAIN_BACK_STEPS: usize = 16;

/// Most segments of a stop chain.
pub(super) const CHAIN_MAX: usize = 256;

/// Nodes inserted at most by segment splits (each one makes a segment shorter).
pub(super) const MAX_SPLITS: usize = 10_000;

/// Fraction of the feed cap at or below which a segment counts as starting from rest.
pub(super) const REST_FEED: f64 = 1e-9;

/// Servo periods the exact trials may simulate before the plan is refused: this many, plus
/// so many per period planned so far. The bundled curves simulate 3-10 per planned period;
/// the base is some 20 s of planning.
pub(super) const WORK_BUDGET_BASE: u64 = 20_000_000;

pub(super) const WORK_PER_PLANNED_PERIOD: u64 = 200;

/// The base of the same budget for a plan that continues a motion ([`super::MovingStart`]: a
/// re-plan at another feed override), some 0.5 s of planning: a re-plan that cannot find its
/// first segments within it cannot join in time anyway (one from a cut into the trident at
/// 50 % back to 100 % searched its first segment for over 15 s on the base above, a processor
/// busy all that time).
pub(super) const CONTINUED_WORK_BUDGET_BASE: u64 = 500_000;

/// Relative headroom of the planned feed below the programmed feed.
pub(super) const FEED_HEADROOM: f64 = 1e-7;

/// Relative excess of a nominal trial over an acceleration or jerk limit taken for rounding
/// ([`super::just_inside`]).
pub(super) const ROUNDING_EXCESS: f64 = 1e-5;

/// Share of the limits a profile that would ride them exactly aims at instead (the retry of
/// [`super::just_inside`], the tangential limits along a line): a hold stop from any of its
/// samples starts just inside the limits (0.1 %) and lands just after a sample with a jerk
/// up to some 0.05 % lower; with less jerk than the plan's to take an acceleration back, the
/// stop would run past the feed the plan reaches at the cap (on a 2000 mm line at the full
/// limits, no stop for 39 samples near the end of the acceleration).
pub(super) const STOP_ROOM: f64 = 0.998;

/// Margin of the estimate: the searches aim this far inside the limits, so that the exact check
/// of their choice usually passes.
pub(super) const ESTIMATE_MARGIN: f64 = 0.995;

/// An estimated ratio above this after the searches means: lower the end feed straight away.
pub(super) const HOPELESS_ESTIMATE: f64 = 1.05;

/// An estimated speed-cap ratio below this: the exact trial is not expected to exceed a speed
/// cap.
pub(super) const CLEAR_OF_SPEED_CAPS: f64 = 0.9;

/// Fraction of the planning tolerance above which a step's chord error is measured exactly.
pub(super) const EXACT_CHORD_ABOVE: f64 = 0.3;

/// A step whose sagitta bound is below this fraction of the planning tolerance is not probed.
pub(super) const PROBE_BELOW: f64 = 0.1;

/// Safety factor on the sagitta bound from the tabulated curvature.
pub(super) const SAGITTA_BOUND_FACTOR: f64 = 2.0;

/// Factors applied to the end feed when a segment cannot be made to fit (step 8), one per
/// lowering in turn, the last repeated: fine steps first, since the highest end feed that fits
/// is often a few percent below the first one tried, coarser ones after, to reach low feeds in
/// few attempts (a constant 0.8 made the bundled plans up to 5 % longer).
pub(super) const END_FEED_STEPS: [f64; 4] = [0.95, 0.9, 0.85, 0.8];

/// Factor applied to the start feed asked of the previous segment when even a stop at the end
/// fails (step 9).
pub(super) const START_FEED_STEP: f64 = 0.9;

/// Factor applied to the peak of a segment from rest to rest ([`lower_peak_at_rest`]).
pub(super) const PEAK_STEP: f64 = 0.8;

/// Bisections of a phase's jerk between the segment's jerk and the limit in
/// [`with_phase_jerks`].
pub(super) const PHASE_JERK_BISECTIONS: usize = 4;

/// Where [`with_phase_jerks`] aims, as a fraction of the limits by the calibrated estimate,
/// and the bounds of the estimate's margin there.
pub(super) const PHASE_JERK_AIM: f64 = 0.998;

pub(super) const MIN_PHASE_MARGIN: f64 = 0.98;

pub(super) const MAX_PHASE_MARGIN: f64 = 1.03;

/// Finer jerk searches of [`crawl_search`], each over this fraction of the range of the one
/// before.
pub(super) const FINER_JERK_SEARCHES: usize = 2;

pub(super) const FINER_CELL: f64 = 2e-3;

/// A lowering of the peak must bring the worst ratio below this fraction of what it was.
pub(super) const PEAK_PROGRESS: f64 = 0.999;

pub(super) const AT_PEAK: f64 = 0.98;

pub(super) const BELOW_PEAK: f64 = 0.9;

/// Factor on the sampled peak for an excess there.
pub(super) const PEAK_STEP_INSIDE: f64 = 0.95;

/// Start feeds below this fraction of the programmed feed crawl: see [`solve_segment`].
pub(super) const CRAWL_FEED: f64 = 1e-3;

/// The end-feed attempt before which a crawling segment tries a stop at its end.
pub(super) const CRAWL_CHECK_AT: usize = 3;

/// End-feed attempts in a row whose nominal trial's worst ratio improved by less than
/// `STALL_PROGRESS` before a segment tries a stop at its end (see [`solve_segment`]).
pub(super) const STALLED_ATTEMPTS: usize = 3;

pub(super) const STALL_PROGRESS: f64 = 0.999;

/// Lowerings in a row (of the end feed, or at rest of the peak) whose estimate stayed hopeless
/// and improved by less than `STALL_PROGRESS` before a segment gives up on its start feed (see
/// [`solve_segment`]).
/// Measured (`scripts/compare-builds.sh`): the 2,000-line dense G1 program planned in 0.61 x the
/// time, every bundled case and G-code example the same bit for bit (2 and 5 did as well).
pub(super) const HOPELESS_STALLED: usize = 3;

/// A speed excess inside a segment is split off as a node when the profile there is below this
/// fraction of the peak (at the peak, lowering the peak is the cure).
pub(super) const SPLIT_BELOW_PEAK: f64 = 0.99;

// Nodes and the look-ahead (`nodes.rs`)

/// A node is kept when the look-ahead reaches at least this fraction of its cap.
pub(super) const MERGE_TOLERANCE: f64 = 0.999;

/// Successor feeds sampled by [`NodeStream::backward_lowest`].
pub(super) const SUCCESSOR_FEEDS: usize = 16;

// The feedrate limit function and its scan (`flf.rs`)

/// Fraction of the chord tolerance the planner plans for: its per-period check measures the
/// sagitta at the middle parameter only, `verify` searches the whole step for the largest one.
pub(super) const CHORD_MARGIN: f64 = 0.9;

/// Closest spacing of FLF samples on a curve's control polygon (mm): far below any chord
/// tolerance or servo step that matters, and far above what a 0.02 mm G1 line at 500 samples
/// per control point would get.
pub(super) const MIN_SAMPLE_SPACING: f64 = 1e-4;

/// The same for a curve of more than [`CORNER_CONTROL_POINTS`] control points (a spline fitted
/// to a run of short lines, a NURBS block): no coarser than the finest chord tolerance in use or
/// a servo step at any useful feed. At [`MIN_SAMPLE_SPACING`] a 7 mm spline fitted to a dense
/// G1 run got 50,000 samples, whose arc grids were most of the planner's memory and time on
/// such programs. (Lines and corner splines keep the finer spacing: with it for them too, one
/// of 200 holds on a G1 zigzag waited 27.5 ms for a stop.)
pub(super) const MIN_SAMPLE_SPACING_LONG: f64 = 1e-3;

/// Control points of a corner spline (and of anything rounding makes of a G1 program).
pub(super) const CORNER_CONTROL_POINTS: usize = 5;

/// FLF samples per control point at least, however short the curve.
pub(super) const MIN_SAMPLES_PER_POINT: usize = 16;

/// Neighbours on each side a critical sample must not exceed.
pub(super) const NEIGHBOURS: usize = 5;

// S-curve fitting (`scurve_fit.rs`)

/// Halvings of the peak-feed bisection at most: the paper's 30, more only for slivers.
pub(super) const MAX_HALVINGS: i32 = 60;

/// Most segments of a stop chain inside a run (the next boundary is tried where a stop needs
/// more).
pub(super) const INNER_CHAIN_MAX: usize = 32;
