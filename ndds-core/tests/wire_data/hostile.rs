//! Hostile `Data` (kind 16) and `Feedback` (kind 17) datagrams: arbitrary bytes, a valid
//! header followed by noise, mutated valid datagrams and huge length claims never make
//! `DataDatagram::parse` / `FeedbackDatagram::parse` or their submessage iterators panic, and
//! never make them allocate more than the datagram's length justifies (the parent module's
//! counting allocator and `budget`). Also what the steady state allocates: nothing, for the
//! builders once warm and for the parsers up to eight readers.

use ndds_core::wire::data::{
    Addressing, DataSubKind, Gap, Heartbeat, MAX_READERS, Sample, SampleMeta,
};
use ndds_core::wire::feedback::{AckNack, FeedbackSubKind, encode_feedback};
use ndds_core::wire::{
    DataDatagram, DataSub, DataWriter, DropReason, FeedbackDatagram, FeedbackSub, MAX_DATAGRAM,
    MessageKind,
};
use proptest::collection::vec;
use proptest::prelude::*;

use super::messages;
use super::submessages::{data_datagram, feedback_datagram, number_u64};
use super::{CLAIM_U32_MAX, CLAIM_U64_MAX, HEADER_LEN, Usage, budget, header_bytes, measure};

/// What iterating a parsed datagram gave: the submessages that decoded, then the reason that
/// ended the parse, if any.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Outcome {
    decoded: usize,
    ended_by: Option<DropReason>,
}

/// Drains `items`, checking that nothing follows an error item.
fn drain<T>(items: impl Iterator<Item = Result<T, DropReason>>) -> Outcome {
    let mut outcome = Outcome {
        decoded: 0,
        ended_by: None,
    };
    for item in items {
        assert!(outcome.ended_by.is_none(), "an item after the parse ended");
        match item {
            Ok(_) => outcome.decoded += 1,
            Err(reason) => outcome.ended_by = Some(reason),
        }
    }
    outcome
}

fn check_budget(what: &str, len: usize, usage: Usage) {
    assert!(
        usage.peak <= budget(len) && usage.total <= budget(len),
        "{what} of {len} bytes allocated {usage:?} (budget {})",
        budget(len)
    );
}

/// Parses `bytes` as `Data` and drains its submessages, within the allocation budget.
fn parse_data(bytes: &[u8], domain: u16) -> (Result<Outcome, DropReason>, Usage) {
    let (result, usage) = measure(|| DataDatagram::parse(bytes, domain).map(|d| drain(d.subs())));
    check_budget("parsing Data", bytes.len(), usage);
    (result, usage)
}

/// Parses `bytes` as `Feedback` and drains its submessages, within the allocation budget.
fn parse_feedback(bytes: &[u8], domain: u16) -> (Result<Outcome, DropReason>, Usage) {
    let (result, usage) =
        measure(|| FeedbackDatagram::parse(bytes, domain).map(|d| drain(d.subs())));
    check_budget("parsing Feedback", bytes.len(), usage);
    (result, usage)
}

/// Both parsers, at the domain of the datagram's header.
fn parse_both(bytes: &[u8]) -> (Result<Outcome, DropReason>, Result<Outcome, DropReason>) {
    let domain = bytes
        .get(6..8)
        .map_or(0, |d| u16::from_le_bytes([d[0], d[1]]));
    (parse_data(bytes, domain).0, parse_feedback(bytes, domain).0)
}

/// A `Data` or `Feedback` header, a participant, then chunks that each start with a
/// submessage kind byte (known or not) followed by noise: deeper into the parsers than
/// uniform noise gets.
fn data_plane_header_then_noise() -> impl Strategy<Value = Vec<u8>> {
    (
        prop_oneof![Just(MessageKind::Data), Just(MessageKind::Feedback)],
        number_u64(),
        vec(any::<u8>(), 0..12),
        vec((0..6_u8, vec(any::<u8>(), 0..48)), 0..12),
    )
        .prop_map(|(kind, participant, prefix_noise, chunks)| {
            let mut bytes = header_bytes(kind as u8, 0, 1);
            bytes.extend(postcard::to_allocvec(&participant).unwrap());
            bytes.extend(prefix_noise);
            for (sub_kind, noise) in chunks {
                bytes.push(sub_kind);
                bytes.extend(noise);
            }
            bytes
        })
}

