//! Fixtures shared by the SimNet test binaries: sample types, endpoints of simulated clients,
//! and queries over the events a node emitted.

// Each test binary that includes this module uses a different subset of it.
#![allow(dead_code)]

use std::collections::BTreeSet;
use std::time::Duration;

use ndds_core::discovery::{Event, LossReason};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{ConsumerQosWire, EndpointInfo, EndpointQos, Guid, ProducerQosWire};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::simnet::{SimNet, locator};

// ----- sample types and endpoints ----------------------------------------------------------

#[derive(Serialize, Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
}

/// Same topic as `Pose` in the tests, different structure: incompatible.
#[derive(Serialize, Deserialize)]
pub struct PoseV2 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

#[derive(Serialize, Deserialize)]
pub struct Scan {
    pub ranges: Vec<f32>,
}

/// Endpoint `entity` of the client on node `node`.
pub fn guid(node: usize, entity: u32) -> Guid {
    Guid {
        participant: 0xC0DE_0000 + node as u64,
        entity,
    }
}

pub fn endpoint<T: Serialize + DeserializeOwned>(
    guid: Guid,
    topic: &str,
    qos: EndpointQos,
) -> EndpointInfo {
    let type_desc = TypeDescription::try_of::<T>().unwrap();
    EndpointInfo {
        guid,
        topic: topic.to_owned(),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos,
        // On the host of the node the guid belongs to (a node announces only its own host's
        // endpoints).
        locator: locator(
            usize::try_from(guid.participant.wrapping_sub(0xC0DE_0000))
                .ok()
                .filter(|n| *n < 200)
                .unwrap_or(200),
        ),
        pid: 4242,
        process: "simnet".to_owned(),
    }
}

pub fn producer<T: Serialize + DeserializeOwned>(guid: Guid, topic: &str) -> EndpointInfo {
    endpoint::<T>(
        guid,
        topic,
        EndpointQos::Producer(ProducerQosWire::default()),
    )
}

pub fn consumer<T: Serialize + DeserializeOwned>(guid: Guid, topic: &str) -> EndpointInfo {
    endpoint::<T>(
        guid,
        topic,
        EndpointQos::Consumer(ConsumerQosWire::default()),
    )
}

// ----- event queries -----------------------------------------------------------------------

/// When node `n` first emitted an event satisfying `pred` at or after `since`.
pub fn first(
    net: &SimNet,
    n: usize,
    since: Duration,
    pred: impl Fn(&Event) -> bool,
) -> Option<Duration> {
    net.events_since(n, since)
        .find(|(_, e)| pred(e))
        .map(|(at, _)| *at)
}

pub fn count(net: &SimNet, n: usize, since: Duration, pred: impl Fn(&Event) -> bool) -> usize {
    net.events_since(n, since).filter(|(_, e)| pred(e)).count()
}

pub fn matched(local: Guid, other: Guid) -> impl Fn(&Event) -> bool {
    move |e| matches!(e, Event::Matched { local: l, remote } if *l == local && remote.guid == other)
}

pub fn incompatible(local: Guid, other: Guid) -> impl Fn(&Event) -> bool {
    move |e| matches!(e, Event::Incompatible { local: l, remote } if *l == local && remote.guid == other)
}

pub fn unmatched(local: Guid, other: Guid) -> impl Fn(&Event) -> bool {
    move |e| matches!(e, Event::Unmatched { local: l, remote } if *l == local && *remote == other)
}

pub fn lost(node: u64, reason: LossReason) -> impl Fn(&Event) -> bool {
    move |e| matches!(e, Event::NodeLost { node: id, reason: r } if *id == node && *r == reason)
}

pub fn any_unmatched(e: &Event) -> bool {
    matches!(e, Event::Unmatched { .. })
}

/// The (local, other) pairs node `n` currently considers matched, replaying its events.
pub fn match_set(net: &SimNet, n: usize) -> BTreeSet<(Guid, Guid)> {
    let mut pairs = BTreeSet::new();
    for (_, event) in net.events_since(n, Duration::ZERO) {
        match event {
            Event::Matched { local, remote } => {
                pairs.insert((*local, remote.guid));
            }
            Event::Unmatched { local, remote } => {
                pairs.remove(&(*local, *remote));
            }
            _ => {}
        }
    }
    pairs
}

/// Every event of node `n` since `since`, as (local, other) pairs of matches only; fails on
/// any other kind of match event.
pub fn matches_since(net: &SimNet, n: usize, since: Duration) -> BTreeSet<(Guid, Guid)> {
    let mut pairs = BTreeSet::new();
    for (_, event) in net.events_since(n, since) {
        match event {
            Event::Matched { local, remote } => assert!(pairs.insert((*local, remote.guid))),
            Event::Incompatible { .. } | Event::Unmatched { .. } => {
                panic!("node {n}: unexpected {event:?}")
            }
            _ => {}
        }
    }
    pairs
}

// ----- whole-network scenarios ------------------------------------------------------------

/// Every node declares a producer and a consumer of one topic.
pub fn shared_topic(net: &mut SimNet, nodes: usize) {
    for n in 0..nodes {
        net.add_local(n, producer::<Pose>(guid(n, 1), "shared"));
        net.add_local(n, consumer::<Pose>(guid(n, 2), "shared"));
    }
}

/// The matches node `n` has when it sees the endpoints of `peers` (itself included).
pub fn full_match_set(n: usize, peers: &[usize]) -> BTreeSet<(Guid, Guid)> {
    let mut pairs = BTreeSet::new();
    for &m in peers {
        pairs.insert((guid(n, 1), guid(m, 2)));
        pairs.insert((guid(n, 2), guid(m, 1)));
    }
    pairs
}

pub fn sees_all(net: &SimNet, n: usize, peers: &[usize]) -> bool {
    peers
        .iter()
        .all(|&m| net.knows(n, guid(m, 1)) && net.knows(n, guid(m, 2)))
        && net.engine(n).endpoints().count() == 2 * peers.len()
}
