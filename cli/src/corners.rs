//! G1 corner rounding for `plan` and `verify` (one decision, shared): the path both commands
//! use is read and rounded here, deterministically from the file, the mode and `--chord-tol`,
//! as a stream ([`open`]) or whole ([`prepare`], the same stream collected).

use crate::limits::{LimitArgs, Travel};
use nurbs_motion::geometry::{Placement, Toolpath};
use nurbs_motion::planner::corner::{CornerRounder, ProgramPolyline, RoundingStats};
use nurbs_motion::planner::fit::RunFitter;
use nurbs_motion::readers::{open_toolpath, ElementStream, ReadError};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// `--round-corners`: what to do with the corners of straight-line (G1) moves.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RoundCorners {
    /// Round the corners of every run of joined straight lines (G1, DXF LINE / LWPOLYLINE
    /// without bulges, degree-1 JSON) of the tool tip, or of the tool tip and top point (5-axis
    /// G1), within the chord tolerance, then replace each run of short tool-tip pieces (dense CAM
    /// output: 8 or more lines of up to 4 mm at one feed) by cubic B-splines fitted to the
    /// programmed points within the chord tolerance, continuous in tangent and curvature, so
    /// that the feed follows the surface the points were sampled from instead of the corners
    /// between them; arcs and NURBS, and where a run meets them, as programmed.
    #[default]
    #[value(alias = "smooth")]
    Auto,
    /// Round the corners as `auto` does, without fitting runs of short pieces (each corner its
    /// own spline).
    Round,
    /// As `auto`, and fail if the path is not one continuous polyline.
    On,
    /// Plan the programmed path as is (exact stop at every corner).
    Off,
}

/// What rounding did to a polyline.
#[derive(Clone, Copy, Debug)]
pub struct Rounding {
    /// Corners replaced by a five-point cubic B-spline.
    pub corners: usize,
    /// Largest distance of the rounded path to the programmed polyline (mm).
    pub max_deviation: f64,
    /// 5-axis: the same for the top curve (tool axis).
    pub max_top_deviation: Option<f64>,
    /// `--round-corners auto`: runs replaced by a fitted spline, and the pieces they held.
    pub fitted_runs: usize,
    pub fitted_pieces: usize,
}

/// The path to plan or verify as a stream: the programmed elements, rounded as they come.
pub struct PreparedStream {
    pub elements: ElementStream,
    file: PathBuf,
    placement: Placement,
    stats: Option<Arc<Mutex<RoundingStats>>>,
}

impl PreparedStream {
    /// The elements (the stream keeps what rounding did).
    pub fn take_elements(&mut self) -> ElementStream {
        std::mem::replace(&mut self.elements, Box::new(std::iter::empty()))
    }

    /// What rounding has done so far (all of it once the stream has ended); `None` with
    /// `--round-corners off`.
    pub fn rounding(&self) -> Option<Rounding> {
        stream_rounding(&self.stats)
    }

    /// The programmed polyline, read from the file a second time as the setpoints measured
    /// against it need ([`ProgramPolyline::streamed`]).
    pub fn program(&self) -> Result<ProgramPolyline, Box<dyn std::error::Error>> {
        Ok(ProgramPolyline::streamed(
            placed(open_toolpath(&self.file)?, self.placement).map_while(Result::ok),
        ))
    }
}

/// The rounding mode: `flag` (`--round-corners`), else `[NURBS]ROUND_CORNERS` of the INI of
/// `limits`, else `auto`.
pub fn round_corners_mode(flag: Option<RoundCorners>, limits: &LimitArgs) -> Result<RoundCorners, String> {
    if let Some(mode) = flag {
        return Ok(mode);
    }
    match limits.ini_text("NURBS", "ROUND_CORNERS")? {
        None => Ok(RoundCorners::Auto),
        Some((value, file)) => <RoundCorners as clap::ValueEnum>::from_str(&value, true)
            .map_err(|_| format!("{file}: [NURBS]ROUND_CORNERS = {value}: one of auto, round, on, off")),
    }
}

