use nurbs_motion::geometry::{analyze, CurveStats, ElementKind};
use nurbs_motion::readers::read_toolpath;
use serde::Serialize;
use std::path::Path;

#[derive(Serialize)]
struct ElementReport {
    kind: ElementKind,
    degree: usize,
    control_points: usize,
    /// Tool-tip coordinates (2 or 3); 5-axis paths also carry a top curve.
    tip_dim: usize,
    five_axis: bool,
    feed_mm_s: Option<f64>,
    source_line: Option<usize>,
    #[serde(flatten)]
    stats: CurveStats,
}

#[derive(Serialize)]
struct Report {
    file: String,
    arc_length_mm: f64,
    bbox_min: Vec<f64>,
    bbox_max: Vec<f64>,
    max_curvature_per_mm: f64,
    elements: Vec<ElementReport>,
}

pub fn run(path: &Path, json: bool) -> Result<(), Box<dyn std::error::Error>> {
    let toolpath = read_toolpath(path)?;
    let n = toolpath.tip_dim();
    let elements: Vec<ElementReport> = toolpath
        .elements
        .iter()
        .map(|e| ElementReport {
            kind: e.kind,
            degree: e.curve.degree(),
            control_points: e.curve.control_point_count(),
            tip_dim: e.curve.tip_dim(),
            five_axis: e.curve.dim() > e.curve.tip_dim(),
            feed_mm_s: e.feed,
            source_line: e.source_line,
            stats: analyze(&e.curve),
        })
        .collect();
    let mut bbox_min = vec![f64::INFINITY; n];
    let mut bbox_max = vec![f64::NEG_INFINITY; n];
    for e in &elements {
        for a in 0..e.stats.bbox_min.len() {
            bbox_min[a] = bbox_min[a].min(e.stats.bbox_min[a]);
            bbox_max[a] = bbox_max[a].max(e.stats.bbox_max[a]);
        }
    }
    let report = Report {
        file: path.display().to_string(),
        arc_length_mm: elements.iter().map(|e| e.stats.arc_length_mm).sum(),
        bbox_min,
        bbox_max,
        max_curvature_per_mm: elements
            .iter()
            .map(|e| e.stats.max_curvature_per_mm)
            .fold(0.0, f64::max),
        elements,
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!("{}: {} element(s)", report.file, report.elements.len());
    for (i, e) in report.elements.iter().enumerate() {
        println!(
            "  #{i} {:?}{} degree {} control points {} length {:.9} mm  bbox {:?} .. {:?}  max curvature {:.6} 1/mm at u = {:.9}{}",
            e.kind,
            if e.five_axis { " (5-axis)" } else { "" },
            e.degree,
            e.control_points,
            e.stats.arc_length_mm,
            e.stats.bbox_min,
            e.stats.bbox_max,
            e.stats.max_curvature_per_mm,
            e.stats.u_at_max_curvature,
            e.source_line.map(|l| format!("  (line {l})")).unwrap_or_default(),
        );
    }
    println!(
        "  total length {:.9} mm  bbox {:?} .. {:?}  max curvature {:.6} 1/mm",
        report.arc_length_mm, report.bbox_min, report.bbox_max, report.max_curvature_per_mm
    );
    Ok(())
}
