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

fn line(a: &[f64], b: &[f64], feed: Option<f64>) -> PathElement {
    PathElement {
        kind: ElementKind::Polyline,
        curve: Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[a.to_vec(), b.to_vec()], None).expect("line is valid"),
        feed,
        source_line: None,
    }
}

/// The lower of two programmed feeds (`None`: no programmed feed).
fn min_feed(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, None) => x,
        (None, y) => y,
    }
}

/// Rounds the corners of a polyline given by its vertices (2-D or 3-D) within `tolerance`.
pub fn round_polyline(vertices: &[Vec<f64>], tolerance: f64) -> Result<Rounded, String> {
    let feeds = vec![None; vertices.len().saturating_sub(1)];
    round_with_feeds(vertices, &feeds, tolerance)
}

/// [`round_polyline`] with a programmed feed per segment (`feeds[i]` for `vertices[i]` to
/// `vertices[i + 1]`): a straight piece keeps its segment's feed, a corner spline takes the
/// lower feed of its two segments.
fn round_with_feeds(vertices: &[Vec<f64>], feeds: &[Option<f64>], tolerance: f64) -> Result<Rounded, String> {
    let mut v: Vec<Vec<f64>> = Vec::new();
    // seg_feed[i]: feed of the kept segment v[i] to v[i + 1].
    let mut seg_feed: Vec<Option<f64>> = Vec::new();
    for (k, p) in vertices.iter().enumerate() {
        let distinct = match v.last() {
            Some(q) => norm(&sub(p, q)) > 1e-12,
            None => true,
        };
        if distinct {
            if k > 0 && !v.is_empty() {
                seg_feed.push(feeds.get(k - 1).copied().flatten());
            }
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
    // A straight piece runs from segment `start_seg` through collinear vertices: lowest feed.
    let mut start_seg = 0;
    let run_feed = |from: usize, to: usize| seg_feed[from..=to].iter().fold(None, |a, b| min_feed(a, *b));
    for i in 1..n - 1 {
        let u1: Vec<f64> = sub(&v[i], &v[i - 1]).iter().map(|x| x / lens[i - 1]).collect();
        let u2: Vec<f64> = sub(&v[i + 1], &v[i]).iter().map(|x| x / lens[i]).collect();
        let cos = u1.iter().zip(&u2).map(|(a, b)| a * b).sum::<f64>();
        if cos > 1.0 - 1e-12 {
            continue; // straight through
        }
        if cos < -1.0 + 1e-9 {
            // A reversal has no rounding inside the tolerance (the spline would stop and turn
            // back on itself): keep the programmed vertex, where the motion stops.
            if norm(&sub(&v[i], &start)) > 1e-12 {
                elements.push(line(&start, &v[i], run_feed(start_seg, i - 1)));
            }
            start = v[i].clone();
            start_seg = i;
            continue;
        }
        // Deviation is proportional to d: measure it at d = 1 and scale to the tolerance.
        let unit = corner_deviation(&corner_curve(&v[i], &u1, &u2, 1.0), &v[i], &u1, &u2, 1.0);
        let room = 0.5 * lens[i - 1].min(lens[i]);
        let d = (0.999 * tolerance / unit).min(room);
        let curve = corner_curve(&v[i], &u1, &u2, d);
        max_dev = max_dev.max(corner_deviation(&curve, &v[i], &u1, &u2, d));
        let entry = axpy(&v[i], -d, &u1);
        if norm(&sub(&entry, &start)) > 1e-12 {
            elements.push(line(&start, &entry, run_feed(start_seg, i - 1)));
        }
        elements.push(PathElement {
            kind: ElementKind::Nurbs,
            curve,
            feed: min_feed(seg_feed[i - 1], seg_feed[i]),
            source_line: None,
        });
        start = axpy(&v[i], d, &u2);
        start_seg = i;
        corners += 1;
    }
    if norm(&sub(&v[n - 1], &start)) > 1e-12 {
        elements.push(line(&start, &v[n - 1], run_feed(start_seg, n - 2)));
    }
    Ok(Rounded {
        toolpath: Toolpath { elements },
        max_deviation: max_dev,
        corners,
    })
}

type Vertices = Vec<Vec<f64>>;

/// Largest gap between consecutive elements of one continuous polyline (mm).
const JOIN_GAP: f64 = 1e-9;

/// The programmed polyline of a toolpath made of degree-1 elements: its vertices (tool tip,
/// padded to the toolpath's tip dimension) and the programmed feed of each segment (the
/// element's; the zero-length joins between elements get the later element's).
fn polyline_of(toolpath: &Toolpath) -> Result<(Vertices, Vec<Option<f64>>), String> {
    let mut vertices: Vec<Vec<f64>> = Vec::new();
    let mut feeds = Vec::new();
    let tip = toolpath.tip_dim();
    for (i, e) in toolpath.elements.iter().enumerate() {
        if e.curve.degree() != 1 {
            return Err("corner rounding needs a polyline (degree-1 elements)".into());
        }
        for k in 0..e.curve.control_point_count() {
            let mut p = vec![0.0; tip];
            let c = e.curve.control_point(k);
            p[..e.curve.tip_dim()].copy_from_slice(&c[..e.curve.tip_dim()]);
            if k == 0 {
                if let Some(q) = vertices.last() {
                    let gap = norm(&sub(&p, q));
                    if gap > JOIN_GAP {
                        return Err(format!(
                            "element {} starts {gap:.3e} mm away from the end of element {i}: not one continuous polyline",
                            i + 1
                        ));
                    }
                }
            }
            if !vertices.is_empty() {
                feeds.push(e.feed);
            }
            vertices.push(p);
        }
    }
    Ok((vertices, feeds))
}

/// Rounds a toolpath made of degree-1 elements (G1 blocks, polylines, degree-1 splines) as one
/// polyline through their control points (tool tip only). Programmed feeds carry over: a
/// straight piece keeps its element's feed, a corner spline the lower of its two segments'.
pub fn round_toolpath(toolpath: &Toolpath, tolerance: f64) -> Result<Rounded, String> {
    let (vertices, feeds) = polyline_of(toolpath)?;
    round_with_feeds(&vertices, &feeds, tolerance)
}

/// True when every element is a straight-line polyline of the tool tip alone (degree 1, no top
/// curve) and each element starts where the previous one ends: G1 moves, DXF LINE / LWPOLYLINE
/// without bulges, degree-1 JSON curves.
pub fn is_tip_polyline(toolpath: &Toolpath) -> bool {
    !toolpath.elements.is_empty()
        && toolpath
            .elements
            .iter()
            .all(|e| e.curve.degree() == 1 && e.curve.dim() == e.curve.tip_dim())
        && polyline_of(toolpath).is_ok()
}

/// The programmed polyline of a toolpath made of degree-1 elements, for measuring how far
/// setpoints stray from it.
#[derive(Clone, Debug)]
pub struct ProgramPolyline {
    vertices: Vec<Vec<f64>>,
}

impl ProgramPolyline {
    pub fn new(toolpath: &Toolpath) -> Result<Self, String> {
        let (vertices, _) = polyline_of(toolpath)?;
        if vertices.is_empty() {
            return Err("empty polyline".into());
        }
        Ok(ProgramPolyline { vertices })
    }

    fn segment(&self, i: usize, x: &[f64]) -> f64 {
        let n = self.vertices[i].len().min(x.len());
        if self.vertices.len() == 1 {
            return norm(&sub(&x[..n], &self.vertices[0][..n]));
        }
        segment_distance(&x[..n], &self.vertices[i][..n], &self.vertices[i + 1][..n])
    }

    /// Largest distance of `points` (tool-tip coordinates) to the polyline: exact (the
    /// distance of each point to the nearest segment of the whole polyline). A point is first
    /// checked against the segments next to the previous point's nearest one and only scanned
    /// against all segments when that cannot rule it out.
    pub fn max_distance<'a>(&self, points: impl IntoIterator<Item = &'a [f64]>) -> f64 {
        let segs = self.vertices.len().saturating_sub(1).max(1);
        let mut worst: f64 = 0.0;
        let mut hint = 0usize;
        for x in points {
            let near = (hint.saturating_sub(1)..(hint + 3).min(segs))
                .map(|i| self.segment(i, x))
                .fold(f64::INFINITY, f64::min);
            if near <= worst {
                continue;
            }
            let (best, d) = (0..segs)
                .map(|i| (i, self.segment(i, x)))
                .fold((hint, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
            hint = best;
            worst = worst.max(d);
        }
        worst
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g1(points: &[[f64; 2]], feed: f64) -> PathElement {
        let cps: Vec<Vec<f64>> = points.iter().map(|p| p.to_vec()).collect();
        let mut knots = vec![0.0];
        let mut s = 0.0;
        knots.push(0.0);
        for w in cps.windows(2) {
            s += norm(&sub(&w[1], &w[0]));
            knots.push(s);
        }
        knots.push(s);
        PathElement {
            kind: ElementKind::Polyline,
            curve: Nurbs::new(1, knots, &cps, None).unwrap(),
            feed: Some(feed),
            source_line: None,
        }
    }

    /// Two G1 runs at different feeds: straight pieces keep their run's feed, the corner at the
    /// feed change takes the lower one, and collinear vertices are not corners.
    #[test]
    fn programmed_feeds_carry_over() {
        let tp = Toolpath {
            elements: vec![
                g1(&[[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [20.0, 10.0]], 50.0),
                g1(&[[20.0, 10.0], [30.0, 10.0]], 20.0),
            ],
        };
        let r = round_toolpath(&tp, 0.01).unwrap();
        assert_eq!(r.corners, 2);
        let feeds: Vec<Option<f64>> = r.toolpath.elements.iter().map(|e| e.feed).collect();
        assert_eq!(feeds, vec![Some(50.0), Some(50.0), Some(50.0), Some(20.0), Some(20.0)]);
        assert!(r.max_deviation <= 0.01 && r.max_deviation > 0.009);
    }

    /// A reversal keeps its vertex (exact stop); the other corners are rounded.
    #[test]
    fn a_reversal_is_not_rounded() {
        let tp = Toolpath {
            elements: vec![g1(&[[0.0, 0.0], [10.0, 0.0], [5.0, 0.0], [5.0, 5.0]], 50.0)],
        };
        let r = round_toolpath(&tp, 0.01).unwrap();
        assert_eq!(r.corners, 1);
        let kinds: Vec<ElementKind> = r.toolpath.elements.iter().map(|e| e.kind).collect();
        use ElementKind::{Nurbs as N, Polyline as L};
        assert_eq!(kinds, vec![L, L, N, L]);
        let end = r.toolpath.elements[0].curve.point(1.0);
        assert!((end[0] - 10.0).abs() < 1e-12 && end[1].abs() < 1e-12);
    }

    /// Elements that do not join are not one polyline: no rounding across the gap.
    #[test]
    fn a_gap_is_not_bridged() {
        let tp = Toolpath {
            elements: vec![
                g1(&[[0.0, 0.0], [10.0, 0.0]], 50.0),
                g1(&[[10.0, 1.0], [20.0, 1.0]], 50.0),
            ],
        };
        assert!(!is_tip_polyline(&tp));
        let err = round_toolpath(&tp, 0.01).unwrap_err();
        assert!(err.contains("not one continuous polyline"), "{err}");
    }

    /// The hinted search gives the exact largest distance (same as checking every segment).
    #[test]
    fn max_distance_is_exact() {
        let pts: Vec<[f64; 2]> = (0..200)
            .map(|k| {
                let t = k as f64 * 0.05;
                [t.cos() * (5.0 + t), t.sin() * (5.0 + t)]
            })
            .collect();
        let tp = Toolpath {
            elements: vec![g1(&pts, 10.0)],
        };
        let poly = ProgramPolyline::new(&tp).unwrap();
        let probes: Vec<Vec<f64>> = (0..5000)
            .map(|k| {
                let t = k as f64 * 0.002;
                let r = 5.0 + t + 0.3 * (37.0 * t).sin();
                vec![t.cos() * r, t.sin() * r]
            })
            .collect();
        let brute = probes
            .iter()
            .map(|x| {
                (0..pts.len() - 1)
                    .map(|i| segment_distance(x, &pts[i], &pts[i + 1]))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max);
        let got = poly.max_distance(probes.iter().map(|x| x.as_slice()));
        assert!(brute > 0.1);
        assert_eq!(got, brute);
    }
}
