//! One sample being reassembled: its buffer, which pieces arrived, and what it costs.

use std::ops::Range;
use std::time::Instant;

use super::split::Split;
use crate::wire::feedback::MAX_BITMAP_BYTES;

/// Pieces one [`Missing`] report covers.
pub const MISSING_SPAN: u32 = (MAX_BITMAP_BYTES * 8) as u32;

/// Missing pieces of one partial sample, as a `NackFrag` carries them: bit `i` of
/// [`bitmap`](Missing::bitmap) set means piece `base + i` is missing. `base` is the first
/// missing piece, and the bitmap covers at most [`MISSING_SPAN`] pieces from there (ending at
/// its last set bit).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Missing {
    /// The first missing piece (bit 0).
    pub base: u32,
    bits: [u8; MAX_BITMAP_BYTES],
    len: u8,
}

impl Missing {
    /// The bitmap, as `NackFrag::missing` (at most [`MAX_BITMAP_BYTES`] long).
    pub fn bitmap(&self) -> &[u8] {
        &self.bits[..usize::from(self.len)]
    }

    /// The missing pieces this report names, in order.
    pub fn pieces(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.bitmap().len() * 8)
            .filter(|&i| crate::wire::feedback::bit(self.bitmap(), i))
            .map(|i| self.base + i as u32)
    }
}

/// A sample of which some pieces arrived.
pub(super) struct Partial {
    pub(super) split: Split,
    buf: Vec<u8>,
    /// Bit `i` set: piece `i` arrived.
    received: Vec<u64>,
    remaining: u32,
    /// No piece below this one is missing.
    first_missing: u32,
    /// Key in the reassembler's age index: start time and a serial number.
    pub(super) age: (Instant, u64),
    /// Started by a `LastIsBest` call: when it ends, later pieces of its sample are ignored.
    pub(super) last_is_best: bool,
}

impl std::fmt::Debug for Partial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Partial")
            .field("split", &self.split)
            .field("remaining", &self.remaining)
            .field("first_missing", &self.first_missing)
            .field("age", &self.age)
            .finish_non_exhaustive()
    }
}

/// What adding a piece did.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Added {
    /// New bytes; pieces are still missing.
    Pending,
    /// That piece was there already; nothing changed.
    Duplicate,
    /// That was the last missing piece.
    Complete,
}

impl Partial {
    /// Bytes a partial of this geometry allocates when its buffer has `capacity` bytes
    /// (buffer and bitmap; the reassembler adds its bookkeeping).
    pub(super) fn heap_bytes(split: &Split, capacity: usize) -> usize {
        capacity + bitmap_words(split) * 8
    }

    /// A partial sample written into `buf` (emptied; its capacity grown to the sample's length
    /// if needed, which a caller avoids by passing a buffer that large).
    pub(super) fn new(split: Split, mut buf: Vec<u8>, age: (Instant, u64), lib: bool) -> Self {
        buf.clear();
        buf.reserve_exact(split.total_len());
        Partial {
            split,
            buf,
            received: vec![0; bitmap_words(&split)],
            remaining: split.count(),
            first_missing: 0,
            age,
            last_is_best: lib,
        }
    }

    /// Bytes this partial allocates (buffer and bitmap).
    pub(super) fn heap(&self) -> usize {
        Partial::heap_bytes(&self.split, self.buf.capacity())
    }

    /// Copies piece `index` (already checked against the geometry) unless it is there.
    pub(super) fn add(&mut self, index: u32, chunk: &[u8]) -> Added {
        if self.has(index) {
            return Added::Duplicate;
        }
        let Some(range) = self.split.range(index) else {
            return Added::Duplicate;
        };
        self.write(range, chunk);
        self.received[index as usize / 64] |= 1 << (index % 64);
        self.remaining -= 1;
        while self.first_missing < self.split.count() && self.has(self.first_missing) {
            self.first_missing += 1;
        }
        if self.remaining == 0 {
            Added::Complete
        } else {
            Added::Pending
        }
    }

    /// Writes a piece's bytes. The buffer's length is the written prefix, always at a piece
    /// boundary: a piece inside it overwrites the zeros of an earlier gap, a piece beyond it
    /// zero-fills the gap before it and is appended. Pieces arriving in order are copied once
    /// and nothing is zeroed.
    fn write(&mut self, range: Range<usize>, chunk: &[u8]) {
        if range.end <= self.buf.len() {
            self.buf[range].copy_from_slice(chunk);
        } else {
            debug_assert!(
                range.start >= self.buf.len(),
                "the prefix ends at a piece boundary"
            );
            self.buf.resize(range.start, 0);
            self.buf.extend_from_slice(chunk);
        }
    }

    /// The whole sample (meaningful once complete).
    pub(super) fn into_buf(self) -> Vec<u8> {
        self.buf
    }

    /// The first up to [`MISSING_SPAN`] missing pieces.
    pub(super) fn missing(&self) -> Missing {
        let mut report = Missing {
            base: self.first_missing,
            bits: [0; MAX_BITMAP_BYTES],
            len: 0,
        };
        let end = self
            .split
            .count()
            .min(self.first_missing.saturating_add(MISSING_SPAN));
        for index in self.first_missing..end {
            if !self.has(index) {
                let i = (index - self.first_missing) as usize;
                report.bits[i / 8] |= 1 << (i % 8);
                report.len = (i / 8 + 1) as u8;
            }
        }
        report
    }

    fn has(&self, index: u32) -> bool {
        self.received
            .get(index as usize / 64)
            .is_some_and(|w| w & (1 << (index % 64)) != 0)
    }
}

fn bitmap_words(split: &Split) -> usize {
    (split.count() as usize).div_ceil(64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn partial(len: usize) -> Partial {
        let split = Split::new(len, 64).unwrap();
        Partial::new(split, Vec::new(), (Instant::now(), 0), false)
    }

    #[test]
    fn pieces_fill_in_any_order_and_duplicates_change_nothing() {
        let mut p = partial(200);
        assert_eq!(p.add(3, &[3; 8]), Added::Pending);
        assert_eq!(p.add(3, &[9; 8]), Added::Duplicate);
        assert_eq!(p.add(1, &[1; 64]), Added::Pending);
        assert_eq!(p.missing().base, 0);
        assert_eq!(p.missing().bitmap(), &[0b101]);
        assert_eq!(p.add(0, &[0; 64]), Added::Pending);
        assert_eq!(p.missing().pieces().collect::<Vec<_>>(), [2]);
        assert_eq!(p.add(2, &[2; 64]), Added::Complete);
        let buf = p.into_buf();
        assert_eq!(&buf[190..192], &[2; 2]);
        assert_eq!(&buf[192..], &[3; 8]);
        assert_eq!(buf.len(), 200);
    }

    #[test]
    fn missing_reports_at_most_a_span() {
        let p = partial(64 * 2000);
        let report = p.missing();
        assert_eq!(report.base, 0);
        assert_eq!(report.bitmap().len(), MAX_BITMAP_BYTES);
        assert_eq!(report.pieces().count(), MISSING_SPAN as usize);
    }
}
