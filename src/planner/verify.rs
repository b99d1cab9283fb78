//! The project's own checker of a setpoint file (`nurbs-plan verify`): axial limits by finite
//! differences (at rest before the first and after the last row), feed (the limit and every
//! element's programmed feed), distance of every row to the curve, chord error between
//! consecutive rows, start and end points.

use super::axial::{AxialPeaks, FiniteDifferences};
use super::{Limits, PathCurves};
use nurbs_rtcore::math::{norm, sub};

/// One setpoint row: element index, curve parameter, position.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub t: f64,
    pub curve: usize,
    pub u: f64,
    pub q: Vec<f64>,
}

/// What the check measured, and the violations found (empty when the file passes).
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub peaks: AxialPeaks,
    pub max_feed: f64,
    pub max_chord_error: f64,
    pub max_distance_to_curve: f64,
    /// Largest ratio of a step's feed to the programmed feed of its elements (0 when no element
    /// has one).
    pub max_programmed_feed_ratio: f64,
    pub violations: Vec<String>,
    pub rows: usize,
}

/// Relative slack allowed over a limit, for rounding only.
pub const SLACK: f64 = 1e-6;

pub fn verify(curves: &mut PathCurves, limits: &Limits, rows: &[Row]) -> Report {
    let mut v = Verifier::new(curves, limits);
    for r in rows {
        v.push(r);
    }
    v.finish()
}

/// [`verify`] a row at a time, in constant memory (a setpoint file of any length, a path read
/// as the rows reach it and forgotten behind them).
pub struct Verifier<'a> {
    curves: &'a mut PathCurves,
    limits: &'a Limits,
    tip: usize,
    fd: FiniteDifferences,
    report: Report,
    /// The first and the previous row.
    first: Option<Row>,
    prev: Option<Row>,
    /// Violations found row by row, in order; the first row on an element that does not exist
    /// ends the row checks.
    row_violations: Vec<String>,
    missing: Option<String>,
    /// The first row is not the start of the path.
    bad_start: bool,
}

impl<'a> Verifier<'a> {
    pub fn new(curves: &'a mut PathCurves, limits: &'a Limits) -> Self {
        let tip = limits.velocity.len();
        Verifier {
            curves,
            limits,
            tip,
            fd: FiniteDifferences::new(tip, limits.period),
            report: Report::default(),
            first: None,
            prev: None,
            row_violations: Vec::new(),
            missing: None,
            bad_start: false,
        }
    }

    pub fn push(&mut self, r: &Row) {
        use nurbs_rtcore::interpolator::CurveSet;
        let (limits, tip) = (self.limits, self.tip);
        self.report.rows += 1;
        self.fd.push(&r.q, limits);
        if self.missing.is_some() {
            self.prev = Some(r.clone());
            return;
        }
        if self.first.is_none() {
            self.first = Some(r.clone());
            self.curves.load(0);
            let start = self.curves.curve(0).map(|c| c.point(c.u_min()));
            self.bad_start = end_gap(r, start, tip) > 1e-9;
        }
        // The path as far as this row, and nothing before the previous row's element.
        let behind = self.prev.as_ref().map_or(0, |a| a.curve.min(r.curve));
        self.curves.release_before(behind);
        self.curves.load(r.curve.max(behind));
        let Some(p) = self.curves.curve(r.curve).map(|c| c.point(r.u)) else {
            self.missing = Some(format!("t={}: element {} does not exist", r.t, r.curve));
            self.prev = Some(r.clone());
            return;
        };
        let report = &mut self.report;
        let mut q = [0.0; nurbs_rtcore::MAX_DIM];
        q[..tip].copy_from_slice(&r.q[..tip]);
        let d = norm(&sub(&p, &q), tip);
        report.max_distance_to_curve = report.max_distance_to_curve.max(d);
        if let Some(a) = &self.prev {
            let mut qa = [0.0; nurbs_rtcore::MAX_DIM];
            qa[..tip].copy_from_slice(&a.q[..tip]);
            let step = norm(&sub(&q, &qa), tip);
            report.max_feed = report.max_feed.max(step / limits.period);
            if let Some(programmed) = programmed_feed(self.curves, a.curve, r.curve) {
                let ratio = step / limits.period / programmed;
                if ratio > 1.0 + SLACK && report.max_programmed_feed_ratio <= 1.0 + SLACK {
                    // The first overrun: where it starts.
                    self.row_violations.push(format!(
                        "t={}: feed {:.6} exceeds the programmed feed {programmed} of element {}",
                        r.t,
                        step / limits.period,
                        r.curve
                    ));
                }
                report.max_programmed_feed_ratio = report.max_programmed_feed_ratio.max(ratio);
            }
            if a.curve == r.curve && r.u > a.u {
                if let Some(view) = self.curves.curve(r.curve) {
                    report.max_chord_error = report.max_chord_error.max(chord_error(&view, tip, a.u, r.u, &qa, &q));
                }
            }
        }
        self.prev = Some(r.clone());
    }

