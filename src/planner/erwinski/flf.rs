//! Feedrate limit function (Erwinski et al. 2022, eq. 10-14) and its critical points (section III, steps
//! 1-5).
//!
//! The paper writes the centripetal caps with the curvature and the smallest axis limit
//! (eq. 11-12). Here they are written per axis with the derivatives of the axis positions with
//! respect to arc length: at constant feed v, axis i moves with velocity x_i' v, acceleration
//! x_i'' v^2 and jerk x_i''' v^3 exactly, so
//!   F <= V_i / |x_i'|,  F <= sqrt(A_i / |x_i''|),  F <= cbrt(J_i / |x_i'''|).
//! For a planar curve |x''| = kappa, so the acceleration cap is never below eq. 11; the jerk cap
//! also counts the change of curvature (x''' = kappa' n - kappa^2 t), which eq. 12 leaves out.

use super::tuning::*;
use crate::planner::Limits;
use nurbs_rtcore::math::dot;
use nurbs_rtcore::{CachedCurve, CurveView, SpanCache, Vector};

/// The components of the FLF at one parameter value (mm/s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlfValue {
    /// Programmed feed and axial velocity caps.
    pub feed: f64,
    /// Chord error cap, eq. 10.
    pub chord: f64,
    /// Axial acceleration cap at constant feed (eq. 11 per axis).
    pub accel: f64,
    /// Axial jerk cap at constant feed (eq. 12 per axis).
    pub jerk: f64,
}

impl FlfValue {
    /// FLF = min of the components (eq. 14).
    pub fn value(&self) -> f64 {
        self.feed.min(self.chord).min(self.accel).min(self.jerk)
    }
    /// The caps that limit speed alone (feed, axial velocity, chord error).
    pub fn speed_cap(&self) -> f64 {
        self.feed.min(self.chord)
    }
}

/// Derivatives of the tool-tip coordinates with respect to arc length at `u`.
pub fn arc_derivatives(curve: &CurveView, tip: usize, u: f64) -> [Vector; 4] {
    arc_from_parametric(&curve.derivatives(u, 3), tip).0
}

/// Derivatives with respect to arc length from those with respect to the parameter `d` (Faa
/// di Bruno with u_s = 1/g, u_ss = -(C'.C'')/g^4, u_sss = -(|C''|^2 + C'.C''')/g^5 +
/// 4 (C'.C'')^2/g^7), and the parametric speed g = |C'(u)| they are scaled by.
fn arc_from_parametric(d: &[Vector; 4], tip: usize) -> ([Vector; 4], f64) {
    let g2 = dot(&d[1], &d[1], tip);
    let g = g2.sqrt();
    let mut out = [[0.0; nurbs_rtcore::MAX_DIM]; 4];
    out[0] = d[0];
    if g == 0.0 {
        return (out, g);
    }
    let c12 = dot(&d[1], &d[2], tip);
    let u_s = 1.0 / g;
    let u_ss = -c12 / (g2 * g2);
    let u_sss =
        -(dot(&d[2], &d[2], tip) + dot(&d[1], &d[3], tip)) / (g2 * g2 * g) + 4.0 * c12 * c12 / (g2 * g2 * g2 * g);
    for i in 0..tip {
        out[1][i] = d[1][i] * u_s;
        out[2][i] = d[2][i] * u_s * u_s + d[1][i] * u_ss;
        out[3][i] = d[3][i] * u_s * u_s * u_s + 3.0 * d[2][i] * u_s * u_ss + d[1][i] * u_sss;
    }
    (out, g)
}

/// FLF components at `u`.
pub fn flf(curve: &CurveView, tip: usize, limits: &Limits, u: f64) -> FlfValue {
    flf_of(&arc_derivatives(curve, tip, u), tip, limits)
}

