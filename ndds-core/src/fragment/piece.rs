//! The input of the reassembler: one piece of a sample.

use crate::wire::data::Fragment;

/// One piece of a sample, as a [`Fragment`] submessage carries it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Piece<'a> {
    /// The sample's sequence number (per writer).
    pub seq: u64,
    /// Length of the whole sample.
    pub total_len: u32,
    /// Size of every piece but the last.
    pub frag_size: u32,
    /// Index of this piece.
    pub index: u32,
    /// Its bytes.
    pub chunk: &'a [u8],
}

impl<'a> From<&Fragment<'a>> for Piece<'a> {
    fn from(f: &Fragment<'a>) -> Self {
        Piece {
            seq: f.meta.seq,
            total_len: f.total_len,
            frag_size: f.frag_size,
            index: f.index,
            chunk: f.chunk,
        }
    }
}
