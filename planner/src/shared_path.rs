//! The toolpath of a motion, read once and shared by all its plans.
//!
//! A motion is planned more than once: again at another feed override, again from the point a
//! hold or an underrun stopped it. Each such plan starts somewhere ahead of the module, never
//! before it, yet reading the file afresh would read, round and smooth every line before that
//! point again, which takes seconds deep into a long program (100,000 smoothed lines: about
//! 1.5 s per re-plan). Here the file is read once, by whichever plan needs an element first;
//! every plan reads the same elements from a window that starts where the module is and ends
//! where the plan furthest ahead has read ([`SharedPath::release_before`] moves its start), so
//! memory follows the look-ahead and a re-plan finds its start at once.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex, MutexGuard};

use nurbs_motion::geometry::{PathElement, Toolpath};
use nurbs_motion::planner::PathCurves;
use nurbs_motion::readers::{ElementStream, ReadError};

/// A toolpath read as its plans ask for it (cheap to clone: the clones share it).
#[derive(Clone)]
pub struct SharedPath {
    shared: Arc<Mutex<Shared>>,
}

struct Shared {
    /// The unread rest of the file; `None` once it has ended (or failed: `error`).
    source: Option<ElementStream>,
    /// The elements read and still kept, from element `first` on.
    kept: VecDeque<PathElement>,
    first: usize,
    /// Why the file could not be read further: the element after the last one read.
    error: Option<ReadError>,
    /// No plan will start before this element: those before it go once no reader needs them.
    floor: usize,
    /// Each open reader's next element, counted per element.
    readers: BTreeMap<usize, usize>,
}

impl Shared {
    /// Forgets the elements before the floor that no reader still has to read.
    fn trim(&mut self) {
        let keep_from = self.readers.keys().next().map_or(self.floor, |&r| r.min(self.floor));
        while self.first < keep_from && self.kept.pop_front().is_some() {
            self.first += 1;
        }
    }

    fn add_reader(&mut self, at: usize) {
        *self.readers.entry(at).or_insert(0) += 1;
    }

    fn remove_reader(&mut self, at: usize) {
        if let Some(n) = self.readers.get_mut(&at) {
            *n -= 1;
            if *n == 0 {
                self.readers.remove(&at);
            }
        }
    }

    /// Element `i` (read from the file if it is the next one); `None` past the end.
    fn element(&mut self, i: usize) -> Option<Result<PathElement, ReadError>> {
        while self.first + self.kept.len() <= i {
            match self.source.as_mut()?.next() {
                Some(Ok(e)) => self.kept.push_back(e),
                Some(Err(e)) => {
                    self.error = Some(e);
                    self.source = None;
                }
                None => self.source = None,
            }
        }
        match i.checked_sub(self.first) {
            Some(k) => self.kept.get(k).cloned().map(Ok),
            // A reader only ever moves forward from where it began, and what it has still to
            // read is kept: this would be a bug, reported as the path's end with the reason.
            None => Some(Err(ReadError::new(
                "toolpath",
                format!("path element {i} was asked for after it had been released"),
            ))),
        }
    }
}

impl SharedPath {
    /// The path `source` reads, nothing read yet.
    pub fn new(source: ElementStream) -> Self {
        SharedPath {
            shared: Arc::new(Mutex::new(Shared {
                source: Some(source),
                kept: VecDeque::new(),
                first: 0,
                error: None,
                floor: 0,
                readers: BTreeMap::new(),
            })),
        }
    }

    /// A whole toolpath in memory (tests, benches).
    pub fn whole(toolpath: &Toolpath) -> Self {
        SharedPath::new(Box::new(toolpath.elements.clone().into_iter().map(Ok)))
    }

    fn lock(&self) -> MutexGuard<'_, Shared> {
        // A reader that panicked under the lock left the state consistent (every change to it
        // is one statement): go on with it.
        self.shared.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The path for one plan, from the first element a plan may still start at (from the
    /// path's start until [`SharedPath::release_before`] moves it), read as the plan asks.
    pub fn open(&self) -> Result<PathCurves, String> {
        let first = {
            let mut shared = self.lock();
            let first = shared.first;
            shared.add_reader(first);
            first
        };
        let reader = Reader {
            path: self.clone(),
            next: first,
            ended: false,
        };
        PathCurves::streamed_from(first, Box::new(reader)).map_err(|e| e.to_string())
    }

    /// No plan will start before element `i` any more (the module has passed the elements
    /// before it): they are forgotten once every open plan has read past them.
    pub fn release_before(&self, i: usize) {
        let mut shared = self.lock();
        if i > shared.floor {
            shared.floor = i;
            shared.trim();
        }
    }

    /// The elements kept (read and not yet released), as (first index, count).
    pub fn kept(&self) -> (usize, usize) {
        let shared = self.lock();
        (shared.first, shared.kept.len())
    }
}

/// One plan's way through a [`SharedPath`]: the elements in order from where it was opened,
/// then the read error if the file failed, then nothing.
struct Reader {
    path: SharedPath,
    next: usize,
    ended: bool,
}

impl Iterator for Reader {
    type Item = Result<PathElement, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.ended {
            return None;
        }
        let mut shared = self.path.lock();
        let item = shared.element(self.next).or_else(|| shared.error.clone().map(Err));
        match &item {
            Some(Ok(_)) => {
                shared.remove_reader(self.next);
                self.next += 1;
                shared.add_reader(self.next);
            }
            Some(Err(_)) | None => {
                self.ended = true;
                shared.remove_reader(self.next);
            }
        }
        shared.trim();
        item
    }
}

