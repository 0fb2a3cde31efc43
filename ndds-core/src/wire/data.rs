//! `Data` (kind 16): samples and stream control from one writer of a producing process to
//! readers of one consuming process, as a sequence of submessages.
//!
//! ```text
//! header(kind = 16, sender = producing participant id)
//!   | varint reader_participant | varint writer | u64le token | varint n | n × varint reader
//!   | submessage { submessage }          (at least one)
//! submessage := u8 sub_kind | postcard body
//!   sub_kind 1  Sample     one whole sample
//!   sub_kind 2  Fragment   one piece of a sample too large for a datagram
//!   sub_kind 3  Heartbeat  a reliable writer's available range of sequence numbers
//!   sub_kind 4  Gap        sequence numbers a reliable writer can no longer provide
//! ```
//!
//! The datagram prefix names the writer (an entity of the sender participant) and the reader
//! entities of `reader_participant` every submessage is for (at most [`MAX_READERS`]). Several
//! submessages share a datagram when a producer batches small samples, or when a heartbeat
//! rides behind samples. A submessage of a kind this version does not know, or one that does
//! not decode, ends the parse of the datagram (the submessages before it stand).

use serde::{Deserialize, Serialize};
use smallvec::SmallVec;

use super::header::{HEADER_LEN, Header, MessageKind};
use super::{DropReason, MAX_DATAGRAM};

/// Flag bit: the writer is reliable (readers acknowledge, and repair from its history).
pub const FLAG_RELIABLE: u8 = 1;
/// Most reader entities one datagram may address.
pub const MAX_READERS: usize = 1024;

/// The reader entities a datagram addresses; up to eight are held without allocating.
pub type Readers = SmallVec<[u32; 8]>;

/// Submessage kinds inside a `Data` datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum DataSubKind {
    /// [`Sample`]
    Sample = 1,
    /// [`Fragment`]
    Fragment = 2,
    /// [`Heartbeat`]
    Heartbeat = 3,
    /// [`Gap`]
    Gap = 4,
}

/// What every sample and fragment says about its writer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SampleMeta {
    /// Per-writer sequence number, starting at 1.
    pub seq: u64,
    /// Source timestamp: nanoseconds since the Unix epoch when the sample was written.
    pub timestamp_ns: u64,
    /// The writer's strength.
    pub strength: i32,
    /// The writer's persistence in µs.
    pub persistence_us: u64,
    /// [`FLAG_RELIABLE`] and future flags.
    pub flags: u8,
}

/// A whole sample.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Sample<'a> {
    /// Sequence number, timestamp, strength, persistence, flags.
    pub meta: SampleMeta,
    /// postcard encoding of the value. (Encoded as a byte string, the same bytes as a
    /// sequence of `u8` but copied at once rather than byte by byte.)
    #[serde(borrow, with = "serde_bytes")]
    pub payload: &'a [u8],
}

/// One piece of a sample too large for one datagram. All pieces but the last carry exactly
/// `frag_size` bytes; piece `index` covers bytes `index × frag_size ..` of the sample.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Fragment<'a> {
    /// Sequence number, timestamp, strength, persistence, flags of the whole sample.
    pub meta: SampleMeta,
    /// Length of the whole sample in bytes.
    pub total_len: u32,
    /// Size of every piece but the last.
    pub frag_size: u32,
    /// Index of this piece.
    pub index: u32,
    /// Its bytes (a byte string, like [`Sample::payload`]).
    #[serde(borrow, with = "serde_bytes")]
    pub chunk: &'a [u8],
}

/// A reliable writer's history: sequence numbers `first..=last` can be repaired.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Heartbeat {
    /// Oldest sequence number still in the history (`last + 1` when empty).
    pub first: u64,
    /// Newest sequence number written.
    pub last: u64,
}

/// Sequence numbers `from..to` will never be sent (again): readers skip them and report them
/// lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Gap {
    /// First missing sequence number.
    pub from: u64,
    /// One past the last missing sequence number.
    pub to: u64,
}

