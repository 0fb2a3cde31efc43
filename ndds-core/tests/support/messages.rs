//! proptest strategies for every wire message, shared by the wire test binaries.
//!
//! These are the discovery messages, whole datagrams for `wire::encode` / `wire::decode`; the
//! `Data` and `Feedback` submessages are in `submessages.rs`. Endpoints carry real type
//! descriptions (traced from a handful of Rust types with `TypeDescription::try_of`, or opaque
//! names) and the fingerprint that goes with them, so a generated `Announce` is one a real
//! daemon could have sent.

// Each test binary that includes this module uses a different subset of it.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::sync::OnceLock;

use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    Announce, Bye, ConsumerMode, ConsumerQosWire, EndpointInfo, EndpointQos, Guid, Locator,
    Message, MessageKind, NodeInfo, ProducerQosWire, Reliability, Solicit, Withdraw,
};
use proptest::collection::vec;
use proptest::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Serialize, Deserialize)]
struct Pose {
    x: f64,
    y: f64,
    label: Option<String>,
}

#[derive(Serialize, Deserialize)]
enum Mode {
    Idle,
    Move { speed: f32 },
    Hold(u8, u8),
}

#[derive(Serialize, Deserialize)]
struct Tree {
    value: i32,
    children: Vec<Tree>,
    table: BTreeMap<String, [u16; 3]>,
    mode: Mode,
}

#[derive(Serialize, Deserialize)]
struct Meters(f64);

#[derive(Serialize, Deserialize)]
struct Marker;

/// Descriptions of a few traced types and two opaque ones; all different.
pub fn sample_descriptions() -> &'static [TypeDescription] {
    static DESCRIPTIONS: OnceLock<Vec<TypeDescription>> = OnceLock::new();
    DESCRIPTIONS.get_or_init(|| {
        vec![
            TypeDescription::try_of::<f64>().unwrap(),
            TypeDescription::try_of::<Pose>().unwrap(),
            TypeDescription::try_of::<Mode>().unwrap(),
            TypeDescription::try_of::<Tree>().unwrap(),
            TypeDescription::try_of::<(u8, String, Vec<i64>)>().unwrap(),
            TypeDescription::try_of::<BTreeMap<String, [u16; 3]>>().unwrap(),
            TypeDescription::try_of::<Meters>().unwrap(),
            TypeDescription::try_of::<Marker>().unwrap(),
            TypeDescription::opaque("vendor::Blob"),
            TypeDescription::opaque("vendor::Ünïcode \"quoted\""),
        ]
    })
}

/// A discovery message, as strategies generate it.
#[derive(Clone, Debug)]
pub enum OwnedMessage {
    Solicit(Solicit),
    Announce(Announce),
    Withdraw(Withdraw),
    Bye,
}

impl OwnedMessage {
    /// The wire message.
    pub fn as_message(&self) -> Message {
        match self {
            OwnedMessage::Solicit(m) => Message::Solicit(m.clone()),
            OwnedMessage::Announce(m) => Message::Announce(m.clone()),
            OwnedMessage::Withdraw(m) => Message::Withdraw(m.clone()),
            OwnedMessage::Bye => Message::Bye(Bye),
        }
    }
}

/// A complete datagram: header fields plus a message.
#[derive(Clone, Debug)]
pub struct Datagram {
    pub domain: u16,
    pub sender: u64,
    pub message: OwnedMessage,
}

impl Datagram {
    /// The encoded bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::new();
        ndds_core::wire::encode(
            self.domain,
            self.sender,
            &self.message.as_message(),
            &mut out,
        )
        .expect("generated messages fit in a datagram");
        out
    }
}

pub fn guid() -> impl Strategy<Value = Guid> {
    (any::<u64>(), any::<u32>()).prop_map(|(participant, entity)| Guid {
        participant,
        entity,
    })
}

pub fn locator() -> impl Strategy<Value = Locator> {
    (any::<[u8; 4]>(), any::<u16>()).prop_map(|(addr, port)| Locator { addr, port })
}

/// Any string, including multi-byte characters and quotes.
fn text() -> impl Strategy<Value = String> {
    ".{0,24}"
}

