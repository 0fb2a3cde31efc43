//! `Data` (kind 16) and `Feedback` (kind 17) datagrams, sequences of submessages, go through
//! `DataWriter` / `encode_feedback` and back through `DataDatagram::parse` /
//! `FeedbackDatagram::parse`: the exact byte layout, the writer's size limit and overhead
//! bounds, truncation at every length, unknown or broken submessages ending the parse, reader
//! and bitmap limits, and each decoder refusing the other plane's kinds as `unexpected`.

use ndds_core::wire::data::{
    Addressing, DataSubKind, FRAGMENT_OVERHEAD, Fragment, Gap, Heartbeat, MAX_READERS,
    MIN_DATA_LEN, SAMPLE_OVERHEAD, Sample, SampleMeta, prefix_overhead,
};
use ndds_core::wire::feedback::{
    AckNack, FeedbackSubKind, MAX_BITMAP_BYTES, NackFrag, bit, encode_feedback, set_bit,
};
use ndds_core::wire::{
    self, DataDatagram, DataSub, DataWriter, DropReason, FeedbackDatagram, FeedbackSub, HEADER_LEN,
    Header, MAX_DATAGRAM, MessageKind, PROTOCOL_VERSION,
};
use proptest::collection::vec;
use proptest::prelude::*;

use super::submessages::{
    self, OwnedDataDatagram, OwnedFeedbackDatagram, data_datagram, feedback_datagram, sample_meta,
};

/// The `sub_kind` byte of a `Data` submessage, from the code's `DataSubKind`.
fn data_kind(sub: &DataSub<'_>) -> u8 {
    let kind = match sub {
        DataSub::Sample(_) => DataSubKind::Sample,
        DataSub::Fragment(_) => DataSubKind::Fragment,
        DataSub::Heartbeat(_) => DataSubKind::Heartbeat,
        DataSub::Gap(_) => DataSubKind::Gap,
    };
    kind as u8
}

/// `u8 sub_kind | postcard body`, as the layout drawn in `wire/data.rs` says.
pub fn data_sub_bytes(sub: &DataSub<'_>) -> Vec<u8> {
    let body = match sub {
        DataSub::Sample(s) => postcard::to_allocvec(s),
        DataSub::Fragment(f) => postcard::to_allocvec(f),
        DataSub::Heartbeat(h) => postcard::to_allocvec(h),
        DataSub::Gap(g) => postcard::to_allocvec(g),
    }
    .unwrap();
    [vec![data_kind(sub)], body].concat()
}

/// `u8 sub_kind | postcard body`, as the layout drawn in `wire/feedback.rs` says.
pub fn feedback_sub_bytes(sub: &FeedbackSub<'_>) -> Vec<u8> {
    let (kind, body) = match sub {
        FeedbackSub::AckNack(a) => (FeedbackSubKind::AckNack, postcard::to_allocvec(a)),
        FeedbackSub::NackFrag(n) => (FeedbackSubKind::NackFrag, postcard::to_allocvec(n)),
    };
    [vec![kind as u8], body.unwrap()].concat()
}

fn header(kind: MessageKind, domain: u16, sender: u64) -> Vec<u8> {
    let mut out = Vec::new();
    Header {
        kind,
        domain,
        sender,
    }
    .emit(&mut out);
    out
}

/// Header and addressing, by hand: where the submessages of a `Data` datagram start.
fn data_preamble(d: &OwnedDataDatagram) -> Vec<u8> {
    let mut out = header(MessageKind::Data, d.domain, d.sender);
    out.extend(postcard::to_allocvec(&d.reader_participant).unwrap());
    out.extend(postcard::to_allocvec(&d.writer).unwrap());
    out.extend(d.token.to_le_bytes());
    out.extend(postcard::to_allocvec(&d.readers).unwrap());
    out
}

/// Header and writer participant: where the submessages of a `Feedback` datagram start.
fn feedback_preamble(domain: u16, sender: u64, writer_participant: u64, token: u64) -> Vec<u8> {
    let mut out = header(MessageKind::Feedback, domain, sender);
    out.extend(postcard::to_allocvec(&writer_participant).unwrap());
    out.extend(token.to_le_bytes());
    out
}