/// One decoded submessage of a `Data` datagram.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DataSub<'a> {
    /// A whole sample.
    Sample(Sample<'a>),
    /// A piece of a sample.
    Fragment(Fragment<'a>),
    /// A reliable writer's range.
    Heartbeat(Heartbeat),
    /// Numbers that will never come.
    Gap(Gap),
}

impl DataSub<'_> {
    fn kind(&self) -> DataSubKind {
        match self {
            DataSub::Sample(_) => DataSubKind::Sample,
            DataSub::Fragment(_) => DataSubKind::Fragment,
            DataSub::Heartbeat(_) => DataSubKind::Heartbeat,
            DataSub::Gap(_) => DataSubKind::Gap,
        }
    }
}

/// Builds `Data` datagrams into a reusable buffer: no allocation once the buffer has grown.
#[derive(Debug, Default)]
pub struct DataWriter {
    buf: Vec<u8>,
    subs: usize,
    /// False when the addressing cannot be sent (more than [`MAX_READERS`] readers): every
    /// push is refused.
    valid: bool,
    /// What the prefix in `buf[..prefix_len]` was encoded for, so beginning the next datagram
    /// for the same destination reuses it instead of encoding it again.
    prefix: Option<PrefixKey>,
    prefix_len: usize,
}

/// The inputs of an encoded header and addressing.
#[derive(Debug, PartialEq, Eq)]
struct PrefixKey {
    domain: u16,
    sender: u64,
    reader_participant: u64,
    writer: u32,
    token: u64,
    readers: SmallVec<[u32; 8]>,
}

impl PrefixKey {
    fn matches(&self, domain: u16, sender: u64, to: &Addressing<'_>) -> bool {
        self.domain == domain
            && self.sender == sender
            && self.reader_participant == to.reader_participant
            && self.writer == to.writer
            && self.token == to.token
            && self.readers[..] == *to.readers
    }
}

impl DataWriter {
    /// An empty builder.
    pub fn new() -> Self {
        DataWriter::default()
    }

    /// Starts a datagram from `writer` of participant `sender` to `readers` of
    /// `reader_participant`, discarding anything begun before. A datagram names at most
    /// [`MAX_READERS`] readers: with more, every [`DataWriter::push`] is refused (split the
    /// readers into groups).
    pub fn begin(&mut self, domain: u16, sender: u64, to: &Addressing<'_>) {
        self.subs = 0;
        if self
            .prefix
            .as_ref()
            .is_some_and(|key| key.matches(domain, sender, to))
        {
            self.buf.truncate(self.prefix_len);
            return;
        }
        self.buf.clear();
        self.valid = to.readers.len() <= MAX_READERS;
        // Remembered only for small reader lists (the common case), so this never allocates.
        self.prefix = (to.readers.len() <= 8).then(|| PrefixKey {
            domain,
            sender,
            reader_participant: to.reader_participant,
            writer: to.writer,
            token: to.token,
            readers: SmallVec::from_slice(to.readers),
        });
        Header {
            kind: MessageKind::Data,
            domain,
            sender,
        }
        .emit(&mut self.buf);
        let buf = std::mem::take(&mut self.buf);
        // Encoding integers into a Vec cannot fail.
        self.buf = postcard::to_extend(to, buf).unwrap_or_default();
        self.prefix_len = self.buf.len();
    }

