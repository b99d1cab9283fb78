//! Allocation-free evaluation of rational B-spline curves (NURBS) and their first three
//! parameter derivatives.
//!
//! Everything here works on borrowed slices and fixed-size stack arrays sized by
//! [`MAX_DEGREE`] and [`MAX_DIM`], so the same code runs in the planner and on the servo thread.
//! Algorithms: Piegl & Tiller, *The NURBS Book*, A2.1 (span search), A2.3 (basis functions and
//! their derivatives), A4.2 (derivatives of the rational curve by the quotient rule).

use crate::math::{binomial, norm, Vector};

/// Highest supported degree (order 8).
pub const MAX_DEGREE: usize = 7;
/// Highest supported number of coordinates per control point (two 3-D curves for 5-axis).
pub const MAX_DIM: usize = 6;
/// Highest derivative order evaluated (third derivatives give axial jerk).
pub const MAX_DERIV: usize = 3;

const MAX_ORDER: usize = MAX_DEGREE + 1;

/// Why a set of knots, control points and weights is not a usable curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeometryError {
    /// Degree outside 1..=7.
    DegreeOutOfRange { degree: usize },
    /// Coordinates per point outside 2..=6.
    DimensionOutOfRange { dim: usize },
    /// Fewer control points than degree + 1.
    TooFewControlPoints { count: usize, needed: usize },
    /// The flat coordinate array is not `count * dim` long.
    PointDataMismatch { values: usize, dim: usize },
    /// One weight per control point is required.
    WeightCountMismatch { weights: usize, points: usize },
    /// A clamped knot vector has control points + degree + 1 entries.
    KnotCountMismatch { expected: usize, found: usize },
    /// A knot is NaN or infinite.
    NonFiniteKnot { index: usize },
    /// `knots[index] < knots[index - 1]`.
    KnotsDecreasing { index: usize },
    /// The first and last `degree + 1` knots must be equal (clamped curve).
    NotClamped,
    /// An interior knot repeated more than `degree` times would break the curve apart.
    InteriorKnotMultiplicity { index: usize, multiplicity: usize },
    /// The parameter domain has zero length.
    EmptyDomain,
    /// A control-point coordinate is NaN or infinite.
    NonFiniteCoordinate { point: usize, axis: usize },
    /// Weights must be finite and strictly positive.
    NonPositiveWeight { index: usize, value: f64 },
}

impl core::fmt::Display for GeometryError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use GeometryError::*;
        match *self {
            DegreeOutOfRange { degree } => write!(f, "degree {degree} is outside 1..={MAX_DEGREE}"),
            DimensionOutOfRange { dim } => {
                write!(f, "{dim} coordinates per control point; 2..={MAX_DIM} are supported")
            }
            TooFewControlPoints { count, needed } => {
                write!(f, "{count} control points; degree needs at least {needed}")
            }
            PointDataMismatch { values, dim } => {
                write!(f, "{values} coordinate values are not a whole number of {dim}-D points")
            }
            WeightCountMismatch { weights, points } => {
                write!(f, "{weights} weights for {points} control points")
            }
            KnotCountMismatch { expected, found } => write!(
                f,
                "knot vector has {found} entries; control points + degree + 1 = {expected}"
            ),
            NonFiniteKnot { index } => write!(f, "knot {index} is not a finite number"),
            KnotsDecreasing { index } => {
                write!(f, "knots are not non-decreasing: knot {index} is less than knot {}", index - 1)
            }
            NotClamped => write!(
                f,
                "knot vector is not clamped: the first and last degree + 1 knots must be equal"
            ),
            InteriorKnotMultiplicity { index, multiplicity } => write!(
                f,
                "interior knot {index} repeats {multiplicity} times, more than the degree (curve would be discontinuous)"
            ),
            EmptyDomain => write!(f, "the parameter domain has zero length"),
            NonFiniteCoordinate { point, axis } => {
                write!(f, "control point {point}, coordinate {axis} is not a finite number")
            }
            NonPositiveWeight { index, value } => {
                write!(f, "weight {index} is {value}; weights must be finite and > 0")
            }
        }
    }
}

