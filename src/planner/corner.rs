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
    /// 5-axis paths: the same for the top curve (0 for a tool-tip path).
    pub max_top_deviation: f64,
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

/// A polyline vertex: the tool tip, followed on 5-axis paths by the top point (a second point
/// on the tool axis).
type Vertex = Vec<f64>;

/// A curve through `vertices`' tips (and tops, when `tip` is half their length): the tip and
/// top curves share knots and control-point weights, so the tool axis at `u` is the one of the
/// same `u` on both.
fn two_curves(degree: usize, knots: Vec<f64>, points: &[Vertex], tip: usize) -> Nurbs {
    let part = |r: std::ops::Range<usize>| -> Vec<Vec<f64>> { points.iter().map(|p| p[r.clone()].to_vec()).collect() };
    let tips = Nurbs::new(degree, knots.clone(), &part(0..tip), None).expect("tip curve is valid");
    if points[0].len() == tip {
        return tips;
    }
    let tops = Nurbs::new(degree, knots, &part(tip..2 * tip), None).expect("top curve is valid");
    tips.with_top_curve(&tops).expect("tip and top curves match")
}

/// Corner spline at vertex `p` between `a` (before) and `b` (after): control points at
/// fractions `f1` of the way towards `a`, `f1 / 2`, `p`, `f2 / 2` and `f2` towards `b`. For the
/// tip with `f = d / segment length` these are `P - d u1, P - d/2 u1, P, P + d/2 u2, P + d u2`;
/// the top point takes the same fractions of its own segments, so tip and top keep moving in
/// step (the rotary axes turn through the corner instead of stopping at it).
fn corner_curve(a: &[f64], p: &[f64], b: &[f64], f1: f64, f2: f64, tip: usize) -> Nurbs {
    let toward = |q: &[f64], f: f64| -> Vertex { p.iter().zip(q).map(|(x, y)| x + f * (y - x)).collect() };
    let cps = [
        toward(a, f1),
        toward(a, 0.5 * f1),
        p.to_vec(),
        toward(b, 0.5 * f2),
        toward(b, f2),
    ];
    two_curves(3, KNOTS.to_vec(), &cps, tip)
}

/// Largest distance of a corner spline's coordinates `range` (tip, or top) to the two segments
/// it replaces (sampled densely).
fn corner_deviation(curve: &Nurbs, range: std::ops::Range<usize>) -> f64 {
    let first = curve.control_point(0)[range.clone()].to_vec();
    let p = curve.control_point(2)[range.clone()].to_vec();
    let last = curve.control_point(4)[range.clone()].to_vec();
    (0..=400)
        .map(|k| {
            let x = curve.point(k as f64 / 400.0);
            let x = &x[range.clone()];
            segment_distance(x, &first, &p).min(segment_distance(x, &p, &last))
        })
        .fold(0.0, f64::max)
}