fn feedback_preamble_of(d: &OwnedFeedbackDatagram) -> Vec<u8> {
    feedback_preamble(d.domain, d.sender, d.writer_participant, d.token)
}

type Items<T> = Vec<Result<T, DropReason>>;

fn data_items(bytes: &[u8], domain: u16) -> Result<Items<DataSub<'_>>, DropReason> {
    DataDatagram::parse(bytes, domain).map(|d| d.subs().collect())
}

fn feedback_items(bytes: &[u8], domain: u16) -> Result<Items<FeedbackSub<'_>>, DropReason> {
    FeedbackDatagram::parse(bytes, domain).map(|d| d.subs().collect())
}

fn all_ok<T>(subs: Vec<T>) -> Items<T> {
    subs.into_iter().map(Ok).collect()
}

/// What a datagram cut at `cut` bytes must give, when its submessages start at `start` and
/// end at `ends`: below the header `truncated`; without a whole submessage `malformed`;
/// otherwise exactly the submessages that end at or before the cut, then one `malformed` item
/// when a partial submessage follows them.
fn check_cut<T: PartialEq + std::fmt::Debug>(
    parsed: Result<Items<T>, DropReason>,
    originals: Vec<T>,
    start: usize,
    ends: &[usize],
    cut: usize,
) -> Result<(), TestCaseError> {
    let whole = ends.iter().filter(|end| **end <= cut).count();
    let expected = if cut < HEADER_LEN {
        Err(DropReason::Truncated)
    } else if cut <= start {
        Err(DropReason::Malformed)
    } else {
        let last_end = if whole == 0 { start } else { ends[whole - 1] };
        let mut items: Items<T> = originals.into_iter().take(whole).map(Ok).collect();
        if cut > last_end {
            items.push(Err(DropReason::Malformed));
        }
        Ok(items)
    };
    prop_assert_eq!(parsed, expected, "cut at {}", cut);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// A `Data` datagram of several submessages goes through `DataWriter` and back, with the
    /// layout `header | varint reader_participant | varint writer | u64le token | varint n |
    /// n × varint reader | { u8 sub_kind | postcard body }`.
    #[test]
    fn data_datagrams_round_trip(d in data_datagram()) {
        let (bytes, ends) = d.encode_with_ends();
        let subs = d.subs();
        let mut expected = data_preamble(&d);
        for (sub, end) in subs.iter().zip(&ends) {
            expected.extend(data_sub_bytes(sub));
            prop_assert_eq!(*end, expected.len());
        }
        prop_assert_eq!(&bytes, &expected);

        let datagram = DataDatagram::parse(&bytes, d.domain).unwrap();
        prop_assert_eq!(
            (datagram.header.kind, datagram.header.domain, datagram.header.sender),
            (MessageKind::Data, d.domain, d.sender)
        );
        prop_assert_eq!(datagram.reader_participant, d.reader_participant);
        prop_assert_eq!(datagram.writer, d.writer);
        prop_assert_eq!(datagram.token, d.token);
        prop_assert_eq!(datagram.readers.as_slice(), &d.parsed_readers()[..]);
        prop_assert_eq!(datagram.subs().collect::<Vec<_>>(), all_ok(subs));
        // The iterator stays done once it has run out.
        let mut iter = datagram.subs();
        for _ in iter.by_ref() {}
        prop_assert!(iter.next().is_none());
    }

    /// A `Feedback` datagram of several submessages goes through `encode_feedback` and back,
    /// with the layout `header | varint writer_participant | u64le token | { u8 sub_kind |
    /// postcard body }`.
    #[test]
    fn feedback_datagrams_round_trip(d in feedback_datagram()) {
        let bytes = d.encode();
        let subs = d.subs();
        let mut expected = feedback_preamble_of(&d);
        for sub in &subs {
            expected.extend(feedback_sub_bytes(sub));
        }
        prop_assert_eq!(&bytes, &expected);

        let datagram = FeedbackDatagram::parse(&bytes, d.domain).unwrap();
        prop_assert_eq!(
            (datagram.header.kind, datagram.header.domain, datagram.header.sender),
            (MessageKind::Feedback, d.domain, d.sender)
        );
        prop_assert_eq!(datagram.writer_participant, d.writer_participant);
        prop_assert_eq!(datagram.token, d.token);
        prop_assert_eq!(datagram.subs().collect::<Vec<_>>(), all_ok(subs));
    }

    /// `begin` discards everything before it: a reused writer builds the bytes a new one does.
    #[test]
    fn a_reused_writer_builds_what_a_new_one_builds(
        first in data_datagram(),
        second in data_datagram(),
        pushed in 0..8_usize,
    ) {
        let mut writer = DataWriter::new();
        first.begin(&mut writer);
        for sub in first.subs().iter().take(pushed) {
            prop_assert!(writer.push(sub, MAX_DATAGRAM));
        }
        second.begin(&mut writer);
        prop_assert!(writer.is_empty());
        for sub in &second.subs() {
            prop_assert!(writer.push(sub, MAX_DATAGRAM));
        }
        prop_assert_eq!(writer.len(), second.subs.len());
        prop_assert_eq!(writer.bytes(), &second.encode()[..]);
    }

    /// `push` accepts a submessage exactly when the datagram stays within the limit, and a
    /// refused push leaves the datagram as it was; what was accepted parses back.
    #[test]
    fn push_never_exceeds_its_limit(d in data_datagram(), limit in 0..2500_usize) {
        let mut writer = DataWriter::new();
        d.begin(&mut writer);
        let mut accepted = Vec::new();
        for sub in d.subs() {
            let before = writer.bytes().to_vec();
            let count = writer.len();
            let grown = before.len() + data_sub_bytes(&sub).len();
            let pushed = writer.push(&sub, limit);
            prop_assert_eq!(pushed, grown <= limit);
            if pushed {
                prop_assert_eq!(writer.bytes().len(), grown);
                prop_assert!(writer.bytes().starts_with(&before));
                prop_assert_eq!(writer.len(), count + 1);
                accepted.push(sub);
            } else {
                prop_assert_eq!(writer.bytes(), &before[..]);
                prop_assert_eq!(writer.len(), count);
            }
        }
        prop_assert_eq!(writer.is_empty(), accepted.is_empty());
        if !accepted.is_empty() {
            prop_assert!(writer.bytes().len() <= limit);
            prop_assert_eq!(data_items(writer.bytes(), d.domain), Ok(all_ok(accepted)));
        }
    }

    /// The published overheads bound what the encodings add, so a payload budgeted as
    /// `limit - prefix_overhead(readers) - SAMPLE_OVERHEAD` (or a chunk budgeted with
    /// `FRAGMENT_OVERHEAD`) always fits a fresh datagram.
    #[test]
    fn overheads_bound_every_encoding(
        d in data_datagram(),
        meta in sample_meta(),
        (total_len, frag_size, index) in any::<(u32, u32, u32)>(),
        limit in 0..3000_usize,
        big in any::<bool>(),
    ) {
        let limit = if big { MAX_DATAGRAM - limit } else { limit };
        let mut writer = DataWriter::new();
        d.begin(&mut writer);
        prop_assert!(writer.bytes().len() <= prefix_overhead(d.readers.len()));
        let prefix = prefix_overhead(d.readers.len());
        if let Some(room) = limit.checked_sub(prefix + SAMPLE_OVERHEAD) {
            let payload = vec![0x5a; room];
            let sample = DataSub::Sample(Sample { meta, payload: &payload });
            prop_assert!(data_sub_bytes(&sample).len() <= SAMPLE_OVERHEAD + room);
            prop_assert!(writer.push(&sample, limit));
        }
        d.begin(&mut writer);
        if let Some(room) = limit.checked_sub(prefix + FRAGMENT_OVERHEAD) {
            let chunk = vec![0xa5; room];
            let fragment = DataSub::Fragment(Fragment {
                meta,
                total_len,
                frag_size,
                index,
                chunk: &chunk,
            });
            prop_assert!(data_sub_bytes(&fragment).len() <= FRAGMENT_OVERHEAD + room);
            prop_assert!(writer.push(&fragment, limit));
        }
    }

    /// A datagram cut anywhere yields the submessages before the cut and nothing else.
    #[test]
    fn truncated_data_datagrams_yield_only_encoded_submessages(d in data_datagram()) {
        let (bytes, ends) = d.encode_with_ends();
        let start = data_preamble(&d).len();
        for cut in 0..=bytes.len() {
            check_cut(data_items(&bytes[..cut], d.domain), d.subs(), start, &ends, cut)?;
        }
    }

    #[test]
    fn truncated_feedback_datagrams_yield_only_encoded_submessages(d in feedback_datagram()) {
        let (bytes, ends) = d.encode_with_ends();
        let start = feedback_preamble_of(&d).len();
        for cut in 0..=bytes.len() {
            check_cut(feedback_items(&bytes[..cut], d.domain), d.subs(), start, &ends, cut)?;
        }
    }

    /// An unknown `sub_kind` ends the parse with `unknown_kind`; what came before stands and
    /// nothing after it is read.
    #[test]
    fn an_unknown_submessage_kind_ends_the_parse(
        data in data_datagram(),
        feedback in feedback_datagram(),
        data_kind in submessages::unknown_data_sub_kind(),
        feedback_kind in submessages::unknown_feedback_sub_kind(),
        tail in vec(any::<u8>(), 0..40),
    ) {
        let valid = data.encode();
        let bytes = [&valid[..], &[data_kind], &tail, &valid[data_preamble(&data).len()..]].concat();
        let mut expected = all_ok(data.subs());
        expected.push(Err(DropReason::UnknownKind));
        prop_assert_eq!(data_items(&bytes, data.domain), Ok(expected));

        let bytes = [feedback.encode(), vec![feedback_kind], tail].concat();
        let mut expected = all_ok(feedback.subs());
        expected.push(Err(DropReason::UnknownKind));
        prop_assert_eq!(feedback_items(&bytes, feedback.domain), Ok(expected));
    }

    /// A submessage of a known kind that does not decode ends the parse with `malformed`,
    /// even when valid submessages follow it.
    #[test]
    fn a_broken_submessage_ends_the_parse(
        data in data_datagram(),
        feedback in feedback_datagram(),
        data_kind in 1..=4_u8,
        feedback_kind in 1..=2_u8,
    ) {
        // Every submessage body starts with an integer; ten bytes with the high bit set are
        // longer than any u32 or u64 varint.
        let overlong = [0xff_u8; 10];
        let valid = data.encode();
        let following = &valid[data_preamble(&data).len()..];
        let bytes = [&valid[..], &[data_kind], &overlong, following].concat();
        let mut expected = all_ok(data.subs());
        expected.push(Err(DropReason::Malformed));
        prop_assert_eq!(data_items(&bytes, data.domain), Ok(expected));

        let valid = feedback.encode();
        let following = &valid[feedback_preamble_of(&feedback).len()..];
        let bytes = [&valid[..], &[feedback_kind], &overlong, following].concat();
        let mut expected = all_ok(feedback.subs());
        expected.push(Err(DropReason::Malformed));
        prop_assert_eq!(feedback_items(&bytes, feedback.domain), Ok(expected));
    }

    /// The header checks come first, with the reasons `Header::parse` gives; then the domain;
    /// then the kind: each parser takes its own kind only.
    #[test]
    fn damaged_headers_other_domains_and_other_kinds_are_dropped(
        data in data_datagram(),
        feedback in feedback_datagram(),
        at in 0..4_usize,
        value in any::<u8>(),
        other in any::<u16>(),
    ) {
        let parse_both = |bytes: &[u8], domain| {
            let data = DataDatagram::parse(bytes, domain).map(|_| ());
            let feedback = FeedbackDatagram::parse(bytes, domain).map(|_| ());
            (data.err(), feedback.err())
        };
        let unexpected = Some(DropReason::Unexpected);
        for (mut bytes, domain, reasons) in [
            (data.encode(), data.domain, (None, unexpected)),
            (feedback.encode(), feedback.domain, (unexpected, None)),
        ] {
            prop_assert_eq!(parse_both(&bytes, domain), reasons);
            if other != domain {
                let other_domain = Some(DropReason::OtherDomain);
                prop_assert_eq!(parse_both(&bytes, other), (other_domain, other_domain));
            }
            let original = bytes.clone();
            bytes[at] ^= value | 1;
            let foreign = Some(DropReason::ForeignMagic);
            prop_assert_eq!(parse_both(&bytes, domain), (foreign, foreign));
            bytes.copy_from_slice(&original);
            bytes[4] = PROTOCOL_VERSION.wrapping_add(value | 1);
            let version = Some(DropReason::UnsupportedVersion);
            prop_assert_eq!(parse_both(&bytes, domain), (version, version));
            bytes[4] = PROTOCOL_VERSION;
            bytes[5] = [0, 8, 15, 18, 255][usize::from(value) % 5];
            let unknown = Some(DropReason::UnknownKind);
            prop_assert_eq!(parse_both(&bytes, domain), (unknown, unknown));
        }
    }

    /// `wire::decode` never decodes a `Data` or `Feedback` body: it drops them as
    /// `unexpected` (after the domain check of `decode_for_domain`).
    #[test]
    fn discovery_decode_refuses_data_and_feedback(
        data in data_datagram(),
        feedback in feedback_datagram(),
        other in any::<u16>(),
    ) {
        for (bytes, domain) in [(data.encode(), data.domain), (feedback.encode(), feedback.domain)] {
            prop_assert_eq!(wire::decode(&bytes), Err(DropReason::Unexpected));
            prop_assert_eq!(wire::decode_for_domain(&bytes, domain), Err(DropReason::Unexpected));
            if other != domain {
                prop_assert_eq!(
                    wire::decode_for_domain(&bytes, other),
                    Err(DropReason::OtherDomain)
                );
            }
        }
    }

    /// Bit `i` is bit `i % 8` of byte `i / 8`; the bitmap grows only as far as its highest
    /// set bit, and never beyond `MAX_BITMAP_BYTES`.
    #[test]
    fn bitmaps_are_little_endian_bit_strings(indices in vec(0..600_usize, 0..40)) {
        let mut bitmap = Vec::new();
        for &i in &indices {
            let before = bitmap.clone();
            let set = set_bit(&mut bitmap, i);
            prop_assert_eq!(set, i < MAX_BITMAP_BYTES * 8);
            if !set {
                prop_assert_eq!(&bitmap, &before);
            }
        }
        let kept: Vec<usize> =
            indices.iter().copied().filter(|i| *i < MAX_BITMAP_BYTES * 8).collect();
        prop_assert_eq!(bitmap.len(), kept.iter().max().map_or(0, |i| i / 8 + 1));
        for i in 0..MAX_BITMAP_BYTES * 8 + 16 {
            prop_assert_eq!(bit(&bitmap, i), kept.contains(&i));
            let by_hand = bitmap.get(i / 8).is_some_and(|b| (b >> (i % 8)) & 1 == 1);
            prop_assert_eq!(bit(&bitmap, i), by_hand);
        }
    }
}