/// How far [`CurveView::check_values`] got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValuesChecked {
    /// Every value from the first one asked for is valid.
    All,
    /// The values before this one are valid; the budget is spent.
    UpTo(usize),
}

/// Degree, dimension and the lengths of the three arrays (O(1)).
fn check_counts(
    degree: usize,
    dim: usize,
    knots: &[f64],
    points: &[f64],
    weights: &[f64],
) -> Result<(), GeometryError> {
    if !(1..=MAX_DEGREE).contains(&degree) {
        return Err(GeometryError::DegreeOutOfRange { degree });
    }
    if !(2..=MAX_DIM).contains(&dim) {
        return Err(GeometryError::DimensionOutOfRange { dim });
    }
    if !points.len().is_multiple_of(dim) {
        return Err(GeometryError::PointDataMismatch {
            values: points.len(),
            dim,
        });
    }
    let count = points.len() / dim;
    if count < degree + 1 {
        return Err(GeometryError::TooFewControlPoints {
            count,
            needed: degree + 1,
        });
    }
    if weights.len() != count {
        return Err(GeometryError::WeightCountMismatch {
            weights: weights.len(),
            points: count,
        });
    }
    if knots.len() != count + degree + 1 {
        return Err(GeometryError::KnotCountMismatch {
            expected: count + degree + 1,
            found: knots.len(),
        });
    }
    Ok(())
}

/// A validated NURBS curve borrowed from flat arrays.
///
/// `points` holds the control points one after another (`dim` values each); `weights` one
/// weight per point. Constructed through [`CurveView::new`] (or [`CurveView::trusted`] on data
/// checked before), so every evaluation may rely on a well-formed, clamped knot vector.
#[derive(Clone, Copy, Debug)]
pub struct CurveView<'a> {
    degree: usize,
    dim: usize,
    knots: &'a [f64],
    points: &'a [f64],
    weights: &'a [f64],
}

/// Curve point and derivatives with respect to the parameter: `d[0] = C(u)`, `d[1] = C'(u)`, ...
pub type Derivatives = [Vector; MAX_DERIV + 1];

/// Derivatives of a curve's homogeneous form at a parameter: `coords[k]` the k-th derivative of
/// the weighted coordinates, `weight[k]` that of the weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Homogeneous {
    pub coords: [Vector; MAX_DERIV + 1],
    pub weight: [f64; MAX_DERIV + 1],
}

impl<'a> CurveView<'a> {
    /// Validates the data (degree, dimension, clamped non-decreasing finite knots, finite
    /// coordinates, positive weights) and returns a view that can be evaluated. O(size of the
    /// data); [`CurveView::check_values`] does the same checks a slice at a time.
    pub fn new(
        degree: usize,
        dim: usize,
        knots: &'a [f64],
        points: &'a [f64],
        weights: &'a [f64],
    ) -> Result<Self, GeometryError> {
        Self::check_values(degree, dim, knots, points, weights, 0, usize::MAX)?;
        Self::trusted(degree, dim, knots, points, weights)
    }

    /// A view of data that [`CurveView::check_values`] has passed in full and that does not
    /// change while the view is used: only the counts are checked (O(1)). The realtime module
    /// takes its views this way once a published geometry is validated (a new geometry is a new
    /// generation, validated anew). Evaluation relies on the checked data: its indices stay
    /// within the slices whatever the values, and the span search is bounded, but changed knots
    /// give meaningless points (and NaN bounds would trip `f64::clamp`).
    pub fn trusted(
        degree: usize,
        dim: usize,
        knots: &'a [f64],
        points: &'a [f64],
        weights: &'a [f64],
    ) -> Result<Self, GeometryError> {
        check_counts(degree, dim, knots, points, weights)?;
        Ok(Self {
            degree,
            dim,
            knots,
            points,
            weights,
        })
    }

    /// How many checks [`CurveView::check_values`] runs on the whole of valid counts: every
    /// value once, the interior knots twice.
    pub fn value_checks(degree: usize, knots: &[f64], points: &[f64], weights: &[f64]) -> usize {
        knots.len() + weights.len().saturating_sub(degree + 1) + points.len() + weights.len()
    }

