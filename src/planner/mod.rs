//! Feedrate planners. [`erwinski`] is the main, streaming-capable planner of Erwinski et al. 2022; it
//! turns toolpath geometry into `nurbs_rtcore` segment records whose sampled motion never
//! exceeds an axis limit.

pub mod axial;
pub mod corner;
pub mod erwinski;
pub mod fit;
mod limits;
pub mod presets;
pub mod reach;
pub mod simulate;
pub mod verify;
pub mod vpop;
mod window;

pub use erwinski::{
    flf, plan, scurve_fit, FinalRecord, MovingStart, Plan, PlanError, PlanOptions, PlanReport, Planner,
    SLOW_DOWN_SHARES,
};
pub use limits::{Limits, LimitsError};

use crate::geometry::{PathElement, Toolpath};
use crate::readers::{ElementStream, ReadError};
use nurbs_rtcore::interpolator::CurveSet;
use nurbs_rtcore::CurveView;
use window::Window;

/// The curves of a toolpath as the realtime interpolator addresses them (by element index),
/// with their programmed feeds: a whole toolpath, or a stream read as far as the planner asks
/// ([`PathCurves::load`]) and forgotten behind it ([`PathCurves::release_before`]), so that a
/// program of any length is planned in memory that follows the look-ahead.
pub struct PathCurves {
    elements: Window<PathElement>,
    /// The rest of a streamed toolpath; `None` once every element is read.
    source: Option<ElementStream>,
    /// Why the stream ended early: the path ends before the element that could not be read.
    error: Option<ReadError>,
    tip: usize,
    /// Changes whenever elements are forgotten (their memory may hold later curves).
    generation: u64,
}

impl PathCurves {
    /// A whole toolpath (copied).
    pub fn new(toolpath: &Toolpath) -> Self {
        Self::taking(toolpath.clone())
    }

    /// A whole toolpath (taken).
    pub fn taking(toolpath: Toolpath) -> Self {
        let tip = toolpath.tip_dim();
        PathCurves {
            elements: Window::from_vec(toolpath.elements),
            source: None,
            error: None,
            tip,
            generation: 0,
        }
    }

    /// A toolpath read as it is planned; its first element gives the tool-tip dimension (an
    /// element of another is an error when it comes).
    pub fn streamed(source: ElementStream) -> Result<Self, ReadError> {
        Self::streamed_from(0, source)
    }

    /// The same from element `first` on: `source` begins there (a plan that starts further on
    /// needs none of the elements before it).
    pub fn streamed_from(first: usize, mut source: ElementStream) -> Result<Self, ReadError> {
        let element = source.next().transpose()?;
        let tip = element.as_ref().map_or(2, |e| e.curve.tip_dim());
        let mut elements = Window::starting_at(first);
        elements.extend(element);
        Ok(PathCurves {
            elements,
            source: Some(source),
            error: None,
            tip,
            generation: 0,
        })
    }

    /// Whether element `i` exists, reading the stream as far as it; `false` past the path end
    /// (or where the stream failed: [`PathCurves::error`]).
    pub fn load(&mut self, i: usize) -> bool {
        while self.elements.len() <= i {
            let Some(source) = &mut self.source else {
                return false;
            };
            match source.next() {
                Some(Ok(e)) if e.curve.tip_dim() == self.tip => self.elements.push(e),
                Some(Ok(e)) => {
                    // The readers refuse such a file; a source of another kind ends the path here.
                    self.error = Some(ReadError::new(
                        "toolpath",
                        format!(
                            "path element {} is {}-D in a {}-D path",
                            self.elements.len(),
                            e.curve.tip_dim(),
                            self.tip
                        ),
                    ));
                    self.source = None;
                }
                Some(Err(e)) => {
                    self.error = Some(e);
                    self.source = None;
                }
                None => self.source = None,
            }
        }
        true
    }

    /// Hands the unread rest of a streamed path to `wrap`, which gives back what to read it
    /// from instead (the same elements in the same order): e.g. a reader in another thread.
    pub fn wrap_source(&mut self, wrap: impl FnOnce(ElementStream) -> ElementStream) {
        if let Some(source) = self.source.take() {
            self.source = Some(wrap(source));
        }
    }

    /// Reads the stream to its end (forgetting what it reads on the way but the last element).
    pub fn load_to_end(&mut self) {
        while self.source.is_some() {
            let next = self.elements.len();
            if self.load(next) && next > 0 {
                self.release_before(next);
            }
        }
    }

    /// Elements read so far (one past the highest index; forgotten ones included).
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// The first element not forgotten (where a streamed path began, or was released to).
    pub fn first(&self) -> usize {
        self.elements.first_index()
    }

    pub fn is_empty(&self) -> bool {
        self.elements.len() == 0
    }

    /// Whether the whole path has been read (then [`PathCurves::len`] is its length).
    pub fn is_complete(&self) -> bool {
        self.source.is_none()
    }

    /// Why a streamed path ended before its file did.
    pub fn error(&self) -> Option<&ReadError> {
        self.error.as_ref()
    }

    /// Element `i`, read and not forgotten.
    pub fn element(&self, i: usize) -> &PathElement {
        &self.elements[i]
    }

    /// Element `i` if it is read and not forgotten.
    pub fn get(&self, i: usize) -> Option<&PathElement> {
        self.elements.get(i)
    }

    pub fn view(&self, i: usize) -> CurveView<'_> {
        self.elements[i].curve.view()
    }

    /// Programmed feed of element `i` (mm/s; G-code `F`, JSON `feed_mm_s`), if the source gives one.
    pub fn programmed_feed(&self, i: usize) -> Option<f64> {
        self.elements.get(i).and_then(|e| e.feed)
    }

    /// Forgets the elements before `i`.
    pub fn release_before(&mut self, i: usize) {
        if i > self.elements.first_index() {
            self.elements.release_before(i);
            self.generation += 1;
        }
    }

    /// Number of tool-tip coordinates (2 or 3).
    pub fn tip_dim(&self) -> usize {
        self.tip
    }
}

impl CurveSet for PathCurves {
    fn curve(&self, index: usize) -> Option<CurveView<'_>> {
        self.elements.get(index).map(|e| e.curve.view())
    }
    fn tip_axes(&self) -> usize {
        self.tip
    }
    fn generation(&self) -> u64 {
        self.generation
    }
}
