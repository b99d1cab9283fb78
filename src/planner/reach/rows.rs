//! Every constraint of one interval as a linear row in the interval's variables.
//!
//! Along arc length σ from station k the state is a(σ) = ṡ² = a + 2bσ + cσ², b(σ) = s̈ = b + cσ
//! (a' = 2b, b' = c exactly), so at a point θ into the interval
//! - the feed, axis velocity and chord caps: a(θ) ≤ cap, and a(θ) ≥ 0 (a floor where given);
//! - axis acceleration x'' = q''·a(θ) + q'·b(θ): |x''_i| ≤ A_i;
//! - axis jerk x''' = √a(θ)·(q'''·a(θ) + 3q''·b(θ) + q'·c): |x'''_i| ≤ J_i becomes
//!   ±(q'''a + 3q''b + q'c) ≤ J/√a, whose right side is convex in a: its tangent at the
//!   linearisation point a_l lies below it, so the row with the tangent is an inner (safe)
//!   approximation for every a (the `copp` solver of Wang et al. 2026 linearises the same way);
//! - where the path's curvature jumps (a join of a line and an arc), the acceleration jumps by
//!   |Δq''_i|·a and the finite-difference jerk at the servo period T sees 3/4 of it per T: the
//!   jerk rows there are tightened by 0.75·|Δq''_i|·a/T (the tangent of J/√a − k√a).
//!
//! Each is α·a + β·b + γ·c ≤ δ in the variables (a, b, c) of the interval.

use super::grid::{Axes, Local, TIP};

/// `a·A + b·B + c·C ≤ d`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Row {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
}

/// The axis limits the rows are built from, already tightened where asked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisLimits {
    pub acceleration: Axes,
    pub jerk: Axes,
    pub axes: usize,
}

impl AxisLimits {
    /// The same limits times `factor` (and the cap on a times its square).
    pub fn scaled(&self, factor: f64) -> AxisLimits {
        let mut l = *self;
        for i in 0..TIP {
            l.acceleration[i] *= factor;
            l.jerk[i] *= factor;
        }
        l
    }

    /// Largest tangential jerk the axes allow where the path has direction `q1` and no
    /// curvature: min J_i/|q'_i|.
    pub fn tangential_jerk(&self, q1: &Axes) -> f64 {
        (0..self.axes)
            .filter(|&i| q1[i].abs() > 1e-12)
            .map(|i| self.jerk[i] / q1[i].abs())
            .fold(f64::INFINITY, f64::min)
    }

    /// Largest tangential acceleration without curvature: min A_i/|q'_i|.
    pub fn tangential_acceleration(&self, q1: &Axes) -> f64 {
        (0..self.axes)
            .filter(|&i| q1[i].abs() > 1e-12)
            .map(|i| self.acceleration[i] / q1[i].abs())
            .fold(f64::INFINITY, f64::min)
    }
}

/// Smallest linearisation point (mm²/s²): below it the tangent of J/√a would be too steep to
/// be of use, and a plan that slow stands nearly still anyway.
pub const A_LIN_MIN: f64 = 1e-2;

/// What the rows at one point need.
#[derive(Clone, Copy, Debug)]
pub struct Point<'a> {
    pub theta: f64,
    pub local: &'a Local,
    /// Linearisation point of the jerk rows.
    pub a_lin: f64,
    /// Cap rows (a ≤ cap, a ≥ floor) and acceleration rows at this point.
    pub state: bool,
    /// Jerk rows.
    pub jerk: bool,
    /// Jump of q'' at this point (a join), the jerk rows' extra term; zero elsewhere.
    pub jump: Option<&'a Axes>,
    /// Lowest a allowed here (0, or a floor that keeps the greedy pass from a near-stop).
    pub floor: f64,
    /// Cap a where the change of curvature alone takes an axis' jerk (the second-order
    /// estimate, which has no jerk rows).
    pub jerk_cap: bool,
}

/// The highest floor as a share of the cap (see [`point_rows`]).
const FLOOR_OF_CAP: f64 = 0.75;

/// Appends the rows of `p` (limits `lim`, cap times `cap_factor`) to `out`.
pub fn point_rows(out: &mut Vec<Row>, p: &Point, lim: &AxisLimits, cap_factor: f64, period: f64) {
    let th = p.theta;
    let g = p.local;
    // A quantity linear in the state at θ, α·a(θ) + β·b(θ) + γ_0·c, in the interval's variables.
    let at = |alpha: f64, beta: f64, gamma: f64, d: f64| Row {
        a: alpha,
        b: 2.0 * th * alpha + beta,
        c: th * th * alpha + th * beta + gamma,
        d,
    };
    if p.state {
        let mut cap = g.cap * cap_factor;
        if p.jerk_cap {
            // Without the jerk rows (the second-order estimate), at least the speed at which the
            // curvature's change alone takes an axis' jerk: |q'''_i|·a^1.5 ≤ J_i.
            for i in 0..lim.axes {
                if g.q3[i].abs() > 1e-12 {
                    cap = cap.min((lim.jerk[i] / g.q3[i].abs()).powf(2.0 / 3.0));
                }
            }
        }
        out.push(at(1.0, 0.0, 0.0, cap));
        // A floor is a share of a linearisation at a plan under these caps (at most 0.3 of
        // 2.5 times it); one from rows planned under higher caps (a plan at a lower feed
        // override continuing them, `Begin::Moving`) is held to that share of these.
        let floor = p.floor.min(FLOOR_OF_CAP * g.cap * cap_factor);
        out.push(at(-1.0, 0.0, 0.0, -floor));
        for i in 0..lim.axes {
            let (q1, q2) = (g.q1[i], g.q2[i]);
            if q1 == 0.0 && q2 == 0.0 {
                continue;
            }
            out.push(at(q2, q1, 0.0, lim.acceleration[i]));
            out.push(at(-q2, -q1, 0.0, lim.acceleration[i]));
        }
    }
    if p.jerk {
        let al = p.a_lin.max(A_LIN_MIN);
        let sq = al.sqrt();
        for i in 0..lim.axes {
            let (q1, q2, q3) = (g.q1[i], g.q2[i], g.q3[i]);
            if q1 == 0.0 && q2 == 0.0 && q3 == 0.0 {
                continue;
            }
            let j = lim.jerk[i];
            let k = p.jump.map_or(0.0, |d| 0.75 * d[i].abs() / period);
            // J/√a − k√a is negative above a = J/k (no motion passes the jump faster), so
            // its tangent is taken at most there.
            let (al, sq) = if k > 0.0 && al > j / k {
                (j / k, (j / k).sqrt())
            } else {
                (al, sq)
            };
            // Tangent of J/√a − k√a at a_l: value − slope·a_l, slope.
            let slope = -0.5 * j / (al * sq) - 0.5 * k / sq;
            let rhs = 1.5 * j / sq - 0.5 * k * sq;
            for sg in [1.0, -1.0] {
                out.push(at(sg * q3 - slope, 3.0 * sg * q2, sg * q1, rhs));
            }
        }
    }
}

/// The rows that carry the next station's controllable set back into this interval:
/// `n·(a(D), b(D)) ≤ d`.
pub fn successor_row(na: f64, nb: f64, d: f64, length: f64) -> Row {
    let dd = length;
    Row {
        a: na,
        b: 2.0 * dd * na + nb,
        c: dd * dd * na + dd * nb,
        d,
    }
}
