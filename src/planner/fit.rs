//! Smoothing of dense G1 runs: a run of short straight pieces and corner splines (what
//! [`super::corner::CornerRounder`] makes of CAM output that samples a smooth surface every
//! few hundredths of a millimetre) is replaced by one cubic B-spline fitted to the programmed
//! vertices by least squares, within the contour tolerance of the programmed polyline.
//!
//! Why: rounding each corner of a 0.02 mm polyline gives a path whose curvature jumps between
//! zero (the lines) and the corners' peaks every hundredth of a millimetre; the axis jerk that
//! such a path asks for at speed (the `v³ dκ/ds` term) holds the feed to a few mm/s, although
//! the surface the points were sampled from allows hundreds. The fitted spline follows that
//! surface: its curvature is the surface's, smoothed over a few points, and the quantisation of
//! the coordinates (1e-4 mm in most CAM output) is averaged out instead of turned into
//! corners. Commercial controls do the same ("compressors", "smoothing"); here the fit is
//! checked against the programmed polyline both ways (no point of the spline farther than the
//! tolerance from the polyline, no programmed vertex farther than it from the spline), and
//! where it cannot be made to pass the run is split, down to the rounded pieces themselves.
//!
//! A run ends at a real corner: a turn sharper than the corner angle (`--corner-angle`) between
//! lines long enough that a curve through their vertices would leave them by more than the
//! tolerance ([`CORNER_DEPTH`]) (a zigzag of 2 mm lines, a pocket's corners; not the tight turns
//! of a densely sampled curve, where lines of 0.02 mm turn by up to 42 degrees). Such a corner
//! keeps its rounding, a stop for the feed as a corner should be, instead of being fitted over.
//!
//! The spline starts and ends where the run does. Where it meets a rounded piece (or anything
//! else) it runs along the piece's tangent with zero curvature there (three collinear control
//! points), as the pieces it replaces do. A long run is fitted in overlapping windows: a window
//! reaches [`OVERLAP`] pieces past where it is cut, only the part before the cut is kept (cut by
//! knot insertion, so it is exactly that part of the fit), and the next window starts at its
//! end point with its tangent and curvature vector. The kept part's end is determined by data
//! on both sides (a spline fitted up to a free end bends there, up to twice the curvature of the
//! data on a circle), and the path stays continuous in tangent and curvature at every join.

use super::corner::{is_corner_spline, segment_distance, segment_distance_squared, RoundingStats};
use crate::geometry::{ElementKind, Nurbs, PathElement};
use crate::readers::ReadError;
use nurbs_rtcore::math::{dot, norm, sub};
use nurbs_rtcore::span_cache::{CachedCurve, SpanCache};
use nurbs_rtcore::{basis_functions, Vector, MAX_DIM};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

/// Pieces longer than this (mm, control-polygon length) end a run: long lines and wide corners
/// keep their rounding, which already lets the feed up.
const SHORT_PIECE: f64 = 4.0;
/// A run of fewer pieces is left as rounded.
const MIN_RUN: usize = 8;
/// Pieces in one fitted spline at most (about 5 mm of a 0.02 mm program). A longer run is
/// fitted in windows of this many pieces and [`OVERLAP`] more, each kept up to its cut.
const MAX_RUN: usize = 500;
/// Pieces a window reaches past its cut (some five knot spans), so that the part kept is
/// determined by the data on both sides of the cut.
const OVERLAP: usize = 100;
/// The first run is cut this short, so that the planner gets its first element early (a run
/// of `MAX_RUN` pieces takes some 0.1 s to read, round and fit).
const FIRST_RUN: usize = 60;
/// Programmed vertices per knot span of the first fit; fewer on each refinement (by half
/// again as many spans) until the fit passes. The coarsest fit that passes is the smoothest:
/// the quantisation of the coordinates (1e-4 mm, 5 % of a 0.02 mm step) would turn into
/// curvature with a few points per span.
const VERTICES_PER_SPAN: usize = 32;
/// Share of the contour tolerance a fit may use (the rest covers the sampling of the check).
const FIT_SHARE: f64 = 0.98;
/// Extra knots at both ends, as shares of a uniform span ([`fit`]).
const END_GRADING: [f64; 3] = [0.125, 0.25, 0.5];
/// Most fits tried for one run (each refining the spans near where the last one was off).
const MAX_REFINEMENTS: usize = 32;
/// Spline points checked per data interval.
const CHECK_SAMPLES: usize = 8;
/// Share of the fit's budget a spline may leave the chord between two check samples before the
/// samples are halved there ([`deviation`] adds it to what it measures).
const SAMPLE_SAG: f64 = 0.02;
/// Most halvings of a check sample interval (2^6 = 64 samples where there were one).
const MAX_HALVINGS: u32 = 6;
/// Neighbouring data intervals searched for the nearest (the chord-length parameter keeps a
/// spline point near its interval; a larger distance found only makes the fit refine).
const WINDOW: usize = 3;
/// The fairness term's length, in mean data intervals: the fit minimises the squared distances
/// to the data plus the integral of the squared third derivative (in arc length) weighted so
/// that wiggles shorter than about this are smoothed away (the quantisation noise of the
/// coordinates, and the corners of the polyline where the spans are refined to single
/// intervals), and longer shapes are followed. (The weight is data points × (length / run)^6.)
const FAIR_INTERVALS: f64 = 32.0;
/// Factor on the weight of the data in an interval that is off, each refinement.
const REWEIGHT: f64 = 2.0;
/// A turn sharper than the corner angle ends a run where `L θ / 8` (how far an arc through
/// the vertices would leave the shorter line, of length `L`, turning by `θ` radians) is more
/// than this many tolerances: the polyline is no chord of a smooth curve within the tolerance
/// there, the corner was programmed. (1 against 2, 4 and 8 on `3D_Chips.ngc` and the dense
/// programs of `scripts/dense-g1.py`: the fastest by default on both.)
const CORNER_DEPTH: f64 = 1.0;
/// The corner angle by default (degrees; `--corner-angle`, `[NURBS]CORNER_ANGLE`).
pub const CORNER_ANGLE: f64 = 35.0;

/// A tool-tip point or vector (the first three coordinates; the rest zero).
type P3 = Vector;

fn p3(x: &[f64]) -> P3 {
    let mut p = [0.0; MAX_DIM];
    for (a, b) in p.iter_mut().zip(x.iter().take(3)) {
        *a = *b;
    }
    p
}
fn dot3(a: &P3, b: &P3) -> f64 {
    dot(a, b, 3)
}
fn norm3(a: &P3) -> f64 {
    norm(a, 3)
}
/// `p + d t`.
fn axpy(p: &P3, d: f64, t: &P3) -> P3 {
    std::array::from_fn(|i| p[i] + d * t[i])
}
/// `p / d`.
fn scaled(p: &P3, d: f64) -> P3 {
    std::array::from_fn(|i| p[i] / d)
}
fn unit3(a: &P3) -> Option<P3> {
    let l = norm3(a);
    (l > 1e-12).then(|| scaled(a, l))
}

/// How a fitted spline meets what comes before or after it: along the unit tangent `t` with
/// the curvature vector `k` (1/mm), the join of a rounded piece (`k` zero) or of the fitted
/// spline before. (An end without one is free: only through the end point, and the next
/// spline continues this one's tangent and curvature.)
#[derive(Clone, Copy, Debug, PartialEq)]
struct EndCondition {
    t: P3,
    k: P3,
}

/// Where a spline that continues the one before begins: that spline's end point (near the
/// first piece's start, within the tolerance of the polyline, not on it), the join there, and
/// the programmed polyline's point before the first piece's start (the polyline near the join
/// runs on both sides of it).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Start {
    at: P3,
    join: EndCondition,
    before: P3,
}

