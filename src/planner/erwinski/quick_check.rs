//! A fast, approximate axial check used to steer the golden-section searches.
//!
//! The exact check interpolates every sample with the realtime code (five NURBS evaluations
//! each). The geometry of a segment does not change between candidate profiles, only the timing
//! does, so the searches use the continuous axial derivatives instead:
//!   v_i = x_i' v,  a_i = x_i'' v^2 + x_i' a,  j_i = x_i''' v^3 + 3 x_i'' v a + x_i' j,
//! with x', x'', x''' (arc-length derivatives) tabulated once per curve. Whatever the searches
//! choose is then confirmed by the exact check; nothing is emitted on this estimate alone.

use crate::planner::Limits;
use nurbs_rtcore::scurve::SCurveTable;
use nurbs_rtcore::Vector;

/// Axis count covered (tool-tip coordinates).
const AXES: usize = 3;

/// Curvature (1/mm) at or below which a path counts as straight: a line's tabulated curvature
/// is zero up to rounding.
const STRAIGHT_CURVATURE: f64 = 1e-12;

/// Arc-length derivatives of the tool tip on a dense grid of one curve.
#[derive(Clone, Debug, Default)]
pub struct ArcGrid {
    s: Vec<f64>,
    d: Vec<[[f64; AXES]; 3]>,
    tip: usize,
    /// Parameter and parametric speed of the last point (the trapezoidal rule's left end).
    last: (f64, f64),
}

impl ArcGrid {
    /// A grid with no points yet, to be extended with [`ArcGrid::push`] at increasing
    /// parameters (e.g. the FLF scan's), the arc length by the trapezoidal rule on the
    /// parametric speed.
    pub fn empty(tip: usize) -> Self {
        ArcGrid {
            tip: tip.min(AXES),
            ..ArcGrid::default()
        }
    }

    /// Appends the point at parameter `u` (above the last one), with its arc-length derivatives
    /// `x` and parametric speed (as the FLF scan computes them).
    pub fn push(&mut self, u: f64, x: &[Vector; 4], speed: f64) {
        let tip = self.tip;
        let s = match self.s.last() {
            None => 0.0,
            Some(prev) => prev + 0.5 * (speed + self.last.1) * (u - self.last.0),
        };
        self.last = (u, speed);
        let mut d = [[0.0; AXES]; 3];
        for order in 0..3 {
            d[order][..tip].copy_from_slice(&x[order + 1][..tip]);
        }
        self.s.push(s);
        self.d.push(d);
    }

    /// Largest tabulated curvature |x''| over arc lengths `[s0, s1]`, the grid points around
    /// the interval included; `None` where the grid does not reach `s1` yet. `hint` is a
    /// starting index that moves forward with monotone queries.
    pub fn max_curvature(&self, s0: f64, s1: f64, hint: &mut usize) -> Option<f64> {
        let n = self.s.len();
        if n < 2 || self.s[n - 1] < s1 {
            return None;
        }
        while *hint + 2 < n && self.s[*hint + 1] < s0 {
            *hint += 1;
        }
        let mut k2: f64 = 0.0;
        for i in hint.saturating_sub(1)..n {
            k2 = k2.max(self.d[i][1][..self.tip].iter().map(|x| x * x).sum());
            if self.s[i] > s1 {
                break;
            }
        }
        Some(k2.sqrt())
    }

    /// The unit tangent where the path is straight over arc lengths `[s0, s1]` (no curvature
    /// tabulated there, the grid points around the interval included); `None` where it bends
    /// or the grid does not reach `s1` yet.
    pub fn straight_tangent(&self, s0: f64, s1: f64) -> Option<[f64; AXES]> {
        // A segment to the element's end may end a rounding past the grid's trapezoidal sum.
        let end = *self.s.last()?;
        let s1 = if s1 > end && s1 <= end + 1e-9 * end.max(1.0) {
            end
        } else {
            s1
        };
        let mut hint = self.s.partition_point(|&x| x < s0).saturating_sub(1);
        let curvature = self.max_curvature(s0, s1, &mut hint)?;
        (curvature <= STRAIGHT_CURVATURE).then(|| self.d[hint][0])
    }

