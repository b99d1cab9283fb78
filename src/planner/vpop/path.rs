//! The path as VPOp sees it: one coordinate `w` over the whole toolpath (element `e` covers
//! `[e, e + 1]`, linear in its curve parameter), and at every `w` the joint positions q(w) that
//! the limits apply to (the tool tip for 2-/3-axis paths, x y z a|b c on a table-tilting machine) and
//! the tool tip in the workpiece frame (feed and chord error).

use std::cell::RefCell;
use std::collections::VecDeque;

use crate::geometry::Toolpath;
use crate::kinematics::TableTilting;
use crate::planner::axial::MAX_AXES;
use nurbs_rtcore::{CurveView, MAX_DIM};

/// Joint positions, tool tip, and where on the toolpath they are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPoint {
    pub w: f64,
    pub element: usize,
    pub u: f64,
    pub q: [f64; MAX_AXES],
    pub tip: [f64; 3],
}

/// Evaluates joint positions and tool tip along a toolpath.
pub struct JointPath<'a> {
    views: Vec<CurveView<'a>>,
    spans: Vec<(f64, f64)>,
    /// Power-basis copy of every element (the planner's evaluator).
    fast: Vec<PowerCurve>,
    /// Upper estimate of the tool-tip curvature over cells of `w` (range maximum table).
    kappa: CurvatureTable,
    tip: usize,
    kinematics: Option<(TableTilting, Vec<f64>)>,
    /// Programmed feed of every element (mm/s), if the source gives one.
    programmed_feeds: Vec<Option<f64>>,
    /// Where the motion must stop: the tangent breaks (increasing `w`), then the path end.
    stops: Vec<f64>,
}

/// Samples per element of the C-angle continuity table.
const C_TABLE: usize = 4096;

impl<'a> JointPath<'a> {
    /// Tool-tip path (joints = tip coordinates).
    pub fn tip(toolpath: &'a Toolpath) -> Self {
        let views: Vec<CurveView<'a>> = toolpath.elements.iter().map(|e| e.curve.view()).collect();
        let spans = views.iter().map(|v| (v.u_min(), v.u_max())).collect();
        let fast: Vec<PowerCurve> = views.iter().map(PowerCurve::new).collect();
        let tip = toolpath.tip_dim();
        let kappa = CurvatureTable::new(tip);
        let mut stops = tangent_breaks(&views);
        stops.push(views.len() as f64);
        JointPath {
            views,
            spans,
            fast,
            kappa,
            tip,
            kinematics: None,
            programmed_feeds: toolpath.elements.iter().map(|e| e.feed).collect(),
            stops,
        }
    }

    /// The tool-tip path of `toolpath`, the elements `first ..` of a longer path, with the
    /// curvature tables an earlier such path built for them ([`Self::into_curvature_tables`]):
    /// a short path built again and again along a longer one (a stored hold stop at every few
    /// samples) builds each element's table once.
    pub fn tip_reusing(toolpath: &'a Toolpath, first: usize, tables: CurvatureTables) -> Self {
        let mut path = Self::tip(toolpath);
        path.kappa.first = first;
        path.kappa.built = RefCell::new(tables.built);
        path
    }

    /// The curvature tables built so far, by element of the longer path.
    pub fn into_curvature_tables(self) -> CurvatureTables {
        CurvatureTables {
            built: self.kappa.built.into_inner(),
        }
    }

    /// Five-axis path on a table-tilting machine: every element must carry a top curve (dim 6).
    pub fn five_axis(toolpath: &'a Toolpath, machine: TableTilting) -> Result<Self, String> {
        if toolpath
            .elements
            .iter()
            .any(|e| e.curve.dim() != 6 || e.curve.tip_dim() != 3)
        {
            return Err("5-axis planning needs tool tip and top curves in 3-D on every element".into());
        }
        let mut path = Self::tip(toolpath);
        // Continuous C: unwrap along a fine grid; evaluation takes the branch nearest the grid.
        let n = path.views.len();
        let mut table = Vec::with_capacity(n * C_TABLE + 1);
        let mut prev: Option<f64> = None;
        for k in 0..=n * C_TABLE {
            let w = k as f64 / C_TABLE as f64;
            let (_, axis) = path.tip_and_axis(w);
            let (_, c) = machine.angles(axis, prev);
            table.push(c);
            prev = Some(c);
        }
        path.kinematics = Some((machine, table));
        Ok(path)
    }

