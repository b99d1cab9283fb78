//! Jerk-limited feedrate planning along NURBS toolpaths.
//!
//! Layout (dependencies point one way): [`readers`] turn files into [`geometry`]; the planners
//! (coming) turn geometry into `nurbs_rtcore` segment records; the realtime core executes them.

// The numerical loops mirror the indices of the published algorithms.
#![allow(clippy::needless_range_loop)]

pub mod cli;
pub mod geometry;
pub mod planner;
pub mod readers;
