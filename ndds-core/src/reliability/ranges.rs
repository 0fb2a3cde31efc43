//! A set of sequence numbers kept as disjoint half-open ranges `from..to`, merged on insertion
//! (ranges that overlap or touch become one). Used for the seqs a reader knows are lost and
//! for the gaps a writer still has to announce to a reader.

use std::collections::BTreeMap;

/// Disjoint, non-adjacent half-open ranges, keyed by their start.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct RangeSet {
    ranges: BTreeMap<u64, u64>,
}

impl RangeSet {
    /// Adds `from..to`, merging it with the ranges it overlaps or touches. Empty ranges are
    /// ignored.
    pub(crate) fn insert(&mut self, mut from: u64, mut to: u64) {
        if from >= to {
            return;
        }
        if let Some((&start, &end)) = self.ranges.range(..=from).next_back()
            && end >= from
        {
            from = start;
            to = to.max(end);
            self.ranges.remove(&start);
        }
        while let Some((&start, &end)) = self.ranges.range(from..=to).next() {
            to = to.max(end);
            self.ranges.remove(&start);
        }
        self.ranges.insert(from, to);
    }

    /// The range holding `seq`, if any.
    pub(crate) fn containing(&self, seq: u64) -> Option<(u64, u64)> {
        self.ranges
            .range(..=seq)
            .next_back()
            .filter(|&(_, &end)| seq < end)
            .map(|(&start, &end)| (start, end))
    }

    /// True when `seq` is in the set.
    pub(crate) fn contains(&self, seq: u64) -> bool {
        self.containing(seq).is_some()
    }

    /// Removes every seq below `floor`.
    pub(crate) fn remove_below(&mut self, floor: u64) {
        while let Some((&start, &end)) = self.ranges.first_key_value() {
            if start >= floor {
                return;
            }
            self.ranges.remove(&start);
            if end > floor {
                self.ranges.insert(floor, end);
                return;
            }
        }
    }

    /// Removes and returns the lowest range.
    pub(crate) fn pop_first(&mut self) -> Option<(u64, u64)> {
        self.ranges.pop_first()
    }

    /// Removes and returns the highest range.
    pub(crate) fn pop_last(&mut self) -> Option<(u64, u64)> {
        self.ranges.pop_last()
    }

    /// Number of disjoint ranges.
    pub(crate) fn len(&self) -> usize {
        self.ranges.len()
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn ranges(set: &RangeSet) -> Vec<(u64, u64)> {
        set.ranges.iter().map(|(&a, &b)| (a, b)).collect()
    }

    #[test]
    fn touching_and_overlapping_ranges_merge() {
        let mut set = RangeSet::default();
        set.insert(10, 20);
        set.insert(30, 40);
        set.insert(20, 25);
        assert_eq!(ranges(&set), vec![(10, 25), (30, 40)]);
        set.insert(5, 35);
        assert_eq!(ranges(&set), vec![(5, 40)]);
        set.insert(7, 7);
        set.insert(50, u64::MAX);
        assert_eq!(set.len(), 2);
        set.remove_below(12);
        assert_eq!(ranges(&set), vec![(12, 40), (50, u64::MAX)]);
        set.remove_below(45);
        assert_eq!(set.containing(60), Some((50, u64::MAX)));
        assert!(!set.contains(u64::MAX));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn matches_a_plain_set(ops in proptest::collection::vec((0u64..200, 0u64..20), 0..40),
                               floor in 0u64..200) {
            let mut set = RangeSet::default();
            let mut plain = std::collections::BTreeSet::new();
            for (from, len) in ops {
                set.insert(from, from + len);
                plain.extend(from..from + len);
            }
            set.remove_below(floor);
            plain.retain(|&s| s >= floor);
            for seq in 0..260 {
                prop_assert_eq!(set.contains(seq), plain.contains(&seq), "seq {}", seq);
            }
            let r = ranges(&set);
            for pair in r.windows(2) {
                prop_assert!(pair[0].1 < pair[1].0, "disjoint and not touching: {:?}", r);
            }
        }
    }
}
