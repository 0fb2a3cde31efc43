//! Every wire message round-trips, and every way of damaging a valid datagram is dropped with
//! the documented reason.
//!
//! Discovery messages go through `wire::encode` / `wire::decode` here (wrong domain, magic,
//! version or kind, truncation, a trailing byte); `Data` and `Feedback` datagrams, sequences of
//! submessages, in `wire_data/roundtrip.rs`.

#[path = "support/messages.rs"]
mod messages;
#[path = "support/submessages.rs"]
mod submessages;
#[path = "wire_data/roundtrip.rs"]
mod wire_data;

use ndds_core::types::{Format, TypeDescription, TypeLayout};
use ndds_core::wire::{
    self, DataDatagram, DropReason, EncodeError, FeedbackDatagram, HEADER_LEN, MAGIC, MAX_DATAGRAM,
    Message, MessageKind, NodeInfo, PROTOCOL_VERSION, Solicit,
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

    /// A body read as another discovery kind is either malformed or a message of that kind.
    #[test]
    fn body_under_another_known_kind_is_never_misreported(
        d in datagram(),
        kind in messages::discovery_kind(),
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

    /// A discovery body under the `Data` or `Feedback` kind is not decoded at all by
    /// `wire::decode`, and its own kind is not decoded by the data-plane parsers.
    #[test]
    fn discovery_and_data_planes_refuse_each_others_kinds(d in datagram()) {
        let mut bytes = d.encode();
        prop_assert_eq!(
            DataDatagram::parse(&bytes, d.domain).map(|_| ()),
            Err(DropReason::Unexpected)
        );
        prop_assert_eq!(
            FeedbackDatagram::parse(&bytes, d.domain).map(|_| ()),
            Err(DropReason::Unexpected)
        );
        for kind in [MessageKind::Data, MessageKind::Feedback] {
            bytes[5] = kind as u8;
            prop_assert_eq!(wire::decode(&bytes), Err(DropReason::Unexpected));
            prop_assert_eq!(
                wire::decode_for_domain(&bytes, d.domain),
                Err(DropReason::Unexpected)
            );
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
    assert_eq!(values, [1, 2, 3, 4, 5, 6, 7, 16, 17]);
    for kind in MessageKind::ALL {
        assert_eq!(MessageKind::from_u8(kind as u8), Some(kind));
    }
    assert_eq!(MessageKind::Feedback.name(), "Feedback");
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

fn solicit_with_hostname(hostname: String) -> Message {
    Message::Solicit(Solicit {
        node: NodeInfo {
            hostname,
            pid: 1,
            unicast: wire::Locator {
                addr: [10, 0, 0, 1],
                port: 7850,
            },
            lease_ms: 5000,
            announce_period_ms: 1000,
            version: String::new(),
        },
    })
}

#[test]
fn oversized_datagram_is_refused_and_output_untouched() {
    let mut out = Vec::new();
    wire::encode(3, 9, &solicit_with_hostname(String::new()), &mut out).unwrap();
    let fixed = out.len();
    // The longest host name that fits: its length prefix is a 3-byte varint here.
    let fits = "h".repeat(MAX_DATAGRAM - fixed - 2);
    out.clear();
    wire::encode(3, 9, &solicit_with_hostname(fits.clone()), &mut out).unwrap();
    assert_eq!(out.len(), MAX_DATAGRAM);
    match wire::decode(&out) {
        Ok((_, Message::Solicit(solicit))) => assert_eq!(solicit.node.hostname, fits),
        other => panic!("largest datagram did not decode: {other:?}"),
    }

    let mut out = b"kept".to_vec();
    let err = wire::encode(3, 9, &solicit_with_hostname(fits + "h"), &mut out).unwrap_err();
    assert!(
        matches!(err, EncodeError::TooLarge { size } if size == MAX_DATAGRAM + 1),
        "{err:?}"
    );
    assert_eq!(out, b"kept");
}
