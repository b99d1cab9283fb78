//! What `nurbs-planner` sends, prepared from a plan: ring slots in groups that end at a stop
//! within the axis limits, and for path blocks the arena data their stops need. Compiled into
//! the `nurbs-planner` binary and into the tests (never into the realtime module's library: it
//! needs the planner crate).
//!
//! Segment records (the Erwinski planner, streamed): each record the planner hands out is
//! final, and the last one of each run carries its stop, the next segment re-planned to rest
//! and checked by the planner itself ([`FinalRecord`]). A run and its stop make a group
//! ([`Grouper`]): the module takes a group only whole, so it stops only where a checked stop
//! is. Path blocks (VPOp, the reachability planner): the planner runs the module's stop from
//! every block end and checks it by finite differences ([`BlockBuilder`]); a block whose stop
//! it cannot bring within the limits joins the next block's group.
//!
//! One file per job: `segments` (the Erwinski plan into groups), `blocks` (plans of one point
//! per period into path blocks in groups), `block_stops` (the stop after a block: found and
//! checked), `source` (where a motion's groups come from, re-plans
//! at another feed override, the start rule), `streamer` (one motion into the channel). The
//! imports are shared here.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::time::Instant;

use crate::cut::{cut_into, CutFrom, CutPlace, ElementTables, CUT_RAMPS};
use crate::hold_stops::{HoldStops, RecordStops};
use crate::say;
use crate::shared_path::SharedPath;
use crate::writer::{GeometryWriter, Release, WriteError};
use nurbs_hal::channel::{
    Channel, Join, Slot, StopPoint, AT_RECORD_END, SEGMENT_SLOTS, SPLICE_ACCEPTED, SPLICE_DONE, SPLICE_REQUESTED,
};
use nurbs_hal::slot::{PathBlock, Record, SegmentSlot, BLOCK_SAMPLES, FLAG_LAST};
use nurbs_motion::geometry::{ArcLengthTable, Nurbs, Toolpath};
use nurbs_motion::planner::axial::FiniteDifferences;
use nurbs_motion::planner::erwinski::PlanStart;
use nurbs_motion::planner::reach::{self, window::WindowOptions, Planned, ReachOptions, ReachPlan};
use nurbs_motion::planner::simulate::SimState;
use nurbs_motion::planner::verify::SLACK;
use nurbs_motion::planner::vpop::{brake_points, plan_tip, JointPath, PathPoint, SearchOptions, VpopPlan};
use nurbs_motion::planner::{FinalRecord, Limits, MovingStart, PathCurves, PlanOptions, Planner, SLOW_DOWN_SHARES};
use nurbs_rtcore::block_stop::block_stop;
use nurbs_rtcore::interpolator::{Interpolator, Step};
use nurbs_rtcore::{CachedCurve, SegmentRecord, SpanCache, StopRun};

mod block_stops;
mod blocks;
mod segments;
mod source;
mod streamer;

use block_stops::*;
pub use blocks::*;
pub use segments::*;
pub use source::*;
pub use streamer::*;

/// Where a plan from the module's stop point starts: there, or where the machine stands at
/// the end of an element (not the last), at the start of the next one (the module accepts
/// either).
pub fn plan_start(curves: &mut PathCurves, stop: &StopPoint) -> PlanStart {
    PlanStart::at(curves, stop.curve as usize, stop.u, stop.s)
}
