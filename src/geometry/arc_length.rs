//! Arc length of the tool-tip path: Gauss-Legendre quadrature per knot span (adaptively
//! subdivided until converged), the paper's adaptive Simpson rule, and the inverse map from arc
//! length to curve parameter.

use super::Nurbs;

/// 16-point Gauss-Legendre nodes and weights on [-1, 1] (positive half; symmetric).
const GL_X: [f64; 8] = [
    0.095_012_509_837_637_44,
    0.281_603_550_779_258_9,
    0.458_016_777_657_227_4,
    0.617_876_244_402_643_7,
    0.755_404_408_355_003,
    0.865_631_202_387_831_8,
    0.944_575_023_073_232_6,
    0.989_400_934_991_649_9,
];
const GL_W: [f64; 8] = [
    0.189_450_610_455_068_5,
    0.182_603_415_044_923_6,
    0.169_156_519_395_002_5,
    0.149_595_988_816_576_7,
    0.124_628_971_255_533_9,
    0.095_158_511_682_492_78,
    0.062_253_523_938_647_89,
    0.027_152_459_411_754_095,
];

fn gauss16(f: &dyn Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    let (c, h) = (0.5 * (a + b), 0.5 * (b - a));
    let mut s = 0.0;
    for i in 0..8 {
        s += GL_W[i] * (f(c - h * GL_X[i]) + f(c + h * GL_X[i]));
    }
    s * h
}

/// Adaptive Gauss-Legendre: split until two halves agree with the whole to `tol`.
fn gauss_adaptive(f: &dyn Fn(f64) -> f64, a: f64, b: f64, whole: f64, tol: f64, depth: u32) -> f64 {
    let m = 0.5 * (a + b);
    let (l, r) = (gauss16(f, a, m), gauss16(f, m, b));
    if depth == 0 || (l + r - whole).abs() <= tol {
        return l + r;
    }
    gauss_adaptive(f, a, m, l, tol * 0.5, depth - 1) + gauss_adaptive(f, m, b, r, tol * 0.5, depth - 1)
}

/// Adaptive Simpson quadrature of `f` on `[a, b]` to absolute tolerance `tol` (as in the paper).
pub fn adaptive_simpson(f: &dyn Fn(f64) -> f64, a: f64, b: f64, tol: f64) -> f64 {
    #[allow(clippy::too_many_arguments)]
    fn rec(f: &dyn Fn(f64) -> f64, a: f64, b: f64, fa: f64, fm: f64, fb: f64, whole: f64, tol: f64, depth: u32) -> f64 {
        let m = 0.5 * (a + b);
        let (lm, rm) = (0.5 * (a + m), 0.5 * (m + b));
        let (flm, frm) = (f(lm), f(rm));
        let left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
        let right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
        let delta = left + right - whole;
        // At least a few levels, so that a symmetric integrand cannot fool the first estimate.
        if depth == 0 || (depth < 45 && delta.abs() <= 15.0 * tol) {
            return left + right + delta / 15.0;
        }
        rec(f, a, m, fa, flm, fm, left, tol / 2.0, depth - 1) + rec(f, m, b, fm, frm, fb, right, tol / 2.0, depth - 1)
    }
    let (fa, fm, fb) = (f(a), f(0.5 * (a + b)), f(b));
    let whole = (b - a) / 6.0 * (fa + 4.0 * fm + fb);
    rec(f, a, b, fa, fm, fb, whole, tol, 50)
}

/// Arc length of `curve` between parameters `a < b` by adaptive Simpson, span by span.
pub fn simpson_length(curve: &Nurbs, a: f64, b: f64, tol: f64) -> f64 {
    // One validated view for all evaluations (building one validates the whole curve).
    let (view, tip) = (curve.view(), curve.tip_dim());
    let speed = |u: f64| view.speed(u, tip);
    let mut cuts: Vec<f64> = vec![a];
    cuts.extend(curve.breakpoints().into_iter().filter(|&k| k > a && k < b));
    cuts.push(b);
    let n = (cuts.len() - 1) as f64;
    cuts.windows(2)
        .map(|w| adaptive_simpson(&speed, w[0], w[1], tol / n))
        .sum()
}

/// Cumulative arc length of a curve on a fine parameter grid (per knot span), for the total
/// length, the length between two parameters and the inverse map s -> u.
///
/// The table can be built lazily ([`ArcLengthTable::lazy`], [`ArcLengthTable::extend_past`]):
/// the pieces are added in the same order with the same arithmetic, so a lazily built table
/// gives exactly the values of a full one where it is covered.
#[derive(Clone, Debug)]
pub struct ArcLengthTable {
    /// Parameter grid (increasing).
    u: Vec<f64>,
    /// Arc length from the curve start at each grid value.
    s: Vec<f64>,
    /// Knot span boundaries of the curve, and the pieces added so far.
    breaks: Vec<f64>,
    pieces: usize,
}