#[test]
fn every_submessage_kind_has_its_documented_wire_value() {
    let data = [
        DataSubKind::Sample,
        DataSubKind::Fragment,
        DataSubKind::Heartbeat,
        DataSubKind::Gap,
    ];
    assert_eq!(data.map(|k| k as u8), [1, 2, 3, 4]);
    let feedback = [FeedbackSubKind::AckNack, FeedbackSubKind::NackFrag];
    assert_eq!(feedback.map(|k| k as u8), [1, 2]);
}

const TO_TWO: Addressing<'static> = Addressing {
    reader_participant: 2,
    writer: 1,
    token: 0x5eed,
    readers: &[5, 3, 5],
};

const NO_READERS: Addressing<'static> = Addressing {
    reader_participant: 0,
    writer: 0,
    token: 0x5eed,
    readers: &[],
};

/// A datagram must carry a submessage: header and addressing alone are malformed.
#[test]
fn a_datagram_without_submessages_is_malformed() {
    let mut writer = DataWriter::new();
    writer.begin(3, 9, &TO_TWO);
    assert!(writer.is_empty());
    assert_eq!(writer.len(), 0);
    assert_eq!(
        DataDatagram::parse(writer.bytes(), 3).map(|_| ()),
        Err(DropReason::Malformed)
    );
    let feedback = feedback_preamble(3, 9, 2, 0);
    assert_eq!(
        FeedbackDatagram::parse(&feedback, 3).map(|_| ()),
        Err(DropReason::Malformed)
    );
    // One kind byte more and the datagram parses; its one submessage does not.
    let bytes = [writer.bytes(), &[DataSubKind::Gap as u8]].concat();
    assert_eq!(data_items(&bytes, 3), Ok(vec![Err(DropReason::Malformed)]));
    let bytes = [&feedback[..], &[FeedbackSubKind::AckNack as u8]].concat();
    assert_eq!(
        feedback_items(&bytes, 3),
        Ok(vec![Err(DropReason::Malformed)])
    );
}