pub fn node_info() -> impl Strategy<Value = NodeInfo> {
    (
        text(),
        any::<u32>(),
        locator(),
        any::<u32>(),
        any::<u32>(),
        text(),
    )
        .prop_map(
            |(hostname, pid, unicast, lease_ms, announce_period_ms, version)| NodeInfo {
                hostname,
                pid,
                unicast,
                lease_ms,
                announce_period_ms,
                version,
            },
        )
}

fn reliability() -> impl Strategy<Value = Reliability> {
    prop_oneof![
        Just(Reliability::BestEffort),
        any::<u32>().prop_map(|depth| Reliability::Reliable { depth }),
    ]
}

fn mode() -> impl Strategy<Value = ConsumerMode> {
    prop_oneof![Just(ConsumerMode::Immediate), Just(ConsumerMode::Polled)]
}

pub fn qos() -> impl Strategy<Value = EndpointQos> {
    prop_oneof![
        (any::<i32>(), any::<u64>(), reliability()).prop_map(
            |(strength, persistence_us, reliability)| {
                EndpointQos::Producer(ProducerQosWire {
                    strength,
                    persistence_us,
                    reliability,
                })
            }
        ),
        (any::<u64>(), any::<u64>(), mode(), reliability()).prop_map(
            |(min_separation_us, deadline_us, mode, reliability)| {
                EndpointQos::Consumer(ConsumerQosWire {
                    min_separation_us,
                    deadline_us,
                    mode,
                    reliability,
                })
            }
        ),
    ]
}

/// A traced or opaque description (opaque ones with arbitrary names).
pub fn type_description() -> impl Strategy<Value = TypeDescription> {
    prop_oneof![
        4 => (0..sample_descriptions().len()).prop_map(|i| sample_descriptions()[i].clone()),
        1 => text().prop_map(|name| TypeDescription::opaque(&name)),
    ]
}

/// An endpoint whose fingerprint is the fingerprint of its description.
pub fn endpoint() -> impl Strategy<Value = EndpointInfo> {
    (
        guid(),
        "[a-z][a-z0-9/_]{0,30}",
        type_description(),
        qos(),
        locator(),
        any::<u32>(),
        text(),
    )
        .prop_map(
            |(guid, topic, type_desc, qos, locator, pid, process)| EndpointInfo {
                guid,
                topic,
                fingerprint: type_desc.fingerprint(),
                type_desc,
                qos,
                locator,
                pid,
                process,
            },
        )
}

pub fn message() -> impl Strategy<Value = OwnedMessage> {
    prop_oneof![
        node_info().prop_map(|node| OwnedMessage::Solicit(Solicit { node })),
        (node_info(), vec(endpoint(), 0..4), vec(guid(), 0..8)).prop_map(
            |(node, endpoints, withdrawn)| OwnedMessage::Announce(Announce {
                node,
                endpoints,
                withdrawn,
            })
        ),
        vec(guid(), 0..32).prop_map(|endpoints| OwnedMessage::Withdraw(Withdraw { endpoints })),
        Just(OwnedMessage::Bye),
    ]
}

pub fn datagram() -> impl Strategy<Value = Datagram> {
    (any::<u16>(), any::<u64>(), message()).prop_map(|(domain, sender, message)| Datagram {
        domain,
        sender,
        message,
    })
}

/// Any of the kinds this version knows.
pub fn kind() -> impl Strategy<Value = MessageKind> {
    (0..MessageKind::ALL.len()).prop_map(|i| MessageKind::ALL[i])
}

/// The kinds `wire::decode` decodes (everything but `Data` and `Feedback`).
pub const DISCOVERY_KINDS: [MessageKind; 4] = [
    MessageKind::Solicit,
    MessageKind::Announce,
    MessageKind::Withdraw,
    MessageKind::Bye,
];

/// Any discovery kind.
pub fn discovery_kind() -> impl Strategy<Value = MessageKind> {
    (0..DISCOVERY_KINDS.len()).prop_map(|i| DISCOVERY_KINDS[i])
}