    /// Appends a `Sample` or `Fragment` submessage without its trailing bytes (the payload or
    /// chunk), for a sender that hands [`DataWriter::bytes`] and those bytes to the kernel
    /// together (scatter-gather), so they are never copied into the datagram buffer. The
    /// datagram is then exactly `bytes() ++ trailing`; nothing may be pushed after it. Returns
    /// the trailing bytes, or `None` (nothing appended) for other submessages or when the
    /// whole datagram would exceed `limit`.
    pub fn push_head<'s>(&mut self, sub: &DataSub<'s>, limit: usize) -> Option<&'s [u8]> {
        let mark = self.buf.len();
        let trailing = match sub {
            DataSub::Sample(s) => s.payload,
            DataSub::Fragment(f) => f.chunk,
            DataSub::Heartbeat(_) | DataSub::Gap(_) => return None,
        };
        if !self.valid || mark + 1 + trailing.len() > limit.min(MAX_DATAGRAM) {
            return None;
        }
        self.buf.push(sub.kind() as u8);
        let buf = std::mem::take(&mut self.buf);
        // The trailing bytes are a byte string: a varint length, then the bytes.
        let len = trailing.len() as u64;
        let result = match sub {
            DataSub::Sample(s) => postcard::to_extend(&(s.meta, len), buf),
            DataSub::Fragment(f) => {
                postcard::to_extend(&(f.meta, f.total_len, f.frag_size, f.index, len), buf)
            }
            DataSub::Heartbeat(_) | DataSub::Gap(_) => Ok(buf),
        };
        match result {
            Ok(buf) if buf.len() + trailing.len() <= limit.min(MAX_DATAGRAM) => {
                self.buf = buf;
                self.subs += 1;
                Some(trailing)
            }
            Ok(mut buf) => {
                buf.truncate(mark);
                self.buf = buf;
                None
            }
            Err(_) => {
                // Encoding integers into a Vec cannot fail.
                self.buf.truncate(mark);
                None
            }
        }
    }

    /// Appends a submessage if the datagram stays within `limit` bytes; returns whether it
    /// was appended (the datagram is unchanged otherwise).
    pub fn push(&mut self, sub: &DataSub<'_>, limit: usize) -> bool {
        let mark = self.buf.len();
        // Refused before encoding when the bytes carried alone are too many, so offering a
        // large sample costs no buffer growth.
        let carried = match sub {
            DataSub::Sample(s) => s.payload.len(),
            DataSub::Fragment(f) => f.chunk.len(),
            DataSub::Heartbeat(_) | DataSub::Gap(_) => 0,
        };
        if !self.valid || mark + 1 + carried > limit.min(MAX_DATAGRAM) {
            return false;
        }
        self.buf.push(sub.kind() as u8);
        let buf = std::mem::take(&mut self.buf);
        let result = match sub {
            DataSub::Sample(s) => postcard::to_extend(s, buf),
            DataSub::Fragment(f) => postcard::to_extend(f, buf),
            DataSub::Heartbeat(h) => postcard::to_extend(h, buf),
            DataSub::Gap(g) => postcard::to_extend(g, buf),
        };
        match result {
            Ok(buf) if buf.len() <= limit.min(MAX_DATAGRAM) => {
                self.buf = buf;
                self.subs += 1;
                true
            }
            Ok(mut buf) => {
                buf.truncate(mark);
                self.buf = buf;
                false
            }
            Err(_) => {
                // Encoding into a Vec fails only for values serde rejects; none here.
                self.buf.truncate(mark);
                false
            }
        }
    }

    /// Number of submessages in the datagram so far.
    pub fn len(&self) -> usize {
        self.subs
    }

    /// True when no submessage was added since `begin`.
    pub fn is_empty(&self) -> bool {
        self.subs == 0
    }

    /// The datagram so far.
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }
}

/// Who a datagram is for: its writer and readers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Addressing<'a> {
    /// The participant the datagram is for.
    pub reader_participant: u64,
    /// Writer entity within the sending participant.
    pub writer: u32,
    /// The sender's address token for this destination (see [`AddressToken`]): fixed 8
    /// bytes on the wire, echoed in the readers' feedback.
    #[serde(serialize_with = "token_bytes")]
    pub token: u64,
    /// Reader entities within `reader_participant`.
    pub readers: &'a [u32],
}

/// An address token: 64 bits a participant derives from a secret of its own and one
/// destination (address and participant), carried in every `Data` datagram it sends there
/// and echoed in the feedback that comes back. Feedback that echoes the right token proves
/// that its sender receives at that address (an off-path host that forges the address never
/// sees the token); 0 means none.
pub type AddressToken = u64;

/// A token as 8 bytes, little-endian (random tokens would take 10 as a varint).
fn token_bytes<S: serde::Serializer>(token: &u64, s: S) -> Result<S::Ok, S::Error> {
    token.to_le_bytes().serialize(s)
}

/// Bytes of a datagram's header and addressing, at most, for `readers` reader entities.
pub fn prefix_overhead(readers: usize) -> usize {
    HEADER_LEN + 10 + 5 + 8 + 5 + 5 * readers
}

/// Bytes a `Sample` submessage adds to its payload, at most (kind byte, metadata, payload
/// length).
pub const SAMPLE_OVERHEAD: usize = 1 + (10 + 10 + 5 + 10 + 1) + 5;

/// Bytes a `Fragment` submessage adds to its chunk, at most.
pub const FRAGMENT_OVERHEAD: usize = SAMPLE_OVERHEAD + 5 + 5 + 5;

