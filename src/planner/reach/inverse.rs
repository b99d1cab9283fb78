//! The curve parameter at an arc length inside an interval, for sampling: u(σ) as quintic
//! Hermite pieces, each matching u, du/dσ and d²u/dσ² at its ends (so the samples run on a
//! parameterisation with continuous second derivative) and checked against the arc length
//! inside (two points, each to [`TOLERANCE`]), halved where it misses. An interval is fitted once
//! and kept: the stops branching off a plan cross the same intervals again and again, and a
//! sample then costs one polynomial instead of Newton's method on Gauss-Legendre lengths (some
//! 8 curve evaluations). Where no fit within [`MAX_DEPTH`] halvings passes, the sampler inverts
//! by Newton's method as before.

use super::grid::piece_length;
use super::sampler::invert;
use nurbs_rtcore::CurveView;
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

/// Largest distance (mm) of a fitted parameter's arc length from the one asked for, at the
/// points checked: below the rounding of positions some 100 mm from the origin (1.4e-12 mm).
const TOLERANCE: f64 = 1e-13;
/// Halvings of an interval tried before it is left to Newton's method (at most 8 pieces).
const MAX_DEPTH: u32 = 3;
/// Where each piece is checked, as fractions of it (its error is largest inside, zero at the
/// ends with its first two derivatives).
const CHECKED_AT: [f64; 2] = [0.3, 0.7];

/// One quintic Hermite piece of u(σ), from `start` (σ into the interval) over `h`.
#[derive(Clone, Copy, Debug)]
struct Piece {
    start: f64,
    h: f64,
    u0: f64,
    u1: f64,
    /// h·du/dσ at either end.
    d0: f64,
    d1: f64,
    /// h²·d²u/dσ² at either end.
    c0: f64,
    c1: f64,
}

impl Piece {
    fn new(start: f64, h: f64, (u0, du0, ddu0): (f64, f64, f64), (u1, du1, ddu1): (f64, f64, f64)) -> Self {
        Piece {
            start,
            h,
            u0,
            u1,
            d0: h * du0,
            d1: h * du1,
            c0: h * h * ddu0,
            c1: h * h * ddu1,
        }
    }

    /// u at `sigma` (into the interval), within the piece's parameter range.
    fn at(&self, sigma: f64) -> f64 {
        let t = (sigma - self.start) / self.h;
        let (t2, t3) = (t * t, t * t * t);
        let (t4, t5) = (t3 * t, t3 * t2);
        // The quintic Hermite basis: values, first and second derivatives at 0 and 1.
        let h5 = 10.0 * t3 - 15.0 * t4 + 6.0 * t5;
        let h1 = t - 6.0 * t3 + 8.0 * t4 - 3.0 * t5;
        let h2 = 0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5);
        let h3 = 0.5 * (t3 - 2.0 * t4 + t5);
        let h4 = -4.0 * t3 + 7.0 * t4 - 3.0 * t5;
        let u = self.u0 + (self.u1 - self.u0) * h5 + self.d0 * h1 + self.c0 * h2 + self.c1 * h3 + self.d1 * h4;
        u.clamp(self.u0, self.u1)
    }
}

/// u and its first two arc-length derivatives at `u` (from the left at an interval's end,
/// which may be a knot): du/dσ = 1/|C'|, d²u/dσ² = −(C'·C'')/|C'|⁴.
fn ends(view: &CurveView, u: f64, axes: usize, left: bool) -> Option<(f64, f64, f64)> {
    let d = if left {
        view.derivatives_left(u, 2)
    } else {
        view.derivatives(u, 2)
    };
    let dot = |i: usize, j: usize| (0..axes).map(|k| d[i][k] * d[j][k]).sum::<f64>();
    let speed2 = dot(1, 1);
    (speed2 > 0.0 && speed2.is_finite()).then(|| (u, 1.0 / speed2.sqrt(), -dot(1, 2) / (speed2 * speed2)))
}

/// An interval (its element and the bits of its first and last parameter) and its fit.
type Fits = HashMap<(usize, u64, u64), Option<Rc<[Piece]>>>;

/// Fits each generation of [`Inverses`] keeps (a stop's own intervals, where its phases begin
/// inside one of the plan's, are not asked for again: the older generation is dropped).
const FITS_KEPT: usize = 1 << 14;

/// The fitted intervals of one plan (with its stops), each with its pieces or none: the newer
/// and the older of two generations.
#[derive(Default)]
pub struct Inverses {
    fits: RefCell<[Fits; 2]>,
}

/// An interval's fit, as [`Inverses::fit`] hands it to the sampler.
#[derive(Clone)]
pub struct Fit(Rc<[Piece]>);

