//! The `nurbs-plan` command line: `inspect` (geometry report), `plan`, `verify`, `presets` and
//! `kinematics`;
//! and what `nurbs-planner` shares with it: the limit flags with `--ini` and `--limits`
//! ([`LimitArgs`]), the planner choice ([`PlannerKind`]) and the toolpath as both prepare it
//! ([`corners`]).

// Axis loops index several per-axis arrays at once, as the formulas do.
#![allow(clippy::needless_range_loop)]

pub mod corners;
mod inspect;
pub mod limits;
mod machine;
pub mod placement;
mod plan;
mod planner_args;
mod plot;
mod verify;

pub use limits::LimitArgs;
pub use planner_args::PlannerArgs;
pub use verify::read_rows;

use clap::{Parser, Subcommand};
use corners::RoundCorners;
use machine::MachineArgs;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "nurbs-plan",
    version,
    about = "Jerk-limited feedrate planning along NURBS toolpaths"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the named limit sets that `--limits NAME` takes (the papers' and the benchmarks').
    Presets,
    /// Report each path element: kind, degree, control points, arc length, bounding box, maximum curvature.
    Inspect {
        /// Toolpath file (.json, .ngc, .dxf).
        toolpath: PathBuf,
        /// Print one JSON object on stdout instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Plan a jerk-limited feed profile and write one setpoint per servo period.
    Plan {
        toolpath: PathBuf,
        #[command(flatten)]
        limits: LimitArgs,
        /// Setpoint CSV (t,u,x,y[,z],feed,element).
        #[arg(long)]
        out: PathBuf,
        /// Summary JSON (motion time, plan time, peaks per axis).
        #[arg(long)]
        summary: Option<PathBuf>,
        /// Feedrate planner: `erwinski` (segment records, streaming), `vpop` (constraint
        /// intersection at the servo period, VPOp) or `reach` (third-order reachability over
        /// arc-length stations: near time-optimal, tool tip, rest to rest between tangent
        /// breaks).
        #[arg(long, value_enum, default_value_t = PlannerKind::Erwinski)]
        planner: PlannerKind,
        /// Plan as a stream. Erwinski planner: each segment final as soon as back-tracking can
        /// no longer reach it (what `nurbs-planner --stream` runs on the machine; the plan time
        /// then also reports when the first segment was final); rarely a back-tracking cascade
        /// that would reach a final segment makes a stop instead, or fails where the whole-path
        /// plan succeeds. Reachability planner: long stretches in look-ahead windows, each
        /// window's points written once it is planned and the path read only as far as the
        /// windows reach (docs/planners.md); it refuses some paths the whole-stretch plan
        /// plans.
        #[arg(long)]
        stream: bool,
        /// Erwinski planner: how the setpoints map each period's arc length to the curve
        /// parameter (Erwinski et al. 2022, Table I): `rk2pc` (RK2 predictor-corrector, what the realtime
        /// module runs and the plan is checked with), or for comparison `sot`, `tot` (second-,
        /// third-order Taylor) and `fcp` (feed correction polynomial, degree 7 per 2 mm), whose
        /// positions drift off the planned arc length and may exceed the limits (`verify` tells).
        #[arg(long, value_enum, default_value_t = Interp::Rk2pc)]
        interp: Interp,
        /// Also draw the profile as a PNG (Erwinski et al. 2022, Fig. 5): feedrate with the feedrate limit
        /// function's components and the critical points, axial accelerations and axial jerks
        /// (the finite differences `verify` checks) with their limits, over the curve parameter.
        #[arg(long, value_name = "PNG")]
        plot: Option<PathBuf>,
        /// G1 corners (corner rounding of Beudaert et al. 2012, section 3.2, and the fit of runs
        /// of short lines): one of the modes below. Default: `[NURBS]ROUND_CORNERS` of --ini,
        /// else `auto`. `verify` must be given the same mode to check against the same path.
        #[arg(long, value_enum, value_name = "MODE")]
        round_corners: Option<RoundCorners>,
        #[command(flatten)]
        machine: MachineArgs,
    },
    /// Check a setpoint CSV against the limits and the curve; non-zero exit on any violation.
    Verify {
        setpoints: PathBuf,
        toolpath: PathBuf,
        #[command(flatten)]
        limits: LimitArgs,
        /// G1 corners (corner rounding of Beudaert et al. 2012, section 3.2, and the fit of runs
        /// of short lines): one of the modes below. Default: `[NURBS]ROUND_CORNERS` of --ini,
        /// else `auto`. The same mode as `plan`: the setpoints are checked against the same
        /// path, and their distance to the programmed polyline against --chord-tol.
        #[arg(long, value_enum, value_name = "MODE")]
        round_corners: Option<RoundCorners>,
        #[command(flatten)]
        machine: MachineArgs,
    },
    /// The joints of world poses (or with --forward the world poses of joints) on the 5-axis
    /// machine the flags describe, by the functions the planner and the realtime module use:
    /// to check a machine's geometry against its LinuxCNC kinematics module. One pose per line
    /// on stdin, `x y z tilt c` (mm, degrees); one per line on stdout.
    Kinematics {
        /// Joints to world poses (default: world poses to joints).
        #[arg(long)]
        forward: bool,
        #[command(flatten)]
        machine: MachineArgs,
    },
}

/// `plan --interp`: how the setpoints are interpolated.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interp {
    Rk2pc,
    Sot,
    Tot,
    Fcp,
}

impl From<Interp> for nurbs_motion::planner::simulate::Interpolation {
    fn from(i: Interp) -> Self {
        use nurbs_motion::planner::simulate::Interpolation;
        match i {
            Interp::Rk2pc => Interpolation::Rk2pc,
            Interp::Sot => Interpolation::Sot,
            Interp::Tot => Interpolation::Tot,
            Interp::Fcp => Interpolation::Fcp,
        }
    }
}

/// Which feedrate planner `nurbs-plan plan` and `nurbs-planner` run.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlannerKind {
    Erwinski,
    Vpop,
    /// Third-order reachability over arc-length stations.
    Reach,
}

/// Runs the command line; errors are printed to stderr with a non-zero exit code.
pub fn run() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Presets => {
            print!("{}", nurbs_motion::planner::presets::markdown_table());
            Ok(())
        }
        Command::Inspect { toolpath, json } => inspect::run(&toolpath, json),
        Command::Kinematics { forward, machine } => machine::run_kinematics(&machine, forward).map_err(Into::into),
        Command::Plan {
            toolpath,
            limits,
            out,
            summary,
            planner,
            stream,
            interp,
            plot,
            round_corners,
            machine,
        } => plan::run(plan::PlanArgs {
            toolpath: &toolpath,
            limits: &limits,
            out: &out,
            summary: summary.as_deref(),
            planner,
            stream,
            interp: interp.into(),
            plot: plot.as_deref(),
            round_corners,
            machine: &machine,
        }),
        Command::Verify {
            setpoints,
            toolpath,
            limits,
            round_corners,
            machine,
        } => match verify::run(&setpoints, &toolpath, &limits, round_corners, &machine) {
            Ok(true) => Ok(()),
            Ok(false) => return ExitCode::from(1),
            Err(e) => Err(e),
        },
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("nurbs-plan: {e}");
            ExitCode::FAILURE
        }
    }
}
