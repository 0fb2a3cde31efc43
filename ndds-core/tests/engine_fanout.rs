//! The fan-out rule on one engine: every datagram the engine sends to the whole domain goes to
//! the group (unless multicast is off) and to every configured peer, once each.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ndds_core::discovery::{Destination, DiscoveryConfig, Engine, Via};

#[path = "support/probe.rs"]
mod probe;
use ndds_core::types::TypeDescription;
use ndds_core::wire::{
    self, Announce, EndpointInfo, EndpointQos, Guid, Locator, Message, MessageKind, NodeInfo,
    ProducerQosWire,
};
use probe::answer_probe;

fn locator(host: u8) -> Locator {
    Locator {
        addr: [10, 0, 0, host],
        port: 7850,
    }
}

fn producer(entity: u32) -> EndpointInfo {
    let type_desc = TypeDescription::of::<u8>();
    EndpointInfo {
        guid: Guid {
            participant: 7,
            entity,
        },
        topic: "t".into(),
        fingerprint: type_desc.fingerprint(),
        type_desc,
        qos: EndpointQos::Producer(ProducerQosWire::default()),
        locator: locator(1),
        pid: 1,
        process: "p".into(),
    }
}

/// Every datagram sent during a whole life (start-up solicits and announcement, a declaration,
/// a withdrawal, periodic refreshes, `Bye`), each with the destinations of its copies.
fn life(multicast: bool) -> Vec<(MessageKind, Vec<Destination>)> {
    let mut config = DiscoveryConfig::new(0, locator(1));
    config.multicast = multicast;
    // Duplicates and the node itself, as a shared config file lists them.
    config.peers = vec![locator(3), locator(1), locator(2), locator(3)];
    let now = Instant::now();
    let mut engine = Engine::new(config, now).unwrap();
    assert_eq!(engine.peers(), &[locator(2), locator(3)]);
    let mut sent: Vec<(Arc<[u8]>, Destination)> = Vec::new();
    let mut drain = |engine: &mut Engine| {
        sent.extend(
            std::iter::from_fn(|| engine.poll_transmit()).map(|t| (t.payload, t.destination)),
        );
    };
    for ms in [0, 200, 1000, 2500] {
        engine.handle_timeout(now + Duration::from_millis(ms));
        drain(&mut engine);
    }
    engine
        .add_local(now + Duration::from_millis(2500), producer(1))
        .unwrap();
    engine.remove_locals(&[producer(1).guid]);
    engine.close();
    drain(&mut engine);
    // Group the copies by datagram (they share their bytes).
    let mut by_datagram: BTreeMap<*const u8, (MessageKind, Vec<Destination>)> = BTreeMap::new();
    for (payload, destination) in &sent {
        let kind = wire::decode(payload).unwrap().0.kind;
        by_datagram
            .entry(payload.as_ptr())
            .or_insert((kind, Vec::new()))
            .1
            .push(*destination);
    }
    by_datagram.into_values().collect()
}

#[test]
fn every_domain_wide_datagram_also_goes_to_each_peer_once() {
    let datagrams = life(true);
    let expected = vec![
        Destination::Multicast,
        Destination::Unicast(locator(2)),
        Destination::Unicast(locator(3)),
    ];
    for kind in [
        MessageKind::Solicit,
        MessageKind::Announce,
        MessageKind::Withdraw,
        MessageKind::Bye,
    ] {
        assert!(datagrams.iter().any(|(k, _)| *k == kind), "{kind:?} sent");
    }
    for (kind, destinations) in &datagrams {
        assert_eq!(destinations, &expected, "{kind:?}");
    }
}

#[test]
fn with_multicast_off_nothing_goes_to_the_group() {
    let datagrams = life(false);
    assert!(datagrams.len() >= 8, "{datagrams:?}");
    for (kind, destinations) in &datagrams {
        assert_eq!(
            destinations,
            &[
                Destination::Unicast(locator(2)),
                Destination::Unicast(locator(3))
            ],
            "{kind:?}"
        );
    }
}

#[test]
fn a_node_heard_by_unicast_gets_copies_until_its_multicast_is_heard() {
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    let other = locator(5);
    let info = NodeInfo {
        hostname: "other".into(),
        pid: 1,
        unicast: other,
        lease_ms: 5000,
        announce_period_ms: 1000,
        version: String::new(),
    };
    let mut bytes = Vec::new();
    let announce = Message::Announce(Announce {
        node: info,
        endpoints: vec![],
        withdrawn: vec![],
    });
    wire::encode(0, 5, &announce, &mut bytes).unwrap();
    let from = SocketAddr::V4(other.into());
    let with_copy = vec![Destination::Multicast, Destination::Unicast(other)];

    engine.handle_datagram(now, from, Via::Unicast, &bytes);
    assert_eq!(
        engine.fanout(),
        vec![Destination::Multicast],
        "no copies to an address that has not answered its probe"
    );
    answer_probe(&mut engine, now, other, 0, 5);
    assert_eq!(engine.fanout(), with_copy, "heard by unicast only");
    engine.handle_datagram(now, from, Via::Multicast, &bytes);
    assert_eq!(
        engine.fanout(),
        vec![Destination::Multicast],
        "heard by multicast"
    );
    // Half a lease (2.5 s by default) without multicast, although unicast keeps coming.
    let later = now + Duration::from_millis(2500);
    engine.handle_datagram(later, from, Via::Unicast, &bytes);
    assert_eq!(
        engine.fanout(),
        with_copy,
        "multicast silent for half a lease"
    );
}

