//! The plan in time: one piece per interval, each in closed form.
//!
//! Inside an interval with constant c = s⃛/ṡ the arc length σ from its start obeys the linear
//! equation σ̈ = b + c·σ (b' = c along σ and ṡ² = a + 2bσ + cσ²), so
//! σ(τ) = v₀·τ·S(wτ) + ½·b·τ²·S(wτ/2)², σ̇(τ) = v₀·C(wτ) + b·τ·S(wτ), with w = √|c| and
//! S(x) = sinh x / x, C = cosh for c > 0, S(x) = sin x / x, C = cos for c < 0 (no Newton inside
//! a piece). A motion that starts or ends at rest does so in a piece of constant jerk
//! (c = s⃛/ṡ is unbounded at ṡ = 0): from rest to (a₁, b₁) over D, s = j·τ³/6 with
//! a₁ = 1.5·D·b₁, j = b₁²/(2√a₁); to rest likewise, mirrored.

/// sinh(x)/x (`hyperbolic`) or sin(x)/x, and cosh x or cos x, accurate near 0.
fn s_and_c(x: f64, hyperbolic: bool) -> (f64, f64) {
    let x2 = x * x;
    if x2 < 1e-6 {
        let sgn = if hyperbolic { 1.0 } else { -1.0 };
        let s = 1.0 + sgn * x2 / 6.0 + x2 * x2 / 120.0;
        let c = 1.0 + sgn * x2 / 2.0 + x2 * x2 / 24.0;
        (s, c)
    } else if hyperbolic {
        (x.sinh() / x, x.cosh())
    } else {
        (x.sin() / x, x.cos())
    }
}

/// One interval of the plan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Piece {
    /// From rest with constant jerk `jerk` (mm/s³).
    Start { jerk: f64 },
    /// From speed `v` and tangential acceleration `b` (≤ 0) to rest with constant jerk.
    Stop { v: f64, b: f64, jerk: f64 },
    /// The state (a, b) at the interval start and constant c.
    Quadratic { a: f64, b: f64, c: f64 },
    /// From speed `v` and tangential acceleration `b` with constant jerk `jerk`: a phase of an
    /// S-curve stop in time, which ends where its interval does (only ever sampled).
    Jerk { v: f64, b: f64, jerk: f64 },
}

impl Piece {
    /// The piece from state `(a, b)` with control `c`.
    pub fn quadratic(a: f64, b: f64, c: f64) -> Piece {
        Piece::Quadratic { a: a.max(0.0), b, c }
    }

    /// The constant-jerk start that ends in `(a1, b1)` (a1 = 1.5·D·b1); `None` unless b1 > 0.
    pub fn start(a1: f64, b1: f64) -> Option<(Piece, f64)> {
        if !(b1 > 0.0 && a1 > 0.0) {
            return None;
        }
        let v = a1.sqrt();
        let duration = 2.0 * v / b1;
        Some((Piece::Start { jerk: b1 / duration }, duration))
    }

    /// The constant-jerk stop from `(a, b)` (b < 0); its duration and length.
    pub fn stop(a: f64, b: f64) -> Option<(Piece, f64, f64)> {
        if !(b < 0.0 && a > 0.0) {
            return None;
        }
        let v = a.sqrt();
        let duration = -2.0 * v / b;
        let jerk = -b / duration;
        let length = -2.0 * a / (3.0 * b);
        Some((Piece::Stop { v, b, jerk }, duration, length))
    }

    /// Distance σ and speed σ̇ at time τ into the piece.
    pub fn at(&self, tau: f64) -> (f64, f64) {
        match *self {
            Piece::Start { jerk } => (jerk * tau * tau * tau / 6.0, 0.5 * jerk * tau * tau),
            Piece::Stop { v, b, jerk } | Piece::Jerk { v, b, jerk } => (
                v * tau + 0.5 * b * tau * tau + jerk * tau * tau * tau / 6.0,
                v + b * tau + 0.5 * jerk * tau * tau,
            ),
            Piece::Quadratic { a, b, c } => {
                let v = a.sqrt();
                let w = c.abs().sqrt();
                let hyperbolic = c > 0.0;
                let (s1, c1) = s_and_c(w * tau, hyperbolic);
                let (sh, _) = s_and_c(0.5 * w * tau, hyperbolic);
                (v * tau * s1 + 0.5 * b * tau * tau * sh * sh, v * c1 + b * tau * s1)
            }
        }
    }

    /// Distance σ, speed σ̇ and tangential acceleration σ̈ at time τ into the piece (for a
    /// quadratic piece σ̈ = b + c·σ: b' = c along the arc length).
    pub fn state_at(&self, tau: f64) -> (f64, f64, f64) {
        let (sigma, speed) = self.at(tau);
        let acceleration = match *self {
            Piece::Start { jerk } => jerk * tau,
            Piece::Stop { b, jerk, .. } | Piece::Jerk { b, jerk, .. } => b + jerk * tau,
            Piece::Quadratic { b, c, .. } => b + c * sigma,
        };
        (sigma, speed, acceleration)
    }

