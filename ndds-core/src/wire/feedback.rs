//! `Feedback` (kind 17): acknowledgements and repair requests from a consuming process to a
//! producing process's reliable writers.
//!
//! ```text
//! header(kind = 17, sender = consuming participant id)
//!   | varint writer_participant
//!   | u64le token          the address token of the writer participant's data (0: none)
//!   | submessage { submessage }
//! submessage := u8 sub_kind | postcard body
//!   sub_kind 1  AckNack   everything before `acked` arrived; these later ones are missing
//!   sub_kind 2  NackFrag  these pieces of one sample are missing
//! ```
//!
//! Bitmaps are little-endian bit strings: bit `i` (byte `i / 8`, bit `i % 8`) stands for the
//! sequence number `acked + i` (AckNack) or the piece `base + i` (NackFrag). A bitmap is at
//! most [`MAX_BITMAP_BYTES`] long.

use serde::{Deserialize, Serialize};

use super::data::AddressToken;
use super::header::{Header, MessageKind};
use super::{DropReason, MAX_DATAGRAM};

/// Longest bitmap accepted: 512 sequence numbers or pieces per submessage.
pub const MAX_BITMAP_BYTES: usize = 64;

/// Submessage kinds inside a `Feedback` datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FeedbackSubKind {
    /// [`AckNack`]
    AckNack = 1,
    /// [`NackFrag`]
    NackFrag = 2,
}

/// A reliable reader's state: every sample with a sequence number below `acked` arrived (or
/// was given up as lost); the set bits of `missing` name later ones it asks to be repaired.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AckNack<'a> {
    /// Reader entity within the sending participant.
    pub reader: u32,
    /// Writer entity within `writer_participant`.
    pub writer: u32,
    /// All sequence numbers below this one are settled.
    pub acked: u64,
    /// Bit `i` set: `acked + i` is missing.
    #[serde(borrow)]
    pub missing: &'a [u8],
}

/// Missing pieces of one large sample: the set bits of `missing` name pieces `base + i`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NackFrag<'a> {
    /// Reader entity.
    pub reader: u32,
    /// Writer entity.
    pub writer: u32,
    /// The sample's sequence number.
    pub seq: u64,
    /// Piece number of bit 0.
    pub base: u32,
    /// Bit `i` set: piece `base + i` is missing.
    #[serde(borrow)]
    pub missing: &'a [u8],
}

/// One decoded submessage of a `Feedback` datagram.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FeedbackSub<'a> {
    /// Acknowledgement and negative acknowledgement.
    AckNack(AckNack<'a>),
    /// Missing pieces.
    NackFrag(NackFrag<'a>),
}

impl FeedbackSub<'_> {
    fn kind(&self) -> FeedbackSubKind {
        match self {
            FeedbackSub::AckNack(_) => FeedbackSubKind::AckNack,
            FeedbackSub::NackFrag(_) => FeedbackSubKind::NackFrag,
        }
    }

    fn bitmap(&self) -> &[u8] {
        match self {
            FeedbackSub::AckNack(a) => a.missing,
            FeedbackSub::NackFrag(n) => n.missing,
        }
    }
}

/// Encodes a whole `Feedback` datagram into `out` (cleared first). A datagram needs at least
/// one submessage and every bitmap at most [`MAX_BITMAP_BYTES`]; otherwise, or when the
/// result would exceed [`MAX_DATAGRAM`], nothing is encoded (`out` is left empty) and
/// [`DropReason::Invalid`] is returned.
pub fn encode_feedback(
    domain: u16,
    sender: u64,
    writer_participant: u64,
    token: AddressToken,
    subs: &[FeedbackSub<'_>],
    out: &mut Vec<u8>,
) -> Result<(), DropReason> {
    out.clear();
    if subs.is_empty() || subs.iter().any(|s| s.bitmap().len() > MAX_BITMAP_BYTES) {
        return Err(DropReason::Invalid);
    }
    Header {
        kind: MessageKind::Feedback,
        domain,
        sender,
    }
    .emit(out);
    // Encoding integers and byte strings into a Vec cannot fail.
    let mut buf = postcard::to_extend(&writer_participant, std::mem::take(out)).unwrap_or_default();
    buf.extend_from_slice(&token.to_le_bytes());
    for sub in subs {
        buf.push(sub.kind() as u8);
        buf = match sub {
            FeedbackSub::AckNack(a) => postcard::to_extend(a, buf),
            FeedbackSub::NackFrag(n) => postcard::to_extend(n, buf),
        }
        .unwrap_or_default();
    }
    *out = buf;
    if out.len() > MAX_DATAGRAM {
        out.clear();
        return Err(DropReason::Invalid);
    }
    Ok(())
}

/// A parsed `Feedback` datagram.
#[derive(Clone, Debug)]
pub struct FeedbackDatagram<'a> {
    /// The header.
    pub header: Header,
    /// The participant whose writers this is for.
    pub writer_participant: u64,
    /// The address token echoed from that participant's data (0: none).
    pub token: AddressToken,
    rest: &'a [u8],
}