impl Fit {
    /// u at `sigma` into the interval (0 < sigma < its length).
    pub fn at(&self, sigma: f64) -> f64 {
        let k = self.0.partition_point(|p| p.start + p.h <= sigma).min(self.0.len() - 1);
        self.0[k].at(sigma)
    }
}

impl Inverses {
    /// The fit of `element`'s interval from `ua` to `ub`, `length` long; `None` where none
    /// passes its checks.
    pub fn fit(&self, view: &CurveView, element: usize, (ua, ub): (f64, f64), length: f64, axes: usize) -> Option<Fit> {
        let key = (element, ua.to_bits(), ub.to_bits());
        if let Some(found) = {
            let fits = self.fits.borrow();
            fits[0].get(&key).or_else(|| fits[1].get(&key)).cloned()
        } {
            return found.map(Fit);
        }
        let fitted = fit_interval(view, ua, ub, length, axes).map(Rc::from);
        let mut fits = self.fits.borrow_mut();
        if fits[0].len() >= FITS_KEPT {
            fits[1] = std::mem::take(&mut fits[0]);
        }
        fits[0].insert(key, fitted.clone());
        fitted.map(Fit)
    }
}

fn fit_interval(view: &CurveView, ua: f64, ub: f64, length: f64, axes: usize) -> Option<Vec<Piece>> {
    if !(length > 0.0 && ub > ua) {
        return None;
    }
    let a = ends(view, ua, axes, false)?;
    let b = ends(view, ub, axes, true)?;
    let mut pieces = Vec::new();
    fit_piece(view, axes, (0.0, a), (length, b), MAX_DEPTH, &mut pieces).then_some(pieces)
}

/// Fits u(σ) from `(sa, a)` to `(sb, b)`, halving up to `depth` times; false where it fails.
fn fit_piece(
    view: &CurveView,
    axes: usize,
    (sa, a): (f64, (f64, f64, f64)),
    (sb, b): (f64, (f64, f64, f64)),
    depth: u32,
    pieces: &mut Vec<Piece>,
) -> bool {
    let piece = Piece::new(sa, sb - sa, a, b);
    let passes = CHECKED_AT.iter().all(|f| {
        let sigma = sa + f * (sb - sa);
        let u = piece.at(sigma);
        (sa + piece_length(view, a.0, u, axes) - sigma).abs() <= TOLERANCE
    });
    if passes {
        pieces.push(piece);
        return true;
    }
    if depth == 0 {
        return false;
    }
    let sm = 0.5 * (sa + sb);
    let um = invert(view, a.0, sa, sm, a.0, b.0, axes, None).0;
    let Some(m) = ends(view, um, axes, false) else {
        return false;
    };
    fit_piece(view, axes, (sa, a), (sm, m), depth - 1, pieces)
        && fit_piece(view, axes, (sm, m), (sb, b), depth - 1, pieces)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Nurbs;

    /// A quarter circle as a rational quadratic, and a cubic with uneven parametric speed:
    /// every fitted parameter's arc length within the tolerance of the one asked for, at 1,000
    /// points of each interval, and the fit continuous in value across its pieces.
    #[test]
    fn fitted_parameters_have_the_arc_length_asked_for() {
        let w = std::f64::consts::FRAC_1_SQRT_2;
        let circle = Nurbs::new(
            2,
            vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            &[vec![10.0, 0.0], vec![10.0, 10.0], vec![0.0, 10.0]],
            Some(vec![1.0, w, 1.0]),
        )
        .unwrap();
        let cubic = Nurbs::new(
            3,
            vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
            &[vec![0.0, 0.0], vec![0.1, 3.0], vec![5.0, -2.0], vec![6.0, 1.0]],
            None,
        )
        .unwrap();
        let inverses = Inverses::default();
        let mut fitted = 0;
        for (element, curve) in [circle, cubic].iter().enumerate() {
            let view = curve.view();
            let steps = 37;
            for k in 0..steps {
                let (ua, ub) = (k as f64 / steps as f64, (k + 1) as f64 / steps as f64);
                let length = piece_length(&view, ua, ub, 2);
                let Some(fit) = inverses.fit(&view, element, (ua, ub), length, 2) else {
                    continue;
                };
                fitted += 1;
                for n in 1..1000 {
                    let sigma = length * n as f64 / 1000.0;
                    let u = fit.at(sigma);
                    let error = (piece_length(&view, ua, u, 2) - sigma).abs();
                    assert!(
                        error <= 2.0 * TOLERANCE,
                        "element {element}, interval {k}, σ {sigma}: {error:e}"
                    );
                }
            }
        }
        assert!(fitted >= 60, "only {fitted} of 74 intervals fitted");
    }
}
