//! The geometry of a fragmented sample: how many pieces, and which bytes each piece covers.
//! Writers use it to cut a sample, readers to check every piece against it; both sides apply
//! the same rules (see the [module docs](super)).

use std::ops::Range;

use crate::wire::MAX_DATAGRAM;

/// Smallest accepted `frag_size`: a smaller size is refused as absurd (a sample is cut into
/// pieces to fit datagrams, and below this the bookkeeping outweighs the bytes).
pub const MIN_FRAG_SIZE: u32 = 64;

/// Largest accepted `frag_size`: a piece must fit one datagram.
pub const MAX_FRAG_SIZE: u32 = MAX_DATAGRAM as u32;

/// Why a sample cannot be cut as asked.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
pub enum SplitError {
    /// `frag_size` is outside [`MIN_FRAG_SIZE`]`..=`[`MAX_FRAG_SIZE`] (zero included).
    #[error("fragment size {0} outside {MIN_FRAG_SIZE}..={MAX_FRAG_SIZE}")]
    BadFragSize(usize),
    /// The sample is longer than the wire's `total_len` (a `u32`) can say.
    #[error("sample of {0} bytes is too long to fragment")]
    TooLong(usize),
}

/// How a sample of `total_len` bytes is cut into pieces of `frag_size` bytes.
///
/// Piece `i` covers bytes `i × frag_size .. min((i + 1) × frag_size, total_len)`. There is at
/// least one piece: an empty sample is one empty piece.
///
/// ```
/// use ndds_core::fragment::Split;
/// let split = Split::new(1000, 400).unwrap();
/// assert_eq!(split.count(), 3);
/// assert_eq!(split.range(2), Some(800..1000));
/// let payload = vec![7u8; 1000];
/// let pieces: Vec<_> = split.pieces().map(|(i, r)| (i, payload[r].len())).collect();
/// assert_eq!(pieces, [(0, 400), (1, 400), (2, 200)]);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Split {
    total_len: u32,
    frag_size: u32,
    count: u32,
}

impl Split {
    /// The geometry of a sample of `total_len` bytes cut into `frag_size` pieces, or why it
    /// cannot be cut so.
    pub fn new(total_len: usize, frag_size: usize) -> Result<Split, SplitError> {
        let fs = u32::try_from(frag_size)
            .ok()
            .filter(|fs| (MIN_FRAG_SIZE..=MAX_FRAG_SIZE).contains(fs))
            .ok_or(SplitError::BadFragSize(frag_size))?;
        let len = u32::try_from(total_len).map_err(|_| SplitError::TooLong(total_len))?;
        Ok(Split {
            total_len: len,
            frag_size: fs,
            count: len.div_ceil(fs).max(1),
        })
    }

    /// Length of the whole sample.
    pub fn total_len(&self) -> usize {
        self.total_len as usize
    }

    /// Size of every piece but the last.
    pub fn frag_size(&self) -> usize {
        self.frag_size as usize
    }

    /// Number of pieces (at least 1).
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The bytes piece `index` covers, or `None` when there is no such piece.
    pub fn range(&self, index: u32) -> Option<Range<usize>> {
        if index >= self.count {
            return None;
        }
        // index < count, so index × frag_size < total_len + frag_size ≤ 2³² + 2¹⁶: fits usize
        // on the 64-bit targets ndds supports, and is computed in u64 to be sure.
        let start = u64::from(index) * u64::from(self.frag_size);
        let end = (start + u64::from(self.frag_size)).min(u64::from(self.total_len));
        let start = start.min(end);
        Some(start as usize..end as usize)
    }

    /// Length of piece `index`, or `None` when there is no such piece.
    pub fn piece_len(&self, index: u32) -> Option<usize> {
        self.range(index).map(|r| r.len())
    }

    /// Every piece in order: its index and the bytes it covers.
    pub fn pieces(
        &self,
    ) -> impl DoubleEndedIterator<Item = (u32, Range<usize>)> + ExactSizeIterator + use<> {
        let split = *self;
        (0..self.count).map(move |i| (i, split.range(i).unwrap_or(0..0)))
    }
}

/// Number of pieces a sample of `total_len` bytes is cut into with pieces of `frag_size`.
///
/// ```
/// use ndds_core::fragment::{fragment_count, SplitError};
/// assert_eq!(fragment_count(0, 1024), Ok(1));
/// assert_eq!(fragment_count(1025, 1024), Ok(2));
/// assert_eq!(fragment_count(10, 0), Err(SplitError::BadFragSize(0)));
/// ```
pub fn fragment_count(total_len: usize, frag_size: usize) -> Result<u32, SplitError> {
    Split::new(total_len, frag_size).map(|s| s.count())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_tile_the_sample() {
        for (len, fs) in [
            (0, 64),
            (1, 64),
            (64, 64),
            (65, 64),
            (1 << 20, 1400),
            (999, 1000),
        ] {
            let split = Split::new(len, fs).unwrap();
            let mut next = 0;
            for (i, range) in split.pieces() {
                assert_eq!(range.start, next, "len {len} fs {fs} piece {i}");
                let last = i + 1 == split.count();
                assert!(last || range.len() == fs);
                assert!(!last || range.end == len);
                next = range.end;
            }
            assert_eq!(next, len);
            assert_eq!(split.range(split.count()), None);
        }
    }

    #[test]
    fn absurd_sizes_are_refused() {
        assert_eq!(Split::new(10, 0), Err(SplitError::BadFragSize(0)));
        assert_eq!(Split::new(10, 63), Err(SplitError::BadFragSize(63)));
        let huge = MAX_FRAG_SIZE as usize + 1;
        assert_eq!(Split::new(10, huge), Err(SplitError::BadFragSize(huge)));
        assert_eq!(
            Split::new(10, usize::MAX),
            Err(SplitError::BadFragSize(usize::MAX))
        );
        let long = u32::MAX as usize + 1;
        assert_eq!(Split::new(long, 1024), Err(SplitError::TooLong(long)));
    }

    #[test]
    fn the_largest_sample_has_a_last_piece_in_range() {
        let split = Split::new(u32::MAX as usize, MIN_FRAG_SIZE as usize).unwrap();
        let last = split.count() - 1;
        assert_eq!(split.range(last).unwrap().end, u32::MAX as usize);
        assert_eq!(split.range(u32::MAX), None);
    }
}
