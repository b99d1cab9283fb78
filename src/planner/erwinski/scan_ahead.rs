//! The FLF scan, critical points and arc-length table of the elements ahead, computed in a
//! helper thread while the planner solves segments (on dense G1 programs they were some 30 % of
//! its work).
//!
//! The helper reads the path's stream in place of the planner, at most [`AHEAD`] elements
//! ahead of it, and for each short element (at most [`MAX_SAMPLES`] scan samples) computes the
//! scan's samples, the critical points chunk by chunk as the planner would find them, and the
//! complete arc-length table. The planner takes them in the same chunks as it would compute
//! them ([`FlfScan::extend_from`], [`ArcLengthTable::extend_past_from`]); every sample,
//! critical point and table piece depends on its curve and the limits alone, so the plan is the
//! same bit for bit. A longer element is scanned by the planner as it goes, so that its first
//! segments need not wait for the scan of the whole element.

use super::flf::{CriticalPoint, CriticalPointSearch, FlfScan, ScanSample};
use crate::geometry::{ArcLengthTable, PathElement};
use crate::planner::{Limits, PathCurves};
use crate::readers::ReadError;
use std::collections::VecDeque;
use std::sync::mpsc::sync_channel;
use std::sync::{Arc, Mutex};

/// Elements the helper reads ahead of the planner at most.
const AHEAD: usize = 64;

/// Elements with more scan samples than this are scanned by the planner itself.
const MAX_SAMPLES: usize = 4096;

/// An element's scan, computed by the helper.
pub(super) struct Scanned {
    pub samples: Vec<ScanSample>,
    pub table: ArcLengthTable,
    /// Per chunk of samples the planner takes (`per_point` at a time, as it would compute
    /// them), the critical points the search finds once the chunk is in and the parameter
    /// below which no later one can lie; the next chunk's first.
    chunks: VecDeque<(Vec<CriticalPoint>, f64)>,
}

impl Scanned {
    /// The critical points and settled parameter of the next chunk.
    pub fn next_chunk(&mut self) -> (Vec<CriticalPoint>, f64) {
        self.chunks.pop_front().unwrap_or((Vec::new(), f64::INFINITY))
    }
}

/// The planner's end: the scans the helper has handed over, by element index.
pub(super) struct ScanAhead {
    ready: Arc<Mutex<VecDeque<(usize, Scanned)>>>,
}

impl ScanAhead {
    /// Starts the helper on the unread rest of `curves` (nothing where the whole path is read
    /// already). `limits_of` gives an element's planning limits, `per_point` the scan density.
    pub fn start(
        curves: &mut PathCurves,
        tip: usize,
        per_point: usize,
        limits_of: impl Fn(&PathElement) -> Limits + Send + 'static,
    ) -> ScanAhead {
        let ready = Arc::new(Mutex::new(VecDeque::new()));
        let handed = Arc::clone(&ready);
        let mut index = curves.len();
        curves.wrap_source(|source| {
            let (sender, receiver) = sync_channel::<(Result<PathElement, ReadError>, Option<Scanned>)>(AHEAD);
            let helper = std::thread::Builder::new().name("nurbs-scan".into()).spawn(move || {
                for item in source {
                    let scanned = item
                        .as_ref()
                        .ok()
                        .filter(|e| e.curve.tip_dim() == tip)
                        .and_then(|e| scan(e, tip, per_point, &limits_of(e)));
                    let failed = item.is_err();
                    // The planner has gone (done, or stopped): so does the helper.
                    if sender.send((item, scanned)).is_err() || failed {
                        return;
                    }
                }
            });
            match helper {
                Ok(_) => Box::new(receiver.into_iter().map(move |(item, scanned)| {
                    if let (Some(s), Ok(mut ready)) = (scanned, handed.lock()) {
                        // Read but not planned (a plan that starts further on): the planner
                        // scans what is dropped here itself, should it get there.
                        if ready.len() >= 4 * AHEAD {
                            ready.pop_front();
                        }
                        ready.push_back((index, s));
                    }
                    index += 1;
                    item
                })),
                Err(e) => Box::new(std::iter::once(Err(ReadError::new(
                    "toolpath",
                    format!("could not start the scanning thread: {e}"),
                )))),
            }
        });
        ScanAhead { ready }
    }

    /// The helper's scan of element `c`, if it made one (those of elements before `c` are
    /// dropped: the planner has passed them).
    pub fn take(&self, c: usize) -> Option<Scanned> {
        let mut ready = self.ready.lock().ok()?;
        while ready.front().is_some_and(|(i, _)| *i < c) {
            ready.pop_front();
        }
        match ready.front() {
            Some((i, _)) if *i == c => ready.pop_front().map(|(_, s)| s),
            _ => None,
        }
    }
}

/// The scan of a short element; `None` for a long one.
fn scan(element: &PathElement, tip: usize, per_point: usize, limits: &Limits) -> Option<Scanned> {
    let view = element.curve.view();
    let mut scan = FlfScan::lazy(&view, per_point);
    if scan.full_len() > MAX_SAMPLES {
        return None;
    }
    let samples = scan.samples(&view, tip, limits, 0, scan.full_len());
    // The critical-point search as the planner would run it, chunk by chunk.
    let (mut search, mut chunks) = (CriticalPointSearch::default(), VecDeque::new());
    while !scan.is_complete() {
        scan.extend_from(&samples, per_point, &mut |_, _, _| {});
        let mut points = Vec::new();
        search.advance(&view, tip, limits, &scan, &mut points);
        chunks.push_back((points, search.settled_below(&scan)));
    }
    Some(Scanned {
        samples,
        table: ArcLengthTable::new(&element.curve),
        chunks,
    })
}
