//! G1 corner rounding (VPOp paper section 3.2): each corner of a polyline is replaced by a
//! cubic B-spline with five control points `P - d u1, P - d/2 u1, P, P + d/2 u2, P + d u2`
//! (knots `0 0 0 0 1/2 1 1 1 1`). The first three and the last three control points are
//! collinear with the segments, so the curvature is zero where the spline meets them: the path
//! is C2 in arc length. `d` uses as much of the contour tolerance as the segment lengths allow
//! (each segment gives at most half its length to each of its two corners).

use super::window::Window;
use crate::geometry::{ElementKind, Nurbs, PathElement, Toolpath};
use crate::readers::ReadError;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

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

/// Whether `curve` is a corner spline as [`CornerRounder`] makes them (degree 3, five control
/// points, its knots).
pub(super) fn is_corner_spline(curve: &Nurbs) -> bool {
    curve.degree() == 3 && curve.control_point_count() == 5 && curve.knots() == KNOTS
}

fn sub(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}
fn norm(a: &[f64]) -> f64 {
    a.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Distance from `x` to the segment `a`-`b`, over the coordinates all three have. Without
/// allocation: the smoothing's two-way check calls it for every sample against every nearby
/// vertex.
pub(super) fn segment_distance(x: &[f64], a: &[f64], b: &[f64]) -> f64 {
    segment_distance_squared(x, a, b).sqrt()
}

/// The square of [`segment_distance`]: the nearest of many segments is found without a square
/// root for each.
pub(super) fn segment_distance_squared(x: &[f64], a: &[f64], b: &[f64]) -> f64 {
    let n = x.len().min(a.len()).min(b.len());
    let (mut l2, mut along) = (0.0, 0.0);
    for i in 0..n {
        let (ab, ax) = (b[i] - a[i], x[i] - a[i]);
        l2 += ab * ab;
        along += ax * ab;
    }
    let t = if l2 > 0.0 { (along / l2).clamp(0.0, 1.0) } else { 0.0 };
    let mut d2 = 0.0;
    for i in 0..n {
        let r = (x[i] - a[i]) - t * (b[i] - a[i]);
        d2 += r * r;
    }
    d2
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

/// Largest distance of the tip's corner spline at d = 1 to the two segments it replaces, for
/// unit directions `r1` into the vertex and `r2` out of it: sin(turn) / 8, reached at the
/// spline's middle (u = 1/2, the point P + (u_a + u_b) / 8 with u_a, u_b the unit vectors from
/// the vertex along the segments; the distance to either segment grows monotonically up to
/// there, as the control points' do). The sine comes from the cross product, exact for the
/// small turns of dense G1 programs (`corner_deviation` samples the same curve, in the tests).
fn tip_unit_deviation(r1: &[f64], r2: &[f64]) -> f64 {
    let cross2 = match (r1, r2) {
        ([a, b], [c, d]) => (a * d - b * c).powi(2),
        ([a, b, c], [d, e, f]) => (b * f - c * e).powi(2) + (c * d - a * f).powi(2) + (a * e - b * d).powi(2),
        _ => unreachable!("tool-tip vectors have 2 or 3 coordinates"),
    };
    cross2.sqrt() / 8.0
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

/// What corner rounding did so far.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RoundingStats {
    /// Corners replaced by a five-point cubic B-spline.
    pub corners: usize,
    /// Largest distance of a corner spline to the programmed polyline (mm).
    pub max_deviation: f64,
    /// 5-axis: the same for the top curve (tool axis).
    pub max_top_deviation: f64,
    /// A rounded polyline had a top curve.
    pub top: bool,
    /// Runs of short pieces replaced by one fitted spline each ([`super::fit::RunFitter`]),
    /// and the pieces they replaced.
    pub fitted_runs: usize,
    pub fitted_pieces: usize,
}

/// Rounds the corners of one polyline as its vertices come, handing out each straight piece
/// and corner spline as soon as the next vertex settles it. A straight piece keeps the lowest
/// programmed feed of its segments, a corner spline takes the lower feed of its two segments.
/// Vertices longer than `tip` carry the top point (5-axis): the corner is where the tip turns
/// or the tool axis changes its rate of turning per mm of tip travel (both make a joint stop),
/// and both tip and top splines stay within the tolerance of their polylines. Consecutive
/// vertices closer than 1e-12 mm count as one.
struct RunRounder {
    tip: usize,
    tolerance: f64,
    /// The last three distinct vertices (fewer at the run's start).
    v: Vec<Vertex>,
    /// Tip length and programmed feed of the segments between them.
    lens: Vec<f64>,
    seg_feed: Vec<Option<f64>>,
    /// Distinct vertices taken.
    count: usize,
    /// Where the straight piece being built starts, and the lowest feed of its segments so far.
    start: Vertex,
    run_feed: Option<f64>,
}

impl RunRounder {
    fn new(tip: usize, tolerance: f64) -> Self {
        RunRounder {
            tip,
            tolerance,
            v: Vec::with_capacity(3),
            lens: Vec::with_capacity(2),
            seg_feed: Vec::with_capacity(2),
            count: 0,
            start: Vec::new(),
            run_feed: None,
        }
    }

    /// The last vertex taken.
    fn last(&self) -> Option<&Vertex> {
        self.v.last()
    }

    /// Takes the next vertex `p`, reached at the programmed `feed` (of the segment into it).
    fn push(&mut self, p: &[f64], feed: Option<f64>, out: &mut VecDeque<PathElement>, stats: &mut RoundingStats) {
        let tip = self.tip;
        match self.v.last() {
            None => self.start = p.to_vec(),
            Some(q) if norm(&sub(p, q)) <= 1e-12 => return,
            Some(q) => {
                self.lens.push(norm(&sub(&p[..tip], &q[..tip])));
                self.seg_feed.push(feed);
            }
        }
        self.v.push(p.to_vec());
        self.count += 1;
        if self.v.len() == 3 {
            self.corner(out, stats);
            self.v.remove(0);
            self.lens.remove(0);
            self.seg_feed.remove(0);
        }
    }

    /// The middle one of the last three vertices.
    fn corner(&mut self, out: &mut VecDeque<PathElement>, stats: &mut RoundingStats) {
        let (tip, v, lens) = (self.tip, &self.v, &self.lens);
        let five = v[0].len() == 2 * tip;
        self.run_feed = min_feed(self.run_feed, self.seg_feed[0]);
        // Per mm of tip travel on either side: the tip's unit direction, and the top's rate.
        let rate = |k: usize| -> Vec<f64> { sub(&v[k + 1], &v[k]).iter().map(|x| x / lens[k]).collect() };
        // A turn of the tool axis with the tip standing still (5-axis) has no tip length to
        // round along: `None`, the vertex is kept like a reversal.
        let turn = (lens[0] > 1e-12 && lens[1] > 1e-12).then(|| {
            let (r1, r2) = (rate(0), rate(1));
            let cos = r1[..tip].iter().zip(&r2[..tip]).map(|(a, b)| a * b).sum::<f64>();
            (cos, five && norm(&sub(&r1[tip..], &r2[tip..])) > 1e-12)
        });
        match turn {
            Some((cos, axis_kink)) if cos > 1.0 - 1e-12 && !axis_kink => return, // straight through
            Some((cos, _)) if cos >= -1.0 + 1e-9 => {}                           // a corner
            _ => {
                // A reversal has no rounding inside the tolerance (the spline would stop and
                // turn back on itself): keep the programmed vertex, where the motion stops.
                if norm(&sub(&v[1], &self.start)) > 1e-12 {
                    out.push_back(line(&self.start, &v[1], self.run_feed, tip));
                }
                self.start = v[1].clone();
                self.run_feed = None;
                return;
            }
        }
        // Deviation is proportional to d (the tip distance of the first control point from the
        // vertex), for the tip and the top alike: measure it at d = 1 and scale to the tolerance.
        let spline = |d: f64| corner_curve(&v[0], &v[1], &v[2], d / lens[0], d / lens[1], tip);
        let unit_dev = tip_unit_deviation(&rate(0)[..tip], &rate(1)[..tip]);
        let mut d = (0.999 * self.tolerance / unit_dev).min(0.5 * lens[0].min(lens[1]));
        let unit_top_dev = if five {
            corner_deviation(&spline(1.0), tip..2 * tip)
        } else {
            0.0
        };
        if five {
            d = d.min(0.999 * self.tolerance / unit_top_dev);
        }
        let curve = spline(d);
        // The spline at d is the unit one scaled by d about the vertex: so is its deviation
        // (measured once, not again: 401 curve points a corner on a million-line program).
        stats.max_deviation = stats.max_deviation.max(d * unit_dev);
        if five {
            stats.max_top_deviation = stats.max_top_deviation.max(d * unit_top_dev);
        }
        let entry = curve.control_point(0).to_vec();
        if norm(&sub(&entry, &self.start)) > 1e-12 {
            out.push_back(line(&self.start, &entry, self.run_feed, tip));
        }
        self.start = curve.control_point(4).to_vec();
        out.push_back(PathElement {
            kind: ElementKind::Nurbs,
            curve,
            feed: min_feed(self.seg_feed[0], self.seg_feed[1]),
            source_line: None,
        });
        self.run_feed = None;
        stats.corners += 1;
    }

    /// The polyline ends: its last straight piece goes out.
    fn finish(&mut self, out: &mut VecDeque<PathElement>) -> Result<(), String> {
        if self.count < 2 {
            return Err("a polyline needs two distinct points".into());
        }
        let last = self.v.last().expect("two vertices").clone();
        self.run_feed = min_feed(self.run_feed, *self.seg_feed.last().expect("a segment"));
        if norm(&sub(&last, &self.start)) > 1e-12 {
            out.push_back(line(&self.start, &last, self.run_feed, self.tip));
        }
        Ok(())
    }
}

/// Rounds, as they come, the corners of every run of joined straight-line elements (degree 1:
/// G1 moves, DXF lines, degree-1 JSON curves; with or without a top curve) of a stream of path
/// elements within `tolerance`; elements of other kinds pass unchanged, and where a run meets
/// one (or a gap) its end vertex is kept as programmed. What it did so far is in the
/// [`RoundingStats`] it shares ([`CornerRounder::stats`]).
pub struct CornerRounder<I> {
    source: I,
    name: String,
    tolerance: f64,
    /// Refuse what is not one continuous polyline (`--round-corners on`).
    polyline_only: bool,
    /// The run being rounded: its rounder, tip dimension, whether it has a top curve.
    run: Option<(RunRounder, bool)>,
    /// The degree-1 element being taken, and its next vertex to take: a vertex at a time, so
    /// that the first rounded element goes out without the rest of a long element.
    taking: Option<(PathElement, usize)>,
    out: VecDeque<PathElement>,
    stats: Arc<Mutex<RoundingStats>>,
    done: bool,
}

impl<I: Iterator<Item = Result<PathElement, ReadError>>> CornerRounder<I> {
    /// Rounds `source` (of the file `name`, for errors) within `tolerance` (mm, > 0); with
    /// `polyline_only`, an element that does not continue one polyline is an error.
    pub fn new(name: &str, source: I, tolerance: f64, polyline_only: bool) -> Result<Self, String> {
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(format!("contour tolerance {tolerance} must be > 0"));
        }
        Ok(CornerRounder {
            source,
            name: name.to_owned(),
            tolerance,
            polyline_only,
            run: None,
            taking: None,
            out: VecDeque::new(),
            stats: Arc::default(),
            done: false,
        })
    }

    /// What rounding has done so far (complete once the stream has ended).
    pub fn stats(&self) -> Arc<Mutex<RoundingStats>> {
        Arc::clone(&self.stats)
    }

    /// Ends the run being rounded.
    fn end_run(&mut self) -> Result<(), ReadError> {
        if let Some((mut run, _)) = self.run.take() {
            run.finish(&mut self.out).map_err(|e| ReadError::new(&self.name, e))?;
        }
        Ok(())
    }

    /// Takes the next element of the source.
    fn take(&mut self, e: PathElement) -> Result<(), ReadError> {
        let with_top = e.curve.dim() != e.curve.tip_dim();
        let refuse = |what: &str| {
            let at = e.source_line.map_or(String::new(), |l| format!(" (line {l})"));
            Err(ReadError::new(
                &self.name,
                format!("--round-corners on needs a polyline (one continuous run of straight G1 / LINE / degree-1 elements, with or without a top curve), but {what}{at}"),
            ))
        };
        if e.curve.degree() != 1 {
            if self.polyline_only {
                return refuse(&format!("an element is of degree {}", e.curve.degree()));
            }
            self.end_run()?;
            self.out.push_back(e);
            return Ok(());
        }
        let first = e.curve.control_point(0);
        let joins = self.run.as_ref().is_some_and(|(run, top)| {
            *top == with_top
                && run.tip == e.curve.tip_dim()
                && run.last().is_some_and(|q| norm(&sub(first, q)) <= JOIN_GAP)
        });
        if !joins {
            if self.polyline_only && self.run.is_some() {
                return refuse("an element does not continue the one before");
            }
            self.end_run()?;
            self.run = Some((RunRounder::new(e.curve.tip_dim(), self.tolerance), with_top));
        }
        self.stats
            .lock()
            .map_err(|_| ReadError::new(&self.name, "rounding state lost"))?
            .top |= with_top;
        self.taking = Some((e, 0));
        Ok(())
    }

    /// Takes the next vertex of the element being taken, if it has one left.
    fn take_vertex(&mut self) -> Result<bool, ReadError> {
        let (Some((e, k)), Some((run, _))) = (&mut self.taking, &mut self.run) else {
            return Ok(false);
        };
        if *k == e.curve.control_point_count() {
            self.taking = None;
            return Ok(false);
        }
        let mut stats = self
            .stats
            .lock()
            .map_err(|_| ReadError::new(&self.name, "rounding state lost"))?;
        // Every vertex is reached at the element's feed (the join's zero-length segment too).
        run.push(e.curve.control_point(*k), e.feed, &mut self.out, &mut stats);
        *k += 1;
        Ok(true)
    }
}

impl<I: Iterator<Item = Result<PathElement, ReadError>>> Iterator for CornerRounder<I> {
    type Item = Result<PathElement, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(e) = self.out.pop_front() {
                return Some(Ok(e));
            }
            if self.done {
                return None;
            }
            match self.take_vertex() {
                Ok(true) => continue,
                Ok(false) => {}
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
            let step = match self.source.next() {
                Some(Ok(e)) => self.take(e),
                Some(Err(e)) => Err(e),
                None => {
                    self.done = true;
                    self.end_run()
                }
            };
            if let Err(e) = step {
                self.done = true;
                self.out.clear();
                return Some(Err(e));
            }
        }
    }
}