/// The parser reports the readers sorted and each once, whatever order the sender used.
#[test]
fn readers_are_reported_sorted_and_once() {
    let mut writer = DataWriter::new();
    writer.begin(0, 1, &TO_TWO);
    assert!(writer.push(&DataSub::Gap(Gap { from: 1, to: 2 }), MAX_DATAGRAM));
    let datagram = DataDatagram::parse(writer.bytes(), 0).unwrap();
    assert_eq!(datagram.readers.as_slice(), &[3, 5]);
    // On the wire they stay as written (after the one-byte participant and writer and the
    // 8-byte token).
    let written = postcard::to_allocvec(&TO_TWO.readers).unwrap();
    assert_eq!(
        &writer.bytes()[HEADER_LEN + 10..HEADER_LEN + 10 + written.len()],
        &written[..]
    );
}

/// `MAX_READERS` readers parse; one more is malformed.
#[test]
fn more_than_max_readers_is_malformed() {
    let readers: Vec<u32> = (0..MAX_READERS as u32 + 1).collect();
    let gap = DataSub::Gap(Gap { from: 1, to: 2 });
    let bytes = |readers: &[u32]| {
        let mut out = header(MessageKind::Data, 0, 1);
        out.extend(postcard::to_allocvec(&(7_u64, 1_u32, [0xAB_u8; 8], readers)).unwrap());
        out.extend(data_sub_bytes(&gap));
        out
    };
    let max = bytes(&readers[..MAX_READERS]);
    let datagram = DataDatagram::parse(&max, 0).unwrap();
    assert_eq!(datagram.readers.len(), MAX_READERS);
    assert_eq!(data_items(&max, 0), Ok(vec![Ok(gap.clone())]));
    assert_eq!(
        DataDatagram::parse(&bytes(&readers), 0).map(|_| ()),
        Err(DropReason::Malformed)
    );
}