    /// Axes the limits apply to.
    pub fn axes(&self) -> usize {
        if self.kinematics.is_some() {
            5
        } else {
            self.tip
        }
    }
    pub fn tip_dim(&self) -> usize {
        self.tip
    }
    /// Number of path elements.
    pub fn elements(&self) -> usize {
        self.views.len()
    }
    /// Largest coordinate (path end).
    pub fn end(&self) -> f64 {
        self.views.len() as f64
    }
    /// Programmed feed of element `e` (mm/s), if the source gives one.
    pub fn programmed_feed(&self, e: usize) -> Option<f64> {
        self.programmed_feeds.get(e).copied().flatten()
    }
    pub fn machine(&self) -> Option<&TableTilting> {
        self.kinematics.as_ref().map(|(m, _)| m)
    }

    /// The first exact stop at or after `w` (a tangent break or the path end); past the one at
    /// `w` itself once the machine is `at_rest` there.
    pub fn next_stop(&self, w: f64, at_rest: bool) -> f64 {
        let k = self.stops.partition_point(|&s| s < w);
        let k = if at_rest && self.stops.get(k) == Some(&w) {
            k + 1
        } else {
            k
        };
        self.stops[k.min(self.stops.len() - 1)]
    }

    /// Element and curve parameter at `w` (the end of an element belongs to it only at the path end).
    pub fn locate(&self, w: f64) -> (usize, f64) {
        let n = self.views.len();
        let w = w.clamp(0.0, n as f64);
        let e = (w.floor() as usize).min(n - 1);
        let (a, b) = self.spans[e];
        let f = w - e as f64;
        let u = if f >= 1.0 { b } else { a + (b - a) * f };
        (e, u)
    }

    fn tip_and_axis(&self, w: f64) -> ([f64; 3], [f64; 3]) {
        let (e, u) = self.locate(w);
        let p = self.fast[e].point(u);
        let mut tip = [0.0; 3];
        tip[..self.tip].copy_from_slice(&p[..self.tip]);
        let mut axis = [0.0, 0.0, 1.0];
        if self.fast[e].dim == 2 * self.tip && self.tip == 3 {
            axis = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
        }
        (tip, axis)
    }

    /// Joint positions and tool tip from a curve point at `w`.
    fn point_at(&self, w: f64, element: usize, u: f64, p: &[f64; MAX_DIM]) -> PathPoint {
        let mut tip = [0.0; 3];
        tip[..self.tip].copy_from_slice(&p[..self.tip]);
        let mut q = [0.0; MAX_AXES];
        match &self.kinematics {
            None => q[..self.tip].copy_from_slice(&p[..self.tip]),
            Some((m, table)) => {
                let axis = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
                let k = ((w * C_TABLE as f64).round() as usize).min(table.len() - 1);
                let j = m.inverse(tip, axis, Some(table[k].to_degrees()));
                q[..5].copy_from_slice(&j);
            }
        }
        PathPoint { w, element, u, q, tip }
    }

    /// The point at element `element`, curve parameter `u` exactly (its `w` is where that
    /// lies on the path); `None` off the path.
    pub fn eval_at(&self, element: usize, u: f64) -> Option<PathPoint> {
        let &(a, b) = self.spans.get(element)?;
        if !(u >= a && u <= b) {
            return None;
        }
        let w = element as f64 + if b > a { (u - a) / (b - a) } else { 0.0 };
        let p = self.fast[element].point(u);
        Some(self.point_at(w, element, u, &p))
    }

    /// Joint positions and tool tip at `w`.
    pub fn eval(&self, w: f64) -> PathPoint {
        let (element, u) = self.locate(w);
        let p = self.fast[element].point(u);
        self.point_at(w, element, u, &p)
    }