/// A run's programmed polyline: vertices (tool tip) and how its ends join.
struct RunData {
    vertices: Vec<P3>,
    chord: Vec<f64>,
    /// The index in `vertices` of each piece's end.
    piece_ends: Vec<usize>,
    /// Where the spline starts: the first vertex, or the end of the spline it continues.
    origin: P3,
    start: EndCondition,
    /// The polyline point before the first vertex where the spline continues another: that one
    /// has checked the first vertex, and the polyline runs on before it.
    before: Option<P3>,
    /// `None`: a free end.
    end: Option<EndCondition>,
}

impl RunData {
    /// The data up to vertex `last` (the end of a kept part), ending free.
    fn prefix(&self, last: usize) -> RunData {
        RunData {
            vertices: self.vertices[..=last].to_vec(),
            chord: self.chord[..=last].to_vec(),
            piece_ends: self.piece_ends.iter().copied().filter(|&e| e <= last).collect(),
            origin: self.origin,
            start: self.start,
            before: self.before,
            end: None,
        }
    }
}

/// The programmed polyline of rounded pieces: a line's end, a corner spline's vertex (its middle
/// control point) and exit. `start`: the spline before, where the fit continues one (else it
/// starts along the first piece); `free_end`: the fit ends free (a window cut before its end).
fn run_data(pieces: &[PathElement], start: Option<Start>, free_end: bool) -> Option<RunData> {
    let first = &pieces.first()?.curve;
    let last = &pieces.last()?.curve;
    let mut vertices = vec![p3(first.control_point(0))];
    let mut piece_ends = Vec::with_capacity(pieces.len());
    let push = |vertices: &mut Vec<P3>, p: &[f64]| {
        let p = p3(p);
        if vertices.last().is_some_and(|q| norm3(&sub(&p, q)) > 1e-9) {
            vertices.push(p);
        }
    };
    for e in pieces {
        let c = &e.curve;
        if is_corner_spline(c) {
            push(&mut vertices, c.control_point(2));
            push(&mut vertices, c.control_point(4));
        } else {
            push(&mut vertices, c.control_point(c.control_point_count() - 1));
        }
        piece_ends.push(vertices.len() - 1);
    }
    if vertices.len() < 2 {
        return None;
    }
    let mut chord = vec![0.0];
    for w in vertices.windows(2) {
        chord.push(chord[chord.len() - 1] + norm3(&sub(&w[1], &w[0])));
    }
    let n = last.control_point_count();
    let zero = [0.0; MAX_DIM];
    let join = match start {
        Some(s) => s.join,
        None => EndCondition {
            t: unit3(&sub(&p3(first.control_point(1)), &p3(first.control_point(0))))?,
            k: zero,
        },
    };
    let end = if free_end {
        None
    } else {
        Some(EndCondition {
            t: unit3(&sub(&p3(last.control_point(n - 1)), &p3(last.control_point(n - 2))))?,
            k: zero,
        })
    };
    Some(RunData {
        origin: start.map_or(vertices[0], |s| s.at),
        before: start.map(|s| s.before),
        vertices,
        chord,
        piece_ends,
        start: join,
        end,
    })
}

/// Cubic B-spline basis functions at `t` on clamped `knots` of `n` control points: the index of
/// the first of the four that can be non-zero, and their values
/// ([`nurbs_rtcore::basis_functions`] on the span of `t`).
fn basis(knots: &[f64], n: usize, t: f64) -> (usize, [f64; 4]) {
    // The span k (3 <= k < n) with knots[k] <= t < knots[k + 1] (the last one for t = 1).
    let k = knots[4..n].partition_point(|&x| x <= t) + 3;
    let nb = basis_functions(knots, k, 3, t);
    (k - 3, [nb[0], nb[1], nb[2], nb[3]])
}

/// Solves `m x = rhs` for a symmetric positive definite band matrix given by its lower band
/// (`band[i][d]` = m[i][i - d], d < 4), one right-hand side per coordinate; `None` where it is
/// not positive definite.
fn solve_band(mut band: Vec<[f64; 4]>, mut rhs: Vec<P3>) -> Option<Vec<P3>> {
    let n = band.len();
    // Cholesky in place: band[i][d] becomes L[i][i - d].
    for i in 0..n {
        for d in (0..4).rev() {
            if d > i {
                continue;
            }
            let j = i - d;
            let mut s = band[i][d];
            for k in 1..4 {
                // L[i][j - k] L[j][j - k]
                if k > j || d + k >= 4 {
                    continue;
                }
                s -= band[i][d + k] * band[j][k];
            }
            if d == 0 {
                if s.is_nan() || s <= 0.0 {
                    return None;
                }
                band[i][0] = s.sqrt();
            } else {
                band[i][d] = s / band[j][0];
            }
        }
    }
    // L y = rhs, then L^T x = y.
    for i in 0..n {
        let mut s = rhs[i];
        for d in 1..4.min(i + 1) {
            s = axpy(&s, -band[i][d], &rhs[i - d]);
        }
        rhs[i] = scaled(&s, band[i][0]);
    }
    for i in (0..n).rev() {
        let mut s = rhs[i];
        for d in 1..4 {
            if i + d < n {
                s = axpy(&s, -band[i + d][d], &rhs[i + d]);
            }
        }
        rhs[i] = scaled(&s, band[i][0]);
    }
    Some(rhs)
}