/// A parsed `Data` datagram: who it is for, and an iterator over its submessages.
#[derive(Clone, Debug)]
pub struct DataDatagram<'a> {
    /// The header.
    pub header: Header,
    /// The participant the datagram is for.
    pub reader_participant: u64,
    /// Writer entity within the sending participant.
    pub writer: u32,
    /// The sender's token for this destination, to echo in feedback.
    pub token: AddressToken,
    /// Reader entities within `reader_participant`, deduplicated and sorted.
    pub readers: Readers,
    rest: &'a [u8],
}

impl<'a> DataDatagram<'a> {
    /// Parses the header and the addressing (reader participant, writer, readers); the
    /// submessages are decoded by iterating [`DataDatagram::subs`]. The domain is checked
    /// against `domain`; a datagram without submessages, or naming more than
    /// [`MAX_READERS`] readers, is malformed.
    pub fn parse(bytes: &'a [u8], domain: u16) -> Result<Self, DropReason> {
        let (header, body) = Header::parse(bytes)?;
        if header.domain != domain {
            return Err(DropReason::OtherDomain);
        }
        if header.kind != MessageKind::Data {
            return Err(DropReason::Unexpected);
        }
        let (reader_participant, rest) = take::<u64>(body)?;
        let (writer, rest) = take::<u32>(rest)?;
        let (token, rest) = rest.split_first_chunk::<8>().ok_or(DropReason::Malformed)?;
        let token = u64::from_le_bytes(*token);
        let (count, mut rest) = take::<u32>(rest)?;
        // Each reader takes at least one byte: a claim beyond the bytes left is malformed
        // before anything is allocated.
        if count as usize > MAX_READERS || count as usize > rest.len() {
            return Err(DropReason::Malformed);
        }
        let mut readers = Readers::new();
        for _ in 0..count {
            let (reader, tail) = take::<u32>(rest)?;
            readers.push(reader);
            rest = tail;
        }
        readers.sort_unstable();
        readers.dedup();
        if rest.is_empty() {
            return Err(DropReason::Malformed);
        }
        Ok(DataDatagram {
            header,
            reader_participant,
            writer,
            token,
            readers,
            rest,
        })
    }

    /// The submessages, in order. An item that fails to decode is `Err(Malformed)` and ends
    /// the iteration; an unknown submessage kind is `Err(UnknownKind)` and ends it too.
    pub fn subs(&self) -> SubIter<'a> {
        SubIter { rest: self.rest }
    }
}

/// Iterator over the submessages of a [`DataDatagram`].
#[derive(Clone, Debug)]
pub struct SubIter<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for SubIter<'a> {
    type Item = Result<DataSub<'a>, DropReason>;

    fn next(&mut self) -> Option<Self::Item> {
        let (&kind, body) = self.rest.split_first()?;
        let decoded = match kind {
            1 => take(body).map(|(s, rest)| (DataSub::Sample(s), rest)),
            2 => take(body).map(|(f, rest)| (DataSub::Fragment(f), rest)),
            3 => take(body).map(|(h, rest)| (DataSub::Heartbeat(h), rest)),
            4 => take(body).map(|(g, rest)| (DataSub::Gap(g), rest)),
            _ => Err(DropReason::UnknownKind),
        };
        match decoded {
            Ok((sub, rest)) => {
                self.rest = rest;
                Some(Ok(sub))
            }
            Err(reason) => {
                self.rest = &[];
                Some(Err(reason))
            }
        }
    }
}

fn take<'a, T: Deserialize<'a>>(body: &'a [u8]) -> Result<(T, &'a [u8]), DropReason> {
    postcard::take_from_bytes(body).map_err(|_| DropReason::Malformed)
}

