use nurbs_rtcore::math::{dot, Vector};
use nurbs_rtcore::{CurveView, GeometryError};

/// A validated NURBS curve owning its data.
///
/// `tip_dim` is the number of leading coordinates that form the tool-tip path (2 or 3); a
/// two-curve 5-axis path stores tip and top curve side by side (`dim = 2 * tip_dim`).
#[derive(Clone, Debug, PartialEq)]
pub struct Nurbs {
    degree: usize,
    dim: usize,
    tip_dim: usize,
    knots: Vec<f64>,
    points: Vec<f64>,
    weights: Vec<f64>,
}

impl Nurbs {
    /// Builds and validates a curve from control points given as rows of `dim` coordinates.
    pub fn new(
        degree: usize,
        knots: Vec<f64>,
        control_points: &[Vec<f64>],
        weights: Option<Vec<f64>>,
    ) -> Result<Self, GeometryError> {
        let dim = control_points.first().map_or(0, |p| p.len());
        if let Some(bad) = control_points.iter().position(|p| p.len() != dim) {
            return Err(GeometryError::PointDataMismatch {
                values: control_points[bad].len(),
                dim,
            });
        }
        let points: Vec<f64> = control_points.iter().flatten().copied().collect();
        let weights = weights.unwrap_or_else(|| vec![1.0; control_points.len()]);
        Self::from_flat(degree, dim, dim, knots, points, weights)
    }

    /// Builds and validates a curve from flat coordinate data.
    pub fn from_flat(
        degree: usize,
        dim: usize,
        tip_dim: usize,
        knots: Vec<f64>,
        points: Vec<f64>,
        weights: Vec<f64>,
    ) -> Result<Self, GeometryError> {
        CurveView::new(degree, dim, &knots, &points, &weights)?;
        if !(2..=3).contains(&tip_dim) || (dim != tip_dim && dim != 2 * tip_dim) {
            return Err(GeometryError::DimensionOutOfRange { dim });
        }
        Ok(Nurbs {
            degree,
            dim,
            tip_dim,
            knots,
            points,
            weights,
        })
    }

    /// Two curves on the same degree and knots side by side: tool tip and a second point on the
    /// tool axis (5-axis paths).
    pub fn with_top_curve(self, top: &Nurbs) -> Result<Self, GeometryError> {
        if top.degree != self.degree || top.knots != self.knots || top.dim != self.dim || self.dim != self.tip_dim {
            return Err(GeometryError::PointDataMismatch {
                values: top.points.len(),
                dim: self.dim,
            });
        }
        let n = self.control_point_count();
        let mut points = Vec::with_capacity(2 * self.points.len());
        for i in 0..n {
            points.extend_from_slice(&self.points[i * self.dim..(i + 1) * self.dim]);
            points.extend_from_slice(&top.points[i * self.dim..(i + 1) * self.dim]);
        }
        Self::from_flat(self.degree, 2 * self.dim, self.dim, self.knots, points, self.weights)
    }

    /// The curve's evaluation view, in O(1): the data was validated in full at construction
    /// and cannot change (private fields, no mutation), so only the counts are checked again.
    /// Arc lengths and parameter searches take a view for every call.
    pub fn view(&self) -> CurveView<'_> {
        CurveView::trusted(self.degree, self.dim, &self.knots, &self.points, &self.weights)
            .expect("Nurbs is validated at construction")
    }

    pub fn degree(&self) -> usize {
        self.degree
    }
    pub fn dim(&self) -> usize {
        self.dim
    }
    pub fn tip_dim(&self) -> usize {
        self.tip_dim
    }
    pub fn knots(&self) -> &[f64] {
        &self.knots
    }
    pub fn points(&self) -> &[f64] {
        &self.points
    }
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
    pub fn control_point_count(&self) -> usize {
        self.weights.len()
    }
    pub fn control_point(&self, i: usize) -> &[f64] {
        &self.points[i * self.dim..(i + 1) * self.dim]
    }
    pub fn u_min(&self) -> f64 {
        self.knots[self.degree]
    }
    pub fn u_max(&self) -> f64 {
        self.knots[self.control_point_count()]
    }
    pub fn point(&self, u: f64) -> Vector {
        self.view().point(u)
    }

    /// An upper bound on the tool tip's arc length without integrating: the length of its
    /// control polygon, which a non-rational B-spline never exceeds (its derivative is a
    /// B-spline whose coefficients are the polygon's legs scaled by their knot spans); `None`
    /// for a rational curve, whose weights can make it longer.
    pub fn polygon_length(&self) -> Option<f64> {
        if self.weights.iter().any(|&w| w != self.weights[0]) {
            return None;
        }
        let tip = self.tip_dim;
        let leg = |i: usize| {
            let (a, b) = (self.control_point(i), self.control_point(i + 1));
            a[..tip]
                .iter()
                .zip(&b[..tip])
                .map(|(x, y)| (y - x) * (y - x))
                .sum::<f64>()
                .sqrt()
        };
        Some((0..self.control_point_count().saturating_sub(1)).map(leg).sum())
    }

    /// Parametric speed |C'(u)| of the tool tip.
    pub fn speed(&self, u: f64) -> f64 {
        self.view().speed(u, self.tip_dim)
    }

    /// Curvature of the tool-tip path, |C' x C''| / |C'|^3 written for any dimension (eq. 13).
    pub fn curvature(&self, u: f64) -> f64 {
        let d = self.view().derivatives(u, 2);
        curvature_of(&d[1], &d[2], self.tip_dim)
    }

    /// Distinct interior knot values plus the domain ends: the spans on which the curve is a
    /// single rational polynomial.
    pub fn breakpoints(&self) -> Vec<f64> {
        let mut b: Vec<f64> = Vec::new();
        for &k in &self.knots[self.degree..=self.control_point_count()] {
            if b.last() != Some(&k) {
                b.push(k);
            }
        }
        b
    }

    /// The same curve traversed in the other direction, on the same parameter interval.
    pub fn reversed(&self) -> Nurbs {
        let (a, b) = (self.u_min(), self.u_max());
        let knots: Vec<f64> = self.knots.iter().rev().map(|k| a + b - k).collect();
        let n = self.control_point_count();
        let mut points = Vec::with_capacity(self.points.len());
        for i in (0..n).rev() {
            points.extend_from_slice(self.control_point(i));
        }
        let weights: Vec<f64> = self.weights.iter().rev().copied().collect();
        // Validated like any curve ([`Nurbs::view`] relies on it): mirrored knots stay clamped
        // and non-decreasing, the points and weights are the same values.
        Self::from_flat(self.degree, self.dim, self.tip_dim, knots, points, weights)
            .expect("the reverse of a valid curve is valid")
    }
}