/// A valid `Data` or `Feedback` datagram with a few bytes overwritten, inserted or removed
/// after the header.
fn mutated_data_plane_datagram() -> impl Strategy<Value = Vec<u8>> {
    let valid = prop_oneof![
        data_datagram().prop_map(|d| d.encode()),
        feedback_datagram().prop_map(|d| d.encode()),
    ];
    (valid, vec((any::<usize>(), any::<u8>(), 0..3_u8), 1..6)).prop_map(|(mut bytes, edits)| {
        for (at, value, op) in edits {
            let at = HEADER_LEN + at % (bytes.len() - HEADER_LEN + 1);
            match op {
                0 if at < bytes.len() => bytes[at] = value,
                1 => bytes.insert(at, value),
                _ if at < bytes.len() => {
                    bytes.remove(at);
                }
                _ => bytes.push(value),
            }
        }
        bytes
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2048))]

    #[test]
    fn arbitrary_bytes_never_panic_nor_overallocate(bytes in vec(any::<u8>(), 0..2048)) {
        let _ = parse_both(&bytes);
    }

    /// A known header of any kind, then noise: the parsers take their own kind only.
    #[test]
    fn valid_header_then_noise_never_panics_nor_overallocates(
        kind in messages::kind(),
        domain in any::<u16>(),
        body in vec(any::<u8>(), 0..1024),
    ) {
        let bytes = [header_bytes(kind as u8, domain, 1), body].concat();
        let (data, feedback) = parse_both(&bytes);
        let unexpected = Err(DropReason::Unexpected);
        match kind {
            MessageKind::Data => prop_assert_eq!(feedback, unexpected),
            MessageKind::Feedback => prop_assert_eq!(data, unexpected),
            _ => prop_assert_eq!((data, feedback), (unexpected, unexpected)),
        }
    }

    #[test]
    fn structured_noise_never_panics_nor_overallocates(bytes in data_plane_header_then_noise()) {
        let (data, feedback) = parse_both(&bytes);
        // A parse that got as far as the submessages ends for a reason or at the end.
        for outcome in [data, feedback].into_iter().flatten() {
            prop_assert!(matches!(
                outcome.ended_by,
                None | Some(DropReason::Malformed | DropReason::UnknownKind | DropReason::Invalid)
            ));
        }
    }

    #[test]
    fn mutated_datagrams_never_panic_nor_overallocate(bytes in mutated_data_plane_datagram()) {
        let _ = parse_both(&bytes);
    }

    /// Valid datagrams parse completely; with at most eight readers, without allocating.
    #[test]
    fn valid_datagrams_parse_without_allocating(
        data in data_datagram(),
        feedback in feedback_datagram(),
    ) {
        let (outcome, usage) = parse_data(&data.encode(), data.domain);
        prop_assert_eq!(outcome, Ok(Outcome { decoded: data.subs.len(), ended_by: None }));
        if data.parsed_readers().len() <= 8 && data.readers.len() <= 8 {
            prop_assert_eq!((usage.peak, usage.total), (0, 0));
        }
        let (outcome, usage) = parse_feedback(&feedback.encode(), feedback.domain);
        prop_assert_eq!(outcome, Ok(Outcome { decoded: feedback.subs.len(), ended_by: None }));
        prop_assert_eq!((usage.peak, usage.total), (0, 0));
    }
}

/// An address token, as it follows the writer (Data) or the writer participant (Feedback).
const TOKEN: [u8; 8] = [0xAB; 8];

fn data_datagram_of(body: &[&[u8]]) -> Vec<u8> {
    let mut bytes = header_bytes(MessageKind::Data as u8, 0, 1);
    for part in body {
        bytes.extend_from_slice(part);
    }
    bytes
}

fn feedback_datagram_of(body: &[&[u8]]) -> Vec<u8> {
    let mut bytes = header_bytes(MessageKind::Feedback as u8, 0, 1);
    for part in body {
        bytes.extend_from_slice(part);
    }
    bytes
}

