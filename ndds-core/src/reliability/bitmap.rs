//! The `missing` bitmap of an AckNack, held inline (no allocation): bit `i` (byte `i / 8`,
//! bit `i % 8`) stands for the sequence number `acked + i`, as in [`crate::wire::feedback`].

use std::fmt;

use crate::wire::feedback::MAX_BITMAP_BYTES;

/// Most sequence numbers one bitmap can name.
pub const MAX_BITS: usize = MAX_BITMAP_BYTES * 8;

/// A bitmap of at most [`MAX_BITMAP_BYTES`] bytes; [`Bitmap::as_bytes`] is trimmed after the
/// last set bit, so an empty bitmap encodes as zero bytes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Bitmap {
    bytes: [u8; MAX_BITMAP_BYTES],
    len: usize,
}

impl Bitmap {
    /// No bit set.
    pub const fn new() -> Self {
        Bitmap {
            bytes: [0; MAX_BITMAP_BYTES],
            len: 0,
        }
    }

    /// Sets bit `i`; false (and nothing set) when `i` is not below [`MAX_BITS`].
    pub fn set(&mut self, i: usize) -> bool {
        let Some(byte) = self.bytes.get_mut(i / 8) else {
            return false;
        };
        *byte |= 1 << (i % 8);
        self.len = self.len.max(i / 8 + 1);
        true
    }

    /// Bit `i`.
    pub fn get(&self, i: usize) -> bool {
        crate::wire::feedback::bit(self.as_bytes(), i)
    }

    /// True when no bit is set.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of bits set.
    pub fn count(&self) -> u32 {
        self.as_bytes().iter().map(|b| b.count_ones()).sum()
    }

    /// The bytes to put on the wire.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    /// Indices of the set bits, ascending.
    pub fn ones(&self) -> impl Iterator<Item = usize> + '_ {
        ones(self.as_bytes())
    }
}

impl Default for Bitmap {
    fn default() -> Self {
        Bitmap::new()
    }
}

impl fmt::Debug for Bitmap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set().entries(self.ones()).finish()
    }
}

/// Indices of the set bits of a received bitmap, ascending; bytes beyond
/// [`MAX_BITMAP_BYTES`] are ignored.
pub fn ones(bytes: &[u8]) -> impl Iterator<Item = usize> + '_ {
    bytes
        .iter()
        .take(MAX_BITMAP_BYTES)
        .enumerate()
        .filter(|(_, byte)| **byte != 0)
        .flat_map(|(n, &byte)| {
            (0..8)
                .filter(move |b| byte & (1 << b) != 0)
                .map(move |b| n * 8 + b)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_round_trip_and_are_bounded() {
        let mut map = Bitmap::new();
        assert!(map.is_empty() && map.as_bytes().is_empty());
        assert!(map.set(3) && map.set(17) && map.set(MAX_BITS - 1));
        assert!(!map.set(MAX_BITS));
        assert_eq!(map.ones().collect::<Vec<_>>(), vec![3, 17, MAX_BITS - 1]);
        assert_eq!(map.count(), 3);
        assert_eq!(map.as_bytes().len(), MAX_BITMAP_BYTES);
        assert!(map.get(17) && !map.get(18));
        let long = vec![0xFF; MAX_BITMAP_BYTES + 10];
        assert_eq!(ones(&long).count(), MAX_BITS);
    }
}