/// Whatever `DataWriter` builds, `DataDatagram::parse` must accept.
#[test]
fn the_writer_refuses_more_than_max_readers() {
    let readers: Vec<u32> = (0..MAX_READERS as u32 + 1).collect();
    let to = Addressing {
        reader_participant: 7,
        writer: 1,
        token: 0x5eed,
        readers: &readers,
    };
    let mut writer = DataWriter::new();
    writer.begin(0, 1, &to);
    let pushed = writer.push(&DataSub::Gap(Gap { from: 1, to: 2 }), MAX_DATAGRAM);
    assert!(
        !pushed || DataDatagram::parse(writer.bytes(), 0).is_ok(),
        "DataWriter built a datagram of {} readers that the parser refuses",
        readers.len()
    );
}

/// `MIN_DATA_LEN` is documented as the smallest possible `Data` datagram.
#[test]
fn min_data_len_is_the_smallest_datagram_the_parser_accepts() {
    let mut writer = DataWriter::new();
    writer.begin(0, 1, &NO_READERS);
    let smallest = [writer.bytes(), &[DataSubKind::Gap as u8]].concat();
    assert!(DataDatagram::parse(&smallest, 0).is_ok());
    assert!(DataDatagram::parse(&smallest[..smallest.len() - 1], 0).is_err());
    assert_eq!(smallest.len(), MIN_DATA_LEN);
}