    /// [`Self::eval`] and [`Self::derivative`] in one evaluation.
    pub fn eval_d(&self, w: f64) -> (PathPoint, [f64; MAX_AXES], [f64; 3]) {
        let (e, u) = self.locate(w);
        if self.kinematics.is_some() {
            let (dq, dt) = self.derivative(w);
            return (self.eval(w), dq, dt);
        }
        let d = self.fast[e].eval(u, 1);
        let (a, b) = self.spans[e];
        let mut dq = [0.0; MAX_AXES];
        let mut dt = [0.0; 3];
        for i in 0..self.tip {
            dq[i] = d[1][i] * (b - a);
            dt[i] = d[1][i] * (b - a);
        }
        (self.point_at(w, e, u, &d[0]), dq, dt)
    }

    /// dq/dw and d(tip)/dw at `w` (analytic for tip paths, central differences on the machine).
    pub fn derivative(&self, w: f64) -> ([f64; MAX_AXES], [f64; 3]) {
        let (e, u) = self.locate(w);
        let (a, b) = self.spans[e];
        if self.kinematics.is_none() {
            let d = self.fast[e].eval(u, 1)[1];
            let mut dq = [0.0; MAX_AXES];
            let mut dt = [0.0; 3];
            for i in 0..self.tip {
                dq[i] = d[i] * (b - a);
                dt[i] = d[i] * (b - a);
            }
            return (dq, dt);
        }
        let h = 1e-6;
        let lo = (w - h).max(e as f64);
        let hi = (w + h).min(e as f64 + 1.0);
        let (p0, p1) = (self.eval(lo), self.eval(hi));
        let mut dq = [0.0; MAX_AXES];
        let mut dt = [0.0; 3];
        for i in 0..MAX_AXES {
            dq[i] = (p1.q[i] - p0.q[i]) / (hi - lo);
        }
        for i in 0..3 {
            dt[i] = (p1.tip[i] - p0.tip[i]) / (hi - lo);
        }
        (dq, dt)
    }

    /// Tool-tip curvature at `w` (1/mm).
    pub fn curvature(&self, w: f64) -> f64 {
        let (e, u) = self.locate(w);
        curvature_of(&self.fast[e].eval(u, 2), self.tip)
    }

    /// Upper estimate of the tool-tip curvature on `[w0, w1]` (tabulated maxima of the cells
    /// the interval touches).
    pub fn max_curvature(&self, w0: f64, w1: f64) -> f64 {
        self.kappa.max(&self.fast, w0.min(w1), w0.max(w1))
    }

    /// Largest distance between the tip curve on `(a, b)` and the chord between their tips,
    /// measured as `nurbs-plan verify` measures it (same element only).
    pub fn chord_error(&self, a: &PathPoint, b: &PathPoint) -> f64 {
        if a.element != b.element || b.u <= a.u {
            return 0.0;
        }
        let mut pa = [0.0; nurbs_rtcore::MAX_DIM];
        let mut pb = [0.0; nurbs_rtcore::MAX_DIM];
        pa[..3].copy_from_slice(&a.tip);
        pb[..3].copy_from_slice(&b.tip);
        crate::planner::verify::chord_error(&self.views[a.element], self.tip, a.u, b.u, &pa, &pb)
    }
}