    /// The time at distance `sigma`, by Newton's method inside `[0, longest]` (doubled while
    /// short of it), safeguarded by bisection: the distance rises with time while the speed
    /// does not vanish. For the S-curve
    /// phases ([`Piece::Jerk`]), which have no closed form for it.
    pub fn time_to(&self, sigma: f64, longest: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, longest);
        while self.at(hi).0 < sigma && hi < 1e6 {
            hi *= 2.0;
        }
        // Newton's method on σ(τ), kept inside the bracket by bisection.
        let mut t = 0.5 * (lo + hi);
        for _ in 0..100 {
            let (s, v) = self.at(t);
            let err = s - sigma;
            if err == 0.0 {
                return t;
            }
            if err > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let newton = t - err / v;
            let next = if v > 0.0 && newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
            if (next - t).abs() <= 1e-16 * hi || hi - lo <= 1e-16 * hi {
                return next;
            }
            t = next;
        }
        t
    }

    /// Time to cover `length` along the piece; `None` where the motion stops before.
    pub fn duration(&self, length: f64) -> Option<f64> {
        if length <= 0.0 {
            return Some(0.0);
        }
        let Piece::Quadratic { a, b, c } = *self else {
            // The constant-jerk pieces know their durations from their states.
            return None;
        };
        let end = a + 2.0 * b * length + c * length * length;
        if end < 0.0 {
            return None;
        }
        // Bracket, then Newton safeguarded by bisection.
        let guess = 2.0 * length / (a.sqrt() + end.sqrt()).max(1e-300);
        let (mut lo, mut hi) = (0.0, guess.min(1e6));
        let mut grow = 0;
        while self.at(hi).0 < length {
            lo = hi;
            hi *= 2.0;
            grow += 1;
            if grow > 60 || !hi.is_finite() {
                return None;
            }
        }
        let mut t = if guess < hi && guess > lo {
            guess
        } else {
            0.5 * (lo + hi)
        };
        for _ in 0..100 {
            let (s, v) = self.at(t);
            let err = s - length;
            if err.abs() <= 1e-15 * length {
                return Some(t);
            }
            if err > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let newton = t - err / v;
            t = if v > 0.0 && newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
            if hi - lo <= 1e-16 * hi {
                return Some(t);
            }
        }
        Some(t)
    }

    /// a = ṡ² at distance σ into a piece of length `length`.
    pub fn a_at(&self, sigma: f64, length: f64) -> f64 {
        match *self {
            Piece::Start { jerk } => {
                // s = jτ³/6, ṡ = jτ²/2.
                let tau = (6.0 * sigma.max(0.0) / jerk).cbrt();
                let v = 0.5 * jerk * tau * tau;
                v * v
            }
            Piece::Stop { jerk, .. } => {
                // Mirrored: the distance left to rest.
                let left = (length - sigma).max(0.0);
                let tau = (6.0 * left / jerk).cbrt();
                let v = 0.5 * jerk * tau * tau;
                v * v
            }
            Piece::Quadratic { a, b, c } => (a + 2.0 * b * sigma + c * sigma * sigma).max(0.0),
            Piece::Jerk { .. } => {
                let (_, speed) = self.at(self.time_to(sigma, 1.0));
                speed.max(0.0) * speed.max(0.0)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closed_form_keeps_the_quadratic_in_arc_length() {
        for (a, b, c) in [
            (100.0, 300.0, 5e4),
            (100.0, -300.0, -5e4),
            (4.0, 50.0, 1e6),
            (2500.0, 10.0, 1e-9),
        ] {
            let p = Piece::quadratic(a, b, c);
            for k in 0..=8 {
                let tau = 0.0005 * k as f64;
                let (s, v) = p.at(tau);
                let q = a + 2.0 * b * s + c * s * s;
                assert!((v * v - q).abs() <= 1e-9 * q, "{a} {b} {c} at {tau}: {} vs {q}", v * v);
            }
        }
    }

    #[test]
    fn durations_invert_the_distance() {
        let p = Piece::quadratic(400.0, -2000.0, 3e4);
        let t = p.duration(0.05).unwrap();
        assert!((p.at(t).0 - 0.05).abs() < 1e-15);
        // A piece that stops before its end never gets there.
        assert!(Piece::quadratic(1.0, -100.0, 0.0).duration(1.0).is_none());
        let (start, d) = Piece::start(1.5 * 0.01 * 200.0, 200.0).unwrap();
        assert!((start.at(d).0 - 0.01).abs() < 1e-15);
        let (stop, d, len) = Piece::stop(1.5 * 0.01 * 200.0, -200.0).unwrap();
        assert!((len - 0.01).abs() < 1e-15);
        assert!((stop.at(d).0 - 0.01).abs() < 1e-15 && stop.at(d).1.abs() < 1e-12);
    }
}