type Vertices = Vec<Vertex>;

/// Largest gap between consecutive elements of one continuous polyline (mm).
const JOIN_GAP: f64 = 1e-9;

/// The vertices of a toolpath made of degree-1 elements that join (tool tip, padded to the
/// toolpath's tip dimension, then the top point when every element has a top curve); an error
/// naming the element where it is not one continuous polyline.
fn polyline_of(toolpath: &Toolpath) -> Result<Vertices, String> {
    let mut vertices: Vec<Vertex> = Vec::new();
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
            vertices.push(p);
        }
    }
    Ok(vertices)
}

/// Rounds a whole toolpath made of degree-1 elements (G1 blocks, polylines, degree-1 splines)
/// that is one polyline through their control points ([`CornerRounder`], collected): the tool
/// tip, and on 5-axis paths the top curve with the same parameter. Programmed feeds carry
/// over: a straight piece keeps its element's feed, a corner spline the lower of its two
/// segments'.
pub fn round_toolpath(toolpath: &Toolpath, tolerance: f64) -> Result<Rounded, String> {
    polyline_of(toolpath)?;
    let rounder = CornerRounder::new("", toolpath.elements.iter().cloned().map(Ok), tolerance, true)?;
    let stats = rounder.stats();
    let elements = rounder.collect::<Result<Vec<_>, _>>().map_err(|e| e.message)?;
    let stats = *stats.lock().map_err(|_| "rounding state lost")?;
    Ok(Rounded {
        toolpath: Toolpath { elements },
        max_deviation: stats.max_deviation,
        max_top_deviation: stats.max_top_deviation,
        corners: stats.corners,
    })
}

