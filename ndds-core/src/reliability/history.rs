//! A reliable writer's history: the samples some reader may still ask to be repaired, oldest
//! first, with their sizes. Sequence numbers ascend but need not be consecutive (a writer may
//! skip some). Eviction policy belongs to the writer; this is only the store.

use std::collections::VecDeque;

/// One stored sample.
#[derive(Clone, Debug)]
pub(crate) struct Entry<S> {
    pub(crate) seq: u64,
    pub(crate) sample: S,
    pub(crate) bytes: usize,
}

/// Samples in ascending sequence order and their total size.
#[derive(Clone, Debug)]
pub(crate) struct History<S> {
    entries: VecDeque<Entry<S>>,
    bytes: usize,
}

impl<S> History<S> {
    /// An empty history.
    pub(crate) fn new() -> Self {
        History {
            entries: VecDeque::new(),
            bytes: 0,
        }
    }

    /// Appends a sample; `seq` must exceed every stored one (the writer checks).
    pub(crate) fn push(&mut self, seq: u64, sample: S, bytes: usize) {
        self.bytes = self.bytes.saturating_add(bytes);
        self.entries.push_back(Entry { seq, sample, bytes });
    }

    /// Puts back a sample older than every stored one (a sample kept for late joiners that a
    /// new reader is owed); ignored if it is not older.
    pub(crate) fn push_older(&mut self, seq: u64, sample: S, bytes: usize) {
        if self.first_seq().is_some_and(|first| first <= seq) {
            return;
        }
        self.bytes = self.bytes.saturating_add(bytes);
        self.entries.push_front(Entry { seq, sample, bytes });
    }

    /// Removes the oldest sample.
    pub(crate) fn pop_front(&mut self) -> Option<Entry<S>> {
        let entry = self.entries.pop_front()?;
        self.bytes = self.bytes.saturating_sub(entry.bytes);
        Some(entry)
    }

    /// Sequence number of the oldest sample.
    pub(crate) fn first_seq(&self) -> Option<u64> {
        self.entries.front().map(|e| e.seq)
    }

    /// The sample with sequence number `seq`, if stored.
    pub(crate) fn get(&self, seq: u64) -> Option<&S> {
        let at = self.entries.binary_search_by_key(&seq, |e| e.seq).ok()?;
        self.entries.get(at).map(|e| &e.sample)
    }

    /// True when `seq` is stored.
    pub(crate) fn contains(&self, seq: u64) -> bool {
        self.get(seq).is_some()
    }

    /// Number of samples.
    pub(crate) fn len(&self) -> usize {
        self.entries.len()
    }

    /// Total size of the samples.
    pub(crate) fn bytes(&self) -> usize {
        self.bytes
    }

    /// Total size of all samples but the newest.
    pub(crate) fn bytes_before_newest(&self) -> usize {
        let newest = self.entries.back().map_or(0, |e| e.bytes);
        self.bytes.saturating_sub(newest)
    }
}