/// Curvature from first and second derivatives: sqrt(|d1|^2 |d2|^2 - (d1.d2)^2) / |d1|^3.
pub fn curvature_of(d1: &Vector, d2: &Vector, n: usize) -> f64 {
    let s2 = dot(d1, d1, n);
    if s2 == 0.0 {
        return f64::INFINITY;
    }
    let cross2 = (s2 * dot(d2, d2, n) - dot(d1, d2, n).powi(2)).max(0.0);
    cross2.sqrt() / (s2 * s2.sqrt())
}

/// Summary figures of one curve.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CurveStats {
    pub arc_length_mm: f64,
    pub bbox_min: Vec<f64>,
    pub bbox_max: Vec<f64>,
    pub max_curvature_per_mm: f64,
    pub u_at_max_curvature: f64,
}

/// Arc length, bounding box of the tool-tip path and maximum curvature (dense scan refined by
/// golden-section search).
pub fn analyze(curve: &Nurbs) -> CurveStats {
    let n = curve.tip_dim();
    let view = curve.view();
    let spans = curve.breakpoints();
    let samples_per_span = 400;
    let mut bbox_min = vec![f64::INFINITY; n];
    let mut bbox_max = vec![f64::NEG_INFINITY; n];
    let mut best = (f64::NEG_INFINITY, curve.u_min());
    let mut grid = Vec::new();
    for w in spans.windows(2) {
        for i in 0..samples_per_span {
            grid.push(w[0] + (w[1] - w[0]) * i as f64 / samples_per_span as f64);
        }
    }
    grid.push(curve.u_max());
    let kappa = |u: f64| {
        let d = view.derivatives(u, 2);
        let k = curvature_of(&d[1], &d[2], n);
        if k.is_finite() {
            k
        } else {
            0.0
        }
    };
    let values: Vec<f64> = grid.iter().map(|&u| kappa(u)).collect();
    for (i, &u) in grid.iter().enumerate() {
        let p = view.point(u);
        for a in 0..n {
            bbox_min[a] = bbox_min[a].min(p[a]);
            bbox_max[a] = bbox_max[a].max(p[a]);
        }
        if values[i] > best.0 {
            best = (values[i], u);
        }
    }
    // Refine the extremes of every coordinate and of the curvature inside their grid brackets.
    let refine = |f: &dyn Fn(f64) -> f64, i: usize| -> (f64, f64) {
        let lo = grid[i.saturating_sub(1)];
        let hi = grid[(i + 1).min(grid.len() - 1)];
        golden_max(f, lo, hi)
    };
    for a in 0..n {
        let coord = |u: f64| view.point(u)[a];
        let imax = argmax(grid.iter().map(|&u| coord(u)));
        let imin = argmax(grid.iter().map(|&u| -coord(u)));
        bbox_max[a] = bbox_max[a].max(refine(&coord, imax).1);
        bbox_min[a] = bbox_min[a].min(-refine(&|u| -coord(u), imin).1);
    }
    let ik = argmax(values.iter().copied());
    let (u_k, k) = refine(&kappa, ik);
    if k > best.0 {
        best = (k, u_k);
    }
    CurveStats {
        arc_length_mm: super::ArcLengthTable::new(curve).total(),
        bbox_min,
        bbox_max,
        max_curvature_per_mm: best.0,
        u_at_max_curvature: best.1,
    }
}

fn argmax(values: impl Iterator<Item = f64>) -> usize {
    let mut best = (0, f64::NEG_INFINITY);
    for (i, v) in values.enumerate() {
        if v > best.1 {
            best = (i, v);
        }
    }
    best.0
}

/// Golden-section search for a maximum of `f` on `[a, b]`; returns (argmax, max).
pub fn golden_max(f: &dyn Fn(f64) -> f64, mut a: f64, mut b: f64) -> (f64, f64) {
    let r = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - r * (b - a);
    let mut d = a + r * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..80 {
        if (b - a).abs() <= 1e-15 * (1.0 + a.abs()) {
            break;
        }
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - r * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + r * (b - a);
            fd = f(d);
        }
    }
    if fc > fd {
        (c, fc)
    } else {
        (d, fd)
    }
}