/// The spline fitted to a run on the interior knots `main` (sorted, strictly inside (0, 1);
/// knots are in chord length over the run), with the weight of the data per interval, as
/// (knots, control points), or `None` where the least squares have no solution.
fn fit(data: &RunData, main: &[f64], weight: &[f64]) -> Option<(Vec<f64>, Vec<P3>)> {
    let v = &data.vertices;
    let chord = &data.chord;
    let total = chord[chord.len() - 1];
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    // At an end that meets a rounded piece, spans of h/2, h/4 and h/8 inside the end span h:
    // there the spline ends with zero curvature, as the piece does, and bends into the data
    // over that short distance instead of a whole span. (An end that meets another spline, or
    // ends free, keeps the curvature of the data and whole spans: short ones there would follow
    // the noise.)
    let graded = |c: &EndCondition| c.k == [0.0; MAX_DIM];
    let (h0, h1) = (main.first().map_or(1.0, |&k| k), main.last().map_or(1.0, |&k| 1.0 - k));
    let mut interior = main.to_vec();
    if graded(&data.start) {
        interior.extend(END_GRADING.iter().map(|g| g * h0));
    }
    if data.end.as_ref().is_some_and(graded) {
        interior.extend(END_GRADING.iter().map(|g| 1.0 - g * h1));
    }
    interior.sort_by(f64::total_cmp);
    let mut knots = vec![0.0; 4];
    knots.extend(interior);
    knots.extend([1.0; 4]);
    let n = knots.len() - 4;
    // Data: the vertices at their chord-length parameters, with points added along segments
    // longer than half the narrowest span they cross, so that every span has some.
    let narrowest = |a: f64, b: f64| {
        let first = knots.partition_point(|&x| x <= a).saturating_sub(1);
        let last = knots.partition_point(|&x| x < b).min(knots.len() - 1);
        (first..last)
            .map(|j| knots[j + 1] - knots[j])
            .filter(|&w| w > 0.0)
            .fold(1.0f64, f64::min)
    };
    let last = weight.len() - 1;
    let mut points: Vec<(f64, P3, f64)> = Vec::with_capacity(2 * v.len());
    for (i, p) in v.iter().enumerate() {
        if i > 0 {
            let (a, b) = (chord[i - 1] / total, chord[i] / total);
            let inserts = ((b - a) / (0.5 * narrowest(a, b))).ceil() as usize;
            for k in 1..inserts {
                let f = k as f64 / inserts as f64;
                let q = axpy(&v[i - 1], f, &sub(p, &v[i - 1]));
                points.push(((chord[i - 1] + f * (chord[i] - chord[i - 1])) / total, q, weight[i - 1]));
            }
        }
        let w = weight[i.saturating_sub(1).min(last)].max(weight[i.min(last)]);
        points.push((chord[i] / total, *p, w));
    }
    // Fixed control points. A clamped cubic with first interior knots a < b leaves with
    // C'(0) = 3 / a (P1 - P0) and C''(0) = 6 / a ((P2 - P1) / b - (P1 - P0) / a). With
    // P1 = P0 + (C a / 3) t it leaves at the speed C (the chord length per unit parameter)
    // along t, and with P2 = P1 + (C b / 3) t + a b C^2 k / 6 with the curvature vector k and
    // no tangential acceleration. The same at the end, mirrored.
    let mut cps = vec![[0.0; MAX_DIM]; n];
    let mut fixed = vec![false; n];
    cps[0] = data.origin;
    fixed[0] = true;
    let EndCondition { t, k } = data.start;
    let (a, b) = (knots[4], knots[5]);
    cps[1] = axpy(&data.origin, total * a / 3.0, &t);
    cps[2] = axpy(&axpy(&cps[1], total * b / 3.0, &t), a * b * total * total / 6.0, &k);
    fixed[1] = true;
    fixed[2] = true;
    let end = v[v.len() - 1];
    cps[n - 1] = end;
    fixed[n - 1] = true;
    if let Some(EndCondition { t, k }) = data.end {
        let (a, b) = (1.0 - knots[n - 1], 1.0 - knots[n - 2]);
        cps[n - 2] = axpy(&end, -total * a / 3.0, &t);
        cps[n - 3] = axpy(
            &axpy(&cps[n - 2], -total * b / 3.0, &t),
            a * b * total * total / 6.0,
            &k,
        );
        fixed[n - 2] = true;
        fixed[n - 3] = true;
    }
    // Unknowns: the other control points, in order.
    let index: Vec<Option<usize>> = fixed
        .iter()
        .scan(0usize, |next, &f| {
            Some(if f {
                None
            } else {
                *next += 1;
                Some(*next - 1)
            })
        })
        .collect();
    let free = index.iter().flatten().count();
    if free > 0 {
        let mut band = vec![[0.0; 4]; free];
        let mut rhs = vec![[0.0; MAX_DIM]; free];
        // Adds w_j w_k (and w_j times a fixed point's coordinates to the right) for the terms
        // `terms` of one squared residual `sum w P - target`.
        let mut add = |terms: &[(usize, f64)], target: &P3, weight: f64| {
            let mut r = *target;
            for &(c, w) in terms {
                if index[c].is_none() {
                    r = axpy(&r, -w, &cps[c]);
                }
            }
            for &(cj, wj) in terms {
                let Some(j) = index[cj] else { continue };
                rhs[j] = axpy(&rhs[j], weight * wj, &r);
                for &(ck, wk) in terms {
                    if let Some(k) = index[ck] {
                        if k <= j && j - k < 4 {
                            band[j][j - k] += weight * wj * wk;
                        }
                    }
                }
            }
        };
        for (t, p, w) in &points {
            let (first, nb) = basis(&knots, n, *t);
            let terms: [(usize, f64); 4] = std::array::from_fn(|j| (first + j, nb[j]));
            add(&terms, p, *w);
        }
        // Fairness: on the span [U_k, U_k+1] the third derivative is constant, a combination
        // of P_k-3..=P_k (the derivative control points' recursion); its square times the
        // span's width, times `mu` (see FAIR_INTERVALS).
        let mu = points.len() as f64 * (FAIR_INTERVALS / (v.len() - 1) as f64).powi(6);
        for k in 3..n {
            let width = knots[k + 1] - knots[k];
            if width <= 0.0 {
                continue;
            }
            let i = k - 3;
            let q1 = |m: usize| {
                let f = 3.0 / (knots[m + 4] - knots[m + 1]);
                let mut c = [0.0; 4];
                c[m + 1 - i] += f;
                c[m - i] -= f;
                c
            };
            let q2 = |m: usize| {
                let f = 2.0 / (knots[m + 4] - knots[m + 2]);
                let (a, b) = (q1(m), q1(m + 1));
                std::array::from_fn::<f64, 4, _>(|j| f * (b[j] - a[j]))
            };
            let (a, b) = (q2(i), q2(i + 1));
            let terms: [(usize, f64); 4] = std::array::from_fn(|j| (i + j, (b[j] - a[j]) / width));
            add(&terms, &[0.0; MAX_DIM], mu * width);
        }
        let solved = solve_band(band, rhs)?;
        for (c, i) in index.iter().enumerate() {
            if let Some(i) = i {
                cps[c] = solved[*i];
            }
        }
    }
    cps.iter().flatten().all(|x| x.is_finite()).then_some((knots, cps))
}

/// Largest distance between the spline and the programmed polyline of `data`, both ways
/// (spline points to the polyline, programmed vertices to the spline), sampled at least
/// [`CHECK_SAMPLES`] times per data interval and more where the spline bends: between two
/// samples it stays within [`SAMPLE_SAG`] of `budget` of their chord (halved until it does,
/// and that much is added to the result), so that a bump narrower than the sample spacing is
/// seen (a fit across a sharp corner beside a very short piece: 0.027 mm off a polyline with
/// a 0.01 mm tolerance in LinuxCNC's `3D_Chips.ngc` passed eight samples per interval).
fn deviation(data: &RunData, curve: &Nurbs, budget: f64) -> f64 {
    deviations(data, curve, budget).into_iter().fold(0.0, f64::max)
}

