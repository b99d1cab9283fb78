//! G1 corner rounding for `plan` and `verify` (one decision, shared): the path both commands
//! use is read and rounded here, deterministically from the file, the mode and `--chord-tol`.

use super::machine::is_five_axis;
use crate::geometry::Toolpath;
use crate::planner::corner::{is_polyline, round_toolpath, ProgramPolyline};
use crate::readers::read_toolpath;
use std::path::Path;

/// `--round-corners`: what to do with the corners of a straight-line (G1) tool path.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RoundCorners {
    /// Round when every element is a straight line (G1, DXF LINE / LWPOLYLINE without bulges,
    /// degree-1 JSON) of the tool tip, or of the tool tip and top point (5-axis G1), and the
    /// elements join; plan other paths as programmed.
    #[default]
    Auto,
    /// Round, and fail if the path is not such a polyline.
    On,
    /// Plan the programmed polyline as is (exact stop at every corner).
    Off,
}

/// What rounding did to a polyline.
pub struct Rounding {
    /// Corners replaced by a five-point cubic B-spline.
    pub corners: usize,
    /// Largest distance of the rounded path to the programmed polyline (mm), sampled densely.
    pub max_deviation: f64,
    /// 5-axis: the same for the top curve (tool axis).
    pub max_top_deviation: Option<f64>,
}

/// The path to plan or verify: the programmed path, or the rounded one.
pub struct Prepared {
    /// The path the planner follows (rounded when `rounding` is some).
    pub toolpath: Toolpath,
    pub rounding: Option<Rounding>,
    /// The programmed polyline, when the program is one (rounded or not).
    pub program: Option<ProgramPolyline>,
}

impl Prepared {
    /// Largest distance of tool-tip points to the programmed polyline (mm); `None` when the
    /// program is not a polyline.
    pub fn deviation_from_program<'a>(&self, points: impl IntoIterator<Item = &'a [f64]>) -> Option<f64> {
        self.program.as_ref().map(|p| p.max_distance(points))
    }

    /// Summary JSON fields.
    pub fn summary_fields(&self, deviation: Option<f64>) -> serde_json::Value {
        serde_json::json!({
            "rounding_corners": self.rounding.as_ref().map_or(0, |r| r.corners),
            "rounding_max_deviation_mm": self.rounding.as_ref().map(|r| r.max_deviation),
            "rounding_max_top_deviation_mm": self.rounding.as_ref().and_then(|r| r.max_top_deviation),
            "max_deviation_from_program_mm": deviation,
        })
    }

    /// One line for the console, or nothing when the program is not a polyline.
    pub fn describe(&self, deviation: Option<f64>, tolerance: f64) -> Option<String> {
        let dev = deviation?;
        Some(match &self.rounding {
            Some(r) => format!(
                "corners: {} rounded within --chord-tol {tolerance} mm (rounding deviation {:.6} mm{}); setpoints within {:.6} mm of the programmed polyline",
                r.corners,
                r.max_deviation,
                r.max_top_deviation.map_or(String::new(), |t| format!(", top curve {t:.6} mm")),
                dev
            ),
            None => format!("corners: not rounded; setpoints within {dev:.3e} mm of the programmed polyline"),
        })
    }
}

/// Reads `file` and applies `mode` with `tolerance` (`--chord-tol`).
pub fn prepare(file: &Path, mode: RoundCorners, tolerance: f64) -> Result<Prepared, Box<dyn std::error::Error>> {
    let toolpath = read_toolpath(file)?;
    let polyline = is_polyline(&toolpath);
    let program = if polyline {
        Some(ProgramPolyline::new(&toolpath).map_err(|e| format!("{}: {e}", file.display()))?)
    } else {
        None
    };
    let round = match mode {
        RoundCorners::Off => false,
        RoundCorners::Auto => polyline,
        RoundCorners::On if polyline => true,
        RoundCorners::On => {
            return Err(format!(
                "{}: --round-corners on needs a polyline (one continuous run of straight G1 / LINE / degree-1 elements, with or without a top curve)",
                file.display()
            )
            .into())
        }
    };
    if !round {
        return Ok(Prepared {
            toolpath,
            rounding: None,
            program,
        });
    }
    let rounded =
        round_toolpath(&toolpath, tolerance).map_err(|e| format!("{}: corner rounding: {e}", file.display()))?;
    Ok(Prepared {
        toolpath: rounded.toolpath,
        rounding: Some(Rounding {
            corners: rounded.corners,
            max_deviation: rounded.max_deviation,
            max_top_deviation: is_five_axis(&toolpath).then_some(rounded.max_top_deviation),
        }),
        program,
    })
}
