//! Jerk-limited feedrate planning along NURBS toolpaths.
//!
//! Layout (dependencies point one way): [`readers`] turn files into [`geometry`]; the
//! [`planner`]s turn geometry into `nurbs_rtcore` segment records (or per-period positions);
//! the realtime core executes the records, in the planner's checks and on the servo thread.

// The numerical loops mirror the indices of the published algorithms.
#![allow(clippy::needless_range_loop)]

pub mod geometry;
pub mod kinematics;
pub mod panics;
pub mod planner;
pub mod readers;
