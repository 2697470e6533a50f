//! Many short lists stored end to end in one buffer (a neighbour list or the rows of each UAV):
//! refilled every tick without allocating once the buffer has reached its working size, where a
//! vector per list would grow again whenever one list reaches a new length.

use std::ops::Index;

/// Lists `0..len()` of items, each a contiguous span of one shared buffer.
#[derive(Debug, Clone)]
pub struct Ragged<T> {
    items: Vec<T>,
    /// `(start, end)` of each list in `items`.
    spans: Vec<(usize, usize)>,
}

impl<T> Default for Ragged<T> {
    fn default() -> Self {
        Self { items: Vec::new(), spans: Vec::new() }
    }
}

impl<T> Ragged<T> {
    /// Empties it into `n` empty lists, keeping its buffers.
    pub(crate) fn reset(&mut self, n: usize) {
        self.items.clear();
        self.spans.clear();
        self.spans.resize(n, (0, 0));
    }

    /// Makes list `k` the items `fill` appends to the buffer (list `k` must be `< len()`; lists may
    /// be filled in any order, each once per [`Ragged::reset`]).
    pub(crate) fn fill(&mut self, k: usize, fill: impl FnOnce(&mut Vec<T>)) {
        let start = self.items.len();
        fill(&mut self.items);
        self.spans[k] = (start, self.items.len());
    }

    /// Makes each list `k` of `lists`, given as `(k, start, end)`, the items `start..end` of
    /// `items`, all of them copied at once to the end of the buffer (each `k < len()`, once per
    /// [`Ragged::reset`], as [`Ragged::fill`]).
    pub(crate) fn extend_lists(&mut self, items: &[T], lists: impl Iterator<Item = (usize, usize, usize)>)
    where
        T: Clone,
    {
        let offset = self.items.len();
        self.items.extend_from_slice(items);
        for (k, start, end) in lists {
            self.spans[k] = (offset + start, offset + end);
        }
    }

    /// The number of lists.
    pub fn len(&self) -> usize {
        self.spans.len()
    }

    /// True when there are no lists.
    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// List `k`, or None when there is no list `k`.
    pub fn get(&self, k: usize) -> Option<&[T]> {
        self.spans.get(k).and_then(|&(start, end)| self.items.get(start..end))
    }
}

impl<T> Index<usize> for Ragged<T> {
    type Output = [T];

    /// List `k` (empty when there is no list `k`).
    fn index(&self, k: usize) -> &[T] {
        self.get(k).unwrap_or_default()
    }
}

impl<T> FromIterator<Vec<T>> for Ragged<T> {
    /// The lists in the order given.
    fn from_iter<I: IntoIterator<Item = Vec<T>>>(lists: I) -> Self {
        let mut ragged = Ragged::default();
        for list in lists {
            let start = ragged.items.len();
            ragged.items.extend(list);
            ragged.spans.push((start, ragged.items.len()));
        }
        ragged
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Filled in any order, every list reads back what was put in it, and refilling after a
        /// reset forgets the old lists.
        #[test]
        fn lists_read_back_what_was_filled(
            first in prop::collection::vec(prop::collection::vec(0u32..100, 0..6), 0..20),
            second in prop::collection::vec(prop::collection::vec(0u32..100, 0..6), 0..20),
            reversed: bool,
        ) {
            let mut ragged = Ragged::default();
            for lists in [&first, &second] {
                ragged.reset(lists.len());
                let order: Vec<usize> =
                    if reversed { (0..lists.len()).rev().collect() } else { (0..lists.len()).collect() };
                for &k in &order {
                    ragged.fill(k, |out| out.extend(&lists[k]));
                }
                prop_assert_eq!(ragged.len(), lists.len());
                for (k, list) in lists.iter().enumerate() {
                    prop_assert_eq!(&ragged[k], &list[..]);
                    prop_assert_eq!(ragged.get(k), Some(&list[..]));
                }
                prop_assert_eq!(ragged.get(lists.len()), None);
                prop_assert!(ragged[lists.len()].is_empty());
            }
        }
    }
}
