//! The `nurbs-plan` command line: `inspect` (geometry report), `plan` and `verify`.

mod inspect;

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "nurbs-plan", version, about = "Jerk-limited feedrate planning along NURBS toolpaths")]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Report each path element: kind, degree, control points, arc length, bounding box, maximum curvature.
    Inspect {
        /// Toolpath file (.json, .ngc, .dxf).
        toolpath: PathBuf,
        /// Print one JSON object on stdout instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// Runs the command line; errors are printed to stderr with a non-zero exit code.
pub fn run() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Inspect { toolpath, json } => inspect::run(&toolpath, json),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("nurbs-plan: {e}");
            ExitCode::FAILURE
        }
    }
}
