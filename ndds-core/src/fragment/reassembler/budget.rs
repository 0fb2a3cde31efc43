//! The budget of a reassembler: what is charged, and how room is made (spare buffers, then
//! the longest idle writers' records, then the oldest partial samples).

use std::fmt::Debug;

use super::{End, Reassembler};

impl<K: Copy + Ord + Debug> Reassembler<K> {
    /// Gives a buffer back (typically a completed sample, once decoded) to be reused for a
    /// later sample. Kept only while fewer than [`ReassemblyConfig::spare_buffers`](crate::fragment::ReassemblyConfig::spare_buffers) are kept
    /// and it fits the budget; dropped otherwise.
    pub fn recycle(&mut self, buf: Vec<u8>) {
        let cap = buf.capacity();
        let useful = cap > 0 && cap <= self.config.max_sample_bytes.saturating_mul(2);
        let room = self.stats.bytes_in_use.saturating_add(cap) <= self.config.max_total_bytes;
        if useful && room && self.spares.len() < self.config.spare_buffers {
            self.charge(cap);
            self.spares.push(buf);
        }
    }

    /// Frees budget until `need` more bytes fit: spare buffers first, then the records of the
    /// longest idle writers (but not `keep`'s), then the oldest partial samples. False when
    /// nothing is left to free.
    pub(super) fn make_room(&mut self, need: usize, keep: K) -> bool {
        while self.stats.bytes_in_use.saturating_add(need) > self.config.max_total_bytes {
            if let Some(buf) = self.spares.pop() {
                self.uncharge(buf.capacity());
            } else if self.writers.drop_longest_idle(keep) {
                self.uncharge(Self::WRITER_OVERHEAD);
            } else if let Some((_, &key)) = self.age.first_key_value() {
                self.end(key, End::Evicted);
            } else {
                return false;
            }
        }
        true
    }

    /// A spare buffer for `len` bytes: the smallest that holds them, if not larger than
    /// `max_cap` nor than twice `len` plus a datagram. No longer charged as a spare.
    pub(super) fn take_spare(&mut self, len: usize, max_cap: usize) -> Option<Vec<u8>> {
        let limit = len
            .saturating_mul(2)
            .saturating_add(crate::wire::MAX_DATAGRAM)
            .min(max_cap);
        let (at, _) = self
            .spares
            .iter()
            .enumerate()
            .filter(|(_, b)| (len..=limit).contains(&b.capacity()))
            .min_by_key(|(_, b)| b.capacity())?;
        let buf = self.spares.swap_remove(at);
        self.uncharge(buf.capacity());
        Some(buf)
    }

    // ----- writer records ---------------------------------------------------------------------

    /// Makes sure `writer` has a record (making room for it); false when there is no room.
    pub(super) fn ensure_record(&mut self, writer: K) -> bool {
        if self.writers.contains(writer) {
            return true;
        }
        if !self.make_room(Self::WRITER_OVERHEAD, writer) {
            return false;
        }
        self.charge(Self::WRITER_OVERHEAD);
        self.writers.insert(writer);
        true
    }

    /// Pieces of `writer`'s samples below `floor` are stale from now on (if it has a record).
    pub(super) fn raise_floor(&mut self, writer: K, floor: u64) {
        self.writers.raise_floor(writer, floor);
        self.settle(writer);
    }

    /// A writer without partial samples is idle: its record is kept, and may be dropped to
    /// make room (the longest idle first).
    pub(super) fn settle(&mut self, writer: K) {
        if self.partial_seqs(writer).next().is_none() {
            self.writers.set_idle(writer);
        }
    }

    pub(super) fn remove_record(&mut self, writer: K) {
        if self.writers.remove(writer) {
            self.uncharge(Self::WRITER_OVERHEAD);
        }
    }

    // ----- accounting -------------------------------------------------------------------------

    pub(super) fn charge(&mut self, bytes: usize) {
        let stats = &mut self.stats;
        stats.bytes_in_use = stats.bytes_in_use.saturating_add(bytes);
        stats.peak_bytes_in_use = stats.peak_bytes_in_use.max(stats.bytes_in_use);
    }

    pub(super) fn uncharge(&mut self, bytes: usize) {
        debug_assert!(
            bytes <= self.stats.bytes_in_use,
            "uncharged more than charged"
        );
        self.stats.bytes_in_use = self.stats.bytes_in_use.saturating_sub(bytes);
    }

    /// Checks the indexes against each other and recomputes the charge, for tests.
    #[cfg(test)]
    pub(in crate::fragment) fn audit(&self) -> usize {
        assert_eq!(self.age.len(), self.partials.len());
        assert!(self.writers.consistent());
        let mut held = std::collections::BTreeMap::new();
        for &(writer, _) in self.partials.keys() {
            *held.entry(writer).or_insert(0usize) += 1;
        }
        assert_eq!(held, self.held);
        for (&(writer, seq), partial) in &self.partials {
            assert_eq!(self.age.get(&partial.age), Some(&(writer, seq)));
            assert!(self.writers.contains(writer) && !self.writers.is_idle(writer));
        }
        let partials: usize = self
            .partials
            .values()
            .map(crate::fragment::partial::Partial::heap)
            .sum();
        let spares: usize = self.spares.iter().map(Vec::capacity).sum();
        partials
            + self.partials.len() * Self::PARTIAL_OVERHEAD
            + self.writers.len() * Self::WRITER_OVERHEAD
            + spares
    }
}