/// Whatever `encode_feedback` accepts, `FeedbackDatagram::parse` must accept.
#[test]
fn feedback_without_submessages_is_refused_by_the_encoder() {
    let mut out = Vec::new();
    let encoded = encode_feedback(0, 1, 2, 0, &[], &mut out);
    assert!(
        encoded.is_err() || FeedbackDatagram::parse(&out, 0).is_ok(),
        "encode_feedback wrote {out:02x?} and returned {encoded:?}, but the parser says {:?}",
        FeedbackDatagram::parse(&out, 0).map(|_| ())
    );
}

fn ack(missing: &[u8]) -> FeedbackSub<'_> {
    FeedbackSub::AckNack(AckNack {
        reader: 1,
        writer: 2,
        acked: 3,
        missing,
    })
}

fn nack(missing: &[u8]) -> FeedbackSub<'_> {
    FeedbackSub::NackFrag(NackFrag {
        reader: 1,
        writer: 2,
        seq: 3,
        base: 4,
        missing,
    })
}

#[test]
fn bitmaps_longer_than_the_limit_are_rejected() {
    let longest = vec![0xa5; MAX_BITMAP_BYTES];
    let too_long = vec![0xa5; MAX_BITMAP_BYTES + 1];
    let mut out = Vec::new();
    for make in [ack, nack] {
        // The longest bitmap is accepted both ways.
        encode_feedback(5, 6, 7, 0, &[make(&longest)], &mut out).unwrap();
        assert_eq!(feedback_items(&out, 5), Ok(vec![Ok(make(&longest))]));
        // One byte more is refused by the encoder, in any position.
        for subs in [vec![make(&too_long)], vec![make(&longest), make(&too_long)]] {
            assert_eq!(
                encode_feedback(5, 6, 7, 0, &subs, &mut out),
                Err(DropReason::Invalid)
            );
        }
        // And by the parser: the submessage is `invalid` and ends the parse.
        let bytes = [
            feedback_preamble(5, 6, 7, 0),
            feedback_sub_bytes(&make(&longest)),
            feedback_sub_bytes(&make(&too_long)),
            feedback_sub_bytes(&make(&longest)),
        ]
        .concat();
        assert_eq!(
            feedback_items(&bytes, 5),
            Ok(vec![Ok(make(&longest)), Err(DropReason::Invalid)])
        );
    }
}