    pub fn finish(mut self) -> Report {
        use nurbs_rtcore::interpolator::CurveSet;
        let (limits, tip) = (self.limits, self.tip);
        let mut report = std::mem::take(&mut self.report);
        let (Some(_), Some(last_row)) = (self.first.take(), self.prev.take()) else {
            report.violations.push("no setpoints".into());
            return report;
        };
        let mut fd = self.fd;
        fd.finish(limits);
        report.peaks = fd.peaks;
        for i in 0..tip {
            for (name, peak, limit) in [
                ("velocity", fd.peaks.vel[i], limits.velocity[i]),
                ("acceleration", fd.peaks.acc[i], limits.acceleration[i]),
                ("jerk", fd.peaks.jerk[i], limits.jerk[i]),
            ] {
                if peak > limit * (1.0 + SLACK) {
                    report
                        .violations
                        .push(format!("axis {i}: {name} {peak:.6} exceeds limit {limit}"));
                }
            }
        }
        report.violations.append(&mut self.row_violations);
        if let Some(missing) = self.missing {
            report.violations.push(missing);
            return report;
        }
        if report.max_feed > limits.feed * (1.0 + SLACK) {
            report
                .violations
                .push(format!("feed {:.6} exceeds {}", report.max_feed, limits.feed));
        }
        if report.max_chord_error > limits.chord_tolerance * (1.0 + SLACK) {
            report.violations.push(format!(
                "chord error {:.3e} exceeds {}",
                report.max_chord_error, limits.chord_tolerance
            ));
        }
        if report.max_distance_to_curve > 1e-6 {
            report.violations.push(format!(
                "a setpoint is {:.3e} mm off the curve",
                report.max_distance_to_curve
            ));
        }
        let curves = self.curves;
        curves.load_to_end();
        let last = curves.curve(curves.len().saturating_sub(1)).map(|c| c.point(c.u_max()));
        if self.bad_start {
            report
                .violations
                .push("the first setpoint is not the start of the path".into());
        }
        if end_gap(&last_row, last, tip) > 1e-9 {
            report
                .violations
                .push("the last setpoint is not the end of the path".into());
        }
        report
    }
}

/// Distance of a row to a path point (infinite when there is none).
fn end_gap(row: &Row, p: Option<nurbs_rtcore::Vector>, tip: usize) -> f64 {
    let mut q = [0.0; nurbs_rtcore::MAX_DIM];
    q[..tip].copy_from_slice(&row.q[..tip]);
    p.map_or(f64::INFINITY, |p| norm(&sub(&p, &q), tip))
}

/// The feed a step from element `from` to element `to` may not exceed: the highest programmed
/// feed of the elements it touches (each part of the step runs at most at its own element's
/// feed, so the chord does not exceed the highest); `None` when one of them has no programmed
/// feed (only the feed limit applies).
fn programmed_feed(curves: &PathCurves, from: usize, to: usize) -> Option<f64> {
    (from.min(to)..=from.max(to))
        .map(|e| curves.programmed_feed(e))
        .try_fold(0.0f64, |m, f| f.map(|f| m.max(f)))
}

/// Distance from `p` to the segment from `a` to `b` (first `tip` coordinates).
pub fn distance_to_chord(
    p: &nurbs_rtcore::Vector,
    a: &nurbs_rtcore::Vector,
    b: &nurbs_rtcore::Vector,
    tip: usize,
) -> f64 {
    let ab = sub(b, a);
    let ap = sub(p, a);
    let len2 = nurbs_rtcore::math::dot(&ab, &ab, tip);
    let t = if len2 > 0.0 {
        (nurbs_rtcore::math::dot(&ap, &ab, tip) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut e = 0.0;
    for i in 0..tip {
        let d = ap[i] - t * ab[i];
        e += d * d;
    }
    e.sqrt()
}

/// Largest distance between the curve on `(u0, u1)` and the chord from `a` to `b`.
pub fn chord_error(
    view: &nurbs_rtcore::CurveView,
    tip: usize,
    u0: f64,
    u1: f64,
    a: &nurbs_rtcore::Vector,
    b: &nurbs_rtcore::Vector,
) -> f64 {
    let dist = |u: f64| distance_to_chord(&view.point(u), a, b, tip);
    const N: usize = 8;
    let mut best = (0.0, u0);
    for k in 1..N {
        let u = u0 + (u1 - u0) * k as f64 / N as f64;
        let d = dist(u);
        if d > best.0 {
            best = (d, u);
        }
    }
    let h = (u1 - u0) / N as f64;
    let (_, refined) = crate::geometry::golden_max(&dist, (best.1 - h).max(u0), (best.1 + h).min(u1));
    best.0.max(refined)
}
