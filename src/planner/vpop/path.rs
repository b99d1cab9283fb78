//! The path as VPOp sees it: one coordinate `w` over the whole toolpath (element `e` covers
//! `[e, e + 1]`, linear in its curve parameter), and at every `w` the joint positions q(w) that
//! the limits apply to (the tool tip for 2-/3-axis paths, x y z a c on the XYZAC machine) and
//! the tool tip in the workpiece frame (feed and chord error).

use crate::geometry::Toolpath;
use crate::kinematics::Xyzac;
use crate::planner::axial::MAX_AXES;
use nurbs_rtcore::CurveView;

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
    tip: usize,
    kinematics: Option<(Xyzac, Vec<f64>)>,
}

/// Samples per element of the C-angle continuity table.
const C_TABLE: usize = 4096;

impl<'a> JointPath<'a> {
    /// Tool-tip path (joints = tip coordinates).
    pub fn tip(toolpath: &'a Toolpath) -> Self {
        let views: Vec<CurveView<'a>> = toolpath.elements.iter().map(|e| e.curve.view()).collect();
        let spans = views.iter().map(|v| (v.u_min(), v.u_max())).collect();
        JointPath {
            views,
            spans,
            tip: toolpath.tip_dim(),
            kinematics: None,
        }
    }

    /// Five-axis path on an XYZAC machine: every element must carry a top curve (dim 6).
    pub fn five_axis(toolpath: &'a Toolpath, machine: Xyzac) -> Result<Self, String> {
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
    /// Largest coordinate (path end).
    pub fn end(&self) -> f64 {
        self.views.len() as f64
    }
    pub fn machine(&self) -> Option<&Xyzac> {
        self.kinematics.as_ref().map(|(m, _)| m)
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
        let p = self.views[e].point(u);
        let mut tip = [0.0; 3];
        tip[..self.tip].copy_from_slice(&p[..self.tip]);
        let mut axis = [0.0, 0.0, 1.0];
        if self.views[e].dim() == 2 * self.tip && self.tip == 3 {
            axis = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
        }
        (tip, axis)
    }

    /// Joint positions and tool tip at `w`.
    pub fn eval(&self, w: f64) -> PathPoint {
        let (element, u) = self.locate(w);
        let p = self.views[element].point(u);
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

    /// dq/dw and d(tip)/dw at `w` (analytic for tip paths, central differences on the machine).
    pub fn derivative(&self, w: f64) -> ([f64; MAX_AXES], [f64; 3]) {
        let (e, u) = self.locate(w);
        let (a, b) = self.spans[e];
        if self.kinematics.is_none() {
            let d = self.views[e].derivatives(u, 1)[1];
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
        let d = self.views[e].derivatives(u, 2);
        let n = self.tip;
        let dot = |x: &nurbs_rtcore::Vector, y: &nurbs_rtcore::Vector| (0..n).map(|i| x[i] * y[i]).sum::<f64>();
        let s2 = dot(&d[1], &d[1]);
        if s2 == 0.0 {
            return f64::INFINITY;
        }
        let cross2 = (s2 * dot(&d[2], &d[2]) - dot(&d[1], &d[2]).powi(2)).max(0.0);
        cross2.sqrt() / (s2 * s2.sqrt())
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