/// `w` of every point where the path's direction turns (in all coordinates of the curves: for a
/// two-curve path, a kink of the top curve turns the joints too): an interior knot of
/// multiplicity >= degree (C0) or an element join whose unit tangents differ. A finite-jerk
/// motion must stop there, and VPOp lands its last sample exactly on the point.
fn tangent_breaks(views: &[CurveView]) -> Vec<f64> {
    let unit = |d: &[f64; MAX_DIM], n: usize| {
        let len = d[..n].iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut t = [0.0; MAX_DIM];
        if len > 0.0 {
            for i in 0..n {
                t[i] = d[i] / len;
            }
        }
        t
    };
    let turns = |left: &[f64; MAX_DIM], right: &[f64; MAX_DIM], n: usize| {
        let (l, r) = (unit(left, n), unit(right, n));
        (0..n).map(|i| l[i] * r[i]).sum::<f64>() < 1.0 - 1e-12
    };
    let mut out = Vec::new();
    for (e, view) in views.iter().enumerate() {
        let n = view.dim();
        if e > 0 {
            let before = &views[e - 1];
            let left = before.derivatives(before.u_max(), 1)[1];
            if turns(&left, &view.derivatives(view.u_min(), 1)[1], n) {
                out.push(e as f64);
            }
        }
        let (p, knots, count) = (view.degree(), view.knots(), view.control_point_count());
        let (a, b) = (view.u_min(), view.u_max());
        let mut i = p + 1;
        while i < count {
            let mut m = 1;
            while i + m < count && knots[i + m] == knots[i] {
                m += 1;
            }
            let u = knots[i];
            if m >= p && turns(&view.derivatives_left(u, 1)[1], &view.derivatives(u, 1)[1], n) {
                out.push(e as f64 + (u - a) / (b - a));
            }
            i += m;
        }
    }
    out
}

/// Curvature of the first `n` coordinates from a point and its first two derivatives.
fn curvature_of(d: &[[f64; MAX_DIM]; 3], n: usize) -> f64 {
    let dot = |x: &[f64; MAX_DIM], y: &[f64; MAX_DIM]| (0..n).map(|i| x[i] * y[i]).sum::<f64>();
    let s2 = dot(&d[1], &d[1]);
    if s2 == 0.0 {
        return f64::INFINITY;
    }
    let cross2 = (s2 * dot(&d[2], &d[2]) - dot(&d[1], &d[2]).powi(2)).max(0.0);
    cross2.sqrt() / (s2 * s2.sqrt())
}

/// Highest degree the power basis holds.
const MAX_ORDER: usize = nurbs_rtcore::MAX_DEGREE + 1;

/// One knot span as polynomials in `t = (u - u0) / (u1 - u0)`: homogeneous coordinates
/// (weighted point, then weight), coefficient `k` of `t^k`.
#[derive(Clone, Copy)]
struct PowerSpan {
    u0: f64,
    inv: f64,
    coef: [[f64; MAX_DIM + 1]; MAX_ORDER],
}

/// A NURBS curve converted span by span to the power basis: the same curve (to rounding) as
/// the de Boor evaluation of [`CurveView`], evaluated by Horner's rule.
pub struct PowerCurve {
    degree: usize,
    dim: usize,
    /// Start parameter of every non-empty span.
    starts: Vec<f64>,
    spans: Vec<PowerSpan>,
}

impl PowerCurve {
    pub fn new(view: &CurveView) -> Self {
        let p = view.degree();
        let dim = view.dim();
        let knots = view.knots();
        let (pts, ws) = (view.points(), view.weights());
        let n = ws.len();
        let mut spans = Vec::new();
        for i in p..n {
            let (u0, u1) = (knots[i], knots[i + 1]);
            if u1 <= u0 {
                continue;
            }
            // Homogeneous values at p + 1 nodes, then the Vandermonde system for the
            // coefficients (size <= 8, partial pivoting).
            let m = p + 1;
            let mut mat = [[0.0f64; MAX_ORDER]; MAX_ORDER];
            let mut rhs = [[0.0f64; MAX_DIM + 1]; MAX_ORDER];
            for k in 0..m {
                let t = if p == 0 { 0.5 } else { k as f64 / p as f64 };
                let u = u0 + (u1 - u0) * t;
                let nb = nurbs_rtcore::basis_functions(knots, i, p, u);
                for j in 0..=p {
                    let c = i - p + j;
                    let wn = nb[j] * ws[c];
                    for d in 0..dim {
                        rhs[k][d] += wn * pts[c * dim + d];
                    }
                    rhs[k][dim] += wn;
                }
                let mut tk = 1.0;
                for entry in mat[k].iter_mut().take(m) {
                    *entry = tk;
                    tk *= t;
                }
            }
            for col in 0..m {
                let piv = (col..m)
                    .max_by(|&a, &b| mat[a][col].abs().total_cmp(&mat[b][col].abs()))
                    .unwrap_or(col);
                mat.swap(col, piv);
                rhs.swap(col, piv);
                for r in 0..m {
                    if r != col {
                        let f = mat[r][col] / mat[col][col];
                        if f != 0.0 {
                            for c in col..m {
                                mat[r][c] -= f * mat[col][c];
                            }
                            for d in 0..=dim {
                                rhs[r][d] -= f * rhs[col][d];
                            }
                        }
                    }
                }
            }
            let mut coef = [[0.0; MAX_DIM + 1]; MAX_ORDER];
            for k in 0..m {
                for d in 0..=dim {
                    coef[k][d] = rhs[k][d] / mat[k][k];
                }
            }
            spans.push(PowerSpan {
                u0,
                inv: 1.0 / (u1 - u0),
                coef,
            });
        }
        PowerCurve {
            degree: p,
            dim,
            starts: spans.iter().map(|s| s.u0).collect(),
            spans,
        }
    }

