//! A sequence indexed from the start of the path that forgets its front: what a streamed plan
//! keeps of per-segment or per-element state. Indices stay absolute (segment `k` is `w[k]`
//! however many segments before it are gone), so the planner reads the same with or without
//! releasing, and memory follows the look-ahead instead of the program's length.

use std::collections::VecDeque;
use std::ops::{Index, IndexMut};

#[derive(Clone, Debug)]
pub(crate) struct Window<T> {
    /// Absolute index of `items[0]`.
    base: usize,
    items: VecDeque<T>,
}

impl<T> Default for Window<T> {
    fn default() -> Self {
        Window {
            base: 0,
            items: VecDeque::new(),
        }
    }
}

impl<T> Window<T> {
    /// Empty, its first item to come at absolute index `base`.
    pub fn starting_at(base: usize) -> Self {
        Window {
            base,
            items: VecDeque::new(),
        }
    }

    pub fn from_vec(items: Vec<T>) -> Self {
        Window {
            base: 0,
            items: items.into(),
        }
    }

    /// One past the highest index (released items included).
    pub fn len(&self) -> usize {
        self.base + self.items.len()
    }

    pub fn push(&mut self, item: T) {
        self.items.push_back(item);
    }

    pub fn extend(&mut self, items: impl IntoIterator<Item = T>) {
        self.items.extend(items);
    }

    /// Inserts at absolute index `i` (not before the first held item).
    pub fn insert(&mut self, i: usize, item: T) {
        self.items.insert(self.slot(i), item);
    }

    /// Keeps the items below absolute index `len`.
    pub fn truncate(&mut self, len: usize) {
        self.items.truncate(len.saturating_sub(self.base));
    }

    /// Absolute index of the first item held.
    pub fn first_index(&self) -> usize {
        self.base
    }

    pub fn last(&self) -> Option<&T> {
        self.items.back()
    }

    pub fn get(&self, i: usize) -> Option<&T> {
        i.checked_sub(self.base).and_then(|k| self.items.get(k))
    }

    /// Forgets every item below absolute index `i`.
    pub fn release_before(&mut self, i: usize) {
        let n = i.saturating_sub(self.base).min(self.items.len());
        self.items.drain(..n);
        self.base += n;
    }

    fn slot(&self, i: usize) -> usize {
        i.checked_sub(self.base)
            .unwrap_or_else(|| panic!("index {i} was released (first held: {})", self.base))
    }
}

impl<T> Index<usize> for Window<T> {
    type Output = T;
    fn index(&self, i: usize) -> &T {
        &self.items[self.slot(i)]
    }
}

impl<T> IndexMut<usize> for Window<T> {
    fn index_mut(&mut self, i: usize) -> &mut T {
        let k = self.slot(i);
        &mut self.items[k]
    }
}

#[cfg(test)]
mod tests {
    use super::Window;

    #[test]
    fn indices_stay_absolute_after_release() {
        let mut w = Window::from_vec((0..10).collect::<Vec<usize>>());
        w.release_before(4);
        assert_eq!((w.len(), w[4], w[9]), (10, 4, 9));
        assert_eq!((w.get(3), w.get(5)), (None, Some(&5)));
        w.insert(5, 50);
        w.truncate(7);
        assert_eq!((w.len(), w[4], w[5], w[6], w.get(7)), (7, 4, 50, 5, None));
    }

    #[test]
    #[should_panic(expected = "was released")]
    fn a_released_index_is_a_bug() {
        let mut w = Window::from_vec(vec![1, 2, 3]);
        w.release_before(2);
        let _ = w[1];
    }
}