    /// The checks of [`CurveView::new`] on at most `budget` of the curve's values from value
    /// `from` on, counting the knots, then the interior knots again (their multiplicity, once
    /// the whole knot vector is known to be clamped and non-decreasing), then the coordinates,
    /// then the weights; the counts are checked on every call. Reports the same error as `new`
    /// for the same data, whatever the slices. O(1 + budget), allocation-free and panic-free.
    pub fn check_values(
        degree: usize,
        dim: usize,
        knots: &[f64],
        points: &[f64],
        weights: &[f64],
        from: usize,
        budget: usize,
    ) -> Result<ValuesChecked, GeometryError> {
        check_counts(degree, dim, knots, points, weights)?;
        let count = weights.len();
        // Interior knots whose multiplicity is checked: degree + 1 .. count.
        let interior = count - degree - 1;
        let total = Self::value_checks(degree, knots, points, weights);
        let end = from.saturating_add(budget).min(total);
        // The four stretches in turn, each a plain loop over its part of `from..end`.
        let (knots_end, interior_end) = (knots.len(), knots.len() + interior);
        let points_end = interior_end + points.len();
        for index in from.min(knots_end)..end.min(knots_end) {
            let k = knots[index];
            if !k.is_finite() {
                return Err(GeometryError::NonFiniteKnot { index });
            }
            if index > 0 && k < knots[index - 1] {
                return Err(GeometryError::KnotsDecreasing { index });
            }
        }
        if from < knots_end && end >= knots_end {
            let (first, last) = (knots[0], knots[knots_end - 1]);
            if knots[..=degree].iter().any(|k| *k != first)
                || knots[knots_end - degree - 1..].iter().any(|k| *k != last)
            {
                return Err(GeometryError::NotClamped);
            }
            if last <= first {
                return Err(GeometryError::EmptyDomain);
            }
        }
        for index in from.max(knots_end).min(interior_end)..end.max(knots_end).min(interior_end) {
            // Knots are non-decreasing here, so a run of more than `degree` equal knots
            // starting at `i` shows in its first and (degree + 1)-th knot.
            let i = degree + 1 + (index - knots_end);
            let run_start = i == degree + 1 || knots[i - 1] != knots[i];
            if run_start && i + degree < count && knots[i + degree] == knots[i] {
                let mut multiplicity = degree + 1;
                while i + multiplicity < count && knots[i + multiplicity] == knots[i] {
                    multiplicity += 1;
                }
                return Err(GeometryError::InteriorKnotMultiplicity { index: i, multiplicity });
            }
        }
        for index in from.max(interior_end).min(points_end)..end.max(interior_end).min(points_end) {
            let i = index - interior_end;
            if !points[i].is_finite() {
                return Err(GeometryError::NonFiniteCoordinate {
                    point: i / dim,
                    axis: i % dim,
                });
            }
        }
        for index in from.max(points_end).min(total)..end.max(points_end).min(total) {
            let i = index - points_end;
            let w = weights[i];
            if !(w.is_finite() && w > 0.0) {
                return Err(GeometryError::NonPositiveWeight { index: i, value: w });
            }
        }
        Ok(if end >= total {
            ValuesChecked::All
        } else {
            ValuesChecked::UpTo(end)
        })
    }