#[test]
fn a_forged_probe_reply_validates_nothing() {
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    let victim = locator(9);
    let solicit = Message::Solicit(wire::Solicit {
        node: NodeInfo {
            hostname: "spoofed".into(),
            pid: 1,
            unicast: victim,
            lease_ms: 5000,
            announce_period_ms: 1000,
            version: String::new(),
        },
    });
    let mut bytes = Vec::new();
    wire::encode(0, 9, &solicit, &mut bytes).unwrap();
    engine.handle_timeout(now);
    while engine.poll_transmit().is_some() {}
    engine.handle_datagram(now, SocketAddr::V4(victim.into()), Via::Unicast, &bytes);
    let mut guessed = Vec::new();
    wire::encode(
        0,
        9,
        &Message::ProbeReply(wire::ProbeReply { token: 42 }),
        &mut guessed,
    )
    .unwrap();
    engine.handle_datagram(now, SocketAddr::V4(victim.into()), Via::Unicast, &guessed);
    // Past the reply jitter: the victim got one probe, as small as the solicitation, and
    // nothing else.
    engine.handle_timeout(now + Duration::from_secs(1));
    let to_victim: Vec<_> = std::iter::from_fn(|| engine.poll_transmit())
        .filter(|t| t.destination == Destination::Unicast(victim))
        .collect();
    assert_eq!(to_victim.len(), 1, "{to_victim:?}");
    assert!(to_victim[0].payload.len() <= 3 * bytes.len());
    assert_eq!(
        wire::decode(&to_victim[0].payload).unwrap().0.kind,
        MessageKind::Probe
    );
    assert_eq!(engine.fanout(), vec![Destination::Multicast]);
}

/// A correct token validates an address only while its probe is outstanding and a known node
/// announces it: replies cannot fill the validated set with addresses of nobody.
#[test]
fn a_probe_reply_counts_only_for_a_live_node_and_an_outstanding_probe() {
    let now = Instant::now();
    let mut engine = Engine::new(DiscoveryConfig::new(0, locator(1)), now).unwrap();
    let other = locator(5);
    let from = SocketAddr::V4(other.into());
    let announce = Message::Announce(Announce {
        node: NodeInfo {
            hostname: "other".into(),
            pid: 1,
            unicast: other,
            lease_ms: 5000,
            announce_period_ms: 1000,
            version: String::new(),
        },
        endpoints: vec![],
        withdrawn: vec![],
    });
    let mut bytes = Vec::new();
    wire::encode(0, 5, &announce, &mut bytes).unwrap();
    engine.handle_datagram(now, from, Via::Unicast, &bytes);
    let token = std::iter::from_fn(|| engine.poll_transmit())
        .find_map(|t| match wire::decode(&t.payload) {
            Ok((_, Message::Probe(probe))) => Some(probe.token),
            _ => None,
        })
        .expect("a probe");
    // The node leaves; its probe's answer comes after.
    let mut bye = Vec::new();
    wire::encode(0, 5, &Message::Bye(wire::Bye), &mut bye).unwrap();
    engine.handle_datagram(now, from, Via::Unicast, &bye);
    let mut reply = Vec::new();
    wire::encode(
        0,
        5,
        &Message::ProbeReply(wire::ProbeReply { token }),
        &mut reply,
    )
    .unwrap();
    let invalid = engine.stats().dropped(wire::DropReason::Invalid);
    engine.handle_datagram(now, from, Via::Unicast, &reply);
    assert_eq!(
        engine.stats().dropped(wire::DropReason::Invalid),
        invalid + 1
    );
    // Back again: not validated by that old answer; a second answer to no probe counts as
    // nothing either.
    engine.handle_datagram(now, from, Via::Unicast, &bytes);
    assert_eq!(engine.fanout(), vec![Destination::Multicast]);
    answer_probe(&mut engine, now, other, 0, 5);
    assert_eq!(
        engine.fanout(),
        vec![Destination::Multicast, Destination::Unicast(other)]
    );
    engine.handle_datagram(now, from, Via::Unicast, &reply);
    assert_eq!(
        engine.stats().dropped(wire::DropReason::Invalid),
        invalid + 2
    );
}