/// Opens `file` as a stream of elements and applies `mode` ([`round_corners_mode`]) with the
/// chord tolerance of `limits`; with `--ini`, an element that leaves the machine's travel ends
/// the stream with an error ([`within_travel`]).
pub fn open(
    file: &Path,
    mode: Option<RoundCorners>,
    limits: &LimitArgs,
) -> Result<PreparedStream, Box<dyn std::error::Error>> {
    let mode = round_corners_mode(mode, limits)?;
    let tolerance = limits.chord_tolerance()?;
    let placement = limits.placement.placement()?;
    let elements = placed(open_toolpath(file)?, placement);
    let name = file.display().to_string();
    let (elements, stats): (ElementStream, _) = match mode {
        RoundCorners::Off => (elements, None),
        RoundCorners::Auto | RoundCorners::Round | RoundCorners::On => {
            let rounder = CornerRounder::new(&name, elements, tolerance, mode == RoundCorners::On)
                .map_err(|e| format!("{name}: {e}"))?;
            let stats = rounder.stats();
            let elements: ElementStream = if mode != RoundCorners::Round {
                Box::new(RunFitter::new(
                    rounder,
                    tolerance,
                    limits.corner_angle()?,
                    Arc::clone(&stats),
                ))
            } else {
                Box::new(rounder)
            };
            (elements, Some(stats))
        }
    };
    let elements = match limits.travel()? {
        Some(travel) => within_travel(elements, travel, name),
        None => elements,
    };
    Ok(PreparedStream {
        elements,
        file: file.to_owned(),
        placement,
        stats,
    })
}

/// The elements of a file in program coordinates moved to the machine's ([`Placement`]).
fn placed(elements: ElementStream, placement: Placement) -> ElementStream {
    if placement.is_identity() {
        return elements;
    }
    Box::new(elements.map(move |e| e.map(|e| placement.element(e))))
}

/// The elements of `elements` while they stay within `travel`: every control point of the tool
/// tip inside it (a NURBS curve lies in the convex hull of its control points, so the path does
/// too); the first one that does not ends the stream with an error naming it.
pub fn within_travel(elements: ElementStream, travel: Travel, name: String) -> ElementStream {
    let mut index = 0usize;
    Box::new(elements.scan(false, move |failed, item| {
        if *failed {
            return None;
        }
        let i = index;
        index += 1;
        Some(item.and_then(|e| {
            let tip = e.curve.tip_dim().min(travel.min.len());
            for k in 0..e.curve.control_point_count() {
                let p = &e.curve.control_point(k)[..tip];
                if let Some(axis) = (0..tip).find(|&a| !(travel.min[a] <= p[a] && p[a] <= travel.max[a])) {
                    *failed = true;
                    let letter = ["X", "Y", "Z"][axis];
                    let what = format!(
                        "control point {p:?} leaves the machine's travel: {letter} {} .. {} mm ([AXIS_{letter}]MIN_LIMIT/MAX_LIMIT of {})",
                        travel.min[axis],
                        travel.max[axis],
                        travel.source
                    );
                    return Err(match e.source_line {
                        Some(line) => ReadError::at(&name, line, None, format!("the path element that starts here: {what}")),
                        None => ReadError::new(&name, format!("path element {i}: {what}")),
                    });
                }
            }
            Ok(e)
        }))
    }))
}

/// The path to plan or verify, whole: the programmed path, or the rounded one.
pub struct Prepared {
    /// The path the planner follows (rounded when `rounding` is some).
    pub toolpath: Toolpath,
    pub rounding: Option<Rounding>,
}

/// [`open`], read whole.
pub fn prepare(
    file: &Path,
    mode: Option<RoundCorners>,
    limits: &LimitArgs,
) -> Result<Prepared, Box<dyn std::error::Error>> {
    let PreparedStream { elements, stats, .. } = open(file, mode, limits)?;
    let toolpath = Toolpath {
        elements: elements.collect::<Result<Vec<_>, _>>()?,
    };
    Ok(Prepared {
        toolpath,
        rounding: stream_rounding(&stats),
    })
}