    pub fn degree(&self) -> usize {
        self.degree
    }
    pub fn dim(&self) -> usize {
        self.dim
    }
    pub fn knots(&self) -> &'a [f64] {
        self.knots
    }
    pub fn points(&self) -> &'a [f64] {
        self.points
    }
    pub fn weights(&self) -> &'a [f64] {
        self.weights
    }
    pub fn control_point_count(&self) -> usize {
        self.weights.len()
    }
    /// First parameter value of the curve.
    pub fn u_min(&self) -> f64 {
        self.knots[self.degree]
    }
    /// Last parameter value of the curve.
    pub fn u_max(&self) -> f64 {
        self.knots[self.weights.len()]
    }

    /// Knot span index `i` with `knots[i] <= u < knots[i+1]` (A2.1); `u` is clamped to the domain
    /// and the last non-empty span is used at `u_max`.
    pub fn find_span(&self, u: f64) -> usize {
        let n = self.weights.len() - 1;
        if u >= self.knots[n + 1] {
            // Last non-empty span: step back over the clamped end knots.
            let mut i = n;
            while i > self.degree && self.knots[i] >= self.knots[n + 1] {
                i -= 1;
            }
            return i;
        }
        if u <= self.knots[self.degree] {
            let mut i = self.degree;
            while i < n && self.knots[i + 1] <= self.knots[self.degree] {
                i += 1;
            }
            return i;
        }
        let (mut low, mut high) = (self.degree, n + 1);
        let mut mid = (low + high) / 2;
        // Halving ends within log2(n) + 1 rounds on valid knots; the bound keeps a period
        // finite should the data have changed under a trusted view.
        for _ in 0..usize::BITS {
            if !(u < self.knots[mid] || u >= self.knots[mid + 1]) {
                break;
            }
            if u < self.knots[mid] {
                high = mid;
            } else {
                low = mid;
            }
            mid = (low + high) / 2;
        }
        mid
    }

    /// The table of A2.3 at `u` in `span`: the basis functions in its upper triangle
    /// (`ndu[j][degree]` is N_{span-degree+j, degree}), knot differences in its lower one.
    #[inline]
    fn basis_triangle(&self, span: usize, u: f64) -> [[f64; MAX_ORDER]; MAX_ORDER] {
        let p = self.degree;
        let knots = self.knots;
        let mut ndu = [[0.0f64; MAX_ORDER]; MAX_ORDER];
        let mut left = [0.0f64; MAX_ORDER];
        let mut right = [0.0f64; MAX_ORDER];
        ndu[0][0] = 1.0;
        for j in 1..=p {
            left[j] = u - knots[span + 1 - j];
            right[j] = knots[span + j] - u;
            let mut saved = 0.0;
            for r in 0..j {
                // Lower triangle: knot differences; upper triangle: basis functions.
                ndu[j][r] = right[r + 1] + left[j - r];
                let temp = ndu[r][j - 1] / ndu[j][r];
                ndu[r][j] = saved + right[r + 1] * temp;
                saved = left[j - r] * temp;
            }
            ndu[j][j] = saved;
        }
        ndu
    }

    /// Non-zero basis functions and their derivatives up to `order` at `u` in `span` (A2.3).
    /// `ders[k][j]` is the k-th derivative of N_{span-degree+j, degree}.
    fn basis_derivatives(&self, span: usize, u: f64, order: usize) -> [[f64; MAX_ORDER]; MAX_DERIV + 1] {
        let p = self.degree;
        let ndu = self.basis_triangle(span, u);
        let mut ders = [[0.0f64; MAX_ORDER]; MAX_DERIV + 1];
        for j in 0..=p {
            ders[0][j] = ndu[j][p];
        }
        let order = order.min(p).min(MAX_DERIV);
        let mut a = [[0.0f64; MAX_ORDER]; 2];
        for r in 0..=p {
            let (mut s1, mut s2) = (0usize, 1usize);
            a[0][0] = 1.0;
            for k in 1..=order {
                let mut d = 0.0;
                let rk = r as isize - k as isize;
                let pk = p - k;
                if r >= k {
                    a[s2][0] = a[s1][0] / ndu[pk + 1][rk as usize];
                    d = a[s2][0] * ndu[rk as usize][pk];
                }
                let j1 = if rk >= -1 { 1 } else { (-rk) as usize };
                let j2 = if r as isize - 1 <= pk as isize { k - 1 } else { p - r };
                for j in j1..=j2 {
                    let idx = (rk + j as isize) as usize;
                    a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][idx];
                    d += a[s2][j] * ndu[idx][pk];
                }
                if r <= pk {
                    a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
                    d += a[s2][k] * ndu[r][pk];
                }
                ders[k][r] = d;
                core::mem::swap(&mut s1, &mut s2);
            }
        }
        // Multiply by p!/(p-k)!.
        let mut factor = p as f64;
        for (k, row) in ders.iter_mut().enumerate().take(order + 1).skip(1) {
            for v in row.iter_mut().take(p + 1) {
                *v *= factor;
            }
            factor *= (p - k) as f64;
        }
        ders
    }

    /// Point and derivatives up to `order` (≤ 3) at `u` (clamped to the domain); higher entries
    /// are zero. Rational quotient rule of A4.2.
    pub fn derivatives(&self, u: f64, order: usize) -> Derivatives {
        let u = u.clamp(self.u_min(), self.u_max());
        self.derivatives_in_span(u, self.find_span(u), order)
    }

    /// Left-hand limits of the derivatives at `u`: evaluated on the non-empty span that ends at
    /// or after `u` coming from below (differs from [`Self::derivatives`] only at knots).
    pub fn derivatives_left(&self, u: f64, order: usize) -> Derivatives {
        let u = u.clamp(self.u_min(), self.u_max());
        let mut span = self.find_span(u);
        while span > self.degree && self.knots[span] >= u {
            span -= 1;
        }
        self.derivatives_in_span(u, span, order)
    }

    fn derivatives_in_span(&self, u: f64, span: usize, order: usize) -> Derivatives {
        let order = order.min(MAX_DERIV);
        self.rational(&self.homogeneous_in_span(u, span, order), order)
    }

    /// Derivatives up to `order` (≤ 3) of the homogeneous curve (weighted coordinates and
    /// weight) at `u` on knot span `span` (as [`Self::find_span`] gives it):
    /// A^(k) = sum N^(k) w P, w^(k) = sum N^(k) w.
    pub fn homogeneous_in_span(&self, u: f64, span: usize, order: usize) -> Homogeneous {
        let order = order.min(MAX_DERIV);
        let basis = self.basis_derivatives(span, u, order);
        let p = self.degree;
        let dim = self.dim;
        let mut h = Homogeneous::default();
        let kmax = order.min(p);
        for j in 0..=p {
            let i = span - p + j;
            let wi = self.weights[i];
            let point = &self.points[i * dim..i * dim + dim];
            for k in 0..=kmax {
                let nw = basis[k][j] * wi;
                h.weight[k] += nw;
                for (acc, c) in h.coords[k].iter_mut().zip(point) {
                    *acc += nw * c;
                }
            }
        }
        h
    }

    /// Derivatives of the curve up to `order` (≤ 3) from those of its homogeneous form
    /// (quotient rule, A4.2).
    pub fn rational(&self, h: &Homogeneous, order: usize) -> Derivatives {
        let (aw, w) = (&h.coords, &h.weight);
        let mut out = [[0.0f64; MAX_DIM]; MAX_DERIV + 1];
        for k in 0..=order.min(MAX_DERIV) {
            let mut v = aw[k];
            for i in 1..=k {
                let factor = binomial(k, i) * w[i];
                for (x, c) in v.iter_mut().zip(out[k - i].iter()) {
                    *x -= factor * c;
                }
            }
            for x in v.iter_mut().take(self.dim) {
                *x /= w[0];
            }
            out[k] = v;
        }
        out
    }

    /// Curve point at `u`: equal bit for bit to `derivatives(u, 0)[0]`, at about half the cost
    /// (the planner's chord-error probes take it several times per period).
    pub fn point(&self, u: f64) -> Vector {
        let u = u.clamp(self.u_min(), self.u_max());
        let span = self.find_span(u);
        let basis = self.basis_functions(span, u);
        let (p, dim) = (self.degree, self.dim);
        let mut aw = [0.0f64; MAX_DIM];
        let mut w = 0.0;
        for (j, n) in basis.iter().enumerate().take(p + 1) {
            let i = span - p + j;
            let nw = n * self.weights[i];
            w += nw;
            for (acc, c) in aw.iter_mut().zip(&self.points[i * dim..i * dim + dim]) {
                *acc += nw * c;
            }
        }
        for x in aw.iter_mut().take(dim) {
            *x /= w;
        }
        aw
    }

    /// The non-zero basis functions on `span` at `u` (A2.2).
    fn basis_functions(&self, span: usize, u: f64) -> [f64; MAX_ORDER] {
        basis_functions(self.knots, span, self.degree, u)
    }

    /// Parametric speed |C'(u)| of the first `axes` coordinates (the tool-tip curve of a
    /// two-curve 5-axis path uses 3 of 6).
    ///
    /// Equal bit for bit to the norm of `derivatives(u, 1)[1]`: the same arithmetic step for
    /// step (A2.3 at first order, the homogeneous sums, the quotient rule), without the arrays
    /// of the higher orders. Arc-length integration takes it hundreds of times per element; it
    /// was a third of the planning time on dense G1 programs.
    pub fn speed(&self, u: f64, axes: usize) -> f64 {
        let p = self.degree;
        if p == 0 {
            return norm(&self.derivatives(u, 1)[1], axes);
        }
        let u = u.clamp(self.u_min(), self.u_max());
        let span = self.find_span(u);
        let ndu = self.basis_triangle(span, u);
        let dim = self.dim;
        let (mut aw0, mut aw1) = ([0.0f64; MAX_DIM], [0.0f64; MAX_DIM]);
        let (mut w0, mut w1) = (0.0, 0.0);
        for j in 0..=p {
            // First derivative of N_{span-p+j, p} (A2.3 at k = 1, then times p).
            let mut d = 0.0;
            if j >= 1 {
                d = 1.0 / ndu[p][j - 1] * ndu[j - 1][p - 1];
            }
            if j < p {
                d += -1.0 / ndu[p][j] * ndu[j][p - 1];
            }
            let n1 = d * p as f64;
            let i = span - p + j;
            let wi = self.weights[i];
            let point = &self.points[i * dim..i * dim + dim];
            let nw0 = ndu[j][p] * wi;
            w0 += nw0;
            for (acc, c) in aw0.iter_mut().zip(point) {
                *acc += nw0 * c;
            }
            let nw1 = n1 * wi;
            w1 += nw1;
            for (acc, c) in aw1.iter_mut().zip(point) {
                *acc += nw1 * c;
            }
        }
        let mut d1 = [0.0f64; MAX_DIM];
        for k in 0..dim.min(axes) {
            d1[k] = (aw1[k] - w1 * (aw0[k] / w0)) / w0;
        }
        norm(&d1, axes)
    }
}