/// [`deviation`] per data interval: the worst of its spline samples and of its end vertices.
fn deviations(data: &RunData, curve: &Nurbs, budget: f64) -> Vec<f64> {
    let (v, chord) = (&data.vertices, &data.chord);
    let total = chord[chord.len() - 1];
    let intervals = v.len() - 1;
    let sag = SAMPLE_SAG * budget;
    // The samples through the span cache (a cubic span's Taylor polynomials): a few
    // multiplications each instead of a span search and the basis functions, which were a
    // third of the work before the first record on dense programs.
    let mut cache = SpanCache::new();
    let mut cached = CachedCurve::new(curve.view(), &mut cache);
    let mut at = |t: f64| p3(&cached.point(t.clamp(0.0, 1.0)));
    // The samples in order along the spline, and where each data interval's samples begin.
    let mut samples: Vec<P3> = Vec::with_capacity(CHECK_SAMPLES * intervals + 1);
    let mut first = Vec::with_capacity(intervals + 1);
    // Per interval: what the check adds for the spline between its samples.
    let mut margin = vec![sag; intervals];
    // The spline's breaks: an interval that spans several of its polynomial pieces (a long
    // line among refined knots) is sampled as finely in each as in a whole interval elsewhere,
    // so that a turn packed into a few of them is not stepped over (a 90° corner at the end of
    // a 2.3 mm line in `3D_Chips.ngc`, 0.0125 mm off at a 0.01 mm tolerance, had its middle
    // samples on their chords).
    let knots = curve.knots();
    let mut breaks = Vec::new();
    for i in 0..intervals {
        first.push(samples.len());
        let (u0, u1) = (chord[i] / total, chord[i + 1] / total);
        breaks.clear();
        breaks.push(u0);
        breaks.extend(knots.iter().copied().filter(|&u| u0 < u && u < u1));
        breaks.dedup();
        breaks.push(u1);
        for w in breaks.windows(2) {
            let (mut t0, mut p0) = (w[0], at(w[0]));
            for k in 0..CHECK_SAMPLES {
                let t1 = w[0] + (w[1] - w[0]) * (k + 1) as f64 / CHECK_SAMPLES as f64;
                let p1 = at(t1);
                samples.push(p0);
                let unresolved = halve(&mut at, (t0, p0), (t1, p1), sag, MAX_HALVINGS, &mut samples);
                margin[i] = margin[i].max(unresolved);
                (t0, p0) = (t1, p1);
            }
        }
    }
    first.push(samples.len());
    samples.push(at(1.0));
    let mut worst = vec![0.0f64; intervals];
    // The interval each sample belongs to: the last whose first sample is not after it.
    let mut i = 0;
    for (s, x) in samples.iter().enumerate() {
        while i + 1 < intervals && first[i + 1] <= s {
            i += 1;
        }
        // (Squared distances: the square root of the nearest is the nearest square root.)
        let mut d2 = (i.saturating_sub(WINDOW)..=(i + WINDOW).min(intervals - 1))
            .map(|j| segment_distance_squared(&x[..3], &v[j][..3], &v[j + 1][..3]))
            .fold(f64::INFINITY, f64::min);
        if let Some(b) = data.before.filter(|_| i < WINDOW) {
            d2 = d2.min(segment_distance_squared(&x[..3], &b[..3], &v[0][..3]));
        }
        worst[i] = worst[i].max(d2.sqrt() + margin[i]);
    }
    // Each vertex's nearest chord between the spline's samples within the window: its own
    // intervals first, then another only where the box around that interval's samples (its
    // chords lie inside) is nearer than the nearest chord so far: the same minimum, with a
    // fraction of the distances.
    let boxes: Vec<[[f64; 3]; 2]> = (0..intervals)
        .map(|j| {
            let mut b = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
            for x in &samples[first[j]..=first[j + 1]] {
                for k in 0..3 {
                    b[0][k] = b[0][k].min(x[k]);
                    b[1][k] = b[1][k].max(x[k]);
                }
            }
            b
        })
        .collect();
    // (The first vertex of a spline that continues another is that one's to check.)
    let checked = usize::from(data.before.is_some());
    for (i, p) in v.iter().enumerate().skip(checked) {
        let window = i.saturating_sub(WINDOW)..(i + WINDOW).min(intervals);
        let own = [i.saturating_sub(1), i.min(intervals - 1)];
        let nearest_in = |j: usize, d2: f64| {
            (first[j]..first[j + 1])
                .map(|s| segment_distance_squared(&p[..3], &samples[s][..3], &samples[s + 1][..3]))
                .fold(d2, f64::min)
        };
        let mut d2 = f64::INFINITY;
        for j in window.clone() {
            if own.contains(&j) {
                d2 = nearest_in(j, d2);
            }
        }
        for j in window.filter(|j| !own.contains(j)) {
            let [lo, hi] = &boxes[j];
            let box_d2: f64 = (0..3)
                .map(|k| {
                    let d = (lo[k] - p[k]).max(p[k] - hi[k]).max(0.0);
                    d * d
                })
                .sum();
            // (With a margin far above the rounding of either distance.)
            if box_d2 <= d2 * (1.0 + 1e-9) {
                d2 = nearest_in(j, d2);
            }
        }
        let d = d2.sqrt();
        for j in [i.saturating_sub(1), i.min(intervals - 1)] {
            worst[j] = worst[j].max(d + margin[j]);
        }
    }
    worst
}

/// Pushes the samples strictly between `(a, pa)` and `(b, pb)` (parameter, point) in order:
/// the middle, where it lies farther than `sag` from the chord, with the halves' own. Returns
/// how far a middle lay from its chord where the halvings ran out before it came within `sag`
/// (zero where none did): the check adds that instead of `sag` there.
fn halve(
    at: &mut dyn FnMut(f64) -> P3,
    (a, pa): (f64, P3),
    (b, pb): (f64, P3),
    sag: f64,
    depth: u32,
    out: &mut Vec<P3>,
) -> f64 {
    let m = 0.5 * (a + b);
    let pm = at(m);
    let off = segment_distance(&pm[..3], &pa[..3], &pb[..3]);
    if off <= sag {
        return 0.0;
    }
    if depth == 0 {
        // Within twice the middle's distance for a cubic this finely cut (its bulge between
        // two samples is nearly a parabola's).
        return 2.0 * off;
    }
    let left = halve(at, (a, pa), (m, pm), sag, depth - 1, out);
    out.push(pm);
    left.max(halve(at, (m, pm), (b, pb), sag, depth - 1, out))
}

/// The join at the end of `curve`: unit tangent and curvature vector.
fn join_at_end(curve: &Nurbs) -> Option<EndCondition> {
    let d = curve.view().derivatives(curve.u_max(), 2);
    let (c1, c2) = (p3(&d[1]), p3(&d[2]));
    let t = unit3(&c1)?;
    let normal = axpy(&c2, -dot3(&c2, &t), &t);
    Some(EndCondition {
        t,
        k: scaled(&normal, dot3(&c1, &c1)),
    })
}

/// Inserts `u` (strictly inside) into the clamped cubic B-spline (`knots`, `cps`) until it is a
/// triple knot (Boehm) and returns the part on `[0, u]`, its knots scaled to `[0, 1]`: exactly
/// the same curve, ending at the point the whole one passes at `u`.
fn left_part(knots: &[f64], cps: &[P3], u: f64) -> (Vec<f64>, Vec<P3>) {
    let mut knots = knots.to_vec();
    let mut cps = cps.to_vec();
    while knots.iter().filter(|&&x| x == u).count() < 3 {
        // The span k with knots[k] <= u < knots[k + 1]; the new points k - 2..=k blend their
        // neighbours (weight 0 where u is already a knot: those only shift).
        let k = knots.partition_point(|&x| x <= u) - 1;
        let mut next = Vec::with_capacity(cps.len() + 1);
        for i in 0..=cps.len() {
            next.push(if i + 3 <= k {
                cps[i]
            } else if i > k {
                cps[i - 1]
            } else {
                let a = (u - knots[i]) / (knots[i + 3] - knots[i]);
                std::array::from_fn(|c| a * cps[i][c] + (1.0 - a) * cps[i - 1][c])
            });
        }
        knots.insert(k + 1, u);
        cps = next;
    }
    let r = knots.partition_point(|&x| x <= u) - 1;
    let mut left: Vec<f64> = knots[..=r].iter().map(|x| x / u).collect();
    left.push(1.0);
    // (u / u may round below 1.)
    for x in &mut left[r - 2..] {
        *x = 1.0;
    }
    cps.truncate(r - 2);
    (left, cps)
}

/// A fitted spline: the element, its deviation, the pieces it replaces.
struct Fitted {
    element: PathElement,
    deviation: f64,
    pieces: usize,
}

/// Why a run has no fit: the data interval where the last fit tried was farthest off.
struct NoFit {
    worst_interval: usize,
}

/// The spline of `data` within `budget` of its polyline (knots, control points, curve,
/// deviation). The first fit has uniform spans of [`VERTICES_PER_SPAN`] vertices; each next one
/// halves the spans near the data intervals that are off, down to single intervals, and weighs
/// the data there [`REWEIGHT`] times more against the fairness term (the fairest fit that
/// passes is the one the feed can follow fastest, and a sharp bend of the data costs only its
/// own neighbourhood), for at most [`MAX_REFINEMENTS`] fits.
fn fit_within(data: &RunData, budget: f64, dim: usize) -> Result<(Vec<f64>, Vec<P3>, Nurbs, f64), NoFit> {
    let chord = &data.chord;
    let total = chord[chord.len() - 1];
    let intervals = data.vertices.len() - 1;
    let spans = intervals.div_ceil(VERTICES_PER_SPAN).max(3);
    let mut main: Vec<f64> = (1..spans).map(|k| k as f64 / spans as f64).collect();
    let mut weight = vec![1.0; intervals];
    let mut worst_interval = 0;
    for _ in 0..MAX_REFINEMENTS {
        let Some((knots, cps)) = fit(data, &main, &weight) else {
            break;
        };
        let rows: Vec<Vec<f64>> = cps.iter().map(|p| p[..dim].to_vec()).collect();
        let Ok(curve) = Nurbs::new(3, knots.clone(), &rows, None) else {
            break;
        };
        let off = deviations(data, &curve, budget);
        let d = off.iter().copied().fold(0.0, f64::max);
        if d <= budget {
            return Ok((knots, cps, curve, d));
        }
        worst_interval = (0..intervals).max_by(|&a, &b| off[a].total_cmp(&off[b])).unwrap_or(0);
        // Halve every span that meets an interval off, or one beside it, while it is wider
        // than that interval.
        let mut refined = main.clone();
        let mut bounds = vec![0.0];
        bounds.extend(&main);
        bounds.push(1.0);
        for (i, _) in off.iter().enumerate().filter(|(_, &d)| d > budget) {
            for w in &mut weight[i.saturating_sub(1)..(i + 2).min(intervals)] {
                *w *= REWEIGHT;
            }
            let lo = chord[i.saturating_sub(1)] / total;
            let hi = chord[(i + 2).min(intervals)] / total;
            let width = (chord[i + 1] - chord[i]) / total;
            let first = bounds.partition_point(|&x| x <= lo).saturating_sub(1);
            for j in first..bounds.len() - 1 {
                if bounds[j] >= hi {
                    break;
                }
                if bounds[j + 1] - bounds[j] > width {
                    refined.push(0.5 * (bounds[j] + bounds[j + 1]));
                }
            }
        }
        refined.sort_by(f64::total_cmp);
        refined.dedup();
        main = refined;
    }
    Err(NoFit { worst_interval })
}

