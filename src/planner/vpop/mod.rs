//! VPOp (Beudaert, Lavernhe, Tournier 2012): time-discretised feedrate planning by
//! constraint intersection at the servo period, with per-axis velocity, acceleration and jerk
//! limits of any machine structure (2-/3-axis tool tip, XYZAC or XYZBC 5-axis), dichotomy back-tracking
//! and look-ahead to the path end.
//!
//! The output is one path position per servo period; by construction every sample passes the
//! finite-difference check of [`crate::planner::axial`] against the limits themselves (the
//! paper tolerated a 120 % jerk overrun).

mod backtrack;
pub mod constraints;
pub mod path;

pub use backtrack::{BrakeSetting, Release, SearchOptions, SearchStats, BRAKES};
pub use path::{CurvatureTables, JointPath, PathPoint};

use crate::geometry::Toolpath;
use crate::kinematics::TableTilting;
use crate::planner::{Limits, LimitsError};
use std::time::Instant;

/// A VPOp plan: one point per servo period, at rest before the first and after the last.
#[derive(Clone, Debug)]
pub struct VpopPlan {
    pub points: Vec<PathPoint>,
    /// Limits as used (one value per joint axis).
    pub limits: Limits,
    /// Axes the limits apply to (tip coordinates, or x y z a c).
    pub axes: usize,
    /// Motion time (s): (points - 1) periods.
    pub motion_time: f64,
    /// Wall-clock planning time (s).
    pub plan_time: f64,
    pub stats: SearchStats,
}

/// Why a plan could not be made.
#[derive(Clone, Debug, PartialEq)]
pub enum VpopError {
    Limits(LimitsError),
    Path(String),
    Search(String),
}

impl std::fmt::Display for VpopError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VpopError::Limits(e) => write!(f, "{e}"),
            VpopError::Path(e) => write!(f, "invalid path: {e}"),
            VpopError::Search(e) => write!(f, "VPOp: {e}"),
        }
    }
}
impl std::error::Error for VpopError {}

/// Plans the tool-tip path of `toolpath` (2 or 3 axes; a top curve is ignored).
pub fn plan_tip(toolpath: &Toolpath, limits: &Limits, options: SearchOptions) -> Result<VpopPlan, VpopError> {
    if toolpath.elements.is_empty() {
        return Err(VpopError::Path("no elements".into()));
    }
    let path = JointPath::tip(toolpath);
    run(&path, limits, options)
}

/// Plans a two-curve (tip + top) toolpath on a table-tilting machine; limits in joint order
/// x, y, z, tilt (a or b), c (rotary in degrees).
pub fn plan_five_axis(
    toolpath: &Toolpath,
    machine: TableTilting,
    limits: &Limits,
    options: SearchOptions,
) -> Result<VpopPlan, VpopError> {
    if toolpath.elements.is_empty() {
        return Err(VpopError::Path("no elements".into()));
    }
    let path = JointPath::five_axis(toolpath, machine).map_err(VpopError::Path)?;
    run(&path, limits, options)
}

/// VPOp's own deceleration sequence from the motion state given by its last three points
/// (oldest first) to rest: the positions of the periods that follow, the machine staying at the
/// last one. Every step passes the same constraints as a planned step. `None` where the
/// sequence does not reach rest.
pub fn brake_points(
    path: &JointPath,
    limits: &Limits,
    options: SearchOptions,
    last: [PathPoint; 3],
) -> Result<Option<Vec<PathPoint>>, VpopError> {
    let limits = limits.for_axes(path.axes()).map_err(VpopError::Limits)?;
    let stepper = constraints::Stepper::new(path, &limits);
    let mut search = backtrack::Search::new(&stepper, options);
    Ok(search.brake_points(constraints::History { p: last }))
}

/// Plans along any [`JointPath`].
pub fn run(path: &JointPath, limits: &Limits, options: SearchOptions) -> Result<VpopPlan, VpopError> {
    let mut points = Vec::new();
    let run = run_streamed(path, limits, options, &mut |p| {
        points.push(*p);
        Ok(())
    })?;
    Ok(run.with_points(points))
}

/// What the command lines say where VPOp is given a hold reserve ([`Limits::hold_reserve`]):
/// VPOp plans at the limits themselves (its stops come at every path block's end).
pub const HOLD_RESERVE_IGNORED: &str =
    "the hold reserve applies to the Erwinski planner: VPOp plans at the limits themselves";

/// What a streamed plan came to; its points went to the caller as they became final.
#[derive(Clone, Debug)]
pub struct VpopRun {
    /// Points handed out.
    pub points: usize,
    /// Limits as used (one value per joint axis).
    pub limits: Limits,
    /// Axes the limits apply to.
    pub axes: usize,
    /// Motion time (s): (points - 1) periods.
    pub motion_time: f64,
    /// Wall-clock planning time (s), the caller's handling of the points included.
    pub plan_time: f64,
    /// Wall-clock time until the first points were handed out (s).
    pub first_points_time: f64,
    pub stats: SearchStats,
}

impl VpopRun {
    /// The plan these figures are of, with its `points` (as handed out).
    pub fn with_points(self, points: Vec<PathPoint>) -> VpopPlan {
        VpopPlan {
            points,
            limits: self.limits,
            axes: self.axes,
            motion_time: self.motion_time,
            plan_time: self.plan_time,
            stats: self.stats,
        }
    }
}

/// Plans along `path`, handing each point to `emit` as soon as it is final (see
/// [`backtrack::Search::run_streamed`]): the motion of any length with the points of a few
/// milliseconds in memory. The points are those [`run`] returns, bit for bit.
pub fn run_streamed(
    path: &JointPath,
    limits: &Limits,
    options: SearchOptions,
    emit: &mut dyn FnMut(&PathPoint) -> Result<(), String>,
) -> Result<VpopRun, VpopError> {
    let started = Instant::now();
    if path.is_empty() {
        return Err(VpopError::Path("no elements".into()));
    }
    let limits = limits.for_axes(path.axes()).map_err(VpopError::Limits)?;
    let stepper = constraints::Stepper::new(path, &limits);
    let mut search = backtrack::Search::new(&stepper, options);
    let mut first_points_time = None;
    let points = search
        .run_streamed(&mut |p| {
            first_points_time.get_or_insert_with(|| started.elapsed().as_secs_f64());
            emit(p)
        })
        .map_err(VpopError::Search)?;
    let stats = search.stats;
    Ok(VpopRun {
        points,
        motion_time: (points - 1) as f64 * limits.period,
        axes: path.axes(),
        plan_time: started.elapsed().as_secs_f64(),
        first_points_time: first_points_time.unwrap_or(0.0),
        stats,
        limits,
    })
}
