//! Running segment records through the realtime interpolator, as the servo thread will.

use super::axial::FiniteDifferences;
use super::{Limits, PathCurves};
use nurbs_rtcore::executor::{Interpolator, Sample, Step};
use nurbs_rtcore::SegmentRecord;

/// Interpolator and finite-difference state between two segments: the planner's checkpoint.
#[derive(Clone, Copy, Debug)]
pub struct SimState {
    pub interp: Interpolator,
    pub check: FiniteDifferences,
    pub samples: usize,
    /// The last sample produced (chord checks span segment boundaries).
    pub last_sample: Option<Sample>,
}

impl SimState {
    pub fn start(axes: usize, period: f64) -> Self {
        SimState {
            interp: Interpolator::new(),
            check: FiniteDifferences::new(axes, period),
            samples: 0,
            last_sample: None,
        }
    }
}

/// Runs `record` from `state` until the interpolator needs the next record (or the path ends),
/// feeding every sample to the finite-difference check and to `sink`. Returns `false` if the
/// interpolator rejected the record.
pub fn run_segment(
    curves: &PathCurves,
    limits: &Limits,
    state: &mut SimState,
    record: SegmentRecord,
    sink: &mut dyn FnMut(&Sample),
) -> bool {
    let mut pending = Some(record);
    let tip = limits.velocity.len();
    loop {
        match state.interp.step(curves, limits.period, &mut || pending.take()) {
            Step::Sample(s) => {
                state.check.push(&s.point[..tip], limits);
                state.samples += 1;
                sink(&s);
            }
            Step::Starved => return true,
            Step::Finished => {
                state.check.finish(limits);
                return true;
            }
            Step::BadRecord => return false,
        }
    }
}

/// All setpoints of a plan, one per period.
pub fn setpoints(curves: &PathCurves, limits: &Limits, records: &[SegmentRecord]) -> Vec<Sample> {
    let mut state = SimState::start(limits.velocity.len(), limits.period);
    let mut out = Vec::new();
    for r in records {
        run_segment(curves, limits, &mut state, *r, &mut |s| out.push(*s));
    }
    out
}