    /// Derivatives at arc length `s`, linearly interpolated; `hint` is a starting index that
    /// moves forward with monotone queries.
    fn at(&self, s: f64, hint: &mut usize) -> [[f64; AXES]; 3] {
        let n = self.s.len();
        while *hint + 2 < n && self.s[*hint + 1] < s {
            *hint += 1;
        }
        let (i, j) = (*hint, (*hint + 1).min(n - 1));
        let span = self.s[j] - self.s[i];
        let f = if span > 0.0 {
            ((s - self.s[i]) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let mut out = [[0.0; AXES]; 3];
        for o in 0..3 {
            for a in 0..self.tip {
                out[o][a] = self.d[i][o][a] * (1.0 - f) + self.d[j][o][a] * f;
            }
        }
        out
    }
}

/// Outcome of the estimate for one candidate profile.
#[derive(Clone, Copy, Debug)]
pub struct Estimate {
    /// Worst ratio of an axial value (or the chord error) to its limit.
    pub ratio: f64,
    /// The same for the speed caps alone (axial velocity, chord error).
    pub speed_ratio: f64,
    pub acc_violation: f64,
    pub jerk_violation: f64,
    /// Whether every sample was looked at (see `Scope`); if not, `ratio` is above 1 but not
    /// the worst, and the violations are partial.
    pub complete: bool,
}

/// How much of a profile [`estimate`] looks at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    /// Every sample.
    Full,
    /// Up to the first sample over a limit: enough to tell whether the profile passes.
    Verdict,
}

/// Estimates the axial peaks of `profile` starting at arc length `s_start`, sampled at
/// `t_first + k dt` (local time), against `limits` scaled by `margin`. The samples before a
/// `Scope::Verdict` stops are computed exactly as in a full estimate.
pub fn estimate(
    grid: &ArcGrid,
    limits: &Limits,
    margin: f64,
    table: &SCurveTable,
    s_start: f64,
    t_first: f64,
    scope: Scope,
) -> Estimate {
    let dt = limits.period;
    let tip = grid.tip;
    let eps = 0.9 * limits.chord_tolerance;
    let mut est = Estimate {
        ratio: 0.0,
        speed_ratio: 0.0,
        acc_violation: 0.0,
        jerk_violation: 0.0,
        complete: true,
    };
    let mut hint = grid.s.partition_point(|&x| x < s_start).saturating_sub(1);
    let total = table.total_time();
    // The limits as divided by, computed once (the same values as inline).
    let mut acc_limit = [0.0; AXES];
    let mut jerk_limit = [0.0; AXES];
    for a in 0..tip {
        acc_limit[a] = margin * limits.acceleration[a];
        jerk_limit[a] = margin * limits.jerk[a];
    }
    let full = scope == Scope::Full;
    let mut phase = 0usize;
    let mut k = 0usize;
    let mut count = 0usize;
    loop {
        let t = t_first + k as f64 * dt;
        if t > total {
            break;
        }
        k += 1;
        let st = table.state_at_from(t, &mut phase);
        let d = grid.at(s_start + st.s, &mut hint);
        let mut kappa2 = 0.0;
        let mut worst = est.ratio;
        for a in 0..tip {
            let (x1, x2, x3) = (d[0][a], d[1][a], d[2][a]);
            // No margin on velocity: cruising at a feed equal to an axis limit is legitimate.
            let vel = (x1 * st.v).abs() / limits.velocity[a];
            let acc = (x2 * st.v * st.v + x1 * st.a).abs() / acc_limit[a];
            let jerk = (x3 * st.v * st.v * st.v + 3.0 * x2 * st.v * st.a + x1 * st.j).abs() / jerk_limit[a];
            worst = max_of(max_of(worst, vel), max_of(acc, jerk));
            est.speed_ratio = max_of(est.speed_ratio, vel);
            if full {
                // (A verdict needs no violations: a profile it passes has none.)
                est.acc_violation += excess(acc - 1.0);
                est.jerk_violation += excess(jerk - 1.0);
            }
            kappa2 += x2 * x2;
        }
        let step = st.v * dt;
        let chord = kappa2.sqrt() * step * step / 8.0 / eps;
        est.ratio = max_of(worst, chord);
        est.speed_ratio = max_of(est.speed_ratio, chord);
        count += 1;
        if !full && est.ratio > 1.0 {
            est.complete = false;
            break;
        }
    }
    let n = count.max(1) as f64;
    est.acc_violation /= n;
    est.jerk_violation /= n;
    est
}

/// `a.max(b)` for an `a` that is not NaN (a NaN `b` leaves `a`, as `f64::max` does), without
/// the NaN handling of `f64::max` on both sides, which dominated the estimate's time.
#[inline]
fn max_of(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// `x.max(0.0)`: the positive part (a NaN gives 0, as there).
#[inline]
fn excess(x: f64) -> f64 {
    if x > 0.0 {
        x
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The estimate's `max_of` and `excess` give what `f64::max` gives wherever the estimate
    /// uses them (a first operand that is not NaN), NaN, infinities and signed zeros included.
    #[test]
    fn max_of_and_excess_agree_with_f64_max() {
        let values = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for a in values.iter().filter(|a| !a.is_nan()) {
            for b in values {
                assert_eq!(max_of(*a, b), a.max(b), "max_of({a}, {b})");
            }
        }
        for x in values {
            assert_eq!(excess(x), x.max(0.0), "excess({x})");
        }
    }
}