fn element(curve: Nurbs, pieces: &[PathElement]) -> PathElement {
    PathElement {
        kind: ElementKind::Nurbs,
        curve,
        feed: pieces[0].feed,
        source_line: pieces.iter().find_map(|p| p.source_line),
    }
}

/// The spline of a run of pieces within `budget` (mm) of their programmed polyline, ending
/// along the last piece; where no fit passes, the piece where the last one tried was
/// farthest off (the caller leaves the pieces around it as rounded and fits the rest).
fn fitted(pieces: &[PathElement], start: Option<Start>, budget: f64) -> Result<Fitted, Option<usize>> {
    let data = run_data(pieces, start, false).ok_or(None)?;
    match fit_within(&data, budget, pieces[0].curve.dim()) {
        Ok((_, _, curve, deviation)) => Ok(Fitted {
            element: element(curve, pieces),
            deviation,
            pieces: pieces.len(),
        }),
        Err(NoFit { worst_interval }) => Err(Some(
            data.piece_ends
                .partition_point(|&e| e <= worst_interval)
                .min(pieces.len() - 1),
        )),
    }
}

/// A window of pieces fitted with a free end and cut at the end of piece `keep - 1` (the rest
/// only shapes the part kept): the part kept, checked on its own against its polyline, and how
/// the next spline starts from it. `None` where the window or the part kept does not pass.
fn fitted_and_cut(pieces: &[PathElement], start: Option<Start>, keep: usize, budget: f64) -> Option<(Fitted, Start)> {
    let data = run_data(pieces, start, true)?;
    let dim = pieces[0].curve.dim();
    let (knots, cps, _, _) = fit_within(&data, budget, dim).ok()?;
    let last = data.piece_ends[keep - 1];
    let u = data.chord[last] / data.chord[data.chord.len() - 1];
    if last < 1 || !(u > 0.0 && u < 1.0) {
        return None;
    }
    let (knots, cps) = left_part(&knots, &cps, u);
    let rows: Vec<Vec<f64>> = cps.iter().map(|p| p[..dim].to_vec()).collect();
    let curve = Nurbs::new(3, knots, &rows, None).ok()?;
    let kept = data.prefix(last);
    let deviation = deviation(&kept, &curve, budget);
    if deviation > budget {
        return None;
    }
    let next = Start {
        at: cps[cps.len() - 1],
        join: join_at_end(&curve)?,
        before: data.vertices[last - 1],
    };
    let fitted = Fitted {
        element: element(curve, &pieces[..keep]),
        deviation,
        pieces: keep,
    };
    Some((fitted, next))
}

/// One part of a run after fitting: a spline, or pieces left as rounded.
enum Part {
    Spline(Box<Fitted>),
    Pieces(Vec<PathElement>),
}

/// Pieces left as rounded on either side of the piece where a fit fails.
const ISOLATION: usize = 2;

/// Fits `pieces`; where no fit passes, leaves the pieces around the one where it failed
/// ([`ISOLATION`] on either side) as rounded and fits the rest before and after in the same
/// way (a sharp spot of the data costs its neighbourhood, not the run). Parts shorter than
/// [`MIN_RUN`] stay as rounded. The first part continues the spline before where `start`
/// says so (a spline is the first part only if it does).
fn fit_or_split(pieces: &[PathElement], start: Option<Start>, budget: f64, parts: &mut Vec<Part>) {
    if pieces.is_empty() {
        return;
    }
    if pieces.len() >= MIN_RUN || start.is_some() {
        match fitted(pieces, start, budget) {
            Ok(f) => {
                parts.push(Part::Spline(Box::new(f)));
                return;
            }
            Err(Some(at)) if pieces.len() >= MIN_RUN => {
                let (lo, hi) = (at.saturating_sub(ISOLATION), (at + ISOLATION + 1).min(pieces.len()));
                fit_or_split(&pieces[..lo], start, budget, parts);
                parts.push(Part::Pieces(pieces[lo..hi].to_vec()));
                fit_or_split(&pieces[hi..], None, budget, parts);
                return;
            }
            Err(_) => {}
        }
    }
    parts.push(Part::Pieces(pieces.to_vec()));
}

/// A straight line from where a spline ends (`start.at`, within the tolerance of the polyline
/// but not on it) to the first of the pieces that follow it where they could not continue it:
/// a corner the planner stops at, a fallback that keeps the path within the tolerance.
fn bridge(start: &Start, pieces: &[PathElement]) -> Option<PathElement> {
    let first = pieces.first()?;
    let b = first.curve.control_point(0);
    if norm3(&sub(&start.at, &p3(b))) <= 1e-12 {
        return None;
    }
    let dim = first.curve.dim();
    let curve = Nurbs::new(
        1,
        vec![0.0, 0.0, 1.0, 1.0],
        &[start.at[..dim].to_vec(), b.to_vec()],
        None,
    )
    .ok()?;
    Some(PathElement {
        kind: ElementKind::Polyline,
        curve,
        feed: first.feed,
        source_line: first.source_line,
    })
}

/// The part kept of a window, held back until the next part shows it continues it.
struct Pending {
    pieces: Vec<PathElement>,
    start: Option<Start>,
    spline: Box<Fitted>,
    /// Where the next part starts if it continues this one.
    next: Start,
}

/// Replaces, as they come, the runs of short rounded pieces of a stream of path elements (the
/// output of [`super::corner::CornerRounder`]) by fitted splines within `tolerance` of the
/// programmed polyline; every other element passes unchanged. What it did is added to the
/// rounding's [`RoundingStats`].
pub struct RunFitter<I> {
    source: I,
    budget: f64,
    tolerance: f64,
    /// Cosine of the corner angle: a corner spline turning more may end the run.
    corner_cos: f64,
    run: Vec<PathElement>,
    /// The part kept of the last window (a run longer than [`MAX_RUN`]).
    pending: Option<Pending>,
    /// Pieces a window keeps: [`FIRST_RUN`], then [`MAX_RUN`].
    cap: usize,
    out: VecDeque<PathElement>,
    error: Option<ReadError>,
    stats: Arc<Mutex<RoundingStats>>,
    done: bool,
}

impl<I: Iterator<Item = Result<PathElement, ReadError>>> RunFitter<I> {
    /// Fits the runs of `source` within `tolerance` (mm, > 0), ended at corners sharper than
    /// `corner_angle` (degrees) between long lines, counting into `stats`.
    pub fn new(source: I, tolerance: f64, corner_angle: f64, stats: Arc<Mutex<RoundingStats>>) -> Self {
        RunFitter {
            source,
            budget: FIT_SHARE * tolerance,
            tolerance,
            corner_cos: corner_angle.to_radians().cos(),
            run: Vec::new(),
            pending: None,
            cap: FIRST_RUN,
            out: VecDeque::new(),
            error: None,
            stats,
            done: false,
        }
    }