/// A reader count of four billion (or more than a u32) is malformed before any reader is
/// stored; so is one beyond `MAX_READERS`, or beyond the bytes that follow.
#[test]
fn huge_reader_counts_are_malformed_and_cheap() {
    let beyond_max = postcard::to_allocvec(&(MAX_READERS as u32 + 1)).unwrap();
    let many_zeros = vec![0_u8; MAX_READERS + 8];
    let cases = [
        // Participant 7, writer 1, a token, u32::MAX readers, two of them, a heartbeat.
        data_datagram_of(&[&[7, 1], &TOKEN, &CLAIM_U32_MAX, &[3, 4], &[3, 1, 2]]),
        data_datagram_of(&[&[7, 1], &TOKEN, &CLAIM_U64_MAX, &[3, 4], &[3, 1, 2]]),
        // MAX_READERS + 1 readers, all present.
        data_datagram_of(&[&[7, 1], &TOKEN, &beyond_max, &many_zeros]),
        // 100 readers claimed, 3 bytes follow.
        data_datagram_of(&[&[7, 1], &TOKEN, &[100], &[3, 1, 2]]),
    ];
    for bytes in &cases {
        let (outcome, usage) = parse_data(bytes, 0);
        assert_eq!(outcome, Err(DropReason::Malformed), "{bytes:02x?}");
        assert_eq!(usage.peak, 0, "{} bytes: {usage:?}", bytes.len());
    }
}

/// A payload, chunk or bitmap claiming gigabytes ends the parse as malformed, allocating
/// nothing: those bytes are borrowed from the datagram, never copied.
#[test]
fn payloads_chunks_and_bitmaps_claiming_gigabytes_are_malformed_and_cheap() {
    let sample = DataSubKind::Sample as u8;
    let fragment = DataSubKind::Fragment as u8;
    // Participant 7, writer 1, a token, no readers; then one-byte varints up to the length
    // claim.
    let prefix: &[u8] = &[7, 1, 0xAB, 0xAB, 0xAB, 0xAB, 0xAB, 0xAB, 0xAB, 0xAB, 0];
    let meta: &[u8] = &[1, 2, 3, 4, 5];
    let data_cases = [
        data_datagram_of(&[prefix, &[sample], meta, &CLAIM_U32_MAX, b"xy"]),
        data_datagram_of(&[prefix, &[sample], meta, &CLAIM_U64_MAX, b"xy"]),
        data_datagram_of(&[prefix, &[fragment], meta, &[9, 4, 1], &CLAIM_U32_MAX, b"xy"]),
    ];
    for bytes in &data_cases {
        let (outcome, usage) = parse_data(bytes, 0);
        let ended = Outcome {
            decoded: 0,
            ended_by: Some(DropReason::Malformed),
        };
        assert_eq!(outcome, Ok(ended), "{bytes:02x?}");
        assert_eq!((usage.peak, usage.total), (0, 0), "{bytes:02x?}");
    }
    let ack = FeedbackSubKind::AckNack as u8;
    let nack = FeedbackSubKind::NackFrag as u8;
    let feedback_cases = [
        // Writer participant 7, a token; reader 1, writer 2, acked 3, bitmap of u32::MAX bytes.
        feedback_datagram_of(&[&[7], &TOKEN, &[ack, 1, 2, 3], &CLAIM_U32_MAX, b"xy"]),
        feedback_datagram_of(&[&[7], &TOKEN, &[ack, 1, 2, 3], &CLAIM_U64_MAX, b"xy"]),
        feedback_datagram_of(&[&[7], &TOKEN, &[nack, 1, 2, 3, 4], &CLAIM_U32_MAX, b"xy"]),
    ];
    for bytes in &feedback_cases {
        let (outcome, usage) = parse_feedback(bytes, 0);
        let ended = Outcome {
            decoded: 0,
            ended_by: Some(DropReason::Malformed),
        };
        assert_eq!(outcome, Ok(ended), "{bytes:02x?}");
        assert_eq!((usage.peak, usage.total), (0, 0), "{bytes:02x?}");
    }
}

/// The most readers a datagram may name cost four bytes each, well within the budget.
#[test]
fn the_most_readers_stay_within_the_budget() {
    let readers: Vec<u32> = (0..MAX_READERS as u32).rev().collect();
    let mut writer = DataWriter::new();
    let to = Addressing {
        reader_participant: 7,
        writer: 1,
        token: 0x5eed,
        readers: &readers,
    };
    writer.begin(0, 1, &to);
    assert!(writer.push(&DataSub::Gap(Gap { from: 1, to: 2 }), MAX_DATAGRAM));
    let (outcome, usage) = parse_data(writer.bytes(), 0);
    assert_eq!(
        outcome,
        Ok(Outcome {
            decoded: 1,
            ended_by: None
        })
    );
    assert!(usage.peak <= 2 * 4 * MAX_READERS, "{usage:?}");
}