/// The smallest `Data` datagram the parser accepts: header, reader participant, writer,
/// token, reader count (one byte each when zero, the token 8), and one submessage kind byte.
pub const MIN_DATA_LEN: usize = HEADER_LEN + 12;

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(payload: &[u8]) -> DataSub<'_> {
        DataSub::Sample(Sample {
            meta: SampleMeta {
                seq: 9,
                timestamp_ns: 123,
                strength: -2,
                persistence_us: 1000,
                flags: FLAG_RELIABLE,
            },
            payload,
        })
    }

    const TO: Addressing<'static> = Addressing {
        reader_participant: 0xCD,
        writer: 1,
        token: 0x0123_4567_89AB_CDEF,
        readers: &[3, 2, 3],
    };

    #[test]
    fn a_head_and_its_trailing_bytes_are_the_pushed_submessage() {
        let fragment = DataSub::Fragment(Fragment {
            meta: SampleMeta {
                seq: 300,
                timestamp_ns: u64::MAX,
                strength: -7,
                persistence_us: 5,
                flags: FLAG_RELIABLE,
            },
            total_len: 100_000,
            frag_size: 1400,
            index: 70,
            chunk: &[9; 1400],
        });
        for sub in [
            sample(&[]),
            sample(&[1; 200]),
            sample(&[2; 70_000][..65_000]),
            fragment,
        ] {
            let mut whole = DataWriter::new();
            whole.begin(7, 0xAB, &TO);
            let pushed = whole.push(&sub, MAX_DATAGRAM);
            let mut head = DataWriter::new();
            head.begin(7, 0xAB, &TO);
            let trailing = head.push_head(&sub, MAX_DATAGRAM);
            assert_eq!(pushed, trailing.is_some());
            if let Some(trailing) = trailing {
                assert_eq!([head.bytes(), trailing].concat(), whole.bytes());
            }
        }
        let mut w = DataWriter::new();
        w.begin(7, 0xAB, &TO);
        assert!(w.push_head(&sample(&[1; 500]), 400).is_none());
        assert!(w.is_empty());
        let gap = DataSub::Gap(Gap { from: 1, to: 2 });
        assert!(w.push_head(&gap, MAX_DATAGRAM).is_none());
    }

    #[test]
    fn batches_round_trip_and_respect_the_limit() {
        let mut w = DataWriter::new();
        w.begin(7, 0xAB, &TO);
        assert!(w.push(&sample(&[1; 10]), 200));
        let heartbeat = DataSub::Heartbeat(Heartbeat { first: 3, last: 9 });
        assert!(w.push(&heartbeat, 200));
        let before = w.bytes().to_vec();
        assert!(!w.push(&sample(&[0; 300]), 200), "would exceed the limit");
        assert_eq!(w.bytes(), &before[..], "unchanged by a refused push");
        let datagram = DataDatagram::parse(w.bytes(), 7).unwrap();
        assert_eq!(datagram.reader_participant, 0xCD);
        assert_eq!(datagram.writer, 1);
        assert_eq!(datagram.readers.as_slice(), &[2, 3], "sorted, deduplicated");
        assert_eq!(datagram.header.sender, 0xAB);
        let subs: Vec<_> = datagram.subs().collect::<Result<_, _>>().unwrap();
        assert_eq!(subs, vec![sample(&[1; 10]), heartbeat]);
        assert_eq!(
            DataDatagram::parse(w.bytes(), 8).unwrap_err(),
            DropReason::OtherDomain
        );
    }

    #[test]
    fn a_broken_submessage_ends_the_iteration() {
        let mut w = DataWriter::new();
        w.begin(0, 1, &TO);
        assert!(w.push(&sample(&[5; 4]), 1000));
        let mut bytes = w.bytes().to_vec();
        bytes.extend_from_slice(&[1, 0xff, 0xff]);
        let datagram = DataDatagram::parse(&bytes, 0).unwrap();
        let subs: Vec<_> = datagram.subs().collect();
        assert_eq!(subs.len(), 2);
        assert!(subs[0].is_ok());
        assert_eq!(subs[1], Err(DropReason::Malformed));
        bytes.truncate(w.bytes().len());
        bytes.push(99);
        let subs: Vec<_> = DataDatagram::parse(&bytes, 0).unwrap().subs().collect();
        assert_eq!(subs[1], Err(DropReason::UnknownKind));
    }

    #[test]
    fn a_huge_reader_count_is_malformed_before_anything_is_allocated() {
        let mut bytes = Vec::new();
        Header {
            kind: MessageKind::Data,
            domain: 0,
            sender: 1,
        }
        .emit(&mut bytes);
        bytes.extend_from_slice(&[5, 1, 0xFF, 0xFF, 0xFF, 0xFF, 0x0F, 1, 2]);
        assert_eq!(
            DataDatagram::parse(&bytes, 0).unwrap_err(),
            DropReason::Malformed
        );
    }
}
