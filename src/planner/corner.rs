//! G1 corner rounding (VPOp paper section 3.2): each corner of a polyline is replaced by a
//! cubic B-spline with five control points `P - d u1, P - d/2 u1, P, P + d/2 u2, P + d u2`
//! (knots `0 0 0 0 1/2 1 1 1 1`). The first three and the last three control points are
//! collinear with the segments, so the curvature is zero where the spline meets them: the path
//! is C2 in arc length. `d` uses as much of the contour tolerance as the segment lengths allow
//! (each segment gives at most half its length to each of its two corners).

use crate::geometry::{ElementKind, Nurbs, PathElement, Toolpath};

/// A rounded polyline and how far it strays from the programmed one.
#[derive(Clone, Debug)]
pub struct Rounded {
    pub toolpath: Toolpath,
    /// Largest distance from the rounded path to the programmed polyline (mm).
    pub max_deviation: f64,
    /// Corners rounded.
    pub corners: usize,
}

const KNOTS: [f64; 9] = [0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 1.0];

fn sub(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}
fn norm(a: &[f64]) -> f64 {
    a.iter().map(|x| x * x).sum::<f64>().sqrt()
}
fn axpy(p: &[f64], k: f64, u: &[f64]) -> Vec<f64> {
    p.iter().zip(u).map(|(x, y)| x + k * y).collect()
}

/// Distance from `x` to the segment `a`-`b`.
fn segment_distance(x: &[f64], a: &[f64], b: &[f64]) -> f64 {
    let ab = sub(b, a);
    let ax = sub(x, a);
    let l2: f64 = ab.iter().map(|v| v * v).sum();
    let t = if l2 > 0.0 {
        (ax.iter().zip(&ab).map(|(p, q)| p * q).sum::<f64>() / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(&sub(&ax, &ab.iter().map(|v| t * v).collect::<Vec<_>>()))
}

fn corner_curve(p: &[f64], u1: &[f64], u2: &[f64], d: f64) -> Nurbs {
    let cps = vec![
        axpy(p, -d, u1),
        axpy(p, -0.5 * d, u1),
        p.to_vec(),
        axpy(p, 0.5 * d, u2),
        axpy(p, d, u2),
    ];
    Nurbs::new(3, KNOTS.to_vec(), &cps, None).expect("corner spline is valid")
}

/// Largest distance of a corner spline to the two segments it replaces (sampled densely).
fn corner_deviation(curve: &Nurbs, p: &[f64], u1: &[f64], u2: &[f64], d: f64) -> f64 {
    let a = axpy(p, -d, u1);
    let b = axpy(p, d, u2);
    let n = curve.tip_dim();
    (0..=400)
        .map(|k| {
            let x = curve.point(k as f64 / 400.0);
            segment_distance(&x[..n], &a, p).min(segment_distance(&x[..n], p, &b))
        })
        .fold(0.0, f64::max)
}

fn line(a: &[f64], b: &[f64]) -> PathElement {
    PathElement {
        kind: ElementKind::Polyline,
        curve: Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[a.to_vec(), b.to_vec()], None).expect("line is valid"),
        feed: None,
        source_line: None,
    }
}

/// Rounds the corners of a polyline given by its vertices (2-D or 3-D) within `tolerance`.
pub fn round_polyline(vertices: &[Vec<f64>], tolerance: f64) -> Result<Rounded, String> {
    let mut v: Vec<Vec<f64>> = Vec::new();
    for p in vertices {
        let distinct = match v.last() {
            Some(q) => norm(&sub(p, q)) > 1e-12,
            None => true,
        };
        if distinct {
            v.push(p.clone());
        }
    }
    if v.len() < 2 {
        return Err("a polyline needs two distinct points".into());
    }
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Err(format!("contour tolerance {tolerance} must be > 0"));
    }
    let n = v.len();
    let lens: Vec<f64> = (0..n - 1).map(|i| norm(&sub(&v[i + 1], &v[i]))).collect();
    let mut elements = Vec::new();
    let mut start = v[0].clone();
    let mut max_dev: f64 = 0.0;
    let mut corners = 0;
    for i in 1..n - 1 {
        let u1: Vec<f64> = sub(&v[i], &v[i - 1]).iter().map(|x| x / lens[i - 1]).collect();
        let u2: Vec<f64> = sub(&v[i + 1], &v[i]).iter().map(|x| x / lens[i]).collect();
        let cos = u1.iter().zip(&u2).map(|(a, b)| a * b).sum::<f64>();
        if cos > 1.0 - 1e-12 {
            continue; // straight through
        }
        // Deviation is proportional to d: measure it at d = 1 and scale to the tolerance.
        let unit = corner_deviation(&corner_curve(&v[i], &u1, &u2, 1.0), &v[i], &u1, &u2, 1.0);
        let room = 0.5 * lens[i - 1].min(lens[i]);
        let d = (0.999 * tolerance / unit).min(room);
        let curve = corner_curve(&v[i], &u1, &u2, d);
        max_dev = max_dev.max(corner_deviation(&curve, &v[i], &u1, &u2, d));
        let entry = axpy(&v[i], -d, &u1);
        if norm(&sub(&entry, &start)) > 1e-12 {
            elements.push(line(&start, &entry));
        }
        elements.push(PathElement {
            kind: ElementKind::Nurbs,
            curve,
            feed: None,
            source_line: None,
        });
        start = axpy(&v[i], d, &u2);
        corners += 1;
    }
    if norm(&sub(&v[n - 1], &start)) > 1e-12 {
        elements.push(line(&start, &v[n - 1]));
    }
    Ok(Rounded {
        toolpath: Toolpath { elements },
        max_deviation: max_dev,
        corners,
    })
}

/// Rounds a toolpath made of degree-1 elements (G1 blocks, polylines, degree-1 splines) as one
/// polyline through their control points (tool tip only).
pub fn round_toolpath(toolpath: &Toolpath, tolerance: f64) -> Result<Rounded, String> {
    let mut vertices: Vec<Vec<f64>> = Vec::new();
    let tip = toolpath.tip_dim();
    for e in &toolpath.elements {
        if e.curve.degree() != 1 {
            return Err("corner rounding needs a polyline (degree-1 elements)".into());
        }
        for k in 0..e.curve.control_point_count() {
            let mut p = vec![0.0; tip];
            let c = e.curve.control_point(k);
            p[..e.curve.tip_dim()].copy_from_slice(&c[..e.curve.tip_dim()]);
            vertices.push(p);
        }
    }
    round_polyline(&vertices, tolerance)
}
