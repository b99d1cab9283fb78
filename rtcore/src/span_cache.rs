//! Curve evaluation through Taylor polynomials of the knot spans in use.
//!
//! On one knot span a NURBS curve of degree p is the quotient of polynomials of degree p, so
//! for p <= 3 the derivatives of its homogeneous form at the span's start ([`Homogeneous`])
//! describe the whole span exactly, and evaluating anywhere in it costs a few multiplications
//! instead of a span search and the basis functions with their derivatives. The interpolator
//! evaluates the curve several times per period, nearly always in the span of the period before,
//! and the planner's trials (which run that interpolator) and the FLF scan far more often.
//!
//! The result of an evaluation depends on the span and the parameter only, never on what the
//! cache held before: a miss computes the span's polynomials and evaluates them as a hit would.
//! So the servo thread and the planner's checkpointed copies produce the same setpoints bit for
//! bit, whatever their caches hold. Curves of degree above 3 are evaluated by
//! [`CurveView::derivatives`] directly.
//!
//! Plain data, no allocation: [`SpanCache`] is `Copy` and lives in the interpolator's state.

use crate::math::Vector;
use crate::nurbs::{CurveView, Derivatives, Homogeneous, MAX_DERIV};

/// One span's Taylor data, and what identifies the span.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct SpanEntry {
    /// Address of the curve's knot vector (`0`: empty entry) and the span index.
    knots: usize,
    span: usize,
    /// The span's parameter range `[start, end)`.
    start: f64,
    end: f64,
    /// Derivatives of the homogeneous form at `start`.
    at_start: Homogeneous,
}

/// Taylor data of the two knot spans used last (two, so that evaluations on both sides of a
/// knot, as a step across it makes, do not evict each other).
///
/// A span is known by the address of its curve's knots and its index, so curve data rewritten
/// in place must come with a new generation ([`SpanCache::use_generation`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpanCache {
    entries: [SpanEntry; 2],
    /// Index of the entry used last.
    latest: usize,
    /// Generation of the curve data the entries were taken from.
    generation: u64,
}

impl SpanCache {
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets every span if the curve data's generation is not the one the entries come from
    /// (the HAL module's geometry is rewritten in place when a plan is replaced).
    pub fn use_generation(&mut self, generation: u64) {
        if generation != self.generation {
            *self = SpanCache {
                generation,
                ..Self::default()
            };
        }
    }
}

/// A curve evaluated through a [`SpanCache`].
pub struct CachedCurve<'a, 'c> {
    view: CurveView<'a>,
    cache: &'c mut SpanCache,
}

impl<'a, 'c> CachedCurve<'a, 'c> {
    pub fn new(view: CurveView<'a>, cache: &'c mut SpanCache) -> Self {
        CachedCurve { view, cache }
    }

    /// The curve itself (knots, domain, and evaluation without the cache).
    pub fn view(&self) -> CurveView<'a> {
        self.view
    }

    /// Point and derivatives up to `order` (<= 3) at `u` (clamped to the domain), as
    /// [`CurveView::derivatives`] gives them to rounding; higher entries are zero.
    pub fn derivatives(&mut self, u: f64, order: usize) -> Derivatives {
        self.evaluate(u, order, false)
    }

    /// Left-hand limits at `u`, as [`CurveView::derivatives_left`] (they differ from
    /// [`Self::derivatives`] only at knots).
    pub fn derivatives_left(&mut self, u: f64, order: usize) -> Derivatives {
        self.evaluate(u, order, true)
    }

    fn evaluate(&mut self, u: f64, order: usize, left: bool) -> Derivatives {
        let u = u.clamp(self.view.u_min(), self.view.u_max());
        if self.view.degree() > MAX_DERIV {
            return if left {
                self.view.derivatives_left(u, order)
            } else {
                self.view.derivatives(u, order)
            };
        }
        let k = self.entry(u, left);
        from_taylor(&self.view, &self.cache.entries[k], u, order)
    }

    /// Curve point at `u`: equal bit for bit to `self.derivatives(u, 0)[0]`.
    pub fn point(&mut self, u: f64) -> Vector {
        self.derivatives(u, 0)[0]
    }

    /// Index of the entry of the span holding `u` (from the right, or for `left` from the
    /// left), filled on a miss.
    fn entry(&mut self, u: f64, left: bool) -> usize {
        let knots = self.view.knots();
        let address = knots.as_ptr() as usize;
        let holds = |e: &SpanEntry| {
            e.knots == address
                && if left {
                    u > e.start && u <= e.end
                } else {
                    u >= e.start && u < e.end
                }
        };
        let latest = self.cache.latest;
        let other = 1 - latest;
        if holds(&self.cache.entries[latest]) {
            return latest;
        }
        if holds(&self.cache.entries[other]) {
            self.cache.latest = other;
            return other;
        }
        // The span as `CurveView::derivatives` / `derivatives_left` choose it; at the domain's
        // ends that is a span `u` lies on the closed end of.
        let mut span = self.view.find_span(u);
        if left {
            while span > self.view.degree() && knots[span] >= u {
                span -= 1;
            }
        }
        let (start, end) = (knots[span], knots[span + 1]);
        let e = &mut self.cache.entries[other];
        if !(e.knots == address && e.span == span) {
            *e = SpanEntry {
                knots: address,
                span,
                start,
                end,
                at_start: self.view.homogeneous_in_span(start, span, MAX_DERIV),
            };
        }
        self.cache.latest = other;
        other
    }
}