/// The largest `Data` datagram is exactly `MAX_DATAGRAM` bytes, whatever limit `push` is
/// given; one byte more is refused and leaves the datagram unchanged.
#[test]
fn push_never_builds_a_datagram_larger_than_the_maximum() {
    let meta = SampleMeta {
        seq: 1,
        ..SampleMeta::default()
    };
    let heartbeat = DataSub::Heartbeat(Heartbeat { first: 1, last: 4 });
    let mut writer = DataWriter::new();
    writer.begin(3, 9, &TO_TWO);
    assert!(writer.push(&heartbeat, usize::MAX));
    let before = writer.bytes().to_vec();
    let empty = data_sub_bytes(&DataSub::Sample(Sample { meta, payload: &[] })).len();
    // The payload length prefix grows from 1 to 3 bytes.
    let fits = vec![0xa5; MAX_DATAGRAM - before.len() - empty - 2];
    let too_big = vec![0xa5; fits.len() + 1];
    for limit in [MAX_DATAGRAM, MAX_DATAGRAM + 1, usize::MAX] {
        let big = DataSub::Sample(Sample {
            meta,
            payload: &too_big,
        });
        assert!(!writer.push(&big, limit));
        assert_eq!(writer.bytes(), &before[..]);
        assert_eq!(writer.len(), 1);
    }
    let largest = DataSub::Sample(Sample {
        meta,
        payload: &fits,
    });
    assert!(writer.push(&largest, usize::MAX));
    assert_eq!(writer.bytes().len(), MAX_DATAGRAM);
    assert_eq!(
        data_items(writer.bytes(), 3),
        Ok(vec![Ok(heartbeat), Ok(largest)])
    );
}

#[test]
fn feedback_larger_than_a_datagram_is_refused() {
    let missing = vec![0xff; MAX_BITMAP_BYTES];
    let ack = FeedbackSub::AckNack(AckNack {
        reader: u32::MAX,
        writer: u32::MAX,
        acked: u64::MAX,
        missing: &missing,
    });
    let one = feedback_sub_bytes(&ack).len();
    let fits = (MAX_DATAGRAM - feedback_preamble(0, 1, 2, 0).len()) / one;
    let mut out = Vec::new();
    encode_feedback(0, 1, 2, 0, &vec![ack.clone(); fits], &mut out).unwrap();
    assert!(out.len() <= MAX_DATAGRAM);
    assert_eq!(
        encode_feedback(0, 1, 2, 0, &vec![ack; fits + 1], &mut out),
        Err(DropReason::Invalid)
    );
}
