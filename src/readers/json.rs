//! JSON toolpaths in the schema of the benchmark curves: `degree`, `knots`, `control_points`
//! (`[[x,y]]` or `[[x,y,z]]`), optional `weights`, optional `top_control_points` (5-axis: a
//! second curve on the same knots along the tool axis), and optional `feed_mm_s`.

use super::ReadError;
use crate::geometry::{ElementKind, Nurbs, PathElement, Toolpath};
use serde::Deserialize;

#[derive(Deserialize)]
struct CurveFile {
    degree: serde_json::Value,
    knots: Vec<serde_json::Value>,
    control_points: Vec<Vec<serde_json::Value>>,
    weights: Option<Vec<serde_json::Value>>,
    top_control_points: Option<Vec<Vec<serde_json::Value>>>,
    feed_mm_s: Option<f64>,
}

fn number(file: &str, what: &str, v: &serde_json::Value) -> Result<f64, ReadError> {
    // serde_json has no NaN/inf literals; a string such as "NaN" is reported the same way.
    v.as_f64()
        .filter(|x| x.is_finite())
        .ok_or_else(|| ReadError::new(file, format!("{what} is not a finite number: {v}")))
}

fn rows(file: &str, what: &str, rows: &[Vec<serde_json::Value>]) -> Result<Vec<Vec<f64>>, ReadError> {
    rows.iter()
        .enumerate()
        .map(|(i, r)| {
            r.iter()
                .enumerate()
                .map(|(a, v)| number(file, &format!("{what}[{i}][{a}]"), v))
                .collect()
        })
        .collect()
}

/// Parses a JSON curve file into a one-element toolpath.
pub fn parse(file: &str, text: &str) -> Result<Toolpath, ReadError> {
    if text.trim().is_empty() {
        return Err(ReadError::new(file, "file is empty"));
    }
    let raw: CurveFile = serde_json::from_str(text)
        .map_err(|e| ReadError::at(file, e.line(), Some(e.column()), format!("invalid curve JSON: {e}")))?;
    let degree = raw
        .degree
        .as_u64()
        .ok_or_else(|| ReadError::new(file, format!("degree must be a whole number, got {}", raw.degree)))?
        as usize;
    let knots = raw
        .knots
        .iter()
        .enumerate()
        .map(|(i, v)| number(file, &format!("knots[{i}]"), v))
        .collect::<Result<Vec<_>, _>>()?;
    let points = rows(file, "control_points", &raw.control_points)?;
    if points.is_empty() {
        return Err(ReadError::new(file, "control_points is empty"));
    }
    let weights = raw
        .weights
        .map(|w| {
            w.iter()
                .enumerate()
                .map(|(i, v)| number(file, &format!("weights[{i}]"), v))
                .collect::<Result<Vec<_>, _>>()
        })
        .transpose()?;
    let geometry_error = |e: nurbs_rtcore::GeometryError| ReadError::new(file, format!("invalid curve: {e}"));
    let mut curve = Nurbs::new(degree, knots.clone(), &points, weights.clone()).map_err(geometry_error)?;
    if let Some(top) = raw.top_control_points {
        let top_points = rows(file, "top_control_points", &top)?;
        if top_points.len() != points.len() {
            return Err(ReadError::new(
                file,
                format!(
                    "{} top_control_points for {} control_points",
                    top_points.len(),
                    points.len()
                ),
            ));
        }
        let top = Nurbs::new(degree, knots, &top_points, weights).map_err(geometry_error)?;
        curve = curve.with_top_curve(&top).map_err(|_| {
            ReadError::new(
                file,
                "top_control_points must have the same dimension (3) as control_points",
            )
        })?;
    }
    if let Some(f) = raw.feed_mm_s {
        if !(f.is_finite() && f > 0.0) {
            return Err(ReadError::new(file, format!("feed_mm_s must be > 0, got {f}")));
        }
    }
    Ok(Toolpath {
        elements: vec![PathElement {
            kind: ElementKind::Nurbs,
            curve,
            feed: raw.feed_mm_s,
            source_line: None,
        }],
    })
}
