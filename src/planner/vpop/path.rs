//! The path as VPOp sees it: one coordinate `w` over the whole toolpath (element `e` covers
//! `[e, e + 1]`, linear in its curve parameter), and at every `w` the joint positions q(w) that
//! the limits apply to (the tool tip for 2-/3-axis paths, x y z a|b c on a table-tilting machine) and
//! the tool tip in the workpiece frame (feed and chord error).
//!
//! A tool-tip path may be read as it is planned ([`JointPath::streamed`]): elements are read as
//! far as the queries reach and forgotten behind the motion ([`JointPath::release_before`]), so
//! that a program of any length is planned in memory that follows the look-ahead. The answers
//! are the same whether the path is read whole or streamed.

use std::cell::{Cell, Ref, RefCell};
use std::collections::VecDeque;

use crate::geometry::Toolpath;
use crate::kinematics::TableTilting;
use crate::planner::axial::MAX_AXES;
use crate::planner::window::Window;
use crate::planner::PathCurves;
use crate::readers::{ElementStream, ReadError};
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
pub struct JointPath {
    store: RefCell<Store>,
    /// Upper estimate of the tool-tip curvature over cells of `w` (range maximum table).
    kappa: CurvatureTable,
    tip: usize,
    /// The machine and its C angle (degrees) at `C_TABLE` samples per element.
    kinematics: Option<(TableTilting, Vec<f64>)>,
    /// The last answers of [`Self::next_stop`] (asked again and again for nearby states): the
    /// next stop after `w` (asked at rest or not) and after every `w` between it and that stop.
    stop_after: Cell<(f64, bool, f64)>,
    /// The end of the elements in view, the last element it was checked to reach the horizon
    /// from, and that horizon.
    view_checked: Cell<(usize, usize, f64)>,
    /// The derivatives [`Self::derivative`] gives at the last `w` [`Self::eval`] evaluated on a
    /// tool-tip path: a deceleration step asks for them at the point the step before it
    /// found, and the curve evaluation is most of a step's cost.
    last_derivative: Cell<(f64, [f64; MAX_AXES], [f64; 3])>,
}

/// The elements held, as far as they have been read, with what the planner needs of each.
struct Store {
    curves: PathCurves,
    elements: Window<Element>,
    /// The tangent breaks of the elements read (increasing `w`), then the path end once read.
    stops: VecDeque<f64>,
    /// Number of elements once the path has been read to its end.
    count: Option<usize>,
    /// Elements in view of the planner ([`JointPath::next_stop`]).
    view: usize,
    /// Most elements held at once.
    most_held: usize,
}

/// Elements the planner's view moves on by at a time.
const VIEW_STEP: usize = 64;

/// What the planner keeps of one element.
struct Element {
    /// Power-basis copy (the planner's evaluator).
    fast: PowerCurve,
    span: (f64, f64),
    /// Programmed feed (mm/s), if the source gives one.
    feed: Option<f64>,
    /// A lower bound of the tool-tip path length before the element (the sum of the distances
    /// between the elements' end points), and the element's own.
    before: f64,
    chord: f64,
    /// Derivative at the element's end (the next element's join is a tangent break where its
    /// start turns from it).
    end_derivative: [f64; MAX_DIM],
}

/// Samples per element of the C-angle continuity table.
const C_TABLE: usize = 4096;

impl Store {
    fn new(curves: PathCurves) -> Self {
        let first = curves.first();
        Store {
            curves,
            elements: Window::starting_at(first),
            stops: VecDeque::new(),
            count: None,
            view: first,
            most_held: 0,
        }
    }

    /// The lower bound of the tool-tip path length before element `e` (read; at most one
    /// past the last read).
    fn length_before(&self, e: usize) -> f64 {
        match self.elements.get(e) {
            Some(x) => x.before,
            None => self.elements.last().map_or(0.0, |x| x.before + x.chord),
        }
    }