    /// Hands out a part.
    fn emit(&mut self, part: Part) {
        match part {
            Part::Spline(f) => {
                if let Ok(mut stats) = self.stats.lock() {
                    stats.fitted_runs += 1;
                    stats.fitted_pieces += f.pieces;
                    stats.max_deviation = stats.max_deviation.max(f.deviation);
                }
                self.out.push_back(f.element);
            }
            Part::Pieces(pieces) => self.out.extend(pieces),
        }
    }

    /// Hands out the pending part, then `parts`: the pending spline as kept where the first of
    /// `parts` is a spline that continues it, else fitted again to end along its last piece.
    fn settle(&mut self, parts: Vec<Part>, continues: bool) {
        if let Some(p) = self.pending.take() {
            if continues && matches!(parts.first(), Some(Part::Spline(_))) {
                self.emit(Part::Spline(p.spline));
            } else {
                let mut again = Vec::new();
                fit_or_split(&p.pieces, p.start, self.budget, &mut again);
                if let Some(s) = p.start.filter(|_| !matches!(again.first(), Some(Part::Spline(_)))) {
                    // The spline before is out already.
                    again.insert(0, Part::Pieces(bridge(&s, &p.pieces).into_iter().collect()));
                }
                for part in again {
                    self.emit(part);
                }
            }
        }
        for part in parts {
            self.emit(part);
        }
    }

    /// The run holds a window ([`OVERLAP`] pieces past the cap): keeps its fit up to the cap,
    /// or, where it does not pass, fits those pieces on their own.
    fn cut(&mut self) {
        let keep = self.cap;
        self.cap = MAX_RUN;
        let carry = self.pending.as_ref().map(|p| p.next);
        match fitted_and_cut(&self.run, carry, keep, self.budget) {
            Some((spline, next)) => {
                // The kept part continues the pending one: that one goes out as kept.
                if let Some(p) = self.pending.take() {
                    self.emit(Part::Spline(p.spline));
                }
                let spline = Box::new(spline);
                self.pending = Some(Pending {
                    pieces: self.run[..keep].to_vec(),
                    start: carry,
                    spline,
                    next,
                });
            }
            None => {
                let mut parts = Vec::new();
                fit_or_split(&self.run[..keep], carry, self.budget, &mut parts);
                self.settle(parts, carry.is_some());
            }
        }
        self.run.drain(..keep);
    }

    /// Whether the run's last piece is a corner sharper than the corner angle between lines
    /// long enough for it to be a programmed corner ([`CORNER_DEPTH`]), `e` coming next. The
    /// lines' lengths are taken as far as the pieces beside the corner show them.
    fn ends_at_a_corner(&self, e: &PathElement) -> bool {
        let Some((leg, turn)) = self.run.last().and_then(corner_of) else {
            return false;
        };
        if turn.cos() >= self.corner_cos {
            return false;
        }
        let before = leg + line_part(self.run.iter().rev().skip(1));
        let after = leg + line_part(std::iter::once(e));
        before.min(after) * turn / 8.0 > CORNER_DEPTH * self.tolerance
    }

    /// The run ends: fits what is left of it.
    fn finish(&mut self) {
        let carry = self.pending.as_ref().map(|p| p.next);
        let mut parts = Vec::new();
        if !self.run.is_empty() {
            fit_or_split(&self.run, carry, self.budget, &mut parts);
        }
        self.run.clear();
        self.cap = MAX_RUN;
        self.settle(parts, carry.is_some());
    }
}

/// How far a corner spline's legs reach along its lines, and its turn (radians); `None` for
/// anything else.
fn corner_of(e: &PathElement) -> Option<(f64, f64)> {
    let c = &e.curve;
    if !is_corner_spline(c) {
        return None;
    }
    let (p0, p2, p4) = (p3(c.control_point(0)), p3(c.control_point(2)), p3(c.control_point(4)));
    let (u1, u2) = (sub(&p2, &p0), sub(&p4, &p2));
    let leg = norm3(&u1);
    let cos = dot3(&u1, &u2) / (leg * norm3(&u2));
    Some((leg, cos.clamp(-1.0, 1.0).acos()))
}

/// How much of a line the pieces `near` show, going away from a corner (nearest first): a
/// straight piece all of it and the leg of a corner spline beyond it, a corner spline its leg.
fn line_part<'a>(mut near: impl Iterator<Item = &'a PathElement>) -> f64 {
    let Some(e) = near.next() else {
        return 0.0;
    };
    match corner_of(e) {
        Some((leg, _)) => leg,
        None => {
            let c = &e.curve;
            let straight = norm3(&sub(&p3(c.control_point(1)), &p3(c.control_point(0))));
            straight + near.next().and_then(corner_of).map_or(0.0, |(leg, _)| leg)
        }
    }
}

/// Whether `e` may join a run whose pieces have the programmed feed `feed`: a tool-tip straight
/// piece or corner spline, short.
fn joins_run(e: &PathElement, feed: Option<Option<f64>>) -> bool {
    let c = &e.curve;
    let tip_only = c.dim() == c.tip_dim();
    let kind = (c.degree() == 1 && c.control_point_count() == 2) || is_corner_spline(c);
    let polygon: f64 = (1..c.control_point_count())
        .map(|k| norm3(&sub(&p3(c.control_point(k)), &p3(c.control_point(k - 1)))))
        .sum();
    tip_only && kind && polygon <= SHORT_PIECE && polygon > 0.0 && feed.is_none_or(|f| f == e.feed)
}

impl<I: Iterator<Item = Result<PathElement, ReadError>>> Iterator for RunFitter<I> {
    type Item = Result<PathElement, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(e) = self.out.pop_front() {
                return Some(Ok(e));
            }
            if let Some(e) = self.error.take() {
                return Some(Err(e));
            }
            if self.done {
                return None;
            }
            match self.source.next() {
                Some(Ok(e)) => {
                    let feed = self.run.first().map(|p| p.feed);
                    // The rounder's pieces join end to start.
                    let continues = self.run.last().is_none_or(|p| {
                        let c = &p.curve;
                        let end = p3(c.control_point(c.control_point_count() - 1));
                        norm3(&sub(&p3(e.curve.control_point(0)), &end)) <= 1e-9
                    });
                    if continues && self.ends_at_a_corner(&e) {
                        // The corner goes out rounded, between the runs it ends and begins.
                        let corner = self.run.pop();
                        self.finish();
                        self.out.extend(corner);
                        if joins_run(&e, None) {
                            self.run.push(e);
                        } else {
                            self.out.push_back(e);
                        }
                        continue;
                    }
                    if joins_run(&e, feed) && continues {
                        self.run.push(e);
                        if self.run.len() >= self.cap + OVERLAP {
                            self.cut();
                        }
                        continue;
                    }
                    self.finish();
                    if joins_run(&e, None) {
                        self.run.push(e);
                    } else {
                        self.out.push_back(e);
                    }
                }
                Some(Err(e)) => {
                    self.finish();
                    self.error = Some(e);
                    self.done = true;
                }
                None => {
                    self.finish();
                    self.done = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::corner::CornerRounder;

    const TOL: f64 = 0.001;

    /// G1 lines of `step` mm along `f` (arc-length-ish parameter in mm), coordinates rounded to
    /// 1e-4 mm as CAM output is.
    fn g1(points: usize, step: f64, f: impl Fn(f64) -> [f64; 2]) -> Vec<PathElement> {
        let q = |x: f64| (x * 1e4).round() / 1e4;
        let v: Vec<Vec<f64>> = (0..=points)
            .map(|k| {
                let p = f(k as f64 * step);
                vec![q(p[0]), q(p[1])]
            })
            .collect();
        lines_through(&v)
    }

    /// G1 lines through the vertices `v`, one element each.
    fn lines_through(v: &[Vec<f64>]) -> Vec<PathElement> {
        v.windows(2)
            .map(|w| PathElement {
                kind: ElementKind::Polyline,
                curve: Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], w, None).unwrap(),
                feed: Some(100.0),
                source_line: None,
            })
            .collect()
    }

