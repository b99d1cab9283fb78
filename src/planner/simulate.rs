//! Running segment records through the realtime interpolator, as the servo thread will.

use super::axial::FiniteDifferences;
use super::{Limits, PathCurves};
use crate::geometry::{ArcLengthTable, Nurbs, Toolpath};
use nurbs_rtcore::interpolator::{Interpolator, Sample, Step};
use nurbs_rtcore::step_methods::{fcp_eval, sot_step, tot_step, PathCursor};
use nurbs_rtcore::SegmentRecord;
use nurbs_rtcore::{CachedCurve, SpanCache};

/// Interpolator and finite-difference state between two segments: the planner's checkpoint.
#[derive(Clone, Copy, Debug)]
pub struct SimState {
    pub interp: Interpolator,
    pub check: FiniteDifferences,
    pub samples: usize,
    /// The last sample produced (chord checks span segment boundaries).
    pub last_sample: Option<Sample>,
}

impl SimState {
    pub fn start(axes: usize, period: f64) -> Self {
        SimState {
            interp: Interpolator::new(),
            check: FiniteDifferences::new(axes, period),
            samples: 0,
            last_sample: None,
        }
    }
}

/// Runs `record` from `state` until the interpolator needs the next record (or the path ends),
/// feeding every sample to the finite-difference check and to `sink`. Returns `false` if the
/// interpolator rejected the record.
pub fn run_segment(
    curves: &PathCurves,
    limits: &Limits,
    state: &mut SimState,
    record: SegmentRecord,
    sink: &mut dyn FnMut(&Sample),
) -> bool {
    let mut pending = Some(record);
    let tip = limits.velocity.len();
    loop {
        match state.interp.step(curves, limits.period, &mut || pending.take()) {
            Step::Sample(s) => {
                state.check.push(&s.point[..tip], limits);
                state.samples += 1;
                sink(&s);
            }
            Step::Starved => return true,
            Step::Finished => {
                state.check.finish(limits);
                return true;
            }
            Step::BadRecord => return false,
        }
    }
}

/// All setpoints of a plan, one per period.
pub fn setpoints(curves: &PathCurves, limits: &Limits, records: &[SegmentRecord]) -> Vec<Sample> {
    let mut state = SimState::start(limits.velocity.len(), limits.period);
    let mut out = Vec::new();
    for r in records {
        run_segment(curves, limits, &mut state, *r, &mut |s| out.push(*s));
    }
    out
}

/// How the setpoints map each period's planned arc length to the curve parameter (Erwinski et al. 2022,
/// section II and Table I).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// RK2 predictor-corrector, Simpson arc length: what [`setpoints`] and the realtime module
    /// run, and what the plan is checked with.
    Rk2pc,
    /// Second- and third-order Taylor steps of u(s) by each period's arc-length increment.
    Sot,
    Tot,
    /// Feed correction polynomial: u as a degree-7 polynomial of the arc length, fitted per
    /// piece of at most [`FCP_PIECE`] mm of each element.
    Fcp,
}

/// Arc length (mm) covered by one feed correction polynomial.
pub const FCP_PIECE: f64 = 2.0;

/// The plan's setpoints with `method`. RK2-PC gives [`setpoints`]; the others take the same
/// samples (periods, elements, arc lengths, feeds) and compute the parameter, so the position,
/// their own way. They are comparisons: their positions drift off the planned arc length, so they
/// may exceed the limits the plan was checked against (`verify` tells).
pub fn setpoints_with(
    toolpath: &Toolpath,
    limits: &Limits,
    records: &[SegmentRecord],
    method: Interpolation,
) -> Vec<Sample> {
    let curves = PathCurves::new(toolpath);
    let mut samples = setpoints(&curves, limits, records);
    if method == Interpolation::Rk2pc {
        return samples;
    }
    let tip = toolpath.tip_dim();
    // Per element: the Taylor cursor, or the element's polynomials.
    let mut cursor: Option<(usize, PathCursor)> = None;
    let mut fits: Option<(usize, f64, Vec<[f64; 8]>)> = None;
    let mut spans = SpanCache::new();
    for sample in &mut samples {
        let c = sample.curve;
        let view = curves.view(c);
        let curve = &mut CachedCurve::new(view, &mut spans);
        let u = match method {
            Interpolation::Rk2pc => sample.u,
            Interpolation::Sot | Interpolation::Tot => {
                let mut cur = match cursor {
                    Some((e, cur)) if e == c => cur,
                    _ => PathCursor::at(curve, tip, view.u_min(), 0.0),
                };
                let ds = sample.s - cur.s;
                cur = if method == Interpolation::Sot {
                    sot_step(curve, tip, &cur, ds)
                } else {
                    tot_step(curve, tip, &cur, ds)
                };
                cursor = Some((c, cur));
                cur.u
            }
            Interpolation::Fcp => {
                if fits.as_ref().is_none_or(|(e, _, _)| *e != c) {
                    let curve = &toolpath.elements[c].curve;
                    let table = ArcLengthTable::new(curve);
                    let total = table.total();
                    let pieces = ((total / FCP_PIECE).ceil() as usize).max(1);
                    let piece = total / pieces as f64;
                    let polys = (0..pieces)
                        .map(|k| fit_fcp(curve, &table, k as f64 * piece, (k + 1) as f64 * piece))
                        .collect();
                    fits = Some((c, piece, polys));
                }
                let Some((_, piece, polys)) = &fits else {
                    continue;
                };
                let k = ((sample.s / piece).max(0.0) as usize).min(polys.len() - 1);
                let x = sample.s / piece - k as f64;
                fcp_eval(&polys[k], x).clamp(view.u_min(), view.u_max())
            }
        };
        sample.u = u;
        sample.point = curve.point(u);
    }
    samples
}

/// Least-squares polynomial u(x) of degree 7, x in [0, 1] over the arc lengths `s0..s1` of
/// `curve` (normal equations on 65 Chebyshev points; the FCP of Erwinski et al. 2022).
pub fn fit_fcp(curve: &Nurbs, table: &ArcLengthTable, s0: f64, s1: f64) -> [f64; 8] {
    let n = 64;
    let mut ata = [[0.0f64; 8]; 8];
    let mut atb = [0.0f64; 8];
    for i in 0..=n {
        let x = 0.5 - 0.5 * (std::f64::consts::PI * i as f64 / n as f64).cos();
        let u = table.parameter_at(curve, s0 + x * (s1 - s0));
        let mut pw = [1.0f64; 8];
        for k in 1..8 {
            pw[k] = pw[k - 1] * x;
        }
        for r in 0..8 {
            atb[r] += pw[r] * u;
            for c in 0..8 {
                ata[r][c] += pw[r] * pw[c];
            }
        }
    }
    // Gaussian elimination with partial pivoting.
    for col in 0..8 {
        let pivot = (col..8)
            .max_by(|&a, &b| ata[a][col].abs().total_cmp(&ata[b][col].abs()))
            .unwrap_or(col);
        ata.swap(col, pivot);
        atb.swap(col, pivot);
        for r in col + 1..8 {
            let f = ata[r][col] / ata[col][col];
            for c in col..8 {
                ata[r][c] -= f * ata[col][c];
            }
            atb[r] -= f * atb[col];
        }
    }
    let mut x = [0.0; 8];
    for r in (0..8).rev() {
        let mut v = atb[r];
        for c in r + 1..8 {
            v -= ata[r][c] * x[c];
        }
        x[r] = v / ata[r][r];
    }
    x
}