    /// Index of the span of `u`: the last whose start is at or below `u` (the first below the
    /// first start). Guessed from `u`'s place in the parameter range (knots are mostly about
    /// evenly spaced), then walked to; a binary search where the guess is far off.
    fn span_of(&self, u: f64) -> usize {
        let n = self.starts.len();
        let (first, last) = (self.starts[0], self.starts[n - 1]);
        // At or below the first start, and NaN: span 0.
        if u.partial_cmp(&first) != Some(std::cmp::Ordering::Greater) {
            return 0;
        }
        if u >= last {
            return n - 1;
        }
        // Here starts[0] < u < starts[n - 1]: the span k has starts[k] <= u < starts[k + 1].
        let guess = ((u - first) / (last - first) * (n - 1) as f64) as usize;
        let mut k = guess.min(n - 2);
        for _ in 0..4 {
            if self.starts[k] > u {
                k -= 1;
            } else if self.starts[k + 1] <= u {
                k += 1;
            } else {
                return k;
            }
        }
        self.starts.partition_point(|&s| s <= u) - 1
    }

    /// The point at `u`: [`Self::eval`] of order 0, inlined so that the derivative branches
    /// fold away.
    pub fn point(&self, u: f64) -> [f64; MAX_DIM] {
        self.eval(u, 0)[0]
    }

    /// Point and derivatives with respect to `u` up to `order` (<= 2); higher entries zero.
    #[inline]
    pub fn eval(&self, u: f64, order: usize) -> [[f64; MAX_DIM]; 3] {
        let s = &self.spans[self.span_of(u)];
        let t = (u - s.u0) * s.inv;
        let p = self.degree;
        let m = self.dim + 1;
        // Horner with derivatives: f, f', f''/2 of every homogeneous coordinate.
        let mut f = [0.0; MAX_DIM + 1];
        let mut f1 = [0.0; MAX_DIM + 1];
        let mut f2 = [0.0; MAX_DIM + 1];
        f[..m].copy_from_slice(&s.coef[p][..m]);
        for c in s.coef[..p].iter().rev() {
            for d in 0..m {
                if order >= 2 {
                    f2[d] = f2[d] * t + f1[d];
                }
                if order >= 1 {
                    f1[d] = f1[d] * t + f[d];
                }
                f[d] = f[d] * t + c[d];
            }
        }
        let dim = self.dim;
        let mut out = [[0.0; MAX_DIM]; 3];
        let w = f[dim];
        for d in 0..dim {
            out[0][d] = f[d] / w;
        }
        if order >= 1 {
            let w1 = f1[dim] * s.inv;
            for d in 0..dim {
                out[1][d] = (f1[d] * s.inv - w1 * out[0][d]) / w;
            }
            if order >= 2 {
                let w2 = 2.0 * f2[dim] * s.inv * s.inv;
                for d in 0..dim {
                    out[2][d] = (2.0 * f2[d] * s.inv * s.inv - 2.0 * w1 * out[1][d] - w2 * out[0][d]) / w;
                }
            }
        }
        out
    }
}

