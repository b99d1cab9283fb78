//! The command line of `nurbs-planner` (the binary is in the `nurbs-planner` crate): here so that
//! its flags are the ones `nurbs-plan` has, and its man page is rendered with `nurbs-plan`'s.

use crate::corners::RoundCorners;
use crate::{LimitArgs, PlannerKind};
use clap::Parser;
use std::path::PathBuf;

/// `nurbs-planner TOOLPATH ...`: plans a toolpath and streams it to `nurbs_interp`.
#[derive(Parser, Debug)]
#[command(
    name = "nurbs-planner",
    about = "Plan a NURBS toolpath and stream it to nurbs_interp"
)]
pub struct PlannerArgs {
    /// Toolpath (.json, .ngc/.nc/.gcode/.tap, .dxf).
    pub toolpath: PathBuf,
    #[command(flatten)]
    pub limits: LimitArgs,
    /// Motion time (s) to keep queued ahead of the module.
    #[arg(long, default_value_t = 2.0)]
    pub margin: f64,
    /// VPOp: largest tangential deceleration and jerk of the module's stop after a path block,
    /// as a fraction of what the axes allow along the path there. The planner runs the stop
    /// from every block end and lowers it where the axis limits need it.
    #[arg(long, default_value_t = 1.0)]
    pub stop_fraction: f64,
    /// Planner: `erwinski` (S-curve segments, streamed as records) or `vpop` (per-period
    /// positions of 2-/3-axis tool-tip paths, streamed as path blocks).
    #[arg(long, value_enum, default_value_t = PlannerKind::Erwinski)]
    pub planner: PlannerKind,
    /// G1 corners: `auto` rounds the corners of every run of straight lines within the chord
    /// tolerance (as `nurbs-plan plan` does), `on` requires the path to be one polyline, `off`
    /// stops at every corner.
    #[arg(long, value_enum, default_value_t = RoundCorners::Auto)]
    pub round_corners: RoundCorners,
    /// Exit (status 0) once the module has run the whole motion and no stop of it is left to
    /// re-plan: the motion finished, or was aborted or ended by the machine switched off. For
    /// G-code-triggered jobs (`M101` of the sim configuration); without it the planner keeps
    /// serving until a signal ends it.
    #[arg(long)]
    pub exit_when_done: bool,
}