/// Once its buffer has grown, a `DataWriter` builds datagrams without allocating, and
/// `encode_feedback` into a warm buffer allocates nothing either.
#[test]
fn warm_builders_allocate_nothing() {
    let payload = [0x42_u8; 250];
    let readers = [3_u32, 4, 5];
    let to = Addressing {
        reader_participant: 7,
        writer: 1,
        token: 0x5eed,
        readers: &readers,
    };
    let sample = |seq| {
        DataSub::Sample(Sample {
            meta: SampleMeta {
                seq,
                ..SampleMeta::default()
            },
            payload: &payload,
        })
    };
    let mut writer = DataWriter::new();
    let build = |writer: &mut DataWriter, first_seq: u64| {
        writer.begin(0, 1, &to);
        for seq in first_seq..first_seq + 5 {
            assert!(writer.push(&sample(seq), 1400));
        }
        assert!(
            !writer.push(&sample(0), 1400),
            "the sixth sample does not fit"
        );
        assert!(writer.push(&DataSub::Heartbeat(Heartbeat { first: 1, last: 9 }), 1400));
    };
    build(&mut writer, 1);
    let ((), usage) = measure(|| build(&mut writer, 6));
    assert_eq!((usage.peak, usage.total), (0, 0));

    let missing = [0b101_u8; 8];
    let subs = [FeedbackSub::AckNack(AckNack {
        reader: 3,
        writer: 1,
        acked: 5,
        missing: &missing,
    })];
    let mut out = Vec::new();
    encode_feedback(0, 7, 1, 0, &subs, &mut out).unwrap();
    let (result, usage) = measure(|| encode_feedback(0, 7, 1, 0, &subs, &mut out));
    assert_eq!(result, Ok(()));
    assert_eq!((usage.peak, usage.total), (0, 0));
}

/// A push that is refused because the datagram would exceed its limit should not cost more
/// memory than the limit: the fragmenter offers whole samples to find out whether they fit.
#[test]
fn a_refused_push_allocates_no_more_than_its_limit() {
    let big = vec![0_u8; 1 << 20];
    let to = Addressing {
        reader_participant: 7,
        writer: 1,
        token: 0x5eed,
        readers: &[2],
    };
    let mut writer = DataWriter::new();
    writer.begin(0, 1, &to);
    let sample = DataSub::Sample(Sample {
        meta: SampleMeta::default(),
        payload: &big,
    });
    let (pushed, usage) = measure(|| writer.push(&sample, 1400));
    assert!(!pushed);
    assert!(usage.total <= 2 * 1400, "refusing allocated {usage:?}");
}

/// The readers of a parsed datagram are held inline up to eight; more spill to the heap.
#[test]
fn readers_beyond_eight_are_the_only_parse_allocation() {
    for (count, allocates) in [(0, false), (8, false), (9, true)] {
        let readers: Vec<u32> = (0..count).collect();
        let to = Addressing {
            reader_participant: 7,
            writer: 1,
            token: 0x5eed,
            readers: &readers,
        };
        let mut writer = DataWriter::new();
        writer.begin(0, 1, &to);
        let sample = DataSub::Sample(Sample {
            meta: SampleMeta::default(),
            payload: &[1, 2, 3],
        });
        assert!(writer.push(&sample, MAX_DATAGRAM));
        let (_, usage) = parse_data(writer.bytes(), 0);
        assert_eq!(usage.total > 0, allocates, "{count} readers: {usage:?}");
    }
    // The decoded submessage borrows: no copy of the payload.
    let bytes = {
        let mut writer = DataWriter::new();
        writer.begin(
            0,
            1,
            &Addressing {
                reader_participant: 7,
                writer: 1,
                token: 0x5eed,
                readers: &[],
            },
        );
        assert!(writer.push(
            &DataSub::Sample(Sample {
                meta: SampleMeta::default(),
                payload: &[9; 100],
            }),
            MAX_DATAGRAM
        ));
        writer.bytes().to_vec()
    };
    let datagram = DataDatagram::parse(&bytes, 0).unwrap();
    match datagram.subs().next() {
        Some(Ok(DataSub::Sample(sample))) => {
            assert!(bytes.as_ptr_range().contains(&sample.payload.as_ptr()));
        }
        other => panic!("{other:?}"),
    }
}