/// Segments of the programmed polyline kept behind the one nearest to the last point measured.
const PROGRAM_SEGMENTS_BEHIND: usize = 4096;
/// How much of the program past the nearest segment found is read before a setpoint's distance
/// is taken as new worst (mm, beyond that distance itself): more than a setpoint moves in a
/// period at any feed.
const PROGRAM_LOOK_AHEAD: f64 = 1.0;

/// The programmed polyline of a toolpath of degree-1 elements, for measuring how far setpoints
/// stray from it: read from its elements as far as the points measured need, and forgotten
/// more than [`PROGRAM_SEGMENTS_BEHIND`] segments behind them, so that a program of any length
/// is measured in constant memory. The measure is the distance to the nearest segment held:
/// exact while the path does not come back near a part of itself forgotten already, and never
/// below the true distance.
pub struct ProgramPolyline {
    /// The rest of the program's elements.
    source: Option<Box<dyn Iterator<Item = PathElement> + Send>>,
    vertices: Window<Vertex>,
    /// Tool-tip dimension and whether vertices carry a top point, from the first element.
    tip: usize,
    five: bool,
    /// The program turned out not to be one continuous polyline.
    broken: bool,
}

impl ProgramPolyline {
    /// The polyline of a whole toolpath; an error if it is not one.
    pub fn new(toolpath: &Toolpath) -> Result<Self, String> {
        let vertices = polyline_of(toolpath)?;
        if vertices.is_empty() {
            return Err("empty polyline".into());
        }
        Ok(ProgramPolyline {
            source: None,
            vertices: Window::from_vec(vertices),
            tip: toolpath.tip_dim(),
            five: false,
            broken: false,
        })
    }