/// Cells of `w` per element of the curvature table (at least; more on curves with many spans).
const KAPPA_CELLS: usize = 2048;
/// Curvature samples per cell.
const KAPPA_SAMPLES: usize = 4;

/// Upper estimate of the curvature over cells of `w`: per element, a range-maximum table over
/// its cells, built when a query reaches the element, and only the last [`KAPPA_TABLES_KEPT`]
/// kept (a rebuilt table has the same values). The queries follow the motion, so few elements
/// are in use at a time: building all 2,000 elements of a 1,000-line G1 program up front took a
/// second before the first stop check of `nurbs-planner`, and holding them all 330 MB for a VPOp
/// plan of it.
struct CurvatureTable {
    tip: usize,
    /// Built tables with their element (counted in a longer path whose element `first` is this
    /// path's first), the latest last.
    built: RefCell<VecDeque<(usize, ElementCurvature)>>,
    first: usize,
}

/// Curvature tables of a [`JointPath`], to build another one over the same elements with
/// ([`JointPath::tip_reusing`]).
#[derive(Default)]
pub struct CurvatureTables {
    built: VecDeque<(usize, ElementCurvature)>,
}

/// Element curvature tables kept at a time (some 180 kB each for a cubic element).
const KAPPA_TABLES_KEPT: usize = 64;

/// `levels[k][c]`: largest curvature over cells `c .. c + 2^k` of one element.
struct ElementCurvature {
    levels: Vec<Vec<f64>>,
}

impl ElementCurvature {
    fn new(c: &PowerCurve, tip: usize) -> Self {
        let cells = cells_of(c);
        let (u_min, u_max) = (c.starts[0], {
            let s = c.spans.last().unwrap_or(&c.spans[0]);
            s.u0 + 1.0 / s.inv
        });
        let base: Vec<f64> = (0..cells)
            .map(|k| {
                let mut m: f64 = 0.0;
                for j in 0..=KAPPA_SAMPLES {
                    let f = (k as f64 + j as f64 / KAPPA_SAMPLES as f64) / cells as f64;
                    let u = (u_min + (u_max - u_min) * f).min(u_max);
                    // A zero speed (cusp) gives infinity: kept, the caps then stop there.
                    m = m.max(curvature_of(&c.eval(u, 2), tip));
                }
                m
            })
            .collect();
        let mut levels = vec![base];
        let mut width = 1;
        while 2 * width <= levels[0].len() {
            let prev = levels.last().unwrap_or(&levels[0]);
            let next: Vec<f64> = (0..prev.len() - width).map(|i| prev[i].max(prev[i + width])).collect();
            levels.push(next);
            width *= 2;
        }
        ElementCurvature { levels }
    }

    /// Largest curvature over cells `a ..= b`.
    fn max(&self, a: usize, b: usize) -> f64 {
        let len = b - a + 1;
        let k = (usize::BITS - 1 - len.leading_zeros()) as usize;
        let lvl = &self.levels[k];
        lvl[a].max(lvl[b + 1 - (1 << k)])
    }
}

/// Cells of one element: a straight element (degree 1: G1 lines) has no curvature, one cell
/// holds it.
fn cells_of(c: &PowerCurve) -> usize {
    if c.degree == 1 {
        1
    } else {
        KAPPA_CELLS.max(16 * c.spans.len())
    }
}

impl CurvatureTable {
    fn new(tip: usize) -> Self {
        CurvatureTable {
            tip,
            built: RefCell::new(VecDeque::new()),
            first: 0,
        }
    }

    /// Element and cell of `w`.
    fn cell(curves: &[PowerCurve], w: f64) -> (usize, usize) {
        let n = curves.len();
        let w = w.clamp(0.0, n as f64);
        let e = (w.floor() as usize).min(n - 1);
        let cells = cells_of(&curves[e]);
        (e, (((w - e as f64) * cells as f64) as usize).min(cells - 1))
    }