    /// Whether element `e` is held, reading the path as far as it.
    fn load(&mut self, e: usize) -> bool {
        while self.elements.len() <= e && self.count.is_none() {
            let k = self.elements.len();
            if !self.curves.load(k) {
                self.count = Some(k);
                self.stops.push_back(k as f64);
                break;
            }
            let view = self.curves.view(k);
            let n = view.dim();
            let (a, b) = (view.u_min(), view.u_max());
            let fast = PowerCurve::new(&view);
            let ends = (fast.point(a), fast.point(b));
            let tip = self.curves.tip_dim();
            let chord = (0..tip).map(|i| (ends.1[i] - ends.0[i]).powi(2)).sum::<f64>().sqrt();
            let before = self.elements.last().map_or(0.0, |p| p.before + p.chord);
            if let Some(prev) = self.elements.last() {
                if turns(&prev.end_derivative, &view.derivatives(a, 1)[1], n) {
                    self.stops.push_back(k as f64);
                }
            }
            let stops = &mut self.stops;
            interior_breaks(&view, &mut |u| stops.push_back(k as f64 + (u - a) / (b - a)));
            let element = Element {
                fast,
                span: (a, b),
                feed: self.curves.programmed_feed(k),
                before,
                chord,
                end_derivative: view.derivatives(b, 1)[1],
            };
            self.elements.push(element);
            self.most_held = self.most_held.max(self.elements.len() - self.elements.first_index());
        }
        self.elements.len() > e
    }

    /// Elements held or read (one past the highest index).
    fn len(&self) -> usize {
        self.elements.len()
    }
}

impl JointPath {
    /// Tool-tip path (joints = tip coordinates).
    pub fn tip(toolpath: &Toolpath) -> Self {
        Self::whole(PathCurves::new(toolpath))
    }

    /// A whole path, every element read.
    fn whole(curves: PathCurves) -> Self {
        let path = Self::over(curves);
        path.store.borrow_mut().load(usize::MAX - 1);
        path
    }

    /// The tool-tip path of a toolpath read as it is planned (elements read as the queries
    /// reach them, forgotten behind [`Self::release_before`]). A file that fails part way ends
    /// the path before the element that failed ([`Self::read_error`]).
    pub fn streamed(source: ElementStream) -> Result<Self, ReadError> {
        Ok(Self::over(PathCurves::streamed(source)?))
    }

    /// The tool-tip path of `curves`, read as the queries reach them (a streamed path may begin
    /// past element 0: a re-plan from a stop point further on).
    pub fn over(curves: PathCurves) -> Self {
        let tip = curves.tip_dim();
        JointPath {
            store: RefCell::new(Store::new(curves)),
            kappa: CurvatureTable::new(tip),
            tip,
            kinematics: None,
            stop_after: Cell::new((f64::NAN, false, f64::NAN)),
            view_checked: Cell::new((0, 0, f64::NAN)),
            last_derivative: Cell::new((f64::NAN, [0.0; MAX_AXES], [0.0; 3])),
        }
    }