impl Drop for Reader {
    fn drop(&mut self) {
        if !self.ended {
            let mut shared = self.path.lock();
            shared.remove_reader(self.next);
            shared.trim();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nurbs_motion::geometry::{ElementKind, Nurbs};

    /// A stream of `n` straight lines along x, each 1 mm, counting how many were read; the
    /// element `fail_at` (if any) is a read error.
    fn lines(n: usize, fail_at: Option<usize>, read: Arc<Mutex<usize>>) -> ElementStream {
        Box::new((0..n).map(move |i| {
            *read.lock().unwrap() += 1;
            if Some(i) == fail_at {
                return Err(ReadError::new("test", format!("line {i} does not read")));
            }
            let x = i as f64;
            let points = [vec![x, 0.0], vec![x + 1.0, 0.0]];
            Ok(PathElement {
                kind: ElementKind::Polyline,
                curve: Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &points, None).unwrap(),
                feed: None,
                source_line: Some(i + 1),
            })
        }))
    }

    fn start_x(curves: &PathCurves, i: usize) -> f64 {
        curves.element(i).curve.control_point(0)[0]
    }

    #[test]
    fn plans_share_one_read_of_the_file() {
        let read = Arc::new(Mutex::new(0));
        let path = SharedPath::new(lines(100, None, Arc::clone(&read)));
        let mut a = path.open().unwrap();
        assert!(a.load(59));
        assert_eq!(*read.lock().unwrap(), 60);
        // A second plan, opened later, reads the same elements without reading the file again.
        let mut b = path.open().unwrap();
        assert!(b.load(59));
        assert_eq!(*read.lock().unwrap(), 60);
        for i in [0, 31, 59] {
            assert_eq!(a.element(i), b.element(i));
            assert_eq!(start_x(&b, i), i as f64);
        }
        // Reading on: one read for both.
        assert!(b.load(79) && a.load(79));
        assert_eq!(*read.lock().unwrap(), 80);
        assert!(!a.load(100) && a.is_complete() && a.len() == 100);
    }

    #[test]
    fn a_plan_opened_after_a_release_starts_at_the_floor_and_memory_follows() {
        let read = Arc::new(Mutex::new(0));
        let path = SharedPath::new(lines(1000, None, read));
        let mut ahead = path.open().unwrap();
        assert!(ahead.load(299));
        ahead.release_before(290);
        // The module passed element 250: the plan reading ahead is at 300, so 250 on is kept.
        path.release_before(250);
        assert_eq!(path.kept(), (250, 50));
        let mut replan = path.open().unwrap();
        assert_eq!(start_x(&replan, 250), 250.0);
        assert!(replan.get(249).is_none());
        // The re-plan's reader, at 251, keeps what it has still to read while the floor moves on.
        path.release_before(280);
        assert_eq!(path.kept().0, 251);
        assert!(replan.load(299));
        assert_eq!(start_x(&replan, 270), 270.0);
        assert_eq!(path.kept().0, 280);
        // Once it is gone, what no plan needs goes too.
        drop(replan);
        path.release_before(295);
        assert_eq!(path.kept(), (295, 5));
    }

    #[test]
    fn a_read_error_ends_every_plan_at_the_same_element() {
        let read = Arc::new(Mutex::new(0));
        let path = SharedPath::new(lines(100, Some(40), read));
        let mut a = path.open().unwrap();
        assert!(!a.load(50));
        assert_eq!(a.len(), 40);
        assert!(a
            .error()
            .is_some_and(|e| e.to_string().contains("line 40 does not read")));
        let mut b = path.open().unwrap();
        assert!(!b.load(41));
        assert_eq!(b.len(), 40);
        assert_eq!(a.error(), b.error());
    }
}