    fn smooth(program: &[PathElement]) -> (Vec<PathElement>, RoundingStats) {
        smooth_within(program, TOL)
    }

    fn smooth_within(program: &[PathElement], tol: f64) -> (Vec<PathElement>, RoundingStats) {
        let rounder = CornerRounder::new("t", program.iter().cloned().map(Ok), tol, false).unwrap();
        let stats = rounder.stats();
        let out: Vec<PathElement> = RunFitter::new(rounder, tol, CORNER_ANGLE, Arc::clone(&stats))
            .collect::<Result<_, _>>()
            .unwrap();
        let stats = *stats.lock().unwrap();
        (out, stats)
    }

    fn point(e: &PathElement, u: f64) -> P3 {
        p3(&e.curve.point(u))
    }

    /// Unit tangent and curvature vector of `e` at `u`.
    fn frame(e: &PathElement, u: f64) -> (P3, P3) {
        let d = e.curve.view().derivatives(u, 2);
        let (c1, c2) = (p3(&d[1]), p3(&d[2]));
        let t = unit3(&c1).unwrap();
        let s2 = dot3(&c1, &c1);
        let n = axpy(&c2, -dot3(&c2, &t), &t);
        (t, scaled(&n, s2))
    }

    /// Checks, independently of the fitter's own check, that the path `out` and the programmed
    /// polyline are within the tolerance of each other both ways (every segment searched), and
    /// that consecutive elements join in position, tangent and curvature. Returns the largest
    /// curvature of each element (zero for those not fitted).
    fn check(program: &[PathElement], out: &[PathElement]) -> Vec<f64> {
        check_within(program, out, TOL)
    }