    /// The tool-tip path of `toolpath`, the elements `first ..` of a longer path, with the
    /// curvature tables an earlier such path built for them ([`Self::into_curvature_tables`]):
    /// a short path built again and again along a longer one (a stored hold stop at every few
    /// samples) builds each element's table once.
    pub fn tip_reusing(toolpath: Toolpath, first: usize, tables: CurvatureTables) -> Self {
        let mut path = Self::whole(PathCurves::taking(toolpath));
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
    pub fn five_axis(toolpath: &Toolpath, machine: TableTilting) -> Result<Self, String> {
        if toolpath
            .elements
            .iter()
            .any(|e| e.curve.dim() != 6 || e.curve.tip_dim() != 3)
        {
            return Err("5-axis planning needs tool tip and top curves in 3-D on every element".into());
        }
        let mut path = Self::tip(toolpath);
        // Continuous C: unwrap along a fine grid, from the value nearest 0 at the start (as a
        // program whose C starts within ±180° has it); evaluation takes the branch nearest the grid.
        let n = toolpath.elements.len();
        let mut table = Vec::with_capacity(n * C_TABLE + 1);
        let mut prev: Option<f64> = Some(0.0);
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

    /// Largest coordinate (the path end; infinite until the path has been read to its end,
    /// which [`Self::next_stop`] does before the motion can reach it).
    pub fn end(&self) -> f64 {
        self.store.borrow().count.map_or(f64::INFINITY, |n| n as f64)
    }

    /// Most elements held at once so far (the memory a streamed path needs).
    pub fn most_elements_held(&self) -> usize {
        self.store.borrow().most_held
    }

    /// Whether the path has no element.
    pub fn is_empty(&self) -> bool {
        self.held(0).len() == 0
    }

    /// Whether the first element carries a top curve (a 5-axis toolpath, planned whole).
    pub fn has_top_curve(&self) -> bool {
        let store = self.held(0);
        store.len() > 0 && store.curves.get(0).is_some_and(|e| e.curve.dim() != e.curve.tip_dim())
    }

    /// Why a streamed path ended before its file did.
    pub fn read_error(&self) -> Option<ReadError> {
        self.store.borrow().curves.error().cloned()
    }

    /// The store with element `e` held (read if need be; past the path end, the last element).
    #[inline]
    fn held(&self, e: usize) -> Ref<'_, Store> {
        let store = self.store.borrow();
        if store.len() > e || store.count.is_some() {
            return store;
        }
        drop(store);
        self.store.borrow_mut().load(e);
        self.store.borrow()
    }

    /// Feed cap (mm/s) of a step from element `from` to element `to`: the lowest of `limit` and
    /// the programmed feeds of the elements it touches.
    #[inline]
    pub fn feed_cap(&self, from: usize, to: usize, limit: f64) -> f64 {
        let store = self.held(from.max(to));
        (from.min(to)..=from.max(to))
            .filter_map(|e| store.elements.get(e).and_then(|x| x.feed))
            .fold(limit, f64::min)
    }

    /// The first exact stop at or after `w` (a tangent break or the path end); past the one at
    /// `w` itself once the machine is `at_rest` there; at most the end of the elements in view.
    /// The view reaches at least `horizon` (mm of tool-tip path, by a lower bound of the
    /// lengths) beyond the end of `w`'s element: nothing beyond it matters to a step from `w`
    /// (the caller's steps are shorter), and the path need not be read further. The view moves
    /// on by the same rule whether the path is read whole or streamed, so that the answers
    /// are the same.
    pub fn next_stop(&self, w: f64, at_rest: bool, horizon: f64) -> f64 {
        let view = self.view_to(element_of(w).saturating_add(1), horizon) as f64;
        let (asked, asked_at_rest, stop) = self.stop_after.get();
        // The last answer holds between where it was asked and the stop it found.
        let known = if (asked < w && w < stop) || (asked == w && asked_at_rest == at_rest) {
            Some(stop)
        } else {
            let store = self.store.borrow();
            let k = store.stops.partition_point(|&s| s < w);
            let k = if at_rest && store.stops.get(k) == Some(&w) {
                k + 1
            } else {
                k
            };
            let found = match (store.stops.get(k), store.count) {
                (Some(&s), _) => Some(s),
                // At rest on the path end: it stays the bound.
                (None, Some(n)) => Some(n as f64),
                (None, None) => None,
            };
            if let Some(s) = found.filter(|s| *s > w) {
                self.stop_after.set((w, at_rest, s));
            }
            found
        };
        known.map_or(view, |s| s.min(view))
    }

    /// The end of the elements in view once they reach `horizon` beyond element `from`'s start:
    /// [`VIEW_STEP`] elements more at a time, up to the path end.
    #[inline]
    fn view_to(&self, from: usize, horizon: f64) -> usize {
        // The view reaches `horizon` beyond every element up to the last one it was checked for.
        let (view, checked, for_horizon) = self.view_checked.get();
        if from <= checked && horizon == for_horizon {
            return view;
        }
        let mut store = self.store.borrow_mut();
        loop {
            let at_end = store.count.is_some_and(|n| store.view >= n);
            if at_end || (store.view >= from && store.length_before(store.view) - store.length_before(from) >= horizon)
            {
                let checked = if store.view == view && horizon == for_horizon {
                    checked.max(from)
                } else {
                    from
                };
                self.view_checked.set((store.view, checked, horizon));
                return store.view;
            }
            let next = store.view.max(from) + VIEW_STEP;
            store.load(next - 1);
            store.view = store.count.map_or(next, |n| next.min(n));
        }
    }

    /// Forgets the elements before the one of `w` (nothing before it is asked again).
    pub fn release_before(&self, w: f64) {
        let mut store = self.store.borrow_mut();
        let e = element_of(w).min(store.len().saturating_sub(1));
        store.curves.release_before(e);
        store.elements.release_before(e);
        let first = e as f64;
        while store.stops.front().is_some_and(|&s| s < first) {
            store.stops.pop_front();
        }
    }

    /// Element and curve parameter at `w` (the end of an element belongs to it only at the path end).
    fn locate(&self, w: f64) -> (usize, f64) {
        let store = self.held(element_of(w));
        Self::locate_in(&store, w)
    }

    #[inline]
    fn locate_in(store: &Store, w: f64) -> (usize, f64) {
        let n = store.len();
        let w = w.clamp(0.0, n as f64);
        let e = element_of(w).min(n - 1);
        let (a, b) = store.elements[e].span;
        let f = w - e as f64;
        let u = if f >= 1.0 { b } else { a + (b - a) * f };
        (e, u)
    }

    /// Curve point and derivatives up to `order` (power basis) at `w`, with its element, curve
    /// parameter and parameter span.
    #[inline(always)]
    fn curve_derivatives(&self, w: f64, order: usize) -> (usize, f64, (f64, f64), [[f64; MAX_DIM]; 3]) {
        let store = self.held(element_of(w));
        let (e, u) = Self::locate_in(&store, w);
        let x = &store.elements[e];
        (e, u, x.span, x.fast.eval(u, order))
    }

    /// Curve point (power basis) at `w`, with its element and parameter.
    #[inline(always)]
    fn curve_point(&self, w: f64) -> (usize, f64, [f64; MAX_DIM]) {
        let store = self.held(element_of(w));
        let (e, u) = Self::locate_in(&store, w);
        (e, u, store.elements[e].fast.point(u))
    }

    fn tip_and_axis(&self, w: f64) -> ([f64; 3], [f64; 3]) {
        let (e, _, p) = self.curve_point(w);
        let mut tip = [0.0; 3];
        tip[..self.tip].copy_from_slice(&p[..self.tip]);
        let mut axis = [0.0, 0.0, 1.0];
        if self.store.borrow().elements[e].fast.dim == 2 * self.tip && self.tip == 3 {
            axis = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
        }
        (tip, axis)
    }

    /// Joint positions and tool tip from a curve point at `w`.
    #[inline]
    fn point_at(&self, w: f64, element: usize, u: f64, p: &[f64; MAX_DIM]) -> PathPoint {
        // Element by element over fixed lengths: a copy of `self.tip` values was a call to
        // memcpy, some 4 % of the planning time.
        let tip = [p[0], p[1], if self.tip == 3 { p[2] } else { 0.0 }];
        let mut q = [0.0; MAX_AXES];
        match &self.kinematics {
            None => q[..3].copy_from_slice(&tip),
            Some((m, table)) => {
                let axis = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
                let k = ((w * C_TABLE as f64).round() as usize).min(table.len() - 1);
                let j = m.inverse(tip, axis, Some(table[k]));
                q[..5].copy_from_slice(&j);
            }
        }
        PathPoint { w, element, u, q, tip }
    }

    /// The point at element `element`, curve parameter `u` exactly (its `w` is where that
    /// lies on the path); `None` off the path.
    pub fn eval_at(&self, element: usize, u: f64) -> Option<PathPoint> {
        let p = {
            let store = self.held(element);
            let x = store.elements.get(element)?;
            let (a, b) = x.span;
            if !(u >= a && u <= b) {
                return None;
            }
            let w = element as f64 + if b > a { (u - a) / (b - a) } else { 0.0 };
            (w, x.fast.point(u))
        };
        Some(self.point_at(p.0, element, u, &p.1))
    }

    /// Joint positions and tool tip at `w`.
    pub fn eval(&self, w: f64) -> PathPoint {
        if self.kinematics.is_none() {
            let (p, dq, dt) = self.eval_d(w);
            self.last_derivative.set((w, dq, dt));
            return p;
        }
        let (element, u, p) = self.curve_point(w);
        self.point_at(w, element, u, &p)
    }

    /// [`Self::eval`] and [`Self::derivative`] in one evaluation.
    pub fn eval_d(&self, w: f64) -> (PathPoint, [f64; MAX_AXES], [f64; 3]) {
        if self.kinematics.is_some() {
            let (dq, dt) = self.derivative(w);
            return (self.eval(w), dq, dt);
        }
        let (e, u, (a, b), d) = self.curve_derivatives(w, 1);
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
        if self.kinematics.is_none() {
            let (at, dq, dt) = self.last_derivative.get();
            if at == w {
                return (dq, dt);
            }
            let (_, _, (a, b), d) = self.curve_derivatives(w, 1);
            let mut dq = [0.0; MAX_AXES];
            let mut dt = [0.0; 3];
            for i in 0..self.tip {
                dq[i] = d[1][i] * (b - a);
                dt[i] = d[1][i] * (b - a);
            }
            return (dq, dt);
        }
        let (e, _) = self.locate(w);
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

    /// Second and third derivatives of the joints by `w` at `w`: central differences of
    /// [`Self::derivative`] within `w`'s element (the third zero at its ends). For estimates
    /// only (a deceleration sequence's release), never for a check.
    pub fn higher_derivatives(&self, w: f64) -> ([f64; MAX_AXES], [f64; MAX_AXES]) {
        const STEP: f64 = 1e-5;
        let e = element_of(w) as f64;
        let (lo, hi) = ((w - STEP).max(e), (w + STEP).min(e + 1.0 - 1e-9));
        let mut second = [0.0; MAX_AXES];
        let mut third = [0.0; MAX_AXES];
        if hi <= lo {
            return (second, third);
        }
        let (at, _) = self.derivative(w);
        let (below, _) = self.derivative(lo);
        let (above, _) = self.derivative(hi);
        for i in 0..MAX_AXES {
            second[i] = (above[i] - below[i]) / (hi - lo);
            if w > lo && hi > w {
                third[i] = 2.0 * ((above[i] - at[i]) / (hi - w) - (at[i] - below[i]) / (w - lo)) / (hi - lo);
            }
        }
        (second, third)
    }

    /// Upper estimate of the tool-tip curvature on `[w0, w1]` (tabulated maxima of the cells
    /// the interval touches).
    pub fn max_curvature(&self, w0: f64, w1: f64) -> f64 {
        let (w0, w1) = (w0.min(w1), w0.max(w1));
        let store = self.held(element_of(w1));
        self.kappa.max(&store.elements, w0, w1)
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
        let store = self.held(a.element);
        crate::planner::verify::chord_error(&store.curves.view(a.element), self.tip, a.u, b.u, &pa, &pb)
    }
}

/// The element `w` lies in (the one it starts, at an element join), 0 before the path.
#[inline]
fn element_of(w: f64) -> usize {
    // A float-to-integer cast truncates (saturating): the floor for w >= 0.
    w.max(0.0) as usize
}

/// Whether the direction turns from `left` to `right` (first `n` coordinates).
pub(crate) fn turns(left: &[f64; MAX_DIM], right: &[f64; MAX_DIM], n: usize) -> bool {
    let unit = |d: &[f64; MAX_DIM]| {
        let len = d[..n].iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut t = [0.0; MAX_DIM];
        if len > 0.0 {
            for i in 0..n {
                t[i] = d[i] / len;
            }
        }
        t
    };
    let (l, r) = (unit(left), unit(right));
    (0..n).map(|i| l[i] * r[i]).sum::<f64>() < 1.0 - 1e-12
}

/// Hands `found` the curve parameters inside one element where the path's direction turns (in all coordinates
/// of the curve: for a two-curve path, a kink of the top curve turns the joints too): an
/// interior knot of multiplicity >= degree (C0) whose tangents differ. Together with the
/// element joins whose unit tangents differ these are the tangent breaks: a finite-jerk motion
/// must stop there, and VPOp lands its last sample exactly on the point.
pub(crate) fn interior_breaks(view: &CurveView, found: &mut dyn FnMut(f64)) {
    let n = view.dim();
    let (p, knots, count) = (view.degree(), view.knots(), view.control_point_count());
    let mut i = p + 1;
    while i < count {
        let mut m = 1;
        while i + m < count && knots[i + m] == knots[i] {
            m += 1;
        }
        let u = knots[i];
        if m >= p && turns(&view.derivatives_left(u, 1)[1], &view.derivatives(u, 1)[1], n) {
            found(u);
        }
        i += m;
    }
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

/// Upper estimate of the curvature over cells of `w`: per element, the maximum of each of its
/// cells, built when a query reaches the element, and the last [`KAPPA_TABLES_KEPT`] kept (a
/// rebuilt table has the same values). The queries follow the motion and its back-tracking:
/// building all 2,000 elements of a 1,000-line G1 program up front took a second before the
/// first stop check of `nurbs-planner`, and with 64 tables kept the back-tracking over a 5-axis
/// program's short moves built each one some 150 times (a 1,000-move impeller stretch: 470 s of
/// planning).
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

/// Element curvature tables kept at a time (16 kB each for a cubic element): enough for the
/// back-tracking over a dense program's short elements to find them again.
const KAPPA_TABLES_KEPT: usize = 1024;

/// The largest curvature of each cell of one element, and of each block of
/// [`KAPPA_BLOCK`] cells.
struct ElementCurvature {
    cells: Vec<f64>,
    blocks: Vec<f64>,
}

/// The largest of some (at least one) curvatures.
fn largest(values: &[f64]) -> f64 {
    values.iter().fold(values[0], |m, &c| m.max(c))
}

/// Cells per block of an [`ElementCurvature`]: a query looks at fewer than two blocks' cells
/// and the blocks between.
const KAPPA_BLOCK: usize = 64;

impl ElementCurvature {
    fn new(c: &PowerCurve, tip: usize) -> Self {
        let cells = cells_of(c);
        let (u_min, u_max) = (c.starts[0], {
            let s = c.spans.last().unwrap_or(&c.spans[0]);
            s.u0 + 1.0 / s.inv
        });
        // The samples of cell k at fractions (k + j / KAPPA_SAMPLES) / cells, j = 0 ..=
        // KAPPA_SAMPLES: the last of one cell is the first of the next (the same number), so
        // each is evaluated once (building the tables of a dense program's corner splines was
        // a tenth of VPOp's time there).
        let sample = |k: usize, j: usize| {
            let f = (k as f64 + j as f64 / KAPPA_SAMPLES as f64) / cells as f64;
            let u = (u_min + (u_max - u_min) * f).min(u_max);
            // A zero speed (cusp) gives infinity: kept, the caps then stop there.
            curvature_of(&c.eval(u, 2), tip)
        };
        let mut first = sample(0, 0);
        let cells: Vec<f64> = (0..cells)
            .map(|k| {
                let mut m = first;
                for j in 1..KAPPA_SAMPLES {
                    m = m.max(sample(k, j));
                }
                let last = sample(k + 1, 0);
                first = last;
                m.max(last)
            })
            .collect();
        let blocks = cells.chunks(KAPPA_BLOCK).map(largest).collect();
        ElementCurvature { cells, blocks }
    }

    /// Largest curvature over cells `a ..= b`: the cells at both ends, the blocks between.
    fn max(&self, a: usize, b: usize) -> f64 {
        let (first, last) = (a / KAPPA_BLOCK + 1, b / KAPPA_BLOCK);
        if first >= last {
            return largest(&self.cells[a..=b]);
        }
        let ends = largest(&self.cells[a..first * KAPPA_BLOCK]).max(largest(&self.cells[last * KAPPA_BLOCK..=b]));
        ends.max(largest(&self.blocks[first..last]))
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
    fn cell(curves: &Window<Element>, w: f64) -> (usize, usize) {
        let n = curves.len();
        let w = w.clamp(0.0, n as f64);
        let e = element_of(w).min(n - 1);
        let cells = cells_of(&curves[e].fast);
        (e, (((w - e as f64) * cells as f64) as usize).min(cells - 1))
    }

    /// Largest curvature over cells `a ..= b` of element `e` (its table built if need be).
    fn element_max(&self, curves: &Window<Element>, e: usize, a: usize, b: usize) -> f64 {
        let mut built = self.built.borrow_mut();
        let key = self.first + e;
        // The latest first: most queries are on the element the motion is on.
        if let Some((_, table)) = built.iter().rev().find(|(i, _)| *i == key) {
            return table.max(a, b);
        }
        if built.len() == KAPPA_TABLES_KEPT {
            built.pop_front();
        }
        let table = ElementCurvature::new(&curves[e].fast, self.tip);
        let m = table.max(a, b);
        built.push_back((key, table));
        m
    }

    /// Largest curvature over the cells from `w0` to `w1` (`w0 <= w1`).
    fn max(&self, curves: &Window<Element>, w0: f64, w1: f64) -> f64 {
        let ((ea, a), (eb, b)) = (Self::cell(curves, w0), Self::cell(curves, w1));
        if ea == eb {
            return self.element_max(curves, ea, a, b);
        }
        let last = |e: usize| cells_of(&curves[e].fast) - 1;
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
