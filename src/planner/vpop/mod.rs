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

pub use backtrack::{BrakeSetting, SearchOptions, SearchStats, BRAKES};
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
    let started = Instant::now();
    let limits = limits.for_axes(path.axes()).map_err(VpopError::Limits)?;
    let stepper = constraints::Stepper::new(path, &limits);
    let mut search = backtrack::Search::new(&stepper, options);
    let points = search.run().map_err(VpopError::Search)?;
    let stats = search.stats;
    Ok(VpopPlan {
        motion_time: (points.len() - 1) as f64 * limits.period,
        points,
        axes: path.axes(),
        plan_time: started.elapsed().as_secs_f64(),
        stats,
        limits,
    })
}