/// The non-zero basis functions of degree `degree` on knot span `span` at `u` (P&T A2.2), with
/// the arithmetic of the upper triangle of [`CurveView::basis_derivatives`] step for step (so
/// that [`CurveView::point`] equals the zeroth derivative bit for bit). `span` must be a valid
/// span of `knots` for `degree` (`degree <= span < knots.len() - degree - 1`).
pub fn basis_functions(knots: &[f64], span: usize, degree: usize, u: f64) -> [f64; MAX_ORDER] {
    let mut n = [0.0f64; MAX_ORDER];
    let mut left = [0.0f64; MAX_ORDER];
    let mut right = [0.0f64; MAX_ORDER];
    n[0] = 1.0;
    for j in 1..=degree.min(MAX_DEGREE) {
        left[j] = u - knots[span + 1 - j];
        right[j] = knots[span + j] - u;
        let mut saved = 0.0;
        for r in 0..j {
            let temp = n[r] / (right[r + 1] + left[j - r]);
            n[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        n[j] = saved;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checking a curve's values a slice at a time reports what one whole check reports, for
    /// every slice size: valid data, and one fault of each kind placed early and late.
    #[test]
    fn sliced_checks_report_what_the_whole_check_reports() {
        let degree = 3;
        let knots = [0.0, 0.0, 0.0, 0.0, 0.2, 0.5, 0.5, 0.8, 1.0, 1.0, 1.0, 1.0];
        let points: Vec<f64> = (0..16).map(|i| i as f64 * 0.7).collect();
        let weights = [1.0, 0.5, 2.0, 1.0, 1.0, 3.0, 1.0, 1.0];
        type Corrupt = fn(&mut [f64; 12], &mut Vec<f64>, &mut [f64; 8]);
        let cases: [(Corrupt, Option<GeometryError>); 10] = [
            (|_, _, _| {}, None),
            (
                |k, _, _| k[1] = f64::NAN,
                Some(GeometryError::NonFiniteKnot { index: 1 }),
            ),
            (
                |k, _, _| k[9] = f64::INFINITY,
                Some(GeometryError::NonFiniteKnot { index: 9 }),
            ),
            (|k, _, _| k[7] = 0.4, Some(GeometryError::KnotsDecreasing { index: 7 })),
            (|k, _, _| k[11] = 1.5, Some(GeometryError::NotClamped)),
            (
                |k, _, _| k[4..8].copy_from_slice(&[0.5; 4]),
                Some(GeometryError::InteriorKnotMultiplicity {
                    index: 4,
                    multiplicity: 4,
                }),
            ),
            (
                |_, p, _| p[0] = f64::NAN,
                Some(GeometryError::NonFiniteCoordinate { point: 0, axis: 0 }),
            ),
            (
                |_, p, _| p[13] = f64::NEG_INFINITY,
                Some(GeometryError::NonFiniteCoordinate { point: 6, axis: 1 }),
            ),
            (
                |_, _, w| w[7] = 0.0,
                Some(GeometryError::NonPositiveWeight { index: 7, value: 0.0 }),
            ),
            (
                |k, _, w| {
                    k[3] = f64::NAN;
                    w[0] = -1.0
                },
                Some(GeometryError::NonFiniteKnot { index: 3 }),
            ),
        ];
        for (corrupt, expected) in cases {
            let (mut k, mut p, mut w) = (knots, points.clone(), weights);
            corrupt(&mut k, &mut p, &mut w);
            let whole = CurveView::new(degree, 2, &k, &p, &w).map(|_| ());
            assert_eq!(whole.err(), expected);
            for budget in 1..40 {
                let mut from = 0;
                let sliced = loop {
                    match CurveView::check_values(degree, 2, &k, &p, &w, from, budget) {
                        Ok(ValuesChecked::UpTo(next)) => {
                            assert_eq!(next, from + budget, "a slice checks its whole budget");
                            from = next;
                        }
                        Ok(ValuesChecked::All) => break Ok(()),
                        Err(e) => break Err(e),
                    }
                };
                assert_eq!(sliced.err(), expected, "budget {budget}");
            }
        }
    }

    /// `point` is `derivatives(u, 0)[0]` and `speed` the norm of `derivatives(u, 1)[1]` bit for
    /// bit: every degree and dimension, rational weights, a double interior knot, at the ends,
    /// at knots and between, over every number of axes.
    #[test]
    fn point_and_speed_equal_the_derivatives_bit_for_bit() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for degree in 1..=MAX_DEGREE {
            for dim in 2..=MAX_DIM {
                let count = degree + 4;
                let mut knots = vec![0.0; degree + 1];
                // Three interior knots; a double one where the degree allows it.
                let interior = if degree == 1 {
                    [0.2, 0.45, 0.8]
                } else {
                    [0.2, 0.45, 0.45]
                };
                knots.extend(interior);
                knots.extend(vec![1.0; degree + 1]);
                let mut points = [0.0f64; 11 * MAX_DIM];
                let mut weights = [0.0f64; 11];
                for v in points.iter_mut().take(count * dim) {
                    *v = 200.0 * next() - 100.0;
                }
                for w in weights.iter_mut().take(count) {
                    *w = 0.2 + 4.8 * next();
                }
                let view = CurveView::new(degree, dim, &knots, &points[..count * dim], &weights[..count]).unwrap();
                let mut us: [f64; 64] = [0.0; 64];
                us[..6].copy_from_slice(&[0.0, 1.0, 0.2, 0.45, 0.8, -0.5]);
                for u in us.iter_mut().skip(6) {
                    *u = next();
                }
                for u in us {
                    let fast = view.point(u);
                    let reference = view.derivatives(u, 0)[0];
                    assert!(
                        fast.iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()),
                        "degree {degree}, dim {dim}, u {u}: {fast:?} vs {reference:?}"
                    );
                    for axes in 1..=dim {
                        let (fast, reference) = (view.speed(u, axes), norm(&view.derivatives(u, 1)[1], axes));
                        assert_eq!(
                            fast.to_bits(),
                            reference.to_bits(),
                            "degree {degree}, dim {dim}, axes {axes}, u {u}"
                        );
                    }
                }
            }
        }
    }
}
