//! The samples a synced reliable reader holds: received, not yet handed out.
//!
//! A ring of slots, one per seq from the lowest held sample on: holding, finding and taking
//! the lowest sample cost O(1), whatever order samples arrive in (a map ordered by seq moves
//! its entries about at every insertion and removal, which was most of a reader's cost per
//! sample). The reader admits a sample only within `depth` of the first seq it has not handed
//! out or given up, and every held sample lies at or above that seq, so the ring never spans
//! more than `depth` slots.

use std::collections::VecDeque;

/// Most slots the ring spans: a guard against a caller that breaks the window's bound, so
/// that one far-off seq cannot make it allocate without limit.
pub(crate) const MAX_SPAN: u64 = 1 << 20;

/// Samples by seq; slot 0 (seq `start`) is always held while any is.
#[derive(Debug)]
pub(crate) struct Held<S> {
    start: u64,
    slots: VecDeque<Option<S>>,
    count: usize,
}

impl<S> Default for Held<S> {
    fn default() -> Self {
        Held {
            start: 0,
            slots: VecDeque::new(),
            count: 0,
        }
    }
}

impl<S> Held<S> {
    /// Number of samples held.
    pub(crate) fn len(&self) -> usize {
        self.count
    }

    /// The slot of `seq`, if the ring spans it.
    fn index(&self, seq: u64) -> Option<usize> {
        let index = usize::try_from(seq.checked_sub(self.start)?).ok()?;
        (index < self.slots.len()).then_some(index)
    }

    /// True if `seq` is held.
    pub(crate) fn contains(&self, seq: u64) -> bool {
        self.index(seq)
            .is_some_and(|index| self.slots[index].is_some())
    }

    /// The lowest seq held.
    pub(crate) fn first(&self) -> Option<u64> {
        (self.count > 0).then_some(self.start)
    }

    /// Holds `sample` as `seq`; false (and `sample` dropped) if `seq` was held already, or
    /// if holding it would span more than [`MAX_SPAN`] slots (the reader's window keeps far
    /// below it; a sample refused here is simply missing, and asked for again).
    pub(crate) fn insert(&mut self, seq: u64, sample: S) -> bool {
        if self.count > 0 {
            let low = seq.min(self.start);
            let high = seq.max(self.start + self.slots.len() as u64 - 1);
            if high - low >= MAX_SPAN {
                return false;
            }
        }
        if self.count == 0 {
            self.slots.clear();
            self.start = seq;
        } else if seq < self.start {
            for _ in seq..self.start {
                self.slots.push_front(None);
            }
            self.start = seq;
        }
        // Within `depth` of the lowest held seq (the reader's window): fits in a usize.
        let index = usize::try_from(seq - self.start).unwrap_or(usize::MAX);
        if index >= self.slots.len() {
            self.slots.resize_with(index + 1, || None);
        }
        let slot = &mut self.slots[index];
        if slot.is_some() {
            return false;
        }
        *slot = Some(sample);
        self.count += 1;
        true
    }

    /// Takes the lowest held sample if it is `seq`.
    pub(crate) fn take_first(&mut self, seq: u64) -> Option<S> {
        if self.first() != Some(seq) {
            return None;
        }
        let sample = self.slots.pop_front().flatten();
        self.start = self.start.saturating_add(1);
        self.count -= 1;
        self.skip_empty();
        sample
    }

    /// Drops every sample held below `seq`; returns how many there were.
    pub(crate) fn drop_below(&mut self, seq: u64) -> usize {
        let before = self.count;
        while self.count > 0 && self.start < seq {
            if self.slots.pop_front().flatten().is_some() {
                self.count -= 1;
            }
            self.start = self.start.saturating_add(1);
            self.skip_empty();
        }
        before - self.count
    }

    /// Number of consecutive seqs held from `seq` on.
    pub(crate) fn run_from(&self, seq: u64) -> u64 {
        let Some(index) = self.index(seq) else {
            return 0;
        };
        self.slots
            .range(index..)
            .take_while(|slot| slot.is_some())
            .count() as u64
    }

    /// Slot 0 held again (or the ring empty), after the lowest sample left.
    fn skip_empty(&mut self) {
        while self.count > 0 && self.slots.front().is_some_and(Option::is_none) {
            self.slots.pop_front();
            self.start = self.start.saturating_add(1);
        }
        if self.count == 0 {
            self.slots.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Held;
    use std::collections::BTreeMap;

    #[test]
    fn in_order_samples_go_through_one_slot_at_a_time() {
        let mut held = Held::default();
        for seq in 10..1000u64 {
            assert!(held.insert(seq, seq));
            assert_eq!(held.first(), Some(seq));
            assert_eq!(held.take_first(seq), Some(seq));
            assert_eq!(held.len(), 0);
        }
        assert!(held.slots.capacity() < 8, "{}", held.slots.capacity());
    }

    #[test]
    fn it_answers_as_an_ordered_map_would() {
        // Random inserts within a window, takes of the first, drops below a moving point:
        // every answer compared with a BTreeMap's.
        let mut rng = fastrand::Rng::with_seed(7);
        let mut held = Held::default();
        let mut model = BTreeMap::new();
        let mut floor = 100u64;
        for _ in 0..20_000 {
            match rng.u8(0..10) {
                0..=5 => {
                    let seq = floor + rng.u64(0..64);
                    assert_eq!(
                        held.insert(seq, seq * 3),
                        model.insert(seq, seq * 3).is_none()
                    );
                }
                6..=7 => {
                    let first = model.first_key_value().map(|(k, _)| *k);
                    assert_eq!(held.first(), first);
                    if let Some(seq) = first {
                        assert_eq!(held.take_first(seq), model.remove(&seq));
                        floor = floor.max(seq + 1);
                    }
                }
                8 => {
                    let to = floor + rng.u64(0..8);
                    let dropped = model.range(..to).count();
                    model = model.split_off(&to);
                    assert_eq!(held.drop_below(to), dropped);
                    floor = to;
                }
                _ => {
                    let seq = floor + rng.u64(0..64);
                    let run = (seq..).take_while(|s| model.contains_key(s)).count() as u64;
                    assert_eq!(held.run_from(seq), run);
                }
            }
            assert_eq!(held.len(), model.len());
            let seq = floor + rng.u64(0..70);
            assert_eq!(held.contains(seq), model.contains_key(&seq));
            assert!(held.slots.len() <= 64 + 8, "{}", held.slots.len());
        }
    }

    #[test]
    fn a_seq_too_far_from_the_held_ones_is_refused() {
        let mut held = Held::default();
        assert!(held.insert(10, 1u8));
        assert!(!held.insert(10 + super::MAX_SPAN, 2));
        assert!(held.insert(9 + super::MAX_SPAN, 3), "just inside");
        assert_eq!(held.len(), 2);
        assert!(held.slots.len() as u64 <= super::MAX_SPAN);
    }

    #[test]
    fn taking_what_is_not_first_takes_nothing() {
        let mut held = Held::default();
        assert_eq!(held.take_first(5), None::<u8>);
        held.insert(5, 1u8);
        held.insert(7, 2);
        assert_eq!(held.take_first(7), None);
        assert_eq!(held.take_first(5), Some(1));
        assert_eq!(held.first(), Some(7));
        assert!(!held.insert(7, 9), "already held");
        assert_eq!(held.take_first(7), Some(2));
        assert_eq!(held.first(), None);
    }
}
