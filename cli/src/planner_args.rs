//! The command line of `nurbs-planner` (the binary is in the `nurbs-planner` crate): here so that
//! its flags are the ones `nurbs-plan` has, and its man page is rendered with `nurbs-plan`'s.

use crate::corners::RoundCorners;
use crate::{LimitArgs, PlannerKind};
use clap::Parser;
use std::path::PathBuf;

/// `nurbs-planner TOOLPATH ...`: plans a toolpath and streams it to `nurbs_interp`.
#[derive(Parser, Clone, Debug)]
#[command(
    name = "nurbs-planner",
    about = "Plan a NURBS toolpath and stream it to nurbs_interp"
)]
pub struct PlannerArgs {
    /// Toolpath (.json, .ngc/.nc/.gcode/.tap, .dxf).
    pub toolpath: PathBuf,
    #[command(flatten)]
    pub limits: LimitArgs,
    /// Motion time (s) to keep queued ahead of the module (a group goes in whole, so up to a
    /// group more): what a planner that falls behind has to catch up in, and what runs at the
    /// old feed override before a new one takes effect.
    #[arg(long, default_value_t = 0.25)]
    pub margin: f64,
    /// Highest feed override the plans follow (`nurbs-planner.feed-override` is clamped to
    /// it); default: `[DISPLAY]MAX_FEED_OVERRIDE` of --ini, else 1. Above 1 the axis limits
    /// still bound every feed.
    #[arg(long)]
    pub max_feed_override: Option<f64>,
    /// VPOp and reach: largest tangential deceleration and jerk of the module's stop after a
    /// path block, as a fraction of what the axes allow along the path there. The planner runs
    /// the stop from every block end and lowers it where the axis limits need it.
    #[arg(long, default_value_t = 1.0)]
    pub stop_fraction: f64,
    /// Planner: `erwinski` (S-curve segments, streamed as records), `reach` (per-period
    /// positions of 2-/3-axis tool-tip paths, planned in look-ahead windows as the motion runs
    /// and streamed as path blocks) or `vpop` (the same positions' kind, planned whole before
    /// the motion).
    #[arg(long, value_enum, default_value_t = PlannerKind::Erwinski)]
    pub planner: PlannerKind,
    /// G1 corners, as `nurbs-plan plan --round-corners` (`auto`: rounded, runs of short lines
    /// fitted; `round`: rounded only; `on`: as `auto` on one polyline only; `off`: as
    /// programmed). Default: `[NURBS]ROUND_CORNERS` of --ini, else `auto`.
    #[arg(long, value_enum)]
    pub round_corners: Option<RoundCorners>,
    /// Exit (status 0) once the module has run the whole motion and no stop of it is left to
    /// re-plan: the motion finished, or was aborted or ended by the machine switched off. For
    /// G-code-triggered jobs (`M101` of the sim configuration); without it the planner keeps
    /// serving until a signal ends it.
    #[arg(long)]
    pub exit_when_done: bool,
}

impl PlannerArgs {
    /// [`PlannerArgs::max_feed_override`] as given, from the INI, or 1.
    pub fn max_feed_override(&self) -> Result<f64, String> {
        let k = match self.max_feed_override {
            Some(k) => k,
            None => self.limits.ini_max_feed_override()?.unwrap_or(1.0),
        };
        if k.is_finite() && k > 0.0 {
            Ok(k)
        } else {
            Err(format!("the maximum feed override must be a positive factor, not {k}"))
        }
    }
}
