//! proptest strategies for the submessages of `Data` (kind 16) and `Feedback` (kind 17)
//! datagrams, and for whole datagrams of several submessages, shared by the wire test binaries.
//!
//! The wire types borrow their payloads, chunks and bitmaps, so the strategies generate owned
//! forms ([`OwnedDataSub`], [`OwnedFeedbackSub`]) that lend the wire types out with `as_sub()`.
//! Numbers are drawn half from small values (one-byte varints) and half from the whole range
//! (the longest varints), so both ends of every encoding are exercised.

// Each test binary that includes this module uses a different subset of it.
#![allow(dead_code)]

use ndds_core::wire::data::{Addressing, DataWriter, Fragment, Gap, Heartbeat, Sample};
use ndds_core::wire::feedback::{AckNack, MAX_BITMAP_BYTES, NackFrag, encode_feedback};
use ndds_core::wire::{DataSub, FeedbackSub, MAX_DATAGRAM, SampleMeta};
use proptest::collection::vec;
use proptest::prelude::*;

/// A [`DataSub`] that owns its bytes.
#[derive(Clone, Debug)]
pub enum OwnedDataSub {
    Sample {
        meta: SampleMeta,
        payload: Vec<u8>,
    },
    Fragment {
        meta: SampleMeta,
        total_len: u32,
        frag_size: u32,
        index: u32,
        chunk: Vec<u8>,
    },
    Heartbeat(Heartbeat),
    Gap(Gap),
}

impl OwnedDataSub {
    /// The wire submessage, borrowing from `self`.
    pub fn as_sub(&self) -> DataSub<'_> {
        match self {
            OwnedDataSub::Sample { meta, payload } => DataSub::Sample(Sample {
                meta: *meta,
                payload,
            }),
            OwnedDataSub::Fragment {
                meta,
                total_len,
                frag_size,
                index,
                chunk,
            } => DataSub::Fragment(Fragment {
                meta: *meta,
                total_len: *total_len,
                frag_size: *frag_size,
                index: *index,
                chunk,
            }),
            OwnedDataSub::Heartbeat(h) => DataSub::Heartbeat(*h),
            OwnedDataSub::Gap(g) => DataSub::Gap(*g),
        }
    }
}

/// A [`FeedbackSub`] that owns its bitmap.
#[derive(Clone, Debug)]
pub enum OwnedFeedbackSub {
    AckNack {
        reader: u32,
        writer: u32,
        acked: u64,
        missing: Vec<u8>,
    },
    NackFrag {
        reader: u32,
        writer: u32,
        seq: u64,
        base: u32,
        missing: Vec<u8>,
    },
}

impl OwnedFeedbackSub {
    /// The wire submessage, borrowing from `self`.
    pub fn as_sub(&self) -> FeedbackSub<'_> {
        match self {
            OwnedFeedbackSub::AckNack {
                reader,
                writer,
                acked,
                missing,
            } => FeedbackSub::AckNack(AckNack {
                reader: *reader,
                writer: *writer,
                acked: *acked,
                missing,
            }),
            OwnedFeedbackSub::NackFrag {
                reader,
                writer,
                seq,
                base,
                missing,
            } => FeedbackSub::NackFrag(NackFrag {
                reader: *reader,
                writer: *writer,
                seq: *seq,
                base: *base,
                missing,
            }),
        }
    }
}

/// A whole `Data` datagram: header fields, addressing, at least one submessage.
#[derive(Clone, Debug)]
pub struct OwnedDataDatagram {
    pub domain: u16,
    pub sender: u64,
    pub reader_participant: u64,
    pub writer: u32,
    pub token: u64,
    /// As the sender lists them: in any order, repeats allowed.
    pub readers: Vec<u32>,
    pub subs: Vec<OwnedDataSub>,
}