/// The curve's derivatives up to `order` at `u` from a span's Taylor data (exact for degree
/// <= 3: the fourth derivative of the homogeneous form vanishes on a span).
#[inline]
fn from_taylor(view: &CurveView, entry: &SpanEntry, u: f64, order: usize) -> Derivatives {
    let order = order.min(MAX_DERIV);
    let t = u - entry.start;
    let (c, w) = (&entry.at_start.coords, &entry.at_start.weight);
    // Order k: sum over m >= k of c[m] t^(m-k) / (m-k)!, by Horner.
    let taylor = |c0: f64, c1: f64, c2: f64, c3: f64| c0 + t * (c1 + t / 2.0 * (c2 + t / 3.0 * c3));
    let mut h = Homogeneous::default();
    for i in 0..view.dim() {
        h.coords[0][i] = taylor(c[0][i], c[1][i], c[2][i], c[3][i]);
    }
    h.weight[0] = taylor(w[0], w[1], w[2], w[3]);
    if order >= 1 {
        for i in 0..view.dim() {
            h.coords[1][i] = taylor(c[1][i], c[2][i], c[3][i], 0.0);
        }
        h.weight[1] = taylor(w[1], w[2], w[3], 0.0);
    }
    if order >= 2 {
        for i in 0..view.dim() {
            h.coords[2][i] = taylor(c[2][i], c[3][i], 0.0, 0.0);
        }
        h.weight[2] = taylor(w[2], w[3], 0.0, 0.0);
    }
    if order >= 3 {
        h.coords[3] = c[3];
        h.weight[3] = w[3];
    }
    view.rational(&h, order)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The cached evaluation agrees with the de Boor evaluation to rounding, on random rational
    /// curves of degree 1-3 with repeated knots, and is the same bit for bit whatever the cache
    /// held before (a fresh cache gives the same values as one used in any order).
    #[test]
    fn cached_derivatives_match_de_boor_and_do_not_depend_on_history() {
        let mut seed = 7u64;
        for degree in 1..=3 {
            for dim in [2, 3, 6] {
                let mut knots = vec![0.0; degree + 1];
                // A double knot (C1 for a cubic) where the degree allows it.
                knots.extend(if degree == 1 {
                    &[0.2, 0.45, 0.7][..]
                } else {
                    &[0.2, 0.45, 0.45, 0.7][..]
                });
                knots.extend(vec![1.0; degree + 1]);
                let count = knots.len() - degree - 1;
                let points: Vec<f64> = (0..count * dim).map(|_| 200.0 * lcg(&mut seed) - 100.0).collect();
                let weights: Vec<f64> = (0..count).map(|_| 0.2 + 4.8 * lcg(&mut seed)).collect();
                let view = CurveView::new(degree, dim, &knots, &points, &weights).unwrap();
                let mut used = SpanCache::new();
                let mut us: Vec<f64> = vec![0.0, 1.0, 0.2, 0.45, 0.7, -0.5, 1.5];
                us.extend((0..200).map(|_| lcg(&mut seed)));
                for &u in &us {
                    for order in 0..=3 {
                        for left in [false, true] {
                            let run = |cache: &mut SpanCache| {
                                let mut c = CachedCurve::new(view, cache);
                                if left {
                                    c.derivatives_left(u, order)
                                } else {
                                    c.derivatives(u, order)
                                }
                            };
                            let history = run(&mut used);
                            let fresh = run(&mut SpanCache::new());
                            let reference = if left {
                                view.derivatives_left(u, order)
                            } else {
                                view.derivatives(u, order)
                            };
                            for k in 0..=order {
                                for i in 0..dim {
                                    assert_eq!(history[k][i].to_bits(), fresh[k][i].to_bits(), "u {u} k {k}");
                                    let scale = 1.0
                                        + reference[k][i]
                                            .abs()
                                            .max(reference[k].iter().map(|x| x.abs()).fold(0.0, f64::max));
                                    assert!(
                                        (history[k][i] - reference[k][i]).abs() <= 1e-9 * scale,
                                        "degree {degree} dim {dim} u {u} order {order} left {left} k {k}: {} vs {}",
                                        history[k][i],
                                        reference[k][i]
                                    );
                                }
                            }
                        }
                    }
                    let p = CachedCurve::new(view, &mut used).point(u);
                    let d = CachedCurve::new(view, &mut SpanCache::new()).derivatives(u, 2)[0];
                    assert!(p.iter().zip(&d).all(|(a, b)| a.to_bits() == b.to_bits()));
                }
            }
        }
    }
}