fn line(a: &[f64], b: &[f64], feed: Option<f64>, tip: usize) -> PathElement {
    PathElement {
        kind: ElementKind::Polyline,
        curve: two_curves(1, vec![0.0, 0.0, 1.0, 1.0], &[a.to_vec(), b.to_vec()], tip),
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
    let tip = vertices.first().map_or(2, Vec::len);
    round_with_feeds(vertices, tip, &feeds, tolerance)
}

/// [`round_polyline`] with a programmed feed per segment (`feeds[i]` for `vertices[i]` to
/// `vertices[i + 1]`): a straight piece keeps its segment's feed, a corner spline takes the
/// lower feed of its two segments. Vertices longer than `tip` carry the top point (5-axis):
/// the corner is where the tip turns or the tool axis changes its rate of turning per mm of
/// tip travel (both make a joint stop), and both tip and top splines stay within `tolerance`
/// of their polylines.
fn round_with_feeds(vertices: &[Vertex], tip: usize, feeds: &[Option<f64>], tolerance: f64) -> Result<Rounded, String> {
    let five = vertices.first().is_some_and(|v| v.len() == 2 * tip);
    let mut v: Vec<Vertex> = Vec::new();
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
    let lens: Vec<f64> = (0..n - 1).map(|i| norm(&sub(&v[i + 1][..tip], &v[i][..tip]))).collect();
    let mut elements = Vec::new();
    let mut start = v[0].clone();
    let mut max_dev: f64 = 0.0;
    let mut max_top_dev: f64 = 0.0;
    let mut corners = 0;
    // A straight piece runs from segment `start_seg` through collinear vertices: lowest feed.
    let mut start_seg = 0;
    let run_feed = |from: usize, to: usize| seg_feed[from..=to].iter().fold(None, |a, b| min_feed(a, *b));
    for i in 1..n - 1 {
        // Per mm of tip travel on either side: the tip's unit direction, and the top's rate.
        let rate = |k: usize| -> Vec<f64> { sub(&v[k + 1], &v[k]).iter().map(|x| x / lens[k]).collect() };
        // A turn of the tool axis with the tip standing still (5-axis) has no tip length to
        // round along: `None`, the vertex is kept like a reversal.
        let turn = (lens[i - 1] > 1e-12 && lens[i] > 1e-12).then(|| {
            let (r1, r2) = (rate(i - 1), rate(i));
            let cos = r1[..tip].iter().zip(&r2[..tip]).map(|(a, b)| a * b).sum::<f64>();
            (cos, five && norm(&sub(&r1[tip..], &r2[tip..])) > 1e-12)
        });
        match turn {
            Some((cos, axis_kink)) if cos > 1.0 - 1e-12 && !axis_kink => continue, // straight through
            Some((cos, _)) if cos >= -1.0 + 1e-9 => {}                             // a corner
            _ => {
                // A reversal has no rounding inside the tolerance (the spline would stop and
                // turn back on itself): keep the programmed vertex, where the motion stops.
                if norm(&sub(&v[i], &start)) > 1e-12 {
                    elements.push(line(&start, &v[i], run_feed(start_seg, i - 1), tip));
                }
                start = v[i].clone();
                start_seg = i;
                continue;
            }
        }
        // Deviation is proportional to d (the tip distance of the first control point from the
        // vertex), for the tip and the top alike: measure it at d = 1 and scale to the tolerance.
        let spline = |d: f64| corner_curve(&v[i - 1], &v[i], &v[i + 1], d / lens[i - 1], d / lens[i], tip);
        let unit = spline(1.0);
        let unit_dev = corner_deviation(&unit, 0..tip);
        let mut d = (0.999 * tolerance / unit_dev).min(0.5 * lens[i - 1].min(lens[i]));
        let unit_top_dev = if five {
            corner_deviation(&unit, tip..2 * tip)
        } else {
            0.0
        };
        if five {
            d = d.min(0.999 * tolerance / unit_top_dev);
        }
        let curve = spline(d);
        // The spline at d is the unit one scaled by d about the vertex: so is its deviation
        // (measured once, not again: 401 curve points a corner on a million-line program).
        max_dev = max_dev.max(d * unit_dev);
        if five {
            max_top_dev = max_top_dev.max(d * unit_top_dev);
        }
        let entry = curve.control_point(0).to_vec();
        if norm(&sub(&entry, &start)) > 1e-12 {
            elements.push(line(&start, &entry, run_feed(start_seg, i - 1), tip));
        }
        start = curve.control_point(4).to_vec();
        elements.push(PathElement {
            kind: ElementKind::Nurbs,
            curve,
            feed: min_feed(seg_feed[i - 1], seg_feed[i]),
            source_line: None,
        });
        start_seg = i;
        corners += 1;
    }
    if norm(&sub(&v[n - 1], &start)) > 1e-12 {
        elements.push(line(&start, &v[n - 1], run_feed(start_seg, n - 2), tip));
    }
    Ok(Rounded {
        toolpath: Toolpath { elements },
        max_deviation: max_dev,
        max_top_deviation: max_top_dev,
        corners,
    })
}

type Vertices = Vec<Vertex>;

/// Largest gap between consecutive elements of one continuous polyline (mm).
const JOIN_GAP: f64 = 1e-9;

/// The programmed polyline of a toolpath made of degree-1 elements: its vertices (tool tip,
/// padded to the toolpath's tip dimension, then the top point when every element has a top
/// curve) and the programmed feed of each segment (the element's; the zero-length joins
/// between elements get the later element's).
fn polyline_of(toolpath: &Toolpath) -> Result<(Vertices, Vec<Option<f64>>), String> {
    let mut vertices: Vec<Vertex> = Vec::new();
    let mut feeds = Vec::new();
    let tip = toolpath.tip_dim();
    let with_top = |e: &PathElement| e.curve.dim() != e.curve.tip_dim();
    let five = toolpath.elements.first().is_some_and(with_top);
    for (i, e) in toolpath.elements.iter().enumerate() {
        if e.curve.degree() != 1 {
            return Err("corner rounding needs a polyline (degree-1 elements)".into());
        }
        if with_top(e) != five || (five && e.curve.tip_dim() != tip) {
            return Err(format!(
                "element {} and element 1 differ in dimension or tool axis: not one polyline",
                i + 1
            ));
        }
        for k in 0..e.curve.control_point_count() {
            let c = e.curve.control_point(k);
            let p = if five {
                c.to_vec()
            } else {
                let mut p = vec![0.0; tip];
                p[..e.curve.tip_dim()].copy_from_slice(&c[..e.curve.tip_dim()]);
                p
            };
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
/// polyline through their control points: the tool tip, and on 5-axis paths the top curve with
/// the same parameter (see [`round_with_feeds`]). Programmed feeds carry over: a straight
/// piece keeps its element's feed, a corner spline the lower of its two segments'.
pub fn round_toolpath(toolpath: &Toolpath, tolerance: f64) -> Result<Rounded, String> {
    let (vertices, feeds) = polyline_of(toolpath)?;
    round_with_feeds(&vertices, toolpath.tip_dim(), &feeds, tolerance)
}

/// True when every element is a straight-line polyline (degree 1) of the tool tip, or of the
/// tool tip and top point (5-axis G1 with tool-axis vectors), and each element starts where the
/// previous one ends: G1 moves, DXF LINE / LWPOLYLINE without bulges, degree-1 JSON curves.
pub fn is_polyline(toolpath: &Toolpath) -> bool {
    !toolpath.elements.is_empty()
        && toolpath.elements.iter().all(|e| e.curve.degree() == 1)
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
        let mut d = Deviation::default();
        for x in points {
            d.push(self, x);
        }
        d.worst
    }
}

/// [`ProgramPolyline::max_distance`] a point at a time (for setpoints that are not kept).
#[derive(Clone, Copy, Debug, Default)]
pub struct Deviation {
    /// The largest distance so far.
    pub worst: f64,
    hint: usize,
}

impl Deviation {
    pub fn push(&mut self, polyline: &ProgramPolyline, x: &[f64]) {
        let segs = polyline.vertices.len().saturating_sub(1).max(1);
        // Setpoints run along the polyline: follow them from the last nearest segment downhill
        // (a setpoint may be many short segments on), and scan every segment only when that
        // cannot rule the point out (the path may pass near an earlier part of itself).
        let d = |i: usize| polyline.segment(i, x);
        let (mut i, mut near) = (self.hint.min(segs - 1), d(self.hint.min(segs - 1)));
        for step in [1isize, -1] {
            loop {
                let j = i as isize + step;
                if j < 0 || j as usize >= segs {
                    break;
                }
                let dj = d(j as usize);
                if dj >= near {
                    break;
                }
                (i, near) = (j as usize, dj);
            }
        }
        self.hint = i;
        if near <= self.worst {
            return;
        }
        let (best, dmin) = (0..segs)
            .map(|i| (i, d(i)))
            .fold((i, near), |a, b| if b.1 < a.1 { b } else { a });
        self.hint = best;
        self.worst = self.worst.max(dmin);
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
        assert!(!is_polyline(&tp));
        let err = round_toolpath(&tp, 0.01).unwrap_err();
        assert!(err.contains("not one continuous polyline"), "{err}");
    }

    /// A 5-axis G1 path (tip and top point 10 mm up the tool axis): every corner of the tip,
    /// and a vertex where only the tool axis changes its rate of turning, are rounded; tip and
    /// top curves stay within the tolerance of their polylines, and at every join both move on
    /// in step (the same top travel per mm of tip travel on either side: no joint stops).
    #[test]
    fn five_axis_corners_round_tip_and_top_together() {
        let tip = [
            [0.0, 0.0, 0.0],
            [20.0, 0.0, 0.0],
            [40.0, 0.0, 0.0],
            [50.0, 15.0, 2.0],
            [70.0, 20.0, 0.0],
        ];
        let axis = [
            [0.0, 0.0, 1.0],
            [0.2, 0.0, 1.0],
            [0.2, 0.0, 1.0],
            [0.0, 0.3, 1.0],
            [-0.1, 0.1, 1.0],
        ];
        let cps: Vec<Vec<f64>> = tip
            .iter()
            .zip(&axis)
            .map(|(p, a)| {
                let n = norm(a);
                let mut v = p.to_vec();
                v.extend((0..3).map(|i| p[i] + 10.0 * a[i] / n));
                v
            })
            .collect();
        let part = |r: std::ops::Range<usize>| -> Vec<Vec<f64>> { cps.iter().map(|p| p[r.clone()].to_vec()).collect() };
        let knots = vec![0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0];
        let tips = Nurbs::new(1, knots.clone(), &part(0..3), None).unwrap();
        let tops = Nurbs::new(1, knots, &part(3..6), None).unwrap();
        let tp = Toolpath {
            elements: vec![PathElement {
                kind: ElementKind::Polyline,
                curve: tips.with_top_curve(&tops).unwrap(),
                feed: Some(30.0),
                source_line: None,
            }],
        };
        assert!(is_polyline(&tp));
        let tol = 0.01;
        let r = round_toolpath(&tp, tol).unwrap();
        // Vertex 1: the tip goes straight on, the axis starts turning; 2 and 3: tip corners.
        assert_eq!(r.corners, 3);
        assert!(
            r.max_deviation <= tol && r.max_top_deviation <= tol,
            "{} {}",
            r.max_deviation,
            r.max_top_deviation
        );
        // Each corner uses the tolerance of whichever curve it binds first.
        assert!(r.max_deviation > 0.5 * tol && r.max_top_deviation > 0.9 * tol);
        let els = &r.toolpath.elements;
        assert!(els
            .iter()
            .all(|e| e.curve.dim() == 6 && e.curve.tip_dim() == 3 && e.feed == Some(30.0)));
        // Rate of the whole vertex (tip and top) per mm of tip travel near an end of an element.
        let rate = |c: &Nurbs, at_end: bool| -> Vec<f64> {
            let h = 1e-7;
            let (u0, u1) = if at_end {
                (c.u_max() - h, c.u_max())
            } else {
                (c.u_min(), c.u_min() + h)
            };
            let d = sub(&c.point(u1)[..6], &c.point(u0)[..6]);
            let l = norm(&d[..3]);
            d.iter().map(|x| x / l).collect()
        };
        for w in els.windows(2) {
            let (a, b) = (&w[0].curve, &w[1].curve);
            assert!(norm(&sub(&a.point(a.u_max())[..6], &b.point(b.u_min())[..6])) < 1e-12);
            let jump = norm(&sub(&rate(a, true), &rate(b, false)));
            assert!(jump < 1e-5, "rate jumps by {jump} between elements");
        }
        // End points kept.
        let last = els.last().unwrap();
        assert!(norm(&sub(&last.curve.point(last.curve.u_max())[..6], &cps[4])) < 1e-12);
    }

    /// A turn of the tool axis with the tip standing still is kept as programmed (no tip length
    /// to round along), not an error.
    #[test]
    fn an_axis_turn_in_place_is_kept() {
        let tips = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0]];
        let tops = [[0.0, 0.0, 10.0], [10.0, 0.0, 10.0], [13.0, 0.0, 9.5], [13.0, 10.0, 9.5]];
        let knots = vec![0.0, 0.0, 1.0, 2.0, 3.0, 3.0];
        let rows = |p: &[[f64; 3]]| -> Vec<Vec<f64>> { p.iter().map(|x| x.to_vec()).collect() };
        let curve = Nurbs::new(1, knots.clone(), &rows(&tips), None)
            .unwrap()
            .with_top_curve(&Nurbs::new(1, knots, &rows(&tops), None).unwrap())
            .unwrap();
        let tp = Toolpath::single(ElementKind::Polyline, curve);
        let r = round_toolpath(&tp, 0.01).unwrap();
        assert_eq!(r.corners, 0);
        assert_eq!(r.toolpath.elements.len(), 3);
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