impl OwnedDataDatagram {
    /// The submessages as wire values.
    pub fn subs(&self) -> Vec<DataSub<'_>> {
        self.subs.iter().map(OwnedDataSub::as_sub).collect()
    }

    /// Who the datagram is for, as `DataWriter::begin` takes it.
    pub fn addressing(&self) -> Addressing<'_> {
        Addressing {
            reader_participant: self.reader_participant,
            writer: self.writer,
            token: self.token,
            readers: &self.readers,
        }
    }

    /// The readers as the parser reports them: sorted, each once.
    pub fn parsed_readers(&self) -> Vec<u32> {
        let mut readers = self.readers.clone();
        readers.sort_unstable();
        readers.dedup();
        readers
    }

    /// Starts `writer` on this datagram's header and addressing.
    pub fn begin(&self, writer: &mut DataWriter) {
        writer.begin(self.domain, self.sender, &self.addressing());
    }

    /// The bytes `DataWriter` builds, and the offset where each submessage ends.
    pub fn encode_with_ends(&self) -> (Vec<u8>, Vec<usize>) {
        let mut writer = DataWriter::new();
        self.begin(&mut writer);
        let mut ends = Vec::with_capacity(self.subs.len());
        for sub in &self.subs {
            assert!(
                writer.push(&sub.as_sub(), MAX_DATAGRAM),
                "generated submessages fit in a datagram"
            );
            ends.push(writer.bytes().len());
        }
        (writer.bytes().to_vec(), ends)
    }

    /// The bytes `DataWriter` builds.
    pub fn encode(&self) -> Vec<u8> {
        self.encode_with_ends().0
    }
}

/// A whole `Feedback` datagram.
#[derive(Clone, Debug)]
pub struct OwnedFeedbackDatagram {
    pub domain: u16,
    pub sender: u64,
    pub writer_participant: u64,
    pub token: u64,
    pub subs: Vec<OwnedFeedbackSub>,
}

impl OwnedFeedbackDatagram {
    /// The submessages as wire values.
    pub fn subs(&self) -> Vec<FeedbackSub<'_>> {
        self.subs.iter().map(OwnedFeedbackSub::as_sub).collect()
    }

    /// The bytes `encode_feedback` writes for the first `count` submessages.
    pub fn encode_first(&self, count: usize) -> Vec<u8> {
        let mut out = Vec::new();
        encode_feedback(
            self.domain,
            self.sender,
            self.writer_participant,
            self.token,
            &self.subs()[..count],
            &mut out,
        )
        .expect("generated feedback encodes");
        out
    }

    /// The bytes `encode_feedback` writes.
    pub fn encode(&self) -> Vec<u8> {
        self.encode_first(self.subs.len())
    }

    /// The encoded bytes, and the offset where each submessage ends.
    pub fn encode_with_ends(&self) -> (Vec<u8>, Vec<usize>) {
        let ends = (1..=self.subs.len())
            .map(|count| self.encode_first(count).len())
            .collect();
        (self.encode(), ends)
    }
}

/// Small values (one-byte varints) or any value (the longest varints).
pub fn number_u64() -> impl Strategy<Value = u64> {
    prop_oneof![0..128_u64, any::<u64>()]
}

/// Small values or any value.
pub fn number_u32() -> impl Strategy<Value = u32> {
    prop_oneof![0..128_u32, any::<u32>()]
}

/// Small values of either sign (one-byte zigzag varints) or any value.
pub fn number_i32() -> impl Strategy<Value = i32> {
    prop_oneof![-64..64_i32, any::<i32>()]
}

/// Reader entities: none, a few, or more than `Readers` holds inline; in any order and with
/// repeats (the wire does not forbid them; the parser sorts and deduplicates).
pub fn readers() -> impl Strategy<Value = Vec<u32>> {
    vec(number_u32(), 0..12)
}

pub fn sample_meta() -> impl Strategy<Value = SampleMeta> {
    (
        number_u64(),
        number_u64(),
        number_i32(),
        number_u64(),
        any::<u8>(),
    )
        .prop_map(
            |(seq, timestamp_ns, strength, persistence_us, flags)| SampleMeta {
                seq,
                timestamp_ns,
                strength,
                persistence_us,
                flags,
            },
        )
}

