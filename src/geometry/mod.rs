//! Owned toolpath geometry (std): curves as the readers produce them and the planners consume
//! them, with arc length, its inverse and curvature. Evaluation itself is the realtime core's
//! allocation-free [`CurveView`](nurbs_rtcore::CurveView).

mod arc_length;
mod curve;
mod placement;
mod toolpath;

pub use arc_length::{adaptive_simpson, simpson_length, ArcLengthTable};
pub use curve::{analyze, golden_max, CurveStats, Nurbs};
pub use placement::Placement;
pub use toolpath::{ElementKind, PathElement, Toolpath};
