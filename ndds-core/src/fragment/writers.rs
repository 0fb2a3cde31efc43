//! What the reassembler remembers of each writer between samples: the floor below which its
//! pieces are stale, and, while it has no partial sample, how long it has been idle (the
//! longest idle records are dropped first to make room).

use std::collections::BTreeMap;
use std::mem::size_of;

/// One writer's record.
#[derive(Clone, Copy, Debug)]
struct Record {
    /// Pieces of samples below this sequence number are stale.
    floor: u64,
    /// Key in the idle index while the writer has no partial sample.
    idle_since: Option<u64>,
}

/// The records of all writers, and the idle ones in the order they became idle.
#[derive(Debug)]
pub(super) struct Writers<K> {
    records: BTreeMap<K, Record>,
    idle: BTreeMap<u64, K>,
    serial: u64,
}

impl<K: Copy + Ord> Writers<K> {
    /// Bytes charged per record: the record, its idle entry and their share of map nodes.
    pub(super) const RECORD_BYTES: usize =
        3 * (size_of::<K>() + size_of::<Record>() + size_of::<(u64, K)>());

    pub(super) fn new() -> Self {
        Writers {
            records: BTreeMap::new(),
            idle: BTreeMap::new(),
            serial: 0,
        }
    }

    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.records.len()
    }

    pub(super) fn contains(&self, writer: K) -> bool {
        self.records.contains_key(&writer)
    }

    /// Pieces of `writer`'s samples below this are stale (0 without a record).
    pub(super) fn floor(&self, writer: K) -> u64 {
        self.records.get(&writer).map_or(0, |r| r.floor)
    }

    /// A new record, floor 0, not idle. The caller charged it.
    pub(super) fn insert(&mut self, writer: K) {
        let record = Record {
            floor: 0,
            idle_since: None,
        };
        if let Some(old) = self.records.insert(writer, record) {
            self.unindex(old);
        }
    }

    /// Raises `writer`'s floor to `floor` (if it has a record and the floor is lower).
    pub(super) fn raise_floor(&mut self, writer: K, floor: u64) {
        if let Some(record) = self.records.get_mut(&writer) {
            record.floor = record.floor.max(floor);
        }
    }

    /// `writer` has a partial sample: not idle.
    pub(super) fn set_active(&mut self, writer: K) {
        if let Some(serial) = self
            .records
            .get_mut(&writer)
            .and_then(|r| r.idle_since.take())
        {
            self.idle.remove(&serial);
        }
    }

    /// `writer` has no partial sample: idle from now on, unless it was already.
    pub(super) fn set_idle(&mut self, writer: K) {
        let Some(record) = self.records.get_mut(&writer) else {
            return;
        };
        if record.idle_since.is_none() {
            self.serial += 1;
            record.idle_since = Some(self.serial);
            self.idle.insert(self.serial, writer);
        }
    }

    /// Removes the record of the longest idle writer other than `keep`; returns whether
    /// there was one (the caller uncharges it).
    pub(super) fn drop_longest_idle(&mut self, keep: K) -> bool {
        let Some((&serial, &writer)) = self.idle.iter().find(|&(_, &w)| w != keep) else {
            return false;
        };
        self.idle.remove(&serial);
        self.records.remove(&writer).is_some()
    }

    /// Removes `writer`'s record; returns whether it had one (the caller uncharges it).
    pub(super) fn remove(&mut self, writer: K) -> bool {
        match self.records.remove(&writer) {
            Some(record) => {
                self.unindex(record);
                true
            }
            None => false,
        }
    }

    fn unindex(&mut self, record: Record) {
        if let Some(serial) = record.idle_since {
            self.idle.remove(&serial);
        }
    }

    /// Consistency of the two maps, for tests: every idle entry names a record that points
    /// back to it.
    #[cfg(test)]
    pub(super) fn consistent(&self) -> bool {
        let indexed = self
            .records
            .values()
            .filter(|r| r.idle_since.is_some())
            .count();
        indexed == self.idle.len()
            && self.idle.iter().all(|(s, w)| {
                self.records
                    .get(w)
                    .is_some_and(|r| r.idle_since == Some(*s))
            })
    }

    /// Whether `writer` is in the idle index, for tests.
    #[cfg(test)]
    pub(super) fn is_idle(&self, writer: K) -> bool {
        self.records
            .get(&writer)
            .is_some_and(|r| r.idle_since.is_some())
    }
}
