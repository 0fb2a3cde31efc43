//! Every wire message round-trips through `wire::encode` / `wire::decode`, and every way of
//! damaging a valid datagram (wrong domain, magic, version or kind, truncation, a trailing byte)
//! is dropped with the documented reason.

#[path = "support/messages.rs"]
mod messages;

use ndds_core::types::{Format, TypeDescription, TypeLayout};
use ndds_core::wire::{
    self, Data, DropReason, EncodeError, HEADER_LEN, MAGIC, MAX_DATAGRAM, Message, MessageKind,
    PROTOCOL_VERSION,
};
use proptest::prelude::*;

use messages::{Datagram, datagram, sample_descriptions};

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn every_message_round_trips(d in datagram()) {
        let bytes = d.encode();
        let (header, decoded) = wire::decode(&bytes).unwrap();
        let original = d.message.as_message();
        prop_assert_eq!(header.kind, original.kind());
        prop_assert_eq!(header.domain, d.domain);
        prop_assert_eq!(header.sender, d.sender);
        prop_assert_eq!(&decoded, &original);
        // The fixed header layout of wire/header.rs.
        prop_assert_eq!(&bytes[..4], &MAGIC[..]);
        prop_assert_eq!(bytes[4], PROTOCOL_VERSION);
        prop_assert_eq!(bytes[5], original.kind() as u8);
        prop_assert_eq!(&bytes[6..8], &d.domain.to_le_bytes()[..]);
        prop_assert_eq!(&bytes[8..16], &d.sender.to_le_bytes()[..]);
        // Decoded descriptions still carry their fingerprint and still validate.
        if let Message::Announce(announce) = &decoded {
            for endpoint in &announce.endpoints {
                prop_assert_eq!(endpoint.type_desc.fingerprint(), endpoint.fingerprint);
                prop_assert!(endpoint.type_desc.validate().is_ok());
            }
        }
        prop_assert_eq!(wire::decode_for_domain(&bytes, d.domain), Ok((header, decoded)));
    }

    #[test]
    fn other_domains_are_dropped(d in datagram(), other in any::<u16>()) {
        prop_assume!(other != d.domain);
        let bytes = d.encode();
        prop_assert_eq!(wire::decode_for_domain(&bytes, other), Err(DropReason::OtherDomain));
        prop_assert!(wire::decode(&bytes).is_ok());
    }

    #[test]
    fn bad_magic_is_foreign(d in datagram(), at in 0..4usize, value in any::<u8>()) {
        let mut bytes = d.encode();
        prop_assume!(bytes[at] != value);
        bytes[at] = value;
        prop_assert_eq!(wire::decode(&bytes), Err(DropReason::ForeignMagic));
        prop_assert_eq!(
            wire::decode_for_domain(&bytes, d.domain),
            Err(DropReason::ForeignMagic)
        );
    }

    #[test]
    fn other_versions_are_unsupported(d in datagram(), version in any::<u8>()) {
        prop_assume!(version != PROTOCOL_VERSION);
        let mut bytes = d.encode();
        bytes[4] = version;
        prop_assert_eq!(wire::decode(&bytes), Err(DropReason::UnsupportedVersion));
        prop_assert_eq!(
            wire::decode_for_domain(&bytes, d.domain),
            Err(DropReason::UnsupportedVersion)
        );
    }

    #[test]
    fn unknown_kinds_are_dropped(d in datagram(), kind in any::<u8>()) {
        prop_assume!(MessageKind::from_u8(kind).is_none());
        let mut bytes = d.encode();
        bytes[5] = kind;
        prop_assert_eq!(wire::decode(&bytes), Err(DropReason::UnknownKind));
        prop_assert_eq!(
            wire::decode_for_domain(&bytes, d.domain),
            Err(DropReason::UnknownKind)
        );
    }

    /// A body read as another known kind is either malformed or a message of that kind.
    #[test]
    fn body_under_another_known_kind_is_never_misreported(
        d in datagram(),
        kind in messages::kind(),
    ) {
        let mut bytes = d.encode();
        bytes[5] = kind as u8;
        match wire::decode(&bytes) {
            Ok((header, message)) => {
                prop_assert_eq!(header.kind, kind);
                prop_assert_eq!(message.kind(), kind);
            }
            Err(reason) => prop_assert_eq!(reason, DropReason::Malformed),
        }
    }

    /// postcard is prefix-free for a fixed type, so a cut datagram can never decode: the
    /// header part is `Truncated`, the body part `Malformed`, only the whole datagram decodes.
    #[test]
    fn truncation_never_yields_a_message(d in datagram()) {
        let bytes = d.encode();
        for cut in 0..bytes.len() {
            let expected = if cut < HEADER_LEN {
                DropReason::Truncated
            } else {
                DropReason::Malformed
            };
            prop_assert_eq!(wire::decode(&bytes[..cut]), Err(expected), "cut at {}", cut);
            prop_assert_eq!(
                wire::decode_for_domain(&bytes[..cut], d.domain),
                Err(expected),
                "cut at {}",
                cut
            );
        }
        prop_assert!(wire::decode(&bytes).is_ok());
    }

    #[test]
    fn a_trailing_byte_is_malformed(d in datagram(), extra in any::<u8>()) {
        let mut bytes = d.encode();
        bytes.push(extra);
        prop_assert_eq!(wire::decode(&bytes), Err(DropReason::Malformed));
        prop_assert_eq!(wire::decode_for_domain(&bytes, d.domain), Err(DropReason::Malformed));
    }

    /// The canonical text (and so the fingerprint) does not depend on how the arena is
    /// numbered: the same layout with unused nodes inserted in front and every index shifted
    /// has the same fingerprint.
    #[test]
    fn fingerprint_ignores_arena_numbering(which in 0..8usize, padding in 1..5u32) {
        let original = &sample_descriptions()[which];
        let layout = original.layout.as_ref().expect("traced types have a layout");
        let shifted = shift_layout(layout, padding);
        shifted.validate().unwrap();
        let renumbered = TypeDescription { name: original.name.clone(), layout: Some(shifted) };
        prop_assert_eq!(renumbered.canonical_text(), original.canonical_text());
        prop_assert_eq!(renumbered.fingerprint(), original.fingerprint());
    }
}