fn stream_rounding(stats: &Option<Arc<Mutex<RoundingStats>>>) -> Option<Rounding> {
    let stats = *stats.as_ref()?.lock().ok()?;
    Some(Rounding {
        corners: stats.corners,
        max_deviation: stats.max_deviation,
        max_top_deviation: stats.top.then_some(stats.max_top_deviation),
        fitted_runs: stats.fitted_runs,
        fitted_pieces: stats.fitted_pieces,
    })
}

/// Summary JSON fields of rounding and the setpoints' distance to the programmed polyline.
pub fn summary_fields(rounding: Option<Rounding>, deviation: Option<f64>) -> serde_json::Value {
    serde_json::json!({
        "rounding_corners": rounding.map_or(0, |r| r.corners),
        "rounding_max_deviation_mm": rounding.map(|r| r.max_deviation),
        "rounding_max_top_deviation_mm": rounding.and_then(|r| r.max_top_deviation),
        "fitted_runs": rounding.map_or(0, |r| r.fitted_runs),
        "fitted_pieces": rounding.map_or(0, |r| r.fitted_pieces),
        "max_deviation_from_program_mm": deviation,
    })
}

/// The largest distance of the setpoints to the programmed polyline, if it exceeds the
/// tolerance (`verify` and `plan` judge it alike).
pub fn deviation_over(deviation: Option<f64>, tolerance: f64) -> Option<f64> {
    deviation.filter(|d| *d > tolerance * (1.0 + nurbs_motion::planner::verify::SLACK))
}

/// `plan`'s refusal of setpoints that leave the tolerance (written to `out`, for inspection
/// only).
pub fn refuse_deviation(deviation: Option<f64>, tolerance: f64, out: &Path) -> Result<(), String> {
    match deviation_over(deviation, tolerance) {
        Some(dev) => Err(format!(
            "a setpoint is {dev:.6} mm from the programmed polyline, more than --chord-tol {tolerance}: \
             the plan leaves the tolerance and must not run (setpoints written to {} for inspection)",
            out.display()
        )),
        None => Ok(()),
    }
}

/// One line for the console, or nothing when the program is not a polyline.
pub fn describe(rounding: Option<Rounding>, deviation: Option<f64>, tolerance: f64) -> Option<String> {
    let dev = deviation?;
    Some(match rounding {
        Some(r) => format!(
            "corners: {} rounded{} within --chord-tol {tolerance} mm (rounding deviation {:.6} mm{}); setpoints within {:.6} mm of the programmed polyline",
            r.corners,
            if r.fitted_runs > 0 {
                format!(", {} runs of {} short pieces fitted", r.fitted_runs, r.fitted_pieces)
            } else {
                String::new()
            },
            r.max_deviation,
            r.max_top_deviation.map_or(String::new(), |t| format!(", top curve {t:.6} mm")),
            dev
        ),
        None => format!("corners: not rounded; setpoints within {dev:.3e} mm of the programmed polyline"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `plan` refuses setpoints beyond the tolerance (rounding slack only), and says where they
    /// were written; within it, or without a polyline to measure against, it passes.
    #[test]
    fn setpoints_beyond_the_tolerance_are_refused() {
        let out = Path::new("o.csv");
        assert!(refuse_deviation(Some(0.01), 0.01, out).is_ok());
        assert!(refuse_deviation(None, 0.01, out).is_ok());
        let e = refuse_deviation(Some(0.027004), 0.01, out).unwrap_err();
        assert!(
            e.contains("0.027004 mm") && e.contains("--chord-tol 0.01") && e.contains("o.csv"),
            "{e}"
        );
        assert!(refuse_deviation(Some(0.01 * (1.0 + 1e-3)), 0.01, out).is_err());
    }
}
