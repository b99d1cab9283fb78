//! Feedrate planners. [`erwinski`] is the main, streaming-capable planner of Erwinski et al. 2022; it
//! turns toolpath geometry into `nurbs_rtcore` segment records whose sampled motion never
//! exceeds an axis limit.

pub mod axial;
pub mod corner;
pub mod erwinski;
pub mod flf;
mod limits;
mod nodes;
mod quick_check;
pub mod scurve_fit;
pub mod simulate;
pub mod verify;
pub mod vpop;
mod window;

pub use erwinski::{plan, FinalRecord, Plan, PlanError, PlanOptions, PlanReport, Planner};
pub use limits::{Limits, LimitsError};

use crate::geometry::Toolpath;
use nurbs_rtcore::executor::CurveSet;
use nurbs_rtcore::CurveView;

/// The curves of a toolpath as the realtime interpolator addresses them, with their
/// programmed feeds.
pub struct PathCurves<'a> {
    views: Vec<CurveView<'a>>,
    tip: usize,
    feeds: Vec<Option<f64>>,
}

impl<'a> PathCurves<'a> {
    pub fn new(toolpath: &'a Toolpath) -> Self {
        PathCurves {
            views: toolpath.elements.iter().map(|e| e.curve.view()).collect(),
            tip: toolpath.tip_dim(),
            feeds: toolpath.elements.iter().map(|e| e.feed).collect(),
        }
    }
    pub fn len(&self) -> usize {
        self.views.len()
    }
    pub fn is_empty(&self) -> bool {
        self.views.is_empty()
    }
    pub fn view(&self, i: usize) -> &CurveView<'a> {
        &self.views[i]
    }
    /// Programmed feed of element `i` (mm/s; G-code `F`, JSON `feed_mm_s`), if the source gives one.
    pub fn programmed_feed(&self, i: usize) -> Option<f64> {
        self.feeds.get(i).copied().flatten()
    }
}

impl CurveSet for PathCurves<'_> {
    fn curve(&self, index: usize) -> Option<CurveView<'_>> {
        self.views.get(index).copied()
    }
    fn tip_axes(&self) -> usize {
        self.tip
    }
}