/// `layout` with `padding` unreferenced `Unit` nodes before its own formats.
fn shift_layout(layout: &TypeLayout, padding: u32) -> TypeLayout {
    let shift = |i: &u32| i + padding;
    let mut formats = vec![Format::Unit; padding as usize];
    formats.extend(layout.formats.iter().map(|f| match f {
        Format::Option(c) => Format::Option(shift(c)),
        Format::Seq(c) => Format::Seq(shift(c)),
        Format::Map { key, value } => Format::Map {
            key: shift(key),
            value: shift(value),
        },
        Format::Tuple(items) => Format::Tuple(items.iter().map(shift).collect()),
        Format::Array { item, len } => Format::Array {
            item: shift(item),
            len: *len,
        },
        other => other.clone(),
    }));
    // Container shapes refer to formats too.
    let mut containers = layout.containers.clone();
    for container in &mut containers {
        container.shape = shift_shape(&container.shape, padding);
    }
    TypeLayout {
        formats,
        root: shift(&layout.root),
        containers,
    }
}

fn shift_shape(
    shape: &ndds_core::types::ContainerShape,
    padding: u32,
) -> ndds_core::types::ContainerShape {
    use ndds_core::types::{ContainerShape as C, Field, VariantShape as V};
    let fields = |fields: &[Field]| -> Vec<Field> {
        fields
            .iter()
            .map(|f| Field {
                name: f.name.clone(),
                format: f.format + padding,
            })
            .collect()
    };
    let list = |items: &[u32]| -> Vec<u32> { items.iter().map(|i| i + padding).collect() };
    match shape {
        C::UnitStruct => C::UnitStruct,
        C::NewType(f) => C::NewType(f + padding),
        C::TupleStruct(items) => C::TupleStruct(list(items)),
        C::Struct(fs) => C::Struct(fields(fs)),
        C::Enum(variants) => C::Enum(
            variants
                .iter()
                .map(|v| {
                    let mut v = v.clone();
                    v.shape = match &v.shape {
                        V::Unit => V::Unit,
                        V::NewType(f) => V::NewType(f + padding),
                        V::Tuple(items) => V::Tuple(list(items)),
                        V::Struct(fs) => V::Struct(fields(fs)),
                    };
                    v
                })
                .collect(),
        ),
    }
}

#[test]
fn sample_descriptions_are_distinct_and_valid() {
    let descriptions = sample_descriptions();
    for (i, a) in descriptions.iter().enumerate() {
        a.validate().unwrap();
        for b in &descriptions[i + 1..] {
            assert_ne!(a.fingerprint(), b.fingerprint(), "{} vs {}", a.name, b.name);
        }
    }
}

#[test]
fn every_kind_has_its_documented_wire_value() {
    let values: Vec<u8> = MessageKind::ALL.iter().map(|k| *k as u8).collect();
    assert_eq!(values, [1, 2, 3, 4, 16]);
    for kind in MessageKind::ALL {
        assert_eq!(MessageKind::from_u8(kind as u8), Some(kind));
    }
}

#[test]
fn a_bye_is_exactly_a_header() {
    let d = Datagram {
        domain: 7,
        sender: 42,
        message: messages::OwnedMessage::Bye,
    };
    let bytes = d.encode();
    assert_eq!(bytes.len(), HEADER_LEN);
    let (header, message) = wire::decode(&bytes).unwrap();
    assert_eq!(
        (header.kind, header.domain, header.sender),
        (MessageKind::Bye, 7, 42)
    );
    assert_eq!(message, Message::Bye(wire::Bye));
}

#[test]
fn oversized_datagram_is_refused_and_output_untouched() {
    let fixed = data_datagram(&[]).len();
    // The largest payload that fits: the payload length prefix is a 3-byte varint here.
    let fits = vec![0xA5; MAX_DATAGRAM - fixed - 2];
    let bytes = data_datagram(&fits);
    assert_eq!(bytes.len(), MAX_DATAGRAM);
    match wire::decode(&bytes) {
        Ok((_, Message::Data(data))) => assert_eq!(data.payload, &fits[..]),
        other => panic!("largest datagram did not decode: {other:?}"),
    }

    let too_big = vec![0xA5; fits.len() + 1];
    let mut out = b"kept".to_vec();
    let err = wire::encode(3, 9, &Message::Data(data_with(&too_big)), &mut out).unwrap_err();
    assert!(
        matches!(err, EncodeError::TooLarge { size } if size == MAX_DATAGRAM + 1),
        "{err:?}"
    );
    assert_eq!(out, b"kept");
}

fn data_with(payload: &[u8]) -> Data<'_> {
    Data {
        writer: 1,
        reader_participant: 2,
        readers: vec![3].into(),
        seq: 4,
        timestamp_ns: 5,
        strength: -6,
        persistence_us: 7,
        payload,
    }
}

fn data_datagram(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    wire::encode(3, 9, &Message::Data(data_with(payload)), &mut out).unwrap();
    out
}