    fn check_within(program: &[PathElement], out: &[PathElement], tol: f64) -> Vec<f64> {
        let verts: Vec<P3> = std::iter::once(p3(program[0].curve.control_point(0)))
            .chain(program.iter().map(|e| p3(e.curve.control_point(1))))
            .collect();
        let mut path: Vec<P3> = Vec::new();
        let mut kmax = Vec::with_capacity(out.len());
        for e in out {
            kmax.push(0.0);
            let fitted = e.curve.control_point_count() > 5;
            // Samples 5 µm apart or closer: the chords between them stay within 0.1 µm of the
            // path where it bends at a radius of 3 mm.
            let c = &e.curve;
            let polygon: f64 = (1..c.control_point_count())
                .map(|k| norm3(&sub(&p3(c.control_point(k)), &p3(c.control_point(k - 1)))))
                .sum();
            let n = ((polygon / 0.005).ceil() as usize).max(400);
            for k in 0..=n {
                let u = e.curve.u_min() + (e.curve.u_max() - e.curve.u_min()) * k as f64 / n as f64;
                path.push(point(e, u));
                if fitted {
                    *kmax.last_mut().unwrap() = norm3(&frame(e, u).1).max(kmax[kmax.len() - 1]);
                }
            }
        }
        for x in &path {
            let d = verts
                .windows(2)
                .map(|w| segment_distance(&x[..3], &w[0][..3], &w[1][..3]))
                .fold(f64::INFINITY, f64::min);
            assert!(d <= tol, "path point {x:?} {d} mm from the program");
        }
        // Programmed vertices to the path: where the polyline turns by less than 30 degrees (the
        // rounding of a sharper corner keeps its path within the tolerance of the polyline, but
        // cuts the vertex itself by more).
        let turns = |i: usize| {
            let (a, b) = (sub(&verts[i], &verts[i - 1]), sub(&verts[i + 1], &verts[i]));
            dot3(&a, &b) < (30f64).to_radians().cos() * norm3(&a) * norm3(&b)
        };
        for (i, v) in verts.iter().enumerate() {
            if i > 0 && i + 1 < verts.len() && turns(i) {
                continue;
            }
            let d = path
                .windows(2)
                .map(|w| segment_distance(&v[..3], &w[0][..3], &w[1][..3]))
                .fold(f64::INFINITY, f64::min);
            assert!(d <= tol, "programmed vertex {v:?} {d} mm from the path");
        }
        for w in out.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            let gap = norm3(&sub(&point(a, a.curve.u_max()), &point(b, b.curve.u_min())));
            assert!(gap <= 1e-9, "gap {gap}");
            let (ta, ka) = frame(a, a.curve.u_max());
            let (tb, kb) = frame(b, b.curve.u_min());
            assert!(
                norm3(&sub(&ta, &tb)) <= 1e-9,
                "tangent turns by {}",
                norm3(&sub(&ta, &tb))
            );
            let dk = norm3(&sub(&ka, &kb));
            assert!(
                dk <= 1e-6 * (1.0 + norm3(&ka)),
                "curvature jumps by {dk} ({ka:?} to {kb:?})"
            );
        }
        kmax
    }

    /// A dense circle of 5 mm radius (4,000 lines, more than one run of pieces): a few splines, within
    /// the tolerance both ways, continuous in tangent and curvature at every join (the runs cut
    /// at `FIRST_RUN` and `MAX_RUN` continue each other), and their curvature near the circle's,
    /// not that of the quantised corners (up to 20 times it).
    #[test]
    fn a_dense_circle_becomes_a_few_splines_with_its_curvature() {
        let r = 5.0;
        let program = g1(4000, 0.02, |s| [r * (s / r).sin(), r * (1.0 - (s / r).cos())]);
        let rounded = CornerRounder::new("t", program.iter().cloned().map(Ok), TOL, false)
            .unwrap()
            .count();
        let (out, stats) = smooth(&program);
        // Every piece fitted: windows keep FIRST_RUN, then MAX_RUN pieces each while OVERLAP
        // more follow, and the rest is one spline.
        assert_eq!(stats.fitted_pieces, rounded, "{stats:?}");
        let (mut left, mut keep, mut splines) = (rounded, FIRST_RUN, 1);
        while left >= keep + OVERLAP {
            (left, keep, splines) = (left - keep, MAX_RUN, splines + 1);
        }
        assert_eq!(stats.fitted_runs, splines, "{stats:?}");
        assert_eq!(out.len(), stats.fitted_runs);
        let kmax = check(&program, &out);
        // Between the splines of the run (where one window's kept part meets the next) the
        // curvature stays the circle's to 2 %. The run's ends meet straight pieces (zero
        // curvature) and bend in from there, up to 1.8 times the circle's here.
        let inner = kmax[1..kmax.len() - 1].iter().fold(0.0f64, |a, &b| a.max(b));
        assert!(
            inner <= 1.02 / r,
            "curvature up to {inner} on a circle of 1/r = {}",
            1.0 / r
        );
        let ends = kmax[0].max(kmax[kmax.len() - 1]);
        assert!(ends <= 2.0 / r, "curvature up to {ends} at the ends");
    }

    /// A slope of short lines that turns sharply (63 degrees) into a 0.007 mm piece and then a
    /// long flat line (LinuxCNC's `3D_Chips.ngc`, lines 1943-1953, scaled to a tenth with the
    /// tolerance): a fit across the corner bulged 0.027 mm (tolerance 0.01) between the eight
    /// check samples of a data interval, and was taken. Now the path stays within the tolerance.
    #[test]
    fn a_sharp_corner_beside_a_tiny_piece_stays_within_the_tolerance() {
        let yz = [
            (23.991, -26.078),
            (24.491, -26.799),
            (24.741, -27.238),
            (24.991, -27.707),
            (25.491, -28.633),
            (25.741, -29.118),
            (25.866, -29.45),
            (26.226, -30.499),
            (26.233, -30.5),
            (29.991, -30.5),
            (52.999, -30.5),
        ];
        let v: Vec<Vec<f64>> = yz.iter().map(|&(y, z)| vec![1.3, 0.1 * y, 0.1 * z]).collect();
        let program = lines_through(&v);
        let (out, _) = smooth(&program);
        check(&program, &out);
    }

    /// A long line, short lines along a flat bottom that turn by 90 degrees into a 2.3 mm line
    /// up a wall, and on along a slope (LinuxCNC's `3D_Chips.ngc`, lines 1026-1146, at its
    /// 0.01 mm tolerance): the spline turned within a few of its knot spans at the start of the
    /// long interval, and the check's samples there, spread over the interval, lay on their
    /// chords; 0.0125 mm off was taken. Sampled per knot span, it is not.
    #[test]
    fn a_turn_into_a_long_line_is_checked_where_the_spline_turns() {
        let v: Vec<Vec<f64>> = include_str!("testdata/chips-row.txt")
            .lines()
            .skip(1)
            .map(|l| {
                let yz: Vec<f64> = l.split(' ').map(|x| x.parse().unwrap()).collect();
                vec![35.5, yz[0], yz[1]]
            })
            .collect();
        let program = lines_through(&v);
        let (out, stats) = smooth_within(&program, 0.01);
        assert!(stats.fitted_runs >= 1, "{stats:?}");
        check_within(&program, &out, 0.01);
    }

    /// A programmed corner ends a run: dense lines of 0.05 mm turn by 90 degrees (an arc
    /// through the vertices would leave the lines by 10 µm, ten tolerances) into more
    /// of them. Two fitted runs with the corner rounded between them; with the corner angle
    /// above the turn, fitted across it. A zigzag of 2 mm lines turning by 53 degrees is
    /// left rounded (not fitted at all).
    #[test]
    fn a_programmed_corner_ends_a_run() {
        let mut program = g1(120, 0.05, |s| [s, 0.0005 * (s * 2.0).sin()]);
        let end = p3(program.last().unwrap().curve.control_point(1));
        program.extend(g1(120, 0.05, |s| [end[0] + 0.0005 * (s * 2.0).sin(), end[1] + s]));
        let fit = |angle: f64| {
            let rounder = CornerRounder::new("t", program.iter().cloned().map(Ok), TOL, false).unwrap();
            let stats = rounder.stats();
            let out: Vec<PathElement> = RunFitter::new(rounder, TOL, angle, Arc::clone(&stats))
                .collect::<Result<_, _>>()
                .unwrap();
            let stats = *stats.lock().unwrap();
            (out, stats)
        };
        let (out, stats) = fit(CORNER_ANGLE);
        assert_eq!(stats.fitted_runs, 2, "{stats:?}");
        assert_eq!(out.len(), 3);
        assert!(is_corner_spline(&out[1].curve));
        check(&program, &out);
        let (out, stats) = fit(100.0);
        assert!(out.iter().all(|e| e.curve.control_point_count() > 5), "{stats:?}");
        check(&program, &out);

        let zigzag = g1(40, 2.0, |s| [s, (s / 2.0).round() % 2.0]);
        let (out, stats) = smooth(&zigzag);
        assert_eq!(stats.fitted_runs, 0, "{stats:?}");
        assert_eq!(out.len(), 2 * zigzag.len() - 1);
        check(&zigzag, &out);
    }

    /// Dense lines with a sharp corner (107 degrees), then a long line: the path stays within
    /// the tolerance both ways and joined in tangent and curvature, the corner inside a fit or
    /// left rounded, the long line as it was.
    #[test]
    fn a_sharp_corner_and_a_long_line_stay_within_the_tolerance() {
        let mut program = g1(300, 0.02, |s| [s, 0.001 * (s * 3.0).sin()]);
        let end = p3(program.last().unwrap().curve.control_point(1));
        let turn = g1(300, 0.02, |s| [end[0] - 0.3 * s + 0.002 * (s * 2.0).sin(), end[1] + s]);
        program.extend(turn);
        let end = p3(program.last().unwrap().curve.control_point(1));
        program.push(PathElement {
            kind: ElementKind::Polyline,
            curve: Nurbs::new(
                1,
                vec![0.0, 0.0, 1.0, 1.0],
                &[end[..2].to_vec(), vec![end[0] + 10.0, end[1]]],
                None,
            )
            .unwrap(),
            feed: Some(100.0),
            source_line: None,
        });
        let (out, stats) = smooth(&program);
        assert!(stats.fitted_runs >= 2, "{stats:?}");
        check(&program, &out);
        // The long line passes as it was rounded.
        assert!(out.last().unwrap().curve.degree() == 1);
    }

    /// Elements that are not short rounded pieces pass unchanged, and a run shorter than
    /// `MIN_RUN` stays as rounded.
    #[test]
    fn other_elements_and_short_runs_pass_unchanged() {
        let program = g1(3, 0.02, |s| [s, 0.01 * s * s]);
        let rounder = CornerRounder::new("t", program.iter().cloned().map(Ok), TOL, false).unwrap();
        let rounded: Vec<PathElement> = rounder.map(Result::unwrap).collect();
        let (out, stats) = smooth(&program);
        assert_eq!(out, rounded);
        assert_eq!(stats.fitted_runs, 0);
    }

    /// The part of a spline cut by knot insertion is the same curve: its points at t / u equal
    /// the whole one's at t, its end the whole one's at u.
    #[test]
    fn the_left_part_is_the_same_curve() {
        let knots = vec![0.0, 0.0, 0.0, 0.0, 0.2, 0.35, 0.5, 0.8, 1.0, 1.0, 1.0, 1.0];
        let cps: Vec<P3> = (0..8)
            .map(|i| p3(&[i as f64, (i as f64 * 1.3).sin(), 0.1 * (i * i) as f64]))
            .collect();
        let curve = |k: &[f64], c: &[P3]| {
            let rows: Vec<Vec<f64>> = c.iter().map(|p| p[..3].to_vec()).collect();
            Nurbs::new(3, k.to_vec(), &rows, None).unwrap()
        };
        let whole = curve(&knots, &cps);
        // Inside a span, and on a knot already there.
        for u in [0.43, 0.5] {
            let (k, c) = left_part(&knots, &cps, u);
            let left = curve(&k, &c);
            assert!(norm3(&sub(&c[c.len() - 1], &p3(&whole.point(u)))) < 1e-12);
            for i in 0..=50 {
                let t = u * i as f64 / 50.0;
                let d = norm3(&sub(&p3(&left.point(t / u)), &p3(&whole.point(t))));
                assert!(d < 1e-12, "at {t}: {d}");
            }
        }
    }

    /// The band solver agrees with a dense solve.
    #[test]
    fn band_cholesky_solves() {
        let n = 9;
        let mut band = vec![[0.0; 4]; n];
        let mut dense = vec![vec![0.0; n]; n];
        for i in 0..n {
            for d in 0..4.min(i + 1) {
                let v = if d == 0 {
                    10.0 + i as f64
                } else {
                    1.0 / (1.0 + d as f64 + i as f64)
                };
                band[i][d] = v;
                dense[i][i - d] = v;
                dense[i - d][i] = v;
            }
        }
        let x: Vec<P3> = (0..n).map(|i| p3(&[i as f64, 1.0, -(i as f64) * 0.5])).collect();
        let rhs: Vec<P3> = (0..n)
            .map(|i| std::array::from_fn(|c| (0..n).map(|j| dense[i][j] * x[j][c]).sum()))
            .collect();
        let got = solve_band(band, rhs).unwrap();
        for (a, b) in got.iter().zip(&x) {
            assert!(norm3(&sub(a, b)) < 1e-12, "{a:?} {b:?}");
        }
    }
}