/// FLF components from the arc-length derivatives `x` at a point.
pub fn flf_of(x: &[Vector; 4], tip: usize, limits: &Limits) -> FlfValue {
    if x[1][..tip].iter().all(|c| *c == 0.0) {
        // C'(u) = 0: a cusp or a degenerate point, where the direction may turn: stop.
        return FlfValue {
            feed: 0.0,
            chord: 0.0,
            accel: 0.0,
            jerk: 0.0,
        };
    }
    let mut v = FlfValue {
        feed: limits.feed,
        chord: f64::INFINITY,
        accel: f64::INFINITY,
        jerk: f64::INFINITY,
    };
    let mut kappa2 = 0.0;
    for i in 0..tip {
        v.feed = v.feed.min(limits.velocity[i] / x[1][i].abs());
        v.accel = v.accel.min((limits.acceleration[i] / x[2][i].abs()).sqrt());
        v.jerk = v.jerk.min((limits.jerk[i] / x[3][i].abs()).cbrt());
        kappa2 += x[2][i] * x[2][i];
    }
    // Eq. 10: the chord of an arc of radius rho with sagitta eps is 2 sqrt(rho^2 - (rho-eps)^2),
    // covered in one period. Below rho = eps the chord is at most the diameter.
    let eps = CHORD_MARGIN * limits.chord_tolerance;
    if kappa2 > 0.0 {
        let rho = 1.0 / kappa2.sqrt();
        // rho^2 - (rho - eps)^2 written as eps (2 rho - eps): the difference of squares cancels
        // to 0 on a straight line (rho ~ 1e15 from rounding) and would stop the motion there.
        let half_chord = if rho > eps {
            (eps * (2.0 * rho - eps)).sqrt()
        } else {
            rho
        };
        v.chord = 2.0 * half_chord / limits.period;
    }
    v
}

/// A local minimum of the FLF where a segment starts or ends (its feed: the FLF there).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CriticalPoint {
    pub u: f64,
    pub flf: f64,
}

/// One sample of an [`FlfScan`]: its parameter, the arc-length derivatives and parametric speed
/// it comes from, the full FLF and the speed caps.
#[derive(Clone, Copy, Debug)]
pub struct ScanSample {
    pub u: f64,
    pub x: [Vector; 4],
    pub speed: f64,
    pub value: f64,
    pub speed_cap: f64,
}

/// FLF samples over a curve: `u[i]`, `value[i]` (full FLF) and `speed[i]` (speed caps only).
///
/// The samples can be taken lazily, front to back ([`FlfScan::lazy`], [`FlfScan::extend`]);
/// each sample is the same whether taken early or late.
#[derive(Clone, Debug, Default)]
pub struct FlfScan {
    pub u: Vec<f64>,
    pub value: Vec<f64>,
    pub speed: Vec<f64>,
    /// Number of equal parameter steps of the full scan (`steps + 1` samples).
    steps: usize,
}

impl FlfScan {
    /// Step 1: sample at `per_point` equidistant parameters per control point.
    pub fn new(curve: &CurveView, tip: usize, limits: &Limits, per_point: usize) -> Self {
        let mut scan = Self::lazy(curve, per_point);
        scan.extend(curve, tip, limits, usize::MAX, &mut |_, _, _| {});
        scan
    }