    /// Largest curvature over cells `a ..= b` of element `e` (its table built if need be).
    fn element_max(&self, curves: &[PowerCurve], e: usize, a: usize, b: usize) -> f64 {
        let mut built = self.built.borrow_mut();
        let key = self.first + e;
        if let Some((_, table)) = built.iter().rev().find(|(i, _)| *i == key) {
            return table.max(a, b);
        }
        if built.len() == KAPPA_TABLES_KEPT {
            built.pop_front();
        }
        let table = ElementCurvature::new(&curves[e], self.tip);
        let m = table.max(a, b);
        built.push_back((key, table));
        m
    }

    /// Largest curvature over the cells from `w0` to `w1` (`w0 <= w1`).
    fn max(&self, curves: &[PowerCurve], w0: f64, w1: f64) -> f64 {
        let ((ea, a), (eb, b)) = (Self::cell(curves, w0), Self::cell(curves, w1));
        if ea == eb {
            return self.element_max(curves, ea, a, b);
        }
        let last = |e: usize| cells_of(&curves[e]) - 1;
        let mut m = self.element_max(curves, ea, a, last(ea));
        for e in ea + 1..eb {
            m = m.max(self.element_max(curves, e, 0, last(e)));
        }
        m.max(self.element_max(curves, eb, 0, b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::readers::read_toolpath;

    /// The power basis reproduces the de Boor evaluation (points, first and second
    /// derivatives) on every bundled curve.
    #[test]
    fn power_basis_matches_de_boor() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
        for name in [
            "trident.json",
            "butterfly.json",
            "fan.json",
            "open_pocket.json",
            "fan_5axis.json",
        ] {
            let tp = read_toolpath(&dir.join(name)).unwrap();
            for e in &tp.elements {
                let view = e.curve.view();
                let fast = PowerCurve::new(&view);
                let scale = view.points().iter().fold(1.0f64, |m, v| m.max(v.abs()));
                for k in 0..=997 {
                    let u = view.u_min() + (view.u_max() - view.u_min()) * k as f64 / 997.0;
                    let exact = view.derivatives(u, 2);
                    let got = fast.eval(u, 2);
                    for d in 0..view.dim() {
                        assert!((exact[0][d] - got[0][d]).abs() <= 1e-12 * scale, "{name} u {u}");
                        let s1 = exact[1][..view.dim()].iter().fold(scale, |m, v| m.max(v.abs()));
                        assert!((exact[1][d] - got[1][d]).abs() <= 1e-9 * s1, "{name} u {u} d1");
                        let s2 = exact[2][..view.dim()].iter().fold(scale, |m, v| m.max(v.abs()));
                        assert!((exact[2][d] - got[2][d]).abs() <= 1e-7 * s2, "{name} u {u} d2");
                    }
                }
            }
        }
    }

    /// The span guess finds the span the binary search finds (the last start at or below `u`),
    /// on uneven knots too, at and between every knot, outside the range and at NaN.
    #[test]
    fn span_guess_is_the_binary_search() {
        let cps: Vec<Vec<f64>> = (0..9).map(|i| vec![i as f64, (i * i % 5) as f64]).collect();
        let knots = vec![0.0, 0.0, 0.0, 0.0, 0.01, 0.02, 0.5, 0.51, 3.0, 10.0, 10.0, 10.0, 10.0];
        let curve = crate::geometry::Nurbs::new(3, knots.clone(), &cps, None).unwrap();
        let fast = PowerCurve::new(&curve.view());
        let binary = |u: f64| fast.starts.partition_point(|&s| s <= u).saturating_sub(1);
        let mut us = vec![-1.0, f64::NAN, 11.0, f64::INFINITY];
        for w in knots.windows(2) {
            for f in [0.0, 1e-12, 0.3, 0.999_999, 1.0] {
                us.push(w[0] + (w[1] - w[0]) * f);
            }
        }
        us.extend((0..=2000).map(|k| 10.0 * k as f64 / 2000.0));
        for u in us {
            assert_eq!(fast.span_of(u), binary(u), "u = {u}");
        }
    }
}