    /// The polyline of a program read as it is measured (the programmed elements, before any
    /// rounding); if an element turns out not to continue it, [`Deviation::finish`] says so.
    pub fn streamed(elements: impl Iterator<Item = PathElement> + Send + 'static) -> Self {
        ProgramPolyline {
            source: Some(Box::new(elements)),
            vertices: Window::default(),
            tip: 0,
            five: false,
            broken: false,
        }
    }

    /// Whether vertex `i` is held, reading the program as far as it.
    fn load(&mut self, i: usize) -> bool {
        while self.vertices.len() <= i && !self.broken {
            let Some(e) = self.source.as_mut().and_then(|s| s.next()) else {
                self.source = None;
                break;
            };
            let with_top = e.curve.dim() != e.curve.tip_dim();
            if self.vertices.len() == 0 {
                (self.tip, self.five) = (e.curve.tip_dim(), with_top);
            }
            if e.curve.degree() != 1 || with_top != self.five || e.curve.tip_dim() != self.tip {
                self.broken = true;
                break;
            }
            for k in 0..e.curve.control_point_count() {
                let p = e.curve.control_point(k);
                if k == 0 {
                    if let Some(q) = self.vertices.last() {
                        if norm(&sub(p, q)) > JOIN_GAP {
                            self.broken = true;
                            return false;
                        }
                    }
                }
                self.vertices.push(p.to_vec());
            }
        }
        i < self.vertices.len()
    }