impl<'a> FeedbackDatagram<'a> {
    /// Parses the header and the writer participant; the domain is checked against `domain`.
    pub fn parse(bytes: &'a [u8], domain: u16) -> Result<Self, DropReason> {
        let (header, body) = Header::parse(bytes)?;
        if header.domain != domain {
            return Err(DropReason::OtherDomain);
        }
        if header.kind != MessageKind::Feedback {
            return Err(DropReason::Unexpected);
        }
        let (writer_participant, rest) =
            postcard::take_from_bytes::<u64>(body).map_err(|_| DropReason::Malformed)?;
        let (token, rest) = rest.split_first_chunk::<8>().ok_or(DropReason::Malformed)?;
        let token = u64::from_le_bytes(*token);
        if rest.is_empty() {
            return Err(DropReason::Malformed);
        }
        Ok(FeedbackDatagram {
            header,
            writer_participant,
            token,
            rest,
        })
    }

    /// The submessages; a broken or unknown one is an error item that ends the iteration, as
    /// is a bitmap longer than [`MAX_BITMAP_BYTES`].
    pub fn subs(&self) -> FeedbackIter<'a> {
        FeedbackIter { rest: self.rest }
    }
}

/// Iterator over the submessages of a [`FeedbackDatagram`].
#[derive(Clone, Debug)]
pub struct FeedbackIter<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for FeedbackIter<'a> {
    type Item = Result<FeedbackSub<'a>, DropReason>;

    fn next(&mut self) -> Option<Self::Item> {
        let (&kind, body) = self.rest.split_first()?;
        let decoded = match kind {
            1 => postcard::take_from_bytes(body).map(|(a, r)| (FeedbackSub::AckNack(a), r)),
            2 => postcard::take_from_bytes(body).map(|(n, r)| (FeedbackSub::NackFrag(n), r)),
            _ => {
                self.rest = &[];
                return Some(Err(DropReason::UnknownKind));
            }
        };
        match decoded {
            Ok((sub, rest)) if sub.bitmap().len() <= MAX_BITMAP_BYTES => {
                self.rest = rest;
                Some(Ok(sub))
            }
            Ok(_) => {
                self.rest = &[];
                Some(Err(DropReason::Invalid))
            }
            Err(_) => {
                self.rest = &[];
                Some(Err(DropReason::Malformed))
            }
        }
    }
}

/// Bit `i` of a bitmap.
pub fn bit(bitmap: &[u8], i: usize) -> bool {
    bitmap
        .get(i / 8)
        .is_some_and(|byte| byte & (1 << (i % 8)) != 0)
}

/// Sets bit `i`, growing the bitmap as needed (up to [`MAX_BITMAP_BYTES`]); returns false
/// when `i` is beyond that.
pub fn set_bit(bitmap: &mut Vec<u8>, i: usize) -> bool {
    if i / 8 >= MAX_BITMAP_BYTES {
        return false;
    }
    if bitmap.len() <= i / 8 {
        bitmap.resize(i / 8 + 1, 0);
    }
    bitmap[i / 8] |= 1 << (i % 8);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feedback_round_trips_and_bitmaps_are_bounded() {
        let mut missing = Vec::new();
        assert!(set_bit(&mut missing, 3) && set_bit(&mut missing, 17));
        assert!(!set_bit(&mut missing, MAX_BITMAP_BYTES * 8));
        assert!(bit(&missing, 3) && bit(&missing, 17) && !bit(&missing, 4));
        let subs = [
            FeedbackSub::AckNack(AckNack {
                reader: 1,
                writer: 2,
                acked: 40,
                missing: &missing,
            }),
            FeedbackSub::NackFrag(NackFrag {
                reader: 1,
                writer: 2,
                seq: 41,
                base: 10,
                missing: &[0b101],
            }),
        ];
        let mut out = Vec::new();
        encode_feedback(5, 0xAA, 0xBB, 0x1234_5678_9ABC_DEF0, &subs, &mut out).unwrap();
        let datagram = FeedbackDatagram::parse(&out, 5).unwrap();
        assert_eq!(datagram.writer_participant, 0xBB);
        assert_eq!(datagram.token, 0x1234_5678_9ABC_DEF0);
        let decoded: Vec<_> = datagram.subs().collect::<Result<_, _>>().unwrap();
        assert_eq!(decoded, subs);
        let long = vec![0xFF; MAX_BITMAP_BYTES + 1];
        let too_long = [FeedbackSub::AckNack(AckNack {
            reader: 1,
            writer: 2,
            acked: 1,
            missing: &long,
        })];
        assert_eq!(
            encode_feedback(5, 1, 2, 0, &too_long, &mut out),
            Err(DropReason::Invalid)
        );
    }
}