pub fn sample() -> impl Strategy<Value = OwnedDataSub> {
    (sample_meta(), vec(any::<u8>(), 0..300))
        .prop_map(|(meta, payload)| OwnedDataSub::Sample { meta, payload })
}

/// A fragment with arbitrary numbers: the codec does not relate them to each other.
pub fn fragment() -> impl Strategy<Value = OwnedDataSub> {
    (
        sample_meta(),
        (number_u32(), number_u32(), number_u32()),
        vec(any::<u8>(), 0..300),
    )
        .prop_map(
            |(meta, (total_len, frag_size, index), chunk)| OwnedDataSub::Fragment {
                meta,
                total_len,
                frag_size,
                index,
                chunk,
            },
        )
}

pub fn heartbeat() -> impl Strategy<Value = OwnedDataSub> {
    (number_u64(), number_u64())
        .prop_map(|(first, last)| OwnedDataSub::Heartbeat(Heartbeat { first, last }))
}

pub fn gap() -> impl Strategy<Value = OwnedDataSub> {
    (number_u64(), number_u64()).prop_map(|(from, to)| OwnedDataSub::Gap(Gap { from, to }))
}

/// Any `Data` submessage.
pub fn data_sub() -> impl Strategy<Value = OwnedDataSub> {
    prop_oneof![sample(), fragment(), heartbeat(), gap()]
}

/// A bitmap of any accepted length, `0..=MAX_BITMAP_BYTES`.
pub fn bitmap() -> impl Strategy<Value = Vec<u8>> {
    vec(any::<u8>(), 0..=MAX_BITMAP_BYTES)
}

pub fn ack_nack() -> impl Strategy<Value = OwnedFeedbackSub> {
    (number_u32(), number_u32(), number_u64(), bitmap()).prop_map(
        |(reader, writer, acked, missing)| OwnedFeedbackSub::AckNack {
            reader,
            writer,
            acked,
            missing,
        },
    )
}

pub fn nack_frag() -> impl Strategy<Value = OwnedFeedbackSub> {
    (
        number_u32(),
        number_u32(),
        number_u64(),
        number_u32(),
        bitmap(),
    )
        .prop_map(
            |(reader, writer, seq, base, missing)| OwnedFeedbackSub::NackFrag {
                reader,
                writer,
                seq,
                base,
                missing,
            },
        )
}

/// Any `Feedback` submessage.
pub fn feedback_sub() -> impl Strategy<Value = OwnedFeedbackSub> {
    prop_oneof![ack_nack(), nack_frag()]
}

/// A `Data` datagram of one to eight submessages of any kinds.
pub fn data_datagram() -> impl Strategy<Value = OwnedDataDatagram> {
    (
        (any::<u16>(), number_u64()),
        (number_u64(), number_u32(), any::<u64>(), readers()),
        vec(data_sub(), 1..8),
    )
        .prop_map(
            |((domain, sender), (reader_participant, writer, token, readers), subs)| {
                OwnedDataDatagram {
                    domain,
                    sender,
                    reader_participant,
                    writer,
                    token,
                    readers,
                    subs,
                }
            },
        )
}

/// A `Feedback` datagram of one to eight submessages of either kind.
pub fn feedback_datagram() -> impl Strategy<Value = OwnedFeedbackDatagram> {
    (
        any::<u16>(),
        number_u64(),
        number_u64(),
        any::<u64>(),
        vec(feedback_sub(), 1..8),
    )
        .prop_map(
            |(domain, sender, writer_participant, token, subs)| OwnedFeedbackDatagram {
                domain,
                sender,
                writer_participant,
                token,
                subs,
            },
        )
}

/// A `sub_kind` byte that `Data` does not define (0, or 5 and above).
pub fn unknown_data_sub_kind() -> impl Strategy<Value = u8> {
    prop_oneof![Just(0_u8), 5_u8..=255]
}

/// A `sub_kind` byte that `Feedback` does not define (0, or 3 and above).
pub fn unknown_feedback_sub_kind() -> impl Strategy<Value = u8> {
    prop_oneof![Just(0_u8), 3_u8..=255]
}