    fn segment(&self, i: usize, x: &[f64]) -> f64 {
        let n = self.vertices[i].len().min(x.len());
        match self.vertices.get(i + 1) {
            Some(b) => segment_distance(&x[..n], &self.vertices[i][..n], &b[..n]),
            None => norm(&sub(&x[..n], &self.vertices[i][..n])),
        }
    }

    /// Largest distance of `points` (tool-tip coordinates) to the polyline ([`Deviation`]);
    /// `None` if the program is not one polyline.
    pub fn max_distance<'a>(&mut self, points: impl IntoIterator<Item = &'a [f64]>) -> Option<f64> {
        let mut d = Deviation::default();
        for x in points {
            d.push(self, x);
        }
        d.finish(self)
    }
}

/// [`ProgramPolyline::max_distance`] a point at a time (for setpoints that are not kept).
#[derive(Clone, Copy, Debug, Default)]
pub struct Deviation {
    /// The largest distance so far.
    worst: f64,
    hint: usize,
    /// The farthest segment found nearest so far.
    furthest: usize,
}

impl Deviation {
    pub fn push(&mut self, polyline: &mut ProgramPolyline, x: &[f64]) {
        if !polyline.load(self.hint + 1) && !polyline.load(self.hint) {
            return;
        }
        // The segment `i` runs from vertex i to i + 1 (a lone vertex is a segment of its own).
        let last_segment = |p: &ProgramPolyline| p.vertices.len().saturating_sub(2);
        // Setpoints run along the polyline: follow them from the last nearest segment downhill
        // (a setpoint may be many short segments on), and scan every segment held only when
        // that cannot rule the point out (the path may pass near an earlier part of itself).
        let (mut i, mut near) = (self.hint, polyline.segment(self.hint, x));
        for step in [1isize, -1] {
            while let Some(j) = i.checked_add_signed(step) {
                if j < polyline.vertices.first_index() || !polyline.load(j + 1) {
                    break;
                }
                let dj = polyline.segment(j, x);
                if dj >= near {
                    break;
                }
                (i, near) = (j, dj);
            }
        }
        self.hint = i;
        self.furthest = self.furthest.max(i);
        if near > self.worst {
            // The walk stops at the first segment that is no nearer, so the nearest one may lie
            // beyond a bend it has not read yet (a path that leaves and comes back, a retrace):
            // read on from the farthest segment reached so far until the polyline ahead is
            // longer than the distance in question.
            let mut ahead = 0.0;
            let mut k = i.max(self.furthest) + 1;
            while ahead <= near + PROGRAM_LOOK_AHEAD && polyline.load(k + 1) {
                ahead += norm(&sub(&polyline.vertices[k + 1], &polyline.vertices[k]));
                k += 1;
            }
            let (best, dmin) = (polyline.vertices.first_index()..=last_segment(polyline))
                .map(|i| (i, polyline.segment(i, x)))
                // On a tie the later segment: setpoints move forward along the program, and a
                // program that retraces itself (a CAM retract, move over and plunge to where it
                // was) must not send the search back to the earlier pass.
                .fold(
                    (i, near),
                    |a, b| if b.1 < a.1 || (b.1 == a.1 && b.0 > a.0) { b } else { a },
                );
            self.hint = best;
            self.worst = self.worst.max(dmin);
            self.furthest = self.furthest.max(best);
        }
        polyline
            .vertices
            .release_before(self.hint.saturating_sub(PROGRAM_SEGMENTS_BEHIND));
    }