    /// The scan of step 1 with no samples taken yet: `per_point` samples per control point,
    /// but on a short curve no closer than [`MIN_SAMPLE_SPACING`] (or
    /// [`MIN_SAMPLE_SPACING_LONG`]) on its control polygon (at
    /// least [`MIN_SAMPLES_PER_POINT`] per control point): the paper's density was chosen for
    /// curves of tens of millimetres, and a 0.02 mm G1 line would otherwise get 1,000 samples.
    pub fn lazy(curve: &CurveView, per_point: usize) -> Self {
        let n = curve.control_point_count();
        // The tool tip's polygon (a 6-D curve's top coordinates come after its first three).
        let (dim, stride) = (curve.dim().min(3), curve.dim().max(1));
        let p = curve.points();
        let polygon: f64 = (1..n)
            .map(|k| {
                (0..dim)
                    .map(|i| (p[k * stride + i] - p[(k - 1) * stride + i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum();
        let spacing = if n > CORNER_CONTROL_POINTS {
            MIN_SAMPLE_SPACING_LONG
        } else {
            MIN_SAMPLE_SPACING
        };
        let by_length = (polygon / spacing).ceil();
        let floor = n * MIN_SAMPLES_PER_POINT;
        let steps = if by_length.is_finite() && by_length < (n * per_point) as f64 {
            (by_length as usize).max(floor).min(n * per_point)
        } else {
            n * per_point
        };
        FlfScan {
            steps: steps.max(2),
            ..FlfScan::default()
        }
    }

    /// Number of samples of the full scan.
    pub fn full_len(&self) -> usize {
        self.steps + 1
    }

    pub fn is_complete(&self) -> bool {
        self.u.len() == self.full_len()
    }

    /// Takes up to `count` more samples; `each` gets the parameter, arc-length derivatives and
    /// parametric speed of every one (they are computed anyway).
    pub fn extend(
        &mut self,
        curve: &CurveView,
        tip: usize,
        limits: &Limits,
        count: usize,
        each: &mut dyn FnMut(f64, &[Vector; 4], f64),
    ) {
        let end = self.u.len().saturating_add(count).min(self.full_len());
        for sample in self.samples(curve, tip, limits, self.u.len(), end) {
            self.take(&sample, each);
        }
    }

    /// The same as [`FlfScan::extend`], from `samples`: the full scan's samples computed
    /// beforehand ([`FlfScan::samples`] from 0, e.g. in another thread).
    pub fn extend_from(&mut self, samples: &[ScanSample], count: usize, each: &mut dyn FnMut(f64, &[Vector; 4], f64)) {
        let end = self
            .u
            .len()
            .saturating_add(count)
            .min(self.full_len())
            .min(samples.len());
        for sample in &samples[self.u.len()..end] {
            self.take(sample, each);
        }
    }

    /// Samples `from..end` of the full scan. Each depends on its index, the curve and the
    /// limits alone: computed in one go or a chunk at a time, they are the same bit for bit.
    pub fn samples(&self, curve: &CurveView, tip: usize, limits: &Limits, from: usize, end: usize) -> Vec<ScanSample> {
        let (a, b) = (curve.u_min(), curve.u_max());
        // Hundreds of samples per span: evaluated through the span's Taylor polynomials.
        let mut spans = SpanCache::new();
        let cached = &mut CachedCurve::new(*curve, &mut spans);
        (from..end.min(self.full_len()))
            .map(|k| {
                let u = a + (b - a) * k as f64 / self.steps as f64;
                let (x, speed) = arc_from_parametric(&cached.derivatives(u, 3), tip);
                let f = flf_of(&x, tip, limits);
                ScanSample {
                    u,
                    x,
                    speed,
                    value: f.value(),
                    speed_cap: f.speed_cap(),
                }
            })
            .collect()
    }

    fn take(&mut self, sample: &ScanSample, each: &mut dyn FnMut(f64, &[Vector; 4], f64)) {
        each(sample.u, &sample.x, sample.speed);
        self.u.push(sample.u);
        self.value.push(sample.value);
        self.speed.push(sample.speed_cap);
    }

    /// Smallest speed cap among the samples strictly inside `(u0, u1)`, with its parameter.
    pub fn min_speed_cap_between(&self, u0: f64, u1: f64) -> Option<(f64, f64)> {
        let i0 = self.u.partition_point(|&u| u <= u0);
        let i1 = self.u.partition_point(|&u| u < u1);
        (i0..i1)
            .map(|i| (self.speed[i], self.u[i]))
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }
}

/// Steps 2-3: samples lower than their five neighbours on each side, refined by Brent's method
/// inside the bracket of their neighbours.
pub fn critical_points(curve: &CurveView, tip: usize, limits: &Limits, scan: &FlfScan) -> Vec<CriticalPoint> {
    let mut out = Vec::new();
    CriticalPointSearch::default().advance(curve, tip, limits, scan, &mut out);
    out
}

/// Steps 2-3 run along a lazily extended [`FlfScan`]: a sample is judged once its neighbours
/// are taken, so the points come out in increasing `u`, the same as on the full scan.
#[derive(Clone, Copy, Debug)]
pub struct CriticalPointSearch {
    /// Next sample to judge.
    next: usize,
}

impl Default for CriticalPointSearch {
    fn default() -> Self {
        CriticalPointSearch { next: 1 }
    }
}

impl CriticalPointSearch {
    /// Judges every sample whose neighbours `scan` holds, appending the critical points to `out`.
    pub fn advance(
        &mut self,
        curve: &CurveView,
        tip: usize,
        limits: &Limits,
        scan: &FlfScan,
        out: &mut Vec<CriticalPoint>,
    ) {
        let v = &scan.value;
        let n = scan.full_len();
        let mut i = self.next;
        while i + 1 < n {
            let lo = i.saturating_sub(NEIGHBOURS);
            let hi = (i + NEIGHBOURS).min(n - 1);
            if hi >= v.len() {
                break;
            }
            let is_min = (lo..=hi).all(|k| k == i || v[i] <= v[k]) && (lo..=hi).any(|k| v[i] < v[k]);
            if is_min {
                let f = |u: f64| flf(curve, tip, limits, u).value();
                let (u, fu) = brent_min(&f, scan.u[i - 1], scan.u[i], scan.u[i + 1]);
                let (u, fu) = if fu <= v[i] { (u, fu) } else { (scan.u[i], v[i]) };
                out.push(CriticalPoint { u, flf: fu });
                i += NEIGHBOURS; // a plateau yields one point
            } else {
                i += 1;
            }
        }
        self.next = i;
    }

    /// No critical point found later lies below this parameter.
    pub fn settled_below(&self, scan: &FlfScan) -> f64 {
        if self.next + 1 >= scan.full_len() {
            f64::INFINITY
        } else if self.next > scan.u.len() {
            f64::NEG_INFINITY
        } else {
            scan.u[self.next - 1]
        }
    }
}

/// Brent's minimisation on the bracket `a < b < c` (Numerical Recipes `brent`), to a parameter
/// tolerance of 1e-10 relative.
pub fn brent_min(f: &dyn Fn(f64) -> f64, a: f64, b: f64, c: f64) -> (f64, f64) {
    const CGOLD: f64 = 0.381_966_011_250_105_1;
    let (mut a, mut bb) = (a.min(c), a.max(c));
    let (mut x, mut w, mut v) = (b, b, b);
    let mut fx = f(x);
    let (mut fw, mut fv) = (fx, fx);
    let (mut d, mut e): (f64, f64) = (0.0, 0.0);
    for _ in 0..100 {
        let xm = 0.5 * (a + bb);
        let tol1 = 1e-10 * x.abs() + 1e-14;
        let tol2 = 2.0 * tol1;
        if (x - xm).abs() <= tol2 - 0.5 * (bb - a) {
            break;
        }
        if e.abs() > tol1 {
            let r = (x - w) * (fx - fv);
            let mut q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            let etemp = e;
            e = d;
            if p.abs() >= (0.5 * q * etemp).abs() || p <= q * (a - x) || p >= q * (bb - x) {
                e = if x >= xm { a - x } else { bb - x };
                d = CGOLD * e;
            } else {
                d = p / q;
                let u = x + d;
                if u - a < tol2 || bb - u < tol2 {
                    d = tol1.copysign(xm - x);
                }
            }
        } else {
            e = if x >= xm { a - x } else { bb - x };
            d = CGOLD * e;
        }
        let u = if d.abs() >= tol1 { x + d } else { x + tol1.copysign(d) };
        let fu = f(u);
        if fu <= fx {
            if u >= x {
                a = x;
            } else {
                bb = x;
            }
            v = w;
            w = x;
            x = u;
            fv = fw;
            fw = fx;
            fx = fu;
        } else {
            if u < x {
                a = u;
            } else {
                bb = u;
            }
            if fu <= fw || w == x {
                v = w;
                w = u;
                fv = fw;
                fw = fu;
            } else if fu <= fv || v == x || v == w {
                v = u;
                fv = fu;
            }
        }
    }
    (x, fx)
}