/// Sub-intervals per knot span in the table.
const PIECES_PER_SPAN: usize = 8;

impl ArcLengthTable {
    pub fn new(curve: &Nurbs) -> Self {
        let mut table = Self::lazy(curve);
        table.extend_past(curve, f64::INFINITY);
        table
    }

    /// A table covering nothing yet but the curve start.
    pub fn lazy(curve: &Nurbs) -> Self {
        let breaks = curve.breakpoints();
        ArcLengthTable {
            u: vec![breaks[0]],
            s: vec![0.0],
            breaks,
            pieces: 0,
        }
    }

    /// Whether the table reaches the curve end.
    pub fn is_complete(&self) -> bool {
        self.pieces == (self.breaks.len() - 1) * PIECES_PER_SPAN
    }

    /// Adds pieces until the table reaches beyond parameter `t` (or the curve end).
    pub fn extend_past(&mut self, curve: &Nurbs, t: f64) {
        let (view, tip) = (curve.view(), curve.tip_dim());
        let speed = |t: f64| view.speed(t, tip);
        while !self.is_complete() && *self.u.last().unwrap() <= t {
            let (span, i) = (self.pieces / PIECES_PER_SPAN, self.pieces % PIECES_PER_SPAN);
            let w = &self.breaks[span..span + 2];
            let a = w[0] + (w[1] - w[0]) * i as f64 / PIECES_PER_SPAN as f64;
            let b = if i + 1 == PIECES_PER_SPAN {
                w[1]
            } else {
                w[0] + (w[1] - w[0]) * (i + 1) as f64 / PIECES_PER_SPAN as f64
            };
            let whole = gauss16(&speed, a, b);
            let piece = gauss_adaptive(&speed, a, b, whole, 1e-14 * (1.0 + whole), 12);
            self.u.push(b);
            self.s.push(self.s.last().unwrap() + piece);
            self.pieces += 1;
        }
    }

    /// The same as [`ArcLengthTable::extend_past`], copying the pieces of `full`, a complete
    /// table of the same curve (e.g. built in another thread): the same values.
    pub fn extend_past_from(&mut self, full: &ArcLengthTable, t: f64) {
        debug_assert!(full.is_complete() && full.breaks == self.breaks);
        while !self.is_complete() && *self.u.last().unwrap() <= t {
            let k = self.u.len();
            self.u.push(full.u[k]);
            self.s.push(full.s[k]);
            self.pieces += 1;
        }
    }

    pub fn total(&self) -> f64 {
        *self.s.last().unwrap()
    }

    /// Arc length from the curve start to parameter `t` (which a lazy table must reach beyond).
    pub fn length_to(&self, curve: &Nurbs, t: f64) -> f64 {
        debug_assert!(
            self.is_complete() || t < *self.u.last().unwrap(),
            "arc length table too short"
        );
        let t = t.clamp(self.u[0], *self.u.last().unwrap());
        let i = match self.u.partition_point(|&x| x <= t) {
            0 => 0,
            k => k - 1,
        };
        if i + 1 >= self.u.len() {
            return self.total();
        }
        let (view, tip) = (curve.view(), curve.tip_dim());
        let speed = |x: f64| view.speed(x, tip);
        let whole = gauss16(&speed, self.u[i], t);
        self.s[i] + gauss_adaptive(&speed, self.u[i], t, whole, 1e-14 * (1.0 + whole), 12)
    }

    /// Parameter at arc length `target` (Newton's method safeguarded by bisection).
    pub fn parameter_at(&self, curve: &Nurbs, target: f64) -> f64 {
        if target <= 0.0 {
            return self.u[0];
        }
        if target >= self.total() {
            return *self.u.last().unwrap();
        }
        let i = self.s.partition_point(|&x| x <= target).max(1) - 1;
        let (mut lo, mut hi) = (self.u[i], self.u[i + 1]);
        let (view, tip) = (curve.view(), curve.tip_dim());
        let mut t = lo + (hi - lo) * (target - self.s[i]) / (self.s[i + 1] - self.s[i]).max(f64::MIN_POSITIVE);
        for _ in 0..60 {
            let err = self.length_to(curve, t) - target;
            if err.abs() < 1e-12 * (1.0 + target) {
                break;
            }
            if err > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let sp = view.speed(t, tip);
            let newton = t - err / sp;
            t = if sp > 0.0 && newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
        }
        t
    }

    /// Grid of the table (parameter values and cumulative lengths).
    pub fn grid(&self) -> (&[f64], &[f64]) {
        (&self.u, &self.s)
    }
}