    /// The largest distance, or `None` if the program is not one polyline.
    pub fn finish(self, polyline: &ProgramPolyline) -> Option<f64> {
        (!polyline.broken && polyline.vertices.len() > 0).then_some(self.worst)
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

    /// The tip spline's deviation in closed form equals the densely sampled one, for turns from
    /// 0.01 to 179 degrees in 2-D and 3-D and uneven segment lengths.
    #[test]
    fn the_closed_form_deviation_is_the_sampled_one() {
        for turn_deg in [0.01, 1.0, 10.0, 45.0, 90.0, 135.0, 170.0, 179.0] {
            let turn = turn_deg * std::f64::consts::PI / 180.0;
            for (tilt, lens) in [(0.0f64, [1.0, 1.0]), (0.3, [1.0, 7.0]), (1.2, [3.0, 2.0])] {
                let a = [-lens[0], 0.0, 0.0];
                let p = [0.0, 0.0, 0.0];
                let dir = [turn.cos(), turn.sin() * tilt.cos(), turn.sin() * tilt.sin()];
                let b: Vec<f64> = dir.iter().map(|x| x * lens[1]).collect();
                for tip in [2, 3] {
                    if tip == 2 && tilt != 0.0 {
                        continue;
                    }
                    let unit = corner_curve(&a[..tip], &p[..tip], &b[..tip], 1.0 / lens[0], 1.0 / lens[1], tip);
                    let sampled = corner_deviation(&unit, 0..tip);
                    let r1: Vec<f64> = (0..tip).map(|i| (p[i] - a[i]) / lens[0]).collect();
                    let r2: Vec<f64> = (0..tip).map(|i| (b[i] - p[i]) / lens[1]).collect();
                    let closed = tip_unit_deviation(&r1, &r2);
                    assert!(
                        (closed - sampled).abs() <= 1e-12 * sampled,
                        "turn {turn_deg} deg, tip {tip}: {closed} against {sampled}"
                    );
                }
            }
        }
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
        assert!(polyline_of(&tp).is_err());
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
        assert!(polyline_of(&tp).is_ok());
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

    /// The largest distance of `probes` to the polyline `pts`, every segment checked.
    fn brute_max_distance(probes: &[Vec<f64>], pts: &[[f64; 2]]) -> f64 {
        probes
            .iter()
            .map(|x| {
                (0..pts.len() - 1)
                    .map(|i| segment_distance(x, &pts[i], &pts[i + 1]))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
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
        let mut poly = ProgramPolyline::new(&tp).unwrap();
        let probes: Vec<Vec<f64>> = (0..5000)
            .map(|k| {
                let t = k as f64 * 0.002;
                let r = 5.0 + t + 0.3 * (37.0 * t).sin();
                vec![t.cos() * r, t.sin() * r]
            })
            .collect();
        let brute = brute_max_distance(&probes, &pts);
        let got = poly.max_distance(probes.iter().map(|x| x.as_slice())).unwrap();
        assert!(brute > 0.1);
        assert_eq!(got, brute);
    }

    /// A program that retraces itself (a CAM program's retract, move over, plunge to where it
    /// cut before and cut on from there, one G1 element each), measured along it: exact. (It
    /// passes with the search before the tie rule too; the public PCB program of
    /// docs/performance.md is where a tie sent that search back to the earlier pass.)
    #[test]
    fn a_retracing_program_is_measured_exactly() {
        let legs = [
            [0.0, 0.0],
            [5.0, 0.0],
            [5.0, 2.0],
            [8.0, 2.0],
            [8.0, 0.0],
            [5.0, 0.0],
            [5.0, -3.0],
            [0.0, -3.0],
        ];
        let elements: Vec<PathElement> = legs.windows(2).map(|w| g1(w, 10.0)).collect();
        let mut poly = ProgramPolyline::streamed(elements.into_iter());
        // Points along the legs, 0.01 mm apart, each off the path by up to 1e-4 mm.
        let mut probes = Vec::new();
        for w in legs.windows(2) {
            let (a, b) = (w[0], w[1]);
            let n = (norm(&sub(&b, &a)) / 0.01).round() as usize;
            for k in 0..n {
                let t = k as f64 / n as f64;
                let wiggle = 1e-4 * ((probes.len() as f64) * 0.37).sin();
                probes.push(vec![
                    a[0] + t * (b[0] - a[0]) + wiggle,
                    a[1] + t * (b[1] - a[1]) + wiggle,
                ]);
            }
        }
        let brute = brute_max_distance(&probes, &legs);
        let got = poly.max_distance(probes.iter().map(|x| x.as_slice())).unwrap();
        assert!((got - brute).abs() < 1e-15 && brute < 2e-4, "{got} against {brute}");
    }

    /// A streamed program read as far as the points need: a point past a U-turn (a CAM
    /// program's retract, move over and plunge, one G1 element each) is measured against the
    /// segment beyond the turn, which the downhill walk alone does not reach (it stops at the
    /// turn, farther than the segment before it) and had not read.
    #[test]
    fn a_point_past_a_turn_is_measured_against_the_program_beyond_it() {
        let legs = [[0.0, 0.0], [10.0, 0.0], [10.0, 1.0], [0.0, 1.0], [0.0, 2.0]];
        let elements: Vec<PathElement> = legs.windows(2).map(|w| g1(w, 10.0)).collect();
        let mut poly = ProgramPolyline::streamed(elements.into_iter());
        let probes = [vec![0.0, 0.0], vec![0.5, 1.0005]];
        let got = poly.max_distance(probes.iter().map(|x| x.as_slice())).unwrap();
        assert!((got - 0.0005).abs() < 1e-12, "{got}");
    }
}
